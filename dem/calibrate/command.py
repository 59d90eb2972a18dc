"""The calibration's command (``dem.calibrate``, ``python -m dem calibrate``):
``run_calibration`` checks its options (``CalibrationOptions``), drives the search over batches of DEM runs spread over
processes or a dask cluster, takes the runs of the checkpoint on a resume, and writes the files,
the figures and the summary."""
from __future__ import annotations

import json
import os
import shutil
import sys
import time

import numpy as np

from common.io import atomic_write_bytes

from ..params import DemParams, record_params, save_params
from .evaluation import (STOPPED, _check_mean, _combine, _evaluate_task, _header, _log,
                         _past_peak, done_key,
                         _sample_scatter, params_key, read_checkpoint)
from .options import CalibrationOptions
from .figures import _figure, _score_figure, _search_figure
from .report import FIGURE_COLS, _report, _spread, _verdict, _write_csv, _write_runs_csv
from .search import (dense_points, identifiability, make_space, model_of,
                     surrogate_search)
from .targets import (DECIDE_Z, DILATANCY_STRAIN, PEAK_FRACTION, SECANT_STRAIN, TOLERANCES,
                      _fmt_figs, _fmt_values, compare, curve_figures, first_run_decides,
                      hmodel_curve, one_run_scatter)


def _say(verbose, msg):
    if verbose:
        print(msg, file=sys.stderr, flush=True)


_D = CalibrationOptions()        # the defaults of the keywords: the record's


def run_calibration(out_dir, base: DemParams, vary=None, bounds=_D.bounds, target=_D.target,
                    seeds=_D.seeds, check_seeds=_D.check_seeds, initial=_D.initial,
                    batch=_D.batch, max_evals=_D.max_evals, rate=_D.rate,
                    confining=_D.confining, eps_max=_D.eps_max,
                    post_peak_strain=_D.post_peak_strain, smooth=_D.smooth,
                    decide_on_first_run=_D.decide_on_first_run,
                    stop_decided_runs=_D.stop_decided_runs, workers=None,
                    scheduler=None, resume=False, verbose=True, task=None, stage=None,
                    params_note=None, options: CalibrationOptions | None = None,
                    allow_soft=False):
    """Fit the fields ``vary`` of ``base`` (the start set) to the target's drained biaxial test
    (module docstring), every set on the first of ``seeds`` and on the others where that run
    does not decide it missed (``targets.first_run_decides``; on each without
    ``decide_on_first_run``), the
    best one then on ``check_seeds``. ``stop_decided_runs``: a first run (but the start set's)
    stops as soon as its records decide (``targets.InRunDecision``), its figures then known in
    part (``search.FigureModel``'s censored values); the search runs such a set on to its end
    where the model lacks a figure (``search.to_complete``).
    The options of the search and of each test (``vary`` to ``smooth``; ``vary`` None: the
    default --vary) may be given as keywords or as one ``options`` record
    (``CalibrationOptions``), not both; either way ``CalibrationOptions.validate`` checks them
    first (the command line's rule: ValueError of one line naming the option, nothing written).
    Writes out_dir/evaluations.jsonl (checkpoint), calibration.csv (a row per set),
    calibration_runs.csv (a row per run), params.json (a parameter file: the start set
    ``base``; ``params_note`` says where it came from), calibrated.json (the best set, with the
    first seed), curves.csv, calibration.png, calibration_search.png, calibration_score.png,
    report.md and summary.json; returns the summary.  ``max_evals`` counts parameter sets (each
    one run or len(seeds) runs).  ``task``: the run function (default: the DEM run
    ``_evaluate_task``; tests pass a cheap one).  ``stage``: an ``common.options.Stage`` told
    where the run is and what it has written (for the line of an interrupted command).
    ``allow_soft``: search a space whose softest set lies outside the granular regime at
    ``confining`` (``dem.regime.softest``, ``check_regime``; refused otherwise, before anything is
    written); summary.json records the regime of that set (``regime``)."""
    t0 = time.time()
    keywords = dict(bounds=bounds, target=target, seeds=seeds, check_seeds=check_seeds,
                    initial=initial, batch=batch, max_evals=max_evals, rate=rate,
                    confining=confining, eps_max=eps_max, post_peak_strain=post_peak_strain,
                    smooth=smooth, decide_on_first_run=decide_on_first_run,
                    stop_decided_runs=stop_decided_runs)
    if options is None:
        options = CalibrationOptions(**keywords, **({} if vary is None else {"vary": vary}))
    elif vary is not None or any(v != getattr(_D, k) for k, v in keywords.items()):
        given = (["vary"] if vary is not None else []) + [k for k, v in keywords.items()
                                                          if v != getattr(_D, k)]
        raise TypeError(f"run_calibration: options= and the keywords {', '.join(given)}; "
                        "allowed one of them")
    o = options.validate(base)
    target, vary, bounds, seeds, check_seeds = o.target, o.vary, o.bounds, o.seeds, o.check_seeds
    initial, batch, max_evals, rate, confining = (o.initial, o.batch, o.max_evals, o.rate,
                                                  o.confining)
    eps_max, post_peak_strain, smooth = o.eps_max, o.post_peak_strain, o.smooth
    space = make_space(vary, base, bounds)
    from ..regime import check_regime, softest
    soft_set, where = softest(space, base)
    regime = check_regime(soft_set, confining, allow_soft, where, "--sigma2")
    header = _header(target, space, base, seeds, initial, batch, max_evals, rate, confining,
                     eps_max, post_peak_strain, smooth)
    stops = o.stop_decided_runs and o.decide_on_first_run and len(seeds) > 1
    if stops:       # another search: a checkpoint made without it is not resumed with it
        header["stop_decided_runs"] = True
    ck = os.path.join(out_dir, "evaluations.jsonl")
    work = os.path.join(out_dir, "work")
    notes = []
    done = read_checkpoint(ck, header, notes) if resume else {}
    th = time.time()
    hcurve = hmodel_curve(confining, eps_max)
    # the H-model's curve is smooth (1e-5 strain steps): its figures are taken raw; the moving
    # average is for the DEM's noise only
    hfig = curve_figures(hcurve["eps1"], hcurve["q"], 0.0, eps_v=hcurve["eps_v"])
    if hfig["eps1_peak"] >= 0.98 * hcurve["eps1"][-1]:
        raise RuntimeError(f"the {target}'s curve has no peak before eps1 = "
                           f"{hcurve['eps1'][-1]:g} at --sigma2 {confining:g}")
    _say(verbose, f"[calibrate] target {target}: peak q = {hfig['peak_q'] / 1e3:.1f} kPa (at "
                  f"eps1 = {100 * hfig['eps1_peak']:.2f} %), {PEAK_FRACTION:.0%} of it first at "
                  f"eps1 = {100 * hfig['eps1_95']:.3f} %, secant at {100 * SECANT_STRAIN:g} % = "
                  f"{hfig['secant'] / 1e6:.1f} MPa, dilatancy ratio 1 - d eps_v/d eps1 over "
                  f"{100 * DILATANCY_STRAIN:g} % after it = {hfig['dilatancy']:.3f} "
                  f"({time.time() - th:.1f} s); every set on "
                  + (f"seed {seeds[0]}, and on seeds {','.join(map(str, seeds[1:]))} unless that "
                     "run decides it missed" if o.decide_on_first_run and len(seeds) > 1 else
                     f"seeds {','.join(map(str, seeds))}")
                  + ("; a first run stops once its records decide" if stops else ""))
    # -- from here on, files are written
    from .. import io
    os.makedirs(out_dir, exist_ok=True)
    record_params(out_dir, base, "python -m dem calibrate: the start set (the best set is "
                  "calibrated.json)" + (f"; {params_note}" if params_note else ""))
    if not resume and os.path.exists(ck):
        os.replace(ck, os.path.join(out_dir, "evaluations.previous.jsonl"))
        _say(verbose, f"[calibrate] {out_dir} held an earlier calibration: moved to "
                      "evaluations.previous.jsonl (--resume continues one)")
    atomic_write_bytes(ck, ("\n".join([json.dumps({"header": header})]
                                         + [json.dumps(r) for r in done.values()]) + "\n").encode())
    for note in notes:
        _say(verbose, f"[calibrate] {note}")
    if done:
        _say(verbose, f"[calibrate] --resume: {len(done)} finished runs in {ck} (not run again)")
    records = []            # in search order
    counts = {"run": 0, "taken": 0}
    stop_rule = {"target": {k: hfig[k] for k in TOLERANCES}, "n_seeds": len(seeds),
                 "smooth": smooth}
    sink = open(ck, "a")
    task = task or _evaluate_task
    where = stage

    def run_sets(points, stage, set_seeds, which=None, stop=False):
        """Runs of the points ``which`` (indices into points; default all) on every seed of
        set_seeds: {(i, seed): result}. ``stop``: each run stops once its records decide
        (``InRunDecision``); otherwise a run stopped so before is run on to its end."""
        got = {}
        tasks = []
        for i, v in enumerate(points):
            if which is not None and i not in which:
                continue
            for s in set_seeds:
                d = space.params(base, v).replace(seed=s).to_dict()
                key = params_key(d)
                full, cut = done.get(key), done.get(key + STOPPED)
                if full is None and cut is None and resume:
                    # finished in work/ but not logged before the interruption
                    try:
                        with open(os.path.join(work, key, "result.json")) as f:
                            res = json.load(f)
                        _log(sink, res)
                        done[done_key(res)] = res
                        if res.get("stopped"):
                            cut = res
                        else:
                            full = res
                            shutil.rmtree(os.path.join(work, key), ignore_errors=True)
                    except (OSError, ValueError):
                        pass
                # a stopped run is what a run allowed to stop gave; one not allowed to goes on
                res = (cut or full) if stop else full
                on = not stop and full is None and cut is not None
                if res is not None:
                    counts["taken"] += 1
                    got[(i, s)] = res
                    continue
                wd = None if scheduler else os.path.join(work, key)
                tasks.append(((i, s), {"key": key, "params": d, "rate": rate,
                                       "confining": confining, "eps_max": eps_max,
                                       "post_peak_strain": post_peak_strain, "work_dir": wd,
                                       "resume": bool(resume or on),
                                       "stop": stop_rule if stop else None,
                                       "allow_soft": bool(allow_soft)}))

        def collect(tag, res):
            _log(sink, res)
            done[done_key(res)] = res
            got[tag] = res
            counts["run"] += 1
            wd = os.path.join(work, res["key"])
            if os.path.isdir(wd) and not res.get("stopped"):    # a stopped run's may go on
                shutil.rmtree(wd, ignore_errors=True)
            if verbose:
                i, s = tag
                if res.get("stopped"):
                    what = (f"stopped at eps1 = {100 * res['stopped']['eps1']:.3f} %: it "
                            f"decides {', '.join(res['stopped']['figures'])} missed")
                else:
                    r = curve_figures(res["curve"]["eps1"], res["curve"]["q"], smooth,
                                      eps_v=res["curve"]["eps_v"])
                    r.update(compare(r, hfig))
                    what = _fmt_figs(r)
                _say(True, f"[calibrate] {stage} set {set_index(points[i], i)}, seed {s} "
                           f"({counts['run']} runs so far, at most {max_evals} sets): "
                           f"{_fmt_values(space.names, points[i])}: {what}; run "
                           f"{res['wall_time']:.0f} s, elapsed {time.time() - t0:.0f} s")

        if where is not None:
            where.at(f"dem calibrate, {stage} batch after {len(records)} sets (run it again "
                     "with --resume to continue: finished runs are not rerun)")
        if tasks and verbose:
            _say(True, f"[calibrate] {stage}: {len(tasks)} runs"
                       + (f", {len(got)} taken from the checkpoint" if got else ""))
        from ..probes import _map
        _map(tasks, collect, workers, scheduler, fn=task)
        return got

    def set_index(v, i):
        """The index of the set of values v, the i-th of its batch: its record's, or where the
        batch puts it."""
        return next((r["index"] for r in records if tuple(r["values"]) == tuple(v)),
                    len(records) + i)

    def first_run(res):
        """The figures a set's first run decides as missed by its seeds' mean (none with
        --no-first-run-decision): ``targets.first_run_decides`` (a stopped run: those its
        records decided)."""
        if not o.decide_on_first_run:
            return []
        if res.get("stopped"):
            return list(res["stopped"]["figures"])
        fig = curve_figures(res["curve"]["eps1"], res["curve"]["q"], smooth,
                            eps_v=res["curve"]["eps_v"])
        err = compare(fig, hfig)
        return first_run_decides({k: err["err_" + k] for k in TOLERANCES}, len(seeds),
                                 base.n)

    def on_seeds(points, stage, stop=False):
        """Every set of points on its first seed (``stop``: a run stops once decided), then on
        the other seeds where that run leaves the set's mean undecided (on every seed at once
        with --no-first-run-decision): (runs {(i, seed): result}, {i: figures decided})."""
        if not o.decide_on_first_run:
            got = run_sets(points, stage, seeds)    # one batch: every run at once
        else:
            got = run_sets(points, stage, seeds[:1], stop=stop)
        decided = {i: first_run(got[(i, seeds[0])]) for i in range(len(points))}
        rest = [i for i in range(len(points)) if not decided[i]]
        if len(seeds) > 1 and rest and o.decide_on_first_run:
            got.update(run_sets(points, stage, seeds[1:], which=set(rest)))
        return got, decided

    def combined(got, i, decided):
        """The record of set i from its runs ``got``: its first seed's alone where decided."""
        used = seeds[:1] if decided else seeds
        return _combine([got[(i, s)] for s in used], used, smooth, post_peak_strain, hfig)

    def evaluate(points, stage):
        # the start set runs whole: the report shows its curve beside the best's
        got, decided = on_seeds(points, stage, stop=stops and stage != "start")
        out = []
        for i, v in enumerate(points):
            rec = combined(got, i, decided[i])
            rec.update(index=len(records), stage=stage, values=list(v), decided_by=decided[i])
            assert not (decided[i] and rec["met"])    # a decided figure misses its tolerance
            records.append(rec)
            out.append(rec)
            how = (f"seed {seeds[0]} alone (it decides {', '.join(decided[i])} missed by the "
                   f"mean of {len(seeds)})" if decided[i] else
                   f"mean of seeds {','.join(map(str, seeds))}")
            _say(verbose, f"[calibrate] set {rec['index']} ({stage}), {how}: {_fmt_figs(rec)}; "
                          f"score {rec['score']:.3g}"
                          f"{'; MEETS ALL TARGETS' if rec['met'] else ''}")
        _write_csv(out_dir, space, records, hfig)
        if where is not None and not where.written:
            where.wrote("evaluations.jsonl (every finished run)", "calibration.csv")
        return out

    def complete(points, stage):
        """Sets whose first run stopped once decided, run on to the end of that run (from its
        checkpoint: the rows of a run never stopped) and, where the whole run no longer
        decides (never seen: what a stop decides stays decided), on the other seeds; each
        record replaced in place."""
        got, decided = on_seeds(points, stage)
        out = []
        for i, v in enumerate(points):
            old = next(r for r in records if tuple(r["values"]) == tuple(v))
            rec = combined(got, i, decided[i])
            rec.update(index=old["index"], stage=old["stage"], values=old["values"],
                       decided_by=decided[i], run_on=stage)
            records[old["index"]] = rec
            out.append(rec)
            _say(verbose, f"[calibrate] set {rec['index']} ({old['stage']}) run on to its end "
                          f"({stage}: the model lacks its figures): {_fmt_figs(rec)}; score "
                          f"{rec['score']:.3g}")
        _write_csv(out_dir, space, records, hfig)
        return out

    try:
        start = tuple(getattr(base, f) for f in space.names)
        best, seen, trace, why, info = surrogate_search(
            space, evaluate, hfig, start=start, initial=initial, max_evals=max_evals, batch=batch,
            complete=complete if stops else None)
        if best["decided_by"]:
            # the search ended without a met set and its best was run on one seed: its figures
            # are its seeds' mean like every reported set's (and the check's reference)
            got = run_sets([tuple(best["values"])], "best", seeds)
            full = _combine([got[(0, s)] for s in seeds], seeds, smooth, post_peak_strain, hfig)
            full.update(index=best["index"], stage=best["stage"], values=best["values"],
                        decided_by=[], completed=True,
                        **({"run_on": "best"} if best.get("censored") else {}))
            records[best["index"]] = full
            best = full
        check = []
        check_mean = None
        if check_seeds:
            got = run_sets([tuple(best["values"])], "check", check_seeds)
            for s in check_seeds:
                res = got[(0, s)]
                fig = curve_figures(res["curve"]["eps1"], res["curve"]["q"], smooth,
                                    eps_v=res["curve"]["eps_v"])
                check.append({"seed": s, **fig, **compare(fig, hfig),
                              "past_peak": _past_peak(res["curve"], post_peak_strain),
                              "porosity": res.get("porosity"), "wall_time": res["wall_time"],
                              "curve": res["curve"]})
                _say(verbose, f"[calibrate] check: the best set on seed {s} (not fitted on): "
                              f"{_fmt_figs(check[-1])}"
                              f"{'; meets all targets' if check[-1]['met'] else ''}")
            check_mean = _check_mean(check, hfig)
            _say(verbose, f"[calibrate] check: the best set, mean of seeds "
                          f"{','.join(map(str, check_seeds))} (not fitted on): "
                          f"{_fmt_figs(check_mean)}"
                          f"{'; MEETS ALL TARGETS' if check_mean['met'] else ''}")
    finally:
        sink.close()
    start_rec = records[0]
    _write_csv(out_dir, space, records, hfig)
    _write_runs_csv(out_dir, space, records, check, best)
    best_params = DemParams.from_dict(best["params"])
    save_params(os.path.join(out_dir, "calibrated.json"), best_params,
                f"python -m dem calibrate: the best set of {len(records)} ({why}), fitted on "
                f"seeds {','.join(map(str, seeds))}")
    paper = DemParams(n=base.n, seed=base.seed)
    start_label = "DEM, paper set" if base == paper else "DEM, start set"
    curves = ([("hmodel", "", hcurve)]
              + [("dem_start", s, c) for s, c in zip(seeds, start_rec["curves"])]
              + [("dem_calibrated", s, c) for s, c in zip(seeds, best["curves"])]
              + [("dem_calibrated_check", c["seed"], c["curve"]) for c in check])
    io.write_csv(os.path.join(out_dir, "curves.csv"), ["curve", "seed", "eps1", "q", "eps_v"],
                 [[name, s, e, q, v] for name, s, c in curves
                  for e, q, v in zip(c["eps1"], c["q"], c["eps_v"])])
    ident = None
    model = None
    model = model_of(space, [(r["values"], r) for r in records], hfig)
    if model is not None:
        dense = dense_points(len(space.names), 1)
        ub = space.u_of(tuple(best["values"]))
        if ub is not None:
            ident = identifiability(model, space, ub, dense)
    _figure(out_dir, hcurve, hfig, start_rec, best, check, start_label, space, check_mean)
    _search_figure(out_dir, space, records, best)
    if model is not None:
        _score_figure(out_dir, space, records, best, model)
    verdict = _verdict(space, records, best, hfig, why, info, check, check_mean)
    summary = {"target": target, "target_figures": hfig, "tolerances": TOLERANCES,
               "peak_fraction": PEAK_FRACTION, "options": header, "regime": regime,
               "stopped": why,
               "evaluations": len(records),
               "runs": sum(len(r["seeds"]) for r in records) + len(check),
               "seed_rule": {"decide_on_first_run": o.decide_on_first_run, "z": DECIDE_Z,
                             "one_run_scatter": one_run_scatter(base.n),
                             "sets_on_first_run": sum(bool(r["decided_by"]) for r in records),
                             "runs_saved": sum(len(seeds) - len(r["seeds"]) for r in records),
                             "stop_decided_runs": stops,
                             # of the checkpoint's runs (this calibration's, every invocation)
                             "runs_stopped": sum(k.endswith(STOPPED) for k in done),
                             "runs_completed": sum(k.endswith(STOPPED) and k[:-len(STOPPED)]
                                                   in done for k in done),
                             "sets_stopped": sum(bool(r.get("censored")) for r in records)},
               "run_now": counts["run"], "taken_from_checkpoint": counts["taken"],
               "trace": trace, "met": best["met"], "verdict": verdict,
               "best": {k: best[k] for k in ["index", "stage", "values", "score", "met",
                                            "past_peak", "porosity", "steps", "wall_time"]
                        + FIGURE_COLS + ["eps1_peak"] + ["spread_" + k for k in TOLERANCES]},
               "best_seeds": [{k: v for k, v in p.items() if k != "key"} for p in best["seeds"]],
               "best_params": {f: v for f, v in zip(space.names, best["values"])},
               "check": [{k: v for k, v in c.items() if k != "curve"} for c in check],
               "check_mean": check_mean,
               "check_met": None if check_mean is None else check_mean["met"],
               "sample_scatter": _sample_scatter(best["seeds"] + check, len(seeds), len(check)),
               "seeds_spread": _spread(records),
               "model": info, "identifiability": ident,
               "start": {k: start_rec[k] for k in ["values", "score", "met", "past_peak"]
                         + FIGURE_COLS[:-2]},
               "start_label": start_label,
               "mean_wall_time_per_run": (float(np.mean([p["wall_time"] for r in records
                                                         for p in r["seeds"]]))
                                          if records else None),
               "wall_time": time.time() - t0,
               "files": ["params.json", "calibrated.json", "calibration.csv",
                         "calibration_runs.csv", "curves.csv", "calibration.png",
                         "calibration_search.png", "calibration_score.png", "report.md",
                         "evaluations.jsonl", "summary.json"]}
    atomic_write_bytes(os.path.join(out_dir, "summary.json"),
                          json.dumps(summary, indent=1, default=float).encode())
    _report(out_dir, summary, space, records)
    if os.path.isdir(work) and not os.listdir(work):
        os.rmdir(work)
    return summary
