"""The three parts of the cross-check, each run as the paper runs it (sections 3-5).

``hmodel_part``: the material point's drained path, its directional analysis at A (eta = 1.029,
Table I), its stress probes in the DEM's directions and its bifurcation domain; ``fem_part``: the
FE biaxial specimen on a coarse mesh (its perfect specimen follows the material point);
``dem_part``: the DEM sample's compaction, drained biaxial test, the relaxations of its saved
states and the stress probes at the comparison state ``comparison_state`` chooses (and, with
``domain``, at every saved state that holds: the DEM's bifurcation domain).

The parts are imported inside the functions that run them (as in ``dem.crosscheck`` before the
move): ``python -m crosscheck --help`` and its checks of bad options answer before scikit-fem and
the Numba kernels load.
"""
from __future__ import annotations

import json
import os
import sys
import time

__all__ = ["hmodel_part", "fem_part", "dem_part", "dem_job", "comparison_state", "ETA_P3", "ETA2_OF_P3",
           "say", "quiet"]


def say(msg):
    """A progress line of the cross-check on stderr."""
    print(f"[crosscheck] {msg}", file=sys.stderr, flush=True)


def quiet(msg):
    """No progress line (``verbose=False``)."""


# -- the three parts ---------------------------------------------------------------------------
def hmodel_part(eta_a=1.029, sigma2=200e3, alphas=None, domain_sigma2=(100e3, 200e3, 400e3),
                n_dir=180, workers=None, params=None):
    """H-model at A: path, adaptive strain-probe sweep, stress probes in ``alphas`` [deg],
    bifurcation domain. ``params``: the HParams (default Table I with ``n_dir``), at ``sigma2``
    whatever their p0. Returns a dict of arrays (SI, compression positive)."""
    from hmodel import HParams
    from point.experiment import biaxial_test, bifurcation_domain, state_at_eta
    from point.probes import directional_sweep, stress_probes

    P = (HParams(n_dir=n_dir) if params is None else params).replace(p0=sigma2)
    path = biaxial_test(P, sigma2, 1e-5, 0.05)
    rA, sA = state_at_eta(P, eta_a, sigma2)
    sw = directional_sweep(sA, P, n=360)
    out = {"params": P, "path": path, "pathA": rA, "sweep": sw}
    if alphas is not None:
        out["stress_probes"] = stress_probes(sA, P, alphas, sigma_norm=2.5e3, sweep=sw)
    out["domain"] = bifurcation_domain(P, domain_sigma2, workers=workers) if domain_sigma2 else []
    return out


def fem_part(out_dir, nx=4, ny=8, n_dir=72, eps1_max=0.03, params=None, sigma2=200e3):
    """FE biaxial specimen (coarse mesh, no field output) of the material ``params`` (default
    Table I) with ``n_dir`` orientations at ``sigma2``. Returns its curve (dict of arrays)."""
    from fem.biaxial import BiaxialConfig, run_biaxial
    from hmodel import HParams
    P = (HParams() if params is None else params).replace(n_dir=n_dir, p0=sigma2)
    cfg = BiaxialConfig(nx=nx, ny=ny, eps1_max=eps1_max, d_eps1=1e-4, fields=False,
                        n_sphere=200).with_params(P)
    res = run_biaxial(cfg, out_dir=out_dir)
    return {"curve": res.curve, "events": res.events, "summary": res.summary, "n_dir": n_dir,
            "params": P}


# eta = q/p with p = (s1 + s2)/2 of the state whose eta is 1.029 with p = (s1 + 2 s2)/3 (one
# reading of the paper's DEM section): with x = q/s2, 3x/(3 + x) = 1.029 gives x = 1.5662 and
# 2x/(2 + x) = 0.8784, whatever s2
ETA_P3 = 1.029
ETA2_OF_P3 = 2 * (3 * ETA_P3 / (3 - ETA_P3)) / (2 + 3 * ETA_P3 / (3 - ETA_P3))


def comparison_state(refs, norm, alphas):
    """The DEM state of the comparison (Figs. 15-17 beside the H-model's A), by rule: the
    highest saved state whose reference R held at constant stress and whose every probe target
    stays below the largest stress ratio held by a reference (a lower bound of the strength
    under stress control eta_lim) and below the smallest one that ran away (a small sample's
    curve is jagged, so the two can cross): eta_R + max_eta_increment <= limit.  Every probe
    target then lies where the sample can hold it, so every direction can be decided.

    ``refs``: [(name, State R, outcome, meta)].  Returns (name, dict of the rule's numbers);
    when no state satisfies the rule, the lowest state whose reference held, flagged."""
    from dem.domain import _eta, max_eta_increment
    held = [(nm, R) for nm, R, oc, _ in refs if oc == "equilibrium"]
    if not held:
        raise RuntimeError("no saved DEM state could be held at constant stress")
    eta_r = {nm: _eta(R.control.s_to[1], R.control.s_to[0]) for nm, R in held}
    lim_low = max(eta_r.values())
    failed = [_eta(R.control.s_to[1], R.control.s_to[0]) for nm, R, oc, _ in refs if oc == "failure"]
    inc = {nm: max_eta_increment(R, norm, alphas) for nm, R in held}
    limit = min([lim_low] + failed)
    ok = [nm for nm in eta_r if eta_r[nm] + inc[nm] <= limit]
    name = max(ok, key=eta_r.get) if ok else min(eta_r, key=eta_r.get)
    return name, {"state": name, "eta_R": eta_r[name], "max_eta_increment": inc[name],
                  "eta_held_max": lim_low, "eta_failed_min": min(failed) if failed else None,
                  "limit": limit,
                  "rule_met": bool(ok)}


def dem_part(out_dir, n=1000, seed=1, rate=0.05, workers=None, eta_a=1.029, threads=None,
             alphas=None, max_steps=None, resume=False, domain=True, hmodel_boundary=None,
             params=None, scheduler=None, verbose=True):
    """DEM: compaction, drained biaxial test with states saved along the path, their
    relaxation under stress control, and the directional analysis (default: the paper's 45
    directions, each twice) at the comparison state chosen by ``comparison_state``
    and, with ``domain``, at every saved state that holds (the DEM's bifurcation domain,
    ``dem.domain``).  ``max_steps`` caps each probe run (undecided when reached).

    ``threads``: threads of the compaction, the biaxial test (default: auto; the results do
    not depend on it); the relaxations and probes run one thread each in ``workers``
    processes, or on the dask.distributed cluster of ``scheduler`` (its address), each run
    one task: the results do not depend on where a run ran.  ``resume``: keep what an
    interrupted run in ``out_dir`` finished (the biaxial test or its checkpoint, the relaxed
    references, the probe runs already on disk).
    ``params``: DemParams of the sample (default: the paper's set); n and seed override it.
    ``verbose``: progress lines on stderr.
    """
    from dem.pool import run_jobs
    make, finish = dem_job(out_dir, n, seed, rate, eta_a, threads, alphas, max_steps, resume,
                           domain, hmodel_boundary, params, verbose)
    return finish(run_jobs([("dem", make)], workers, scheduler)["dem"])


def dem_job(out_dir, n=1000, seed=1, rate=0.05, eta_a=1.029, threads=None, alphas=None,
            max_steps=None, resume=False, domain=True, hmodel_boundary=None, params=None,
            verbose=True):
    """``dem_part`` in two: the compaction and the biaxial test now (or, with ``resume``, read
    back), then ``(make, finish)``: ``make(tasks)`` the generator of the relaxations and probe
    runs for ``dem.pool`` (``dem.domain.domain_job``), ``finish(result)`` its files and the
    part's dict (what ``dem_part`` returns). The cross-check runs ``make`` beside the DEM burst's
    staircases on one pool (``crosscheck.run``)."""
    from dem import io
    from dem.domain import domain_job
    from dem.experiment import COLUMNS, SAVE_FRACTIONS, BiaxialResult, run_biaxial
    from dem.params import DemParams
    from dem.probes import ProbeOptions, directions
    from common.threads import set_default_threads

    set_default_threads(threads)
    log = say if verbose else quiet
    bdir = os.path.join(out_dir, "biaxial")
    summary_path = os.path.join(bdir, "summary.json")
    a_path = os.path.join(bdir, "stateA.npz")
    if (resume and os.path.exists(summary_path) and os.path.exists(a_path)
            and not os.path.exists(os.path.join(bdir, "checkpoint.npz"))):
        # the biaxial test finished in an earlier run: read it back
        with open(summary_path) as f:
            summ = json.load(f)
        rows = [[r[c] for c in COLUMNS] for r in io.read_csv(os.path.join(bdir, "biaxial.csv"))[1]]
        res = BiaxialResult(rows, a_path, bool(summ["eta_a_reached"]), summ.get("compaction", {}),
                            float(summ["wall_time"]))
        log(f"DEM: biaxial test taken from {bdir} ({len(rows)} rows)")
    else:
        # the states along the path; 1.0 (the peak, above what constant stress holds)
        # brackets eta_lim from above
        P = (params or DemParams()).replace(n=n, seed=seed)
        res = run_biaxial(P, bdir, rate=rate, eta_a=eta_a, vtk=False,
                          resume=resume, save_fractions=SAVE_FRACTIONS + (1.0,),
                          save_etas=(ETA2_OF_P3,), verbose=verbose)
    opts = ProbeOptions() if max_steps is None else ProbeOptions(max_steps=int(max_steps))
    alphas = directions() if alphas is None else [float(a) for a in alphas]
    t_probes0 = time.time()
    chosen = {}

    def choose(refs):
        name, info = comparison_state(refs, opts.norm, alphas)
        chosen.update(info)
        log(f"DEM: comparison state {name} (eta_R {info['eta_R']:.4f}, largest probe increment "
             f"{info['max_eta_increment']:.4f}, largest eta held {info['eta_held_max']:.4f}; "
             f"rule met: {info['rule_met']})")
        return [nm for nm, _, oc, _ in refs if domain and oc == "equilibrium"] + [name]

    ddir = os.path.join(out_dir, "domain")
    make, finish_domain = domain_job(bdir, ddir, alphas=alphas, opts=opts, resume=resume,
                                     hmodel=hmodel_boundary or False, choose=choose,
                                     verbose=verbose)

    def finish(result):
        drows, bounds, probes_by = finish_domain(result)
        probes = probes_by[chosen["state"]]
        stages = {"compaction + biaxial test (when it ran)": res.wall_time,
                  "relaxations and probes (this run)": time.time() - t_probes0}
        eta_peak = bounds["eta_peak"]
        return {"biaxial_rows": res.rows, "state_a": res.state_a_path,
                "eta_a_reached": res.eta_a_reached,
                "n": n, "rate": rate,
                "compaction": res.compaction, "probes": probes, "comparison": chosen,
                "probes_dir": os.path.join(ddir, chosen["state"]),
                "reference_converged": True, "domain_rows": drows, "domain_bounds": bounds,
                "domain_dir": ddir, "eta_peak": eta_peak, "stage_times": stages,
                "probes_by_state": probes_by,
                "p3_state": _p3_state(res.rows, eta_peak)}

    return make, finish


def _p3_state(rows, eta_peak):
    """The first recorded state with q / ((s1 + 2 s2)/3) >= 1.029, or None."""
    from dem.experiment import COLUMNS
    i = {c: k for k, c in enumerate(COLUMNS)}
    for r in rows:
        p3 = (r[i["s1"]] + 2 * r[i["s2"]]) / 3
        if p3 > 0 and r[i["q"]] / p3 >= ETA_P3:
            return {"eta": r[i["eta"]], "eta_fraction": r[i["eta"]] / eta_peak,
                    "eps1": r[i["eps1"]], "eta_p3": r[i["q"]] / p3,
                    "eta_p3_peak": max(x[i["q"]] / ((x[i["s1"]] + 2 * x[i["s2"]]) / 3)
                                       for x in rows if x[i["s1"]] + 2 * x[i["s2"]] > 0)}
    return None

