"""The calibration's report (``dem.calibrate``): calibration.csv (a row per set),
calibration_runs.csv (a row per run), the verdict (``_verdict``) and report.md (``_report``)."""
from __future__ import annotations

import itertools
import os

import numpy as np

from common.io import atomic_write_bytes

from .search import MARGIN_SIGMAS
from .targets import FIGURE_TEXT, SECANT_STRAIN, TOLERANCES, _fmt_figs, _fmt_values

# the figures, their errors and met flags, met and score (summary.json's best and start)
FIGURE_COLS = (list(TOLERANCES) + ["err_" + k for k in TOLERANCES]
               + ["met_" + k for k in TOLERANCES] + ["met", "score"])
CSV_FIXED = FIGURE_COLS + ["eps1_peak", "past_peak", "peak_q_raw"] + [
    "spread_" + k for k in TOLERANCES] + ["porosity", "steps", "wall_time", "runs",
                                          "decided_by", "stopped_at", "censored"]
RUN_FIXED = list(TOLERANCES) + ["eps1_peak", "past_peak", "peak_q_raw", "porosity", "steps",
                                "wall_time"]


def _spread(records):
    """The seeds' spread of each figure over the sets run on more than one seed: mean and
    largest (max - min) / mean."""
    out = {}
    records = [r for r in records if len(r["seeds"]) > 1]
    if not records:
        return {}
    for k in TOLERANCES:
        v = [r["spread_" + k] for r in records]
        out[k] = {"mean": float(np.mean(v)), "max": float(np.max(v)), "tolerance": TOLERANCES[k]}
    return out


def censored_text(censored):
    """calibration.csv's text of a record's "censored" ({figure: how}): "peak_q at least,
    dilatancy unknown"; "" when every figure is exact."""
    return ", ".join(f"{k} {how}" for k, how in (censored or {}).items())


def censored_of(text):
    """The "censored" dict of ``censored_text``'s text."""
    return dict(part.split(" ", 1) for part in str(text or "").split(", ") if part)


def _cell(v):
    return int(v) if isinstance(v, bool) else ("" if v is None else v)


def _write_csv(out_dir, space, records, hfig):
    from .. import io
    cols = ["kind", "index", "stage"] + list(space.names) + CSV_FIXED
    target = {**hfig, "score": 0.0, "met": True, "past_peak": True,
              **{f"{p}_{k}": v for k in TOLERANCES for p, v in (("err", 0.0), ("met", True),
                                                                ("spread", 0.0))}}
    rows = [["hmodel", "", "target"] + [""] * len(space.names)
            + [_cell(target.get(c)) for c in CSV_FIXED]]
    target.update(runs="", decided_by="", stopped_at="", censored="")
    for r in sorted(records, key=lambda r: r["index"]):
        more = {"runs": len(r["seeds"]), "decided_by": "+".join(r.get("decided_by") or []),
                "stopped_at": r.get("stopped_at"), "censored": censored_text(r.get("censored"))}
        rows.append(["dem", r["index"], r["stage"]] + list(r["values"])
                    + [_cell(more[c] if c in more else r[c]) for c in CSV_FIXED])
    io.write_csv(os.path.join(out_dir, "calibration.csv"), cols, rows)


def _write_runs_csv(out_dir, space, records, check, best):
    """A row per run: the set's index and stage, the seed, the figures of that run alone."""
    from .. import io
    cols = ["index", "stage", "seed"] + list(space.names) + RUN_FIXED
    rows = [[r["index"], r["stage"], p["seed"]] + list(r["values"])
            + [_cell(p.get(c)) for c in RUN_FIXED] for r in records for p in r["seeds"]]
    rows += [[best["index"], "check", c["seed"]] + list(best["values"])
             + [_cell(c.get(k, "")) for k in RUN_FIXED] for c in check]
    io.write_csv(os.path.join(out_dir, "calibration_runs.csv"), cols, rows)


def _verdict(space, records, best, hfig, why, info, check, check_mean=None):
    """Which targets the best set meets, why the search stopped, what the model says of the
    box (reachable or not, the targets no set meets, the pairs no set meets together), for each
    target the best set misses the closest any set came, and the check on the other seeds: its
    verdict the mean over them (``check_mean``), each seed's figures beside it."""
    lines = []
    for k, tol in TOLERANCES.items():
        e = best["err_" + k]
        line = {"figure": FIGURE_TEXT[k], "target": hfig[k], "best_value": best[k], "error": e,
                "tolerance": tol, "met": best["met_" + k]}
        if not best["met_" + k]:
            c = min((r for r in records if k not in (r.get("censored") or {})),
                    key=lambda r: (abs(r["err_" + k]), r["index"]))
            line["closest"] = {"index": c["index"], "error": c["err_" + k], "met": c["met_" + k],
                               "params": dict(zip(space.names, c["values"]))}
        lines.append(line)
    pairs = {f"{a}+{b}": any(r["met_" + a] and r["met_" + b] for r in records)
             for a, b in itertools.combinations(TOLERANCES, 2)}
    text = []
    if best["met"]:
        text.append(f"all targets met with {_fmt_values(space.names, best['values'])} "
                    f"(mean of the seeds; stopped: {why})")
    else:
        miss = [l["figure"] for l in lines if not l["met"]]
        text.append(f"targets NOT all met: {', '.join(miss)} missed by the best set "
                    f"({_fmt_values(space.names, best['values'])}); stopped: {why}")
    if info is not None and not best["met"]:
        if not info["reachable"]:
            un = ", ".join(FIGURE_TEXT[k] for k in info["unreachable_targets"]) or "none"
            cf = "; ".join(" and ".join(FIGURE_TEXT[k] for k in p.split("+"))
                           for p in info["conflicts"]) or "none"
            text.append(f"the model of the figures (leave-one-out errors "
                        f"{_fmt_loo(info['loo'])}) shows that no set within the bounds meets "
                        f"every target, even with each widened by the model's error bar "
                        f"({MARGIN_SIGMAS:g} of those errors, growing with the distance to the "
                        f"sets evaluated): the least miss is {info['least_miss']:.2f} "
                        f"tolerance half-widths beyond it; targets no set meets alone: {un}; "
                        f"pairs no set meets together: {cf}; best predicted score "
                        f"{info['predicted_score']:.3g}")
        elif info["predicted_met"]:
            text.append(f"the model still predicts sets that meet every target (least "
                        f"predicted score {info['predicted_score']:.3g}): a larger --max-evals "
                        "continues the same search")
        else:
            text.append(f"the model predicts no set that meets every target (least predicted "
                        f"score {info['predicted_score']:.3g}) but cannot rule one out within "
                        "its error bar: a larger --max-evals continues the same search")
    for l in lines:
        s = (f"{l['figure']}: {l['best_value']:.4g} vs {l['target']:.4g} ({l['error']:+.1%}, "
             f"tolerance {l['tolerance']:.0%}) {'met' if l['met'] else 'NOT met'}")
        if "closest" in l:
            c = l["closest"]
            s += (f"; closest of all sets {c['error']:+.1%} (set {c['index']}, "
                  f"{_fmt_values(c['params'], c['params'].values())})")
        text.append(s)
    if check_mean is not None:
        miss = [FIGURE_TEXT[k] for k in TOLERANCES if not check_mean["met_" + k]]
        text.append(f"check, the mean of seeds {','.join(map(str, check_mean['seeds']))} (not "
                    f"fitted on): {_fmt_figs(check_mean)}: "
                    + ("meets all targets" if check_mean["met"]
                       else f"NOT all targets met (missed: {', '.join(miss)})"))
    for c in check:
        text.append(f"check on seed {c['seed']} (not fitted on), one sample: {_fmt_figs(c)}: "
                    f"{'meets all targets' if c['met'] else 'NOT all targets met'}")
    return {"lines": lines, "pairs_met_together": pairs, "text": text}


def _fmt_loo(loo):
    return ", ".join(f"{k} {v:.1%}" for k, v in loo.items())


def _report(out_dir, s, space, records):
    """report.md: the targets, the best set and its seeds, the check, the score against each
    parameter, the seeds' spread, the model and the identifiability."""
    from .. import io
    hf, b = s["target_figures"], s["best"]
    L = ["# Calibration of the DEM against the H-model's drained biaxial test", "",
         f"`python -m dem calibrate`: n = {s['options']['n']}, seeds "
         f"{', '.join(map(str, s['options']['seeds']))}, varied "
         f"{', '.join(space.names)} over "
         + ", ".join(f"{n} [{lo:.4g}, {hi:.4g}]{' (log)' if lg else ''}"
                     for n, lo, hi, lg in zip(space.names, space.lo, space.hi, space.log))
         + f"; {s['evaluations']} sets, {s['runs']} runs ({s['run_now']} run by this "
           f"invocation in {s['wall_time'] / 60:.1f} min, {s['taken_from_checkpoint']} taken "
           f"from the checkpoint); stopped: **{s['stopped']}**.", "",
         "## Targets (H-model, Table I) and the best set (mean of the seeds)", "",
         "| figure | H-model | tolerance | best set | error |", "|---|---|---|---|---|"]
    units = {"peak_q": (1e-3, "kPa"), "eps1_95": (100, "%"), "secant": (1e-6, "MPa"),
             "dilatancy": (1, "-")}
    for k, tol in TOLERANCES.items():
        f, u = units[k]
        L.append(f"| {FIGURE_TEXT[k]} [{u}] | {hf[k] * f:.4g} | {tol:.0%} | {b[k] * f:.4g} | "
                 f"{b['err_' + k]:+.1%} {'met' if b['met_' + k] else 'NOT met'} |")
    L += ["", "Best set: " + _fmt_values(space.names, b["values"]) + f" (set {b['index']}, "
          f"{b['stage']}); eps1 at the peak itself {100 * b['eps1_peak']:.2f} % (H-model "
          f"{100 * hf['eps1_peak']:.2f} %; not a target: a plateau makes it arbitrary).", "",
          "| seed | peak q [kPa] | eps1 at 95 % [%] | secant [MPa] | dilatancy ratio [-] | "
          "eps1 at the peak [%] | porosity | fitted on |", "|---|---|---|---|---|---|---|---|"]
    for p in s["best_seeds"]:
        L.append(f"| {p['seed']} | {p['peak_q'] / 1e3:.1f} | {100 * p['eps1_95']:.3f} | "
                 f"{p['secant'] / 1e6:.1f} | {p['dilatancy']:.3f} | {100 * p['eps1_peak']:.2f} | "
                 f"{p['porosity'] if p['porosity'] is None else round(p['porosity'], 4)} | yes |")
    for c in s["check"]:
        L.append(f"| {c['seed']} | {c['peak_q'] / 1e3:.1f} ({c['err_peak_q']:+.1%}) | "
                 f"{100 * c['eps1_95']:.3f} ({c['err_eps1_95']:+.1%}) | {c['secant'] / 1e6:.1f} "
                 f"({c['err_secant']:+.1%}) | {c['dilatancy']:.3f} ({c['err_dilatancy']:+.1%}) | "
                 f"{100 * c['eps1_peak']:.2f} | "
                 f"{c['porosity'] if c['porosity'] is None else round(c['porosity'], 4)} | "
                 f"no (check: {'met' if c['met'] else 'NOT met'}) |")
    cm = s.get("check_mean")
    if cm is not None:
        L.append(f"| mean of {', '.join(map(str, cm['seeds']))} | {cm['peak_q'] / 1e3:.1f} "
                 f"({cm['err_peak_q']:+.1%}) | {100 * cm['eps1_95']:.3f} "
                 f"({cm['err_eps1_95']:+.1%}) | {cm['secant'] / 1e6:.1f} ({cm['err_secant']:+.1%}) "
                 f"| {cm['dilatancy']:.3f} ({cm['err_dilatancy']:+.1%}) | "
                 f"{100 * cm['eps1_peak']:.2f} | | no: **the check, "
                 f"{'met' if cm['met'] else 'NOT met'}** |")
    L += ["", "![curves](calibration.png)", "", "## The verdict", ""]
    L += [f"- {t}" for t in s["verdict"]["text"]]
    L += ["", "## The score against each parameter", "",
          "Dots: the sets evaluated (mean of the seeds; filled: all targets met); line: the "
          "model's least predicted score over the other parameters.", "",
          "![score](calibration_score.png)", "", "![search](calibration_search.png)", "",
          "## The runs each set cost", ""]
    sr = s.get("seed_rule")
    if sr is not None:
        n_seeds = len(s["options"]["seeds"])
        first = [r for r in records if r.get("decided_by")]
        if not sr["decide_on_first_run"]:
            L.append(f"Every set on all {n_seeds} seeds (--no-first-run-decision).")
        else:
            sig = ", ".join(f"{FIGURE_TEXT[k]} {v:.1%}" for k, v in sr["one_run_scatter"].items())
            L += [f"Every set on its first seed, then on the other {n_seeds - 1} only where that "
                  f"run leaves the mean over the {n_seeds} seeds undecided: a figure is decided "
                  f"missed on one run where its error exceeds its tolerance by {sr['z']:g} "
                  f"predictive standard deviations of the {n_seeds}-seed mean (a run's scatter "
                  f"at n = {s['options']['n']}: {sig}; docs/dem.md). {len(first)} of "
                  f"{len(records)} sets were decided on one run, {sr['runs_saved']} runs "
                  "saved:", "", "| set | stage | runs | decided missed on its first run |",
                  "|---|---|---|---|"]
            if sr.get("stop_decided_runs"):
                L[-3:] = [
                    L[-3], "", f"A first run (but the start set's) stopped once its records "
                    f"decided a target missed (--stop-decided-runs: the secant modulus is exact "
                    f"from {100 * SECANT_STRAIN:g} % of axial strain, peak q and eps1_95 known "
                    "from below, the dilatancy ratio not at all): "
                    f"{sr['runs_stopped']} runs stopped, {sr['runs_completed']} of them run on "
                    "to their end where the model of the figures lacked a figure (it needs each "
                    "on the number of --vary fields + 2 sets); the other sets' figures enter "
                    "the model as bounds or not at all:", "",
                    "| set | stage | runs | decided missed on its first run | its first run |",
                    "|---|---|---|---|---|"]
                L += [f"| {r['index']} | {r['stage']} | {len(r['seeds'])} | "
                      f"{', '.join(FIGURE_TEXT[k] for k in r.get('decided_by') or []) or '-'} | "
                      + (f"stopped at {100 * r['stopped_at']:.3f} % |" if r.get("censored") else
                         f"stopped, then run on to its end ({r['run_on']}) |"
                         if r.get("run_on") else "whole |")
                      for r in sorted(records, key=lambda r: r["index"])]
            else:
                L += [f"| {r['index']} | {r['stage']} | {len(r['seeds'])} | "
                      f"{', '.join(FIGURE_TEXT[k] for k in r.get('decided_by') or []) or '-'} |"
                      for r in sorted(records, key=lambda r: r["index"])]
    L += ["", "## The seeds' spread", "",
          "(max - min) / mean of each figure over the seeds of a set, over the sets run on more "
          "than one seed:", "",
          "| figure | mean | largest | tolerance |", "|---|---|---|---|"]
    for k, v in s["seeds_spread"].items():
        L.append(f"| {FIGURE_TEXT[k]} | {v['mean']:.1%} | {v['max']:.1%} | {v['tolerance']:.0%} |")
    sc = s.get("sample_scatter")
    if sc is not None:
        n_fit, n_check = len(s["options"]["seeds"]), len(s["check"])
        L += ["", "## A sample's scatter", "",
              f"The best set's {next(iter(sc.values()))['runs']} runs (the seeds fitted on and "
              "the check seeds): the relative standard deviation of one run's figure about "
              f"their mean, and the standard errors of the mean over the {n_fit} seeds fitted "
              f"on and over the {n_check} check seeds. A target is a set's mean: the check "
              "compares the check seeds' mean with it, as the fit compares its seeds' mean.", "",
              "| figure | one run (sd / mean) | mean of the fit | mean of the check | "
              "tolerance |", "|---|---|---|---|---|"]
        for k, v in sc.items():
            se_c = "" if v["se_check"] is None else f"{v['se_check']:.1%}"
            L.append(f"| {FIGURE_TEXT[k]} | {v['sd']:.1%} | {v['se_fit']:.1%} | {se_c} | "
                     f"{v['tolerance']:.0%} |")
    m = s["model"]
    if m is not None:
        L += ["", "## The model of the figures", "",
              f"Leave-one-out error of log(figure): {_fmt_loo(m['loo'])}; smoothing "
              + ", ".join(f"{k} {v:g}" for k, v in m["smoothing"].items())
              + f". Least predicted score {m['predicted_score']:.3g} at "
              + _fmt_values(space.names, space.values(m["u_best"]))
              + f"; a set predicted to meet every target: "
                f"{'yes' if m['predicted_met'] else 'no'}; one not ruled out within the error "
                f"bar: {'yes' if m['reachable'] else 'no'}; largest slopes of log(figure) "
                "between neighbouring sets (per unit of u): "
              + ", ".join(f"{k} {v:.3g}" for k, v in m["slope"].items())
              + "; targets no set meets: "
              + (", ".join(m["unreachable_targets"]) or "none") + "; pairs no set meets "
                "together: " + (", ".join(m["conflicts"]) or "none") + "."]
    idt = s["identifiability"]
    if idt is not None:
        L += ["", "## Identifiability at the best set", "",
              "Change of each figure, in tolerances, for a change of 10 % of each parameter's "
              "range (the model's derivatives):", "",
              "| figure | " + " | ".join(space.names) + " |",
              "|---" * (len(space.names) + 1) + "|"]
        for k, row in idt["sensitivity"].items():
            L.append(f"| {FIGURE_TEXT[k]} | " + " | ".join(f"{0.1 * v:+.2f}" for v in row.values())
                     + " |")
        sv = idt["singular_values"]
        L += ["", "Singular values of that matrix (per unit of u): "
              + ", ".join(f"{v:.3g}" for v in sv)
              + (f"; condition {sv[0] / sv[-1]:.3g}." if sv[-1] > 0 else ".")]
        if idt["met_region"]:
            L += ["", f"The region where the model predicts every target met "
                      f"({idt['met_region_share']:.2%} of the box) spans:", ""]
            for n, (lo, hi) in idt["met_region"].items():
                j = space.names.index(n)
                share = abs(space.u_of_axis(j, hi) - space.u_of_axis(j, lo))
                L.append(f"- {n}: {lo:.4g} to {hi:.4g} ({share:.0%} of its range: "
                         f"{'fixed by the targets' if share <= 0.25 else 'not fixed' if share >= 0.6 else 'partly fixed'})")
        else:
            L += ["", "The model predicts no region where every target is met."]
    atomic_write_bytes(os.path.join(out_dir, "report.md"), ("\n".join(L) + "\n").encode())
