"""The DEM's bifurcation domain along one drained path (paper Fig. 10, for the DEM).

``run_domain`` takes the states that ``dem biaxial`` saved along the path
(``DIR/states/states.csv``), relaxes each into a reference R under stress control and runs the
directional analysis there, every probe of every state being one independent run of one
pool (local processes or dask).  Each probe ends ``equilibrium``, ``failure`` or
``undecided`` (``dem.settle``).  Per state (``domain.csv``): the counts of each outcome, the
minimum W2 over the equilibrium probes and its direction, the cone of W2 <= 0 and the failure
directions.  Along the path:

* the **lower boundary** of the bifurcation domain is the first state (in eta) where some
  direction has W2 <= 0 or fails (Eq. 1: a runaway is W2 <= 0 in the limit);
* the **upper boundary** is the plastic limit under stress control, eta_lim, bracketed by the
  probe targets (and references) that held and those that ran away: the largest eta of a
  target that reached equilibrium and the smallest eta of a target that failed.

The figure compares them with the H-model's boundary at the same confining pressure, in eta and
as a fraction of each model's peak.
"""
from __future__ import annotations

import json
import math
import os
import sys
import time

import numpy as np

from common.io import atomic_write_bytes

from . import io
from .params import record_params
from .probes import (COLUMNS as PROBE_COLUMNS, ProbeOptions, csv_rows, directions,
                     reference_state, state_fingerprint, write_probe_files)

DOMAIN_COLUMNS = ["state", "eta", "eta_fraction", "eps1", "p", "q", "reference", "probed",
                  "n_equilibrium", "n_failure", "n_undecided", "min_w2", "alpha_min_w2",
                  "cone_w2", "failure_directions", "eta_target_max_held",
                  "eta_target_min_failed"]


def _eta(s1, s2):
    return (s1 - s2) / (0.5 * (s1 + s2))


def max_eta_increment(state, norm, alphas):
    """Largest eta(s_R + ds) - eta(s_R) over the probe directions ``alphas`` [deg] of norm
    ``norm`` [Pa] from the reference ``state``."""
    s1, s2 = state.control.s_to[1], state.control.s_to[0]
    a = np.radians(np.asarray(alphas, float))
    return float(np.max(_eta(s1 + norm * np.sin(a), s2 + norm * np.cos(a))) - _eta(s1, s2))


def target_etas(rows, state):
    """eta of each probe's target stress s_R + ds (p = (s1 + s2)/2): (eta (k,), outcome (k,))."""
    s = state.control.s_to            # (sx, sy) of the reference's stress control
    s1, s2 = s[1], s[0]
    a = np.radians([r["alpha_sigma"] for r in rows])
    norm = np.hypot(rows[0]["ds1"], rows[0]["ds2"]) if rows else 0.0
    return (np.array([_eta(s1 + norm * math.sin(x), s2 + norm * math.cos(x)) for x in a]),
            np.array([r["outcome"] for r in rows]))


def state_row(name, meta_row, eta_peak, ref_outcome, rows, state):
    """One row of domain.csv (see DOMAIN_COLUMNS)."""
    from point.probes import arcs
    s1, s2 = state.control.s_to[1], state.control.s_to[0]
    out = {"state": name, "eta": _eta(s1, s2), "eta_fraction": _eta(s1, s2) / eta_peak,
           "eps1": float(meta_row["eps1"]), "p": 0.5 * (s1 + s2), "q": s1 - s2,
           "reference": ref_outcome, "probed": bool(rows), "n_equilibrium": 0, "n_failure": 0, "n_undecided": 0,
           "min_w2": math.nan, "alpha_min_w2": math.nan, "cone_w2": "", "failure_directions": "",
           "eta_target_max_held": math.nan, "eta_target_min_failed": math.nan}
    if ref_outcome == "failure":
        # R itself ran away at constant stress: the state lies above eta_lim
        out["eta_target_min_failed"] = out["eta"]
        return out
    if ref_outcome == "equilibrium":
        # R held at constant stress: a target held, whether or not the state is probed
        out["eta_target_max_held"] = out["eta"]
    if not rows:
        return out
    a = np.array([r["alpha_sigma"] for r in rows])
    oc = np.array([r["outcome"] for r in rows])
    w2 = np.array([r["w2"] for r in rows])
    eq = oc == "equilibrium"
    for k in ("equilibrium", "failure", "undecided"):
        out[f"n_{k}"] = int(np.sum(oc == k))
    if eq.any():
        j = np.flatnonzero(eq)[np.argmin(w2[eq])]
        out["min_w2"], out["alpha_min_w2"] = float(w2[j]), float(a[j])
        out["cone_w2"] = json.dumps(arcs(a[eq], w2[eq] <= 0))
    out["failure_directions"] = json.dumps([float(x) for x in a[oc == "failure"]])
    et, _ = target_etas(rows, state)
    if eq.any():
        out["eta_target_max_held"] = float(np.nanmax([out["eta_target_max_held"], et[eq].max()]))
    if (oc == "failure").any():
        out["eta_target_min_failed"] = float(et[oc == "failure"].min())
    return out


def boundaries(domain_rows, eta_peak):
    """The DEM's lower boundary (first state with W2 <= 0 among equilibrium probes or a
    failure, and the last state before it) and eta_lim bracket: dict."""
    rows = sorted(domain_rows, key=lambda r: r["eta"])
    first = next((r for r in rows if r["reference"] == "failure" or r["n_failure"] > 0
                  or (r["min_w2"] == r["min_w2"] and r["min_w2"] <= 0)), None)
    before = [r for r in rows if r["probed"] and (first is None or r["eta"] < first["eta"])]
    held = [r["eta_target_max_held"] for r in rows if r["eta_target_max_held"] == r["eta_target_max_held"]]
    failed = [r["eta_target_min_failed"] for r in rows
              if r["eta_target_min_failed"] == r["eta_target_min_failed"]]
    lo = max(held) if held else math.nan
    hi = min(failed) if failed else math.nan
    return {"eta_peak": eta_peak,
            "lower_state": first["state"] if first else None,
            "lower_eta": first["eta"] if first else math.nan,
            "lower_eta_fraction": first["eta"] / eta_peak if first else math.nan,
            "lower_why": (None if first is None else "reference failed" if first["reference"] == "failure"
                          else "failure" if first["n_failure"] else "W2 <= 0"),
            "last_stable_eta": before[-1]["eta"] if before else math.nan,
            "eta_lim_low": lo, "eta_lim_high": hi,
            "eta_lim_bracket_consistent": bool(not (lo == lo and hi == hi) or lo <= hi)}


def eta_lim_text(b):
    """One phrase for the strength under stress control: the bracket [largest target held,
    smallest target failed], or, when a target held above one that failed (the limit then
    depends on the direction of the stress path, not on eta alone), both numbers said so."""
    lo, hi = b["eta_lim_low"], b["eta_lim_high"]
    if b["eta_lim_bracket_consistent"]:
        return f"eta_lim in [{lo:.4f}, {hi:.4f}] (largest target held, smallest target failed)"
    return (f"no single eta_lim: targets held up to eta = {lo:.4f} in some directions and failed "
            f"from {hi:.4f} in others (the limit depends on the direction of the stress path)")


def load_states(biaxial_dir, names=None, option="--states"):
    """[(name, State, meta)] of ``biaxial_dir/states`` (all, or the listed file names / targets,
    an unknown one refused naming ``option``), and the biaxial peak eta."""
    sdir = os.path.join(biaxial_dir, "states")
    listing = os.path.join(sdir, "states.csv")
    if not os.path.exists(listing):
        raise ValueError(f"--biaxial {biaxial_dir}: no states/states.csv (run `python -m dem "
                         "biaxial` with this code: it saves states along the path)")
    _, rows = io.read_csv(listing)
    try:
        with open(os.path.join(biaxial_dir, "summary.json")) as f:
            eta_peak = float(json.load(f)["eta_max"])
    except (OSError, ValueError, KeyError) as e:
        raise ValueError(f"--biaxial {biaxial_dir}: no readable summary.json with eta_max "
                         f"({type(e).__name__}: {e}); run `python -m dem biaxial` to the end")
    if names:
        known = {r["file"] for r in rows} | {r["target"] for r in rows}
        bad = [n for n in names if n not in known]
        if bad:
            raise ValueError(f"{option} {','.join(bad)}: not saved in {sdir}; allowed: "
                             + ", ".join(r["target"] for r in rows))
        rows = [r for r in rows if r["file"] in names or r["target"] in names]
    out, steps = [], set()
    for r in sorted(rows, key=lambda r: float(r["eta"])):
        if r["step"] in steps:
            continue        # two targets met by the same recorded state: analysed once
        steps.add(r["step"])
        st, meta = io.load_state(os.path.join(sdir, r["file"]))
        out.append((os.path.splitext(r["file"])[0], st, meta))
    return out, eta_peak


def run_domain(biaxial_dir, out_dir, states=None, alphas=None, opts=ProbeOptions(),
               workers=None, scheduler=None, resume=False, verbose=True, hmodel=True,
               choose=None, allow_soft=False):
    """Relax every saved state, run its directional analysis (one pool for all), write
    ``out_dir/params.json`` (the states' parameters), ``domain.csv``, ``domain_probes.csv``,
    ``boundaries.json``, one sub-folder per state
    (stateR.npz, probe_runs.jsonl, probes.csv, probe_histories.csv, Figs. 15-17) and the
    figures ``fig_domain_w2.png`` and ``fig_domain.png``.

    ``choose(references) -> names``: called once the references are relaxed with a list of
    (name, State R, outcome, meta), it names the states whose directional analysis is run
    (default: every state whose reference held).  Returns (domain rows, boundaries, rows of
    probes by state name). States of parameters outside the granular regime at the test's sigma2
    (``dem.regime.check_biaxial_regime``) are refused unless ``allow_soft``; boundaries.json
    records the regime (``regime``). The runs: ``domain_job``'s, on ``workers`` local processes
    or the dask cluster at ``scheduler`` (``dem.pool``)."""
    from .pool import run_jobs
    make, finish = domain_job(biaxial_dir, out_dir, states, alphas, opts, resume, verbose,
                              hmodel, choose, allow_soft)
    return finish(run_jobs([("domain", make)], workers, scheduler)["domain"])


def _relax_run(state, opts, out_dir, resume, threads=None):
    """A relaxation of a saved state, a task of ``dem.pool`` (one thread, as a probe)."""
    return reference_state(state, out_dir, opts, resume=resume, verbose=False, threads=1)


def domain_job(biaxial_dir, out_dir, states=None, alphas=None, opts=ProbeOptions(),
               resume=False, verbose=True, hmodel=True, choose=None, allow_soft=False):
    """``run_domain`` in two: the checks and the folders now, then ``(make, finish)``:
    ``make(tasks)`` the generator of its runs for ``dem.pool`` (every relaxation, then the
    probes of ``choose``'s states, ``dem.probes.probe_sets_runs``), ``finish(result)`` the
    files and figures from what the generator returned; ``finish`` returns what
    ``run_domain`` does. The cross-check runs ``make`` beside the burst's staircases on one
    pool."""
    from .pool import WAIT
    from .probes import probe_sets_runs
    from .regime import check_biaxial_regime
    opts.validate()
    alphas = directions() if alphas is None else [float(a) for a in alphas]
    todo, eta_peak = load_states(biaxial_dir, states)
    regime = check_biaxial_regime(biaxial_dir, allow_soft)
    t0 = time.time()
    os.makedirs(out_dir, exist_ok=True)
    if todo:      # the states of one biaxial test carry its parameters
        record_params(out_dir, todo[0][1].params, "python -m dem domain; parameters: the states' "
                      f"own ({os.path.abspath(biaxial_dir)})")
    log = (lambda m: print(f"[domain] {m}", file=sys.stderr, flush=True)) if verbose else (lambda m: None)
    dirs = [os.path.join(out_dir, name) for name, _, _ in todo]
    for d in dirs:
        os.makedirs(d, exist_ok=True)
        ck = os.path.join(d, "probe_runs.jsonl")
        if not resume and os.path.exists(ck):
            os.remove(ck)

    def make(tasks):
        log(f"{len(todo)} states x {len(alphas)} directions x 2 runs; relaxing the references")
        refs = [None] * len(todo)

        def got_ref(k):
            def done(res):
                refs[k] = res
                log(f"reference of {todo[k][0]}: {res[1]} ({sum(r is not None for r in refs)}/"
                    f"{len(refs)}, {time.time() - t0:.0f} s)")
            return done

        for k, ((_, st, _), d) in enumerate(zip(todo, dirs)):
            tasks.start(_relax_run, (st, opts, d, resume), {}, got_ref(k))
        yield WAIT
        live = [k for k in range(len(todo)) if refs[k][1] != "failure"]
        if choose is not None:
            names = set(choose([(todo[k][0], refs[k][0], refs[k][1], todo[k][2])
                                for k in range(len(todo))]))
            live = [k for k in live if todo[k][0] in names]
        sets = [(refs[k][0], alphas, os.path.join(dirs[k], "probe_runs.jsonl")) for k in live]
        nf = sum(r[1] == "failure" for r in refs)
        log(f"probes of {len(live)} of {len(todo)} states ({nf} references failed: above eta_lim)")
        results = yield from probe_sets_runs(sets, opts, verbose, tasks)
        return refs, dict(zip(live, results))

    def finish(result):
        refs, by = result
        drows, prow = [], []
        for k, (name, st, meta) in enumerate(todo):
            rows = by.get(k, [])
            if rows:
                write_probe_files(rows, dirs[k], note=f"{name}, {st.params.n} disks")
            drows.append(state_row(name, meta["row"], eta_peak, refs[k][1], rows, refs[k][0]))
            prow += [[name, drows[-1]["eta"]] + r for r in csv_rows(rows)]
        io.write_csv(os.path.join(out_dir, "domain.csv"), DOMAIN_COLUMNS,
                     [[r[c] for c in DOMAIN_COLUMNS] for r in drows])
        io.write_csv(os.path.join(out_dir, "domain_probes.csv"),
                     ["state", "state_eta"] + PROBE_COLUMNS, prow)
        b = boundaries(drows, eta_peak)
        b.update(n_disks=todo[0][1].params.n if todo else None, wall_time=time.time() - t0,
                 directions=alphas, options=opts._asdict(), biaxial=os.path.abspath(biaxial_dir),
                 fingerprints={name: state_fingerprint(st) for name, st, _ in todo},
                 regime=regime)
        hm = (hmodel if isinstance(hmodel, dict) else
              hmodel_boundary(todo[0][1].control.s_to[0] if todo else 200e3) if hmodel else None)
        if hm:
            b["hmodel"] = hm
        atomic_write_bytes(os.path.join(out_dir, "boundaries.json"),
                           json.dumps(b, indent=1, default=float).encode())
        plot_domain(drows, by, todo, b, out_dir)
        log(f"done in {time.time() - t0:.0f} s: lower boundary {b['lower_state']} "
            f"(eta {b['lower_eta']:.4f}, {b['lower_eta_fraction']:.3f} of the peak); "
            f"{eta_lim_text(b)}")
        return drows, b, {todo[k][0]: by[k] for k in by}

    return make, finish


def makespan(durations, workers: int) -> float:
    """Wall time of independent runs of the given ``durations`` (in their order) on ``workers``
    workers, each run going to the first worker free, as a process pool or a dask cluster
    hands them out: the time the last one ends (same unit as ``durations``)."""
    if workers < 1:
        raise ValueError(f"workers={workers!r}; allowed: an integer >= 1")
    free = [0.0] * int(workers)
    for d in durations:
        k = min(range(len(free)), key=free.__getitem__)
        free[k] += float(d)
    return max(free)


def stage_steps(domain_dir):
    """The time steps of every run of a finished ``dem domain`` (or cross-check) folder:
    (relaxations, elastic runs, sliding runs), lists of step counts (a relaxation from its
    ``reference_history.csv``, a probe run from ``probes.csv``), the states in name order (that
    of ``run_domain`` for the states at fractions of the peak), the waves as ``run_domain``
    hands them out (the sliding runs start once every elastic run has ended)."""
    names = sorted(d for d in os.listdir(domain_dir) if d.startswith("state_")
                   and os.path.isdir(os.path.join(domain_dir, d)))
    relax, elastic, sliding = [], [], []
    for name in names:
        _, hist = io.read_csv(os.path.join(domain_dir, name, "reference_history.csv"))
        if hist:
            relax.append(hist[-1]["step"] - hist[0]["step"])
        pfile = os.path.join(domain_dir, name, "probes.csv")
        if os.path.exists(pfile):
            _, rows = io.read_csv(pfile)
            elastic += [r["steps_elastic"] for r in rows]
            sliding += [r["steps"] for r in rows]
    return relax, elastic, sliding


def hmodel_boundary(sigma2):
    """The H-model's lower boundary (first W2 <= 0 and W2_sigma <= 0) and peak on the drained
    path at ``sigma2`` [Pa] (Table I parameters, p = (s1 + s2)/2)."""
    from hmodel import HParams
    from point.experiment import bifurcation_domain
    d = bifurcation_domain(HParams(p0=float(sigma2)), [float(sigma2)], workers=1)[0]
    peak = d.q_peak / d.p_peak
    return {"sigma2": float(sigma2), "eta_w2": d.q_w2 / d.p_w2,
            "eta_w2sigma": d.q_w2sigma / d.p_w2sigma, "eta_peak": peak,
            "eta_w2_fraction": d.q_w2 / d.p_w2 / peak}


def plot_domain(drows, by, todo, b, out_dir):
    """fig_domain_w2.png: W2 against alpha_sigma for every state (failures on the W2 = 0 line);
    fig_domain.png: the lower boundary and eta_lim of the DEM beside the H-model's, in eta and
    as a fraction of each model's peak."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from common.io import save_figure
    fig, ax = plt.subplots(figsize=(8, 4.8), constrained_layout=True)
    cmap = plt.get_cmap("viridis")
    for k, (name, st, _) in enumerate(todo):
        rows = by.get(k, [])
        c = cmap(k / max(1, len(todo) - 1))
        lab = f"eta = {drows[k]['eta']:.3f} ({drows[k]['eta_fraction']:.3f} of peak)"
        if not rows:
            ax.plot([], [], color=c, label=lab + ": reference failed")
            continue
        a = np.array([r["alpha_sigma"] for r in rows])
        oc = np.array([r["outcome"] for r in rows])
        w = np.array([r["w2"] if r["outcome"] == "equilibrium" else np.nan for r in rows])
        ax.plot(a, w, "o-", ms=3, lw=1, color=c, label=lab)
        f = oc == "failure"
        ax.plot(a[f], np.zeros(f.sum()), "^", color=c, mec="C3", ms=7)
        u = oc == "undecided"
        ax.plot(a[u], np.zeros(u.sum()), "s", color="0.6", ms=5)
    ax.plot([], [], "^", color="w", mec="C3", label="failure (runaway)")
    ax.plot([], [], "s", color="0.6", label="undecided")
    ax.axhline(0, color="k", lw=0.6)
    ax.set_xlim(0, 360)
    ax.set_xticks(range(0, 361, 45))
    ax.set_xlabel(r"$\alpha_\sigma$ [deg] ($\tan\alpha_\sigma = d\sigma_1/d\sigma_2$)")
    ax.set_ylabel(r"normalized second-order work $W_2$ [-]")
    n = b.get("n_disks")
    ax.set_title(f"DEM directional analyses along the drained path ({n} disks)", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    save_figure(fig, os.path.join(out_dir, "fig_domain_w2.png"), dpi=120)

    fig, axs = plt.subplots(1, 2, figsize=(10, 4.6), constrained_layout=True)
    for ax, frac in zip(axs, (False, True)):
        scale_d = b["eta_peak"] if frac else 1.0
        x = 0
        et = np.array([r["eta"] for r in drows]) / scale_d
        cls = ["C3" if (r["reference"] == "failure" or r["n_failure"]) else
               "C1" if (r["min_w2"] == r["min_w2"] and r["min_w2"] <= 0) else "C2" for r in drows]
        ax.scatter(np.full(len(et), x), et, c=cls, s=30, zorder=3)
        if b["lower_eta"] == b["lower_eta"]:
            ax.hlines(b["lower_eta"] / scale_d, x - 0.3, x + 0.3, color="k", lw=2)
        lo, hi = b["eta_lim_low"] / scale_d, b["eta_lim_high"] / scale_d
        if lo == lo and hi == hi:
            # held above failed: the band where both happened, hatched
            ax.fill_between([x - 0.3, x + 0.3], min(lo, hi), max(lo, hi), color="C3", alpha=0.25,
                            lw=0, hatch=None if lo <= hi else "//")
        ax.hlines(1.0 if frac else b["eta_peak"], x - 0.3, x + 0.3, color="k", ls=":", lw=1)
        labels = ["DEM"]
        hm = b.get("hmodel")
        if hm:
            sh = hm["eta_peak"] if frac else 1.0
            ax.hlines(hm["eta_w2"] / sh, 0.7, 1.3, color="k", lw=2)
            ax.hlines(hm["eta_w2sigma"] / sh, 0.7, 1.3, color="k", lw=1, ls="--")
            ax.hlines(hm["eta_peak"] / sh, 0.7, 1.3, color="k", ls=":", lw=1)
            labels.append("H-model")
        ax.set_xticks(range(len(labels)))
        ax.set_xticklabels(labels)
        ax.set_xlim(-0.6, len(labels) - 0.4)
        ax.set_ylabel("eta / eta_peak of the model" if frac else r"$\eta = q/p$, $p = (s_1+s_2)/2$")
        ax.grid(alpha=0.3, axis="y")
    axs[0].plot([], [], "o", color="C2", label="all W2 > 0")
    axs[0].plot([], [], "o", color="C1", label="W2 <= 0 (equilibrium)")
    axs[0].plot([], [], "o", color="C3", label="failure")
    axs[0].plot([], [], "-", color="k", lw=2, label="lower boundary (first W2 <= 0 or failure)")
    axs[0].plot([], [], "--", color="k", lw=1, label=r"H-model: first $W_2^\sigma \leq 0$")
    axs[0].fill_between([], [], [], color="C3", alpha=0.25, label=r"DEM $\eta_{lim}$ (held / failed targets)")
    axs[0].plot([], [], ":", color="k", label="peak of the strain-controlled test")
    fig.legend(loc="lower center", ncol=3, fontsize=7, frameon=False, bbox_to_anchor=(0.5, -0.12))
    fig.suptitle("Bifurcation domain at the confining pressure of the DEM sample: lower boundary "
                 "and plastic limit", fontsize=10)
    save_figure(fig, os.path.join(out_dir, "fig_domain.png"), dpi=120)

