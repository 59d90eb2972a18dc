"""The cross-check run: the three parts (``crosscheck.parts``), the burst section
(``crosscheck.burst``), the conclusions, the figures and the report, written into one folder
(``python -m crosscheck --out DIR``; docs/crosscheck.md). The stages in this process run one
after another; the DEM's stages that need only its biaxial test (its domain's relaxations and
probes, its burst's runs) run as one pool (``dem.pool``), and the stages' graph is read back
into the report (``critical_path``).
"""
from __future__ import annotations

import json
import os
import time

from .conclusions import conclusions
from .figures import figures
from .parts import dem_job, fem_part, hmodel_part, quiet, say
from .report import write_report

__all__ = ["run_crosscheck", "critical_path", "DEFAULT_SMALL", "DEFAULT_FULL"]

# the probes' cap is the same in both: a cap is no criterion (dem.settle decides), and the
# slow creep at the edge of the plastic zone needs ~120,000-260,000 steps at 1000 disks
# (20 equilibrium windows of the sample: 20 x 20,000 steps at 1000 disks, 20 x 70,000 at 12,000,
# where plastic probes settle in 210,000-390,000 steps and two of them crept past 400,000)
SIGMA2 = 200e3     # [Pa] the confining stress of the three parts: the DEM sample's (the paper's)
DEFAULT_SMALL = {"n": 1000, "rate": 0.05, "max_steps": 400_000}
DEFAULT_FULL = {"n": 12000, "rate": 0.01, "max_steps": 1_400_000}


def run_crosscheck(out_dir, full=False, n=None, seed=1, rate=None, workers=None, skip_dem=False,
                   fem_mesh=(4, 8), fem_n_dir=72, domain=True, dem_alphas=None,
                   dem_max_steps=None, threads=None, resume=False, dem_domain=None,
                   dem_params=None, scheduler=None, hmodel_params=None, burst=True,
                   burst_ratios=None, burst_fractions=None, graph=True, verbose=True):
    """Run all three parts and write figures, conclusions.json and report.md in ``out_dir``.

    Default: 1000 disks at 0.05/s (minutes); ``full``: the paper's 12,000 disks at 0.01/s.
    ``dem_alphas`` [deg] replaces the 45 probe directions, ``dem_max_steps`` the probe cap;
    ``threads`` and ``resume``: see ``dem_part`` (the H-model and FE parts always rerun).
    ``dem_domain``: the DEM's directional analysis at every saved state (its bifurcation
    domain), default on except with ``full`` (there only at the comparison state: the
    12,000-disk domain is ``python -m dem domain``'s job).  ``dem_params``: a DemParams file
    for the DEM sample (default: the paper's stated set); the report names it.
    ``hmodel_params``: an HParams file for the H-model and the FE parts (default Table I; the FE
    at ``fem_n_dir`` orientations, both at the DEM's 200 kPa whatever the file's p0).
    ``scheduler``: the address of a dask.distributed scheduler for the DEM's relaxations and
    probe runs (see ``dem_part``; the H-model's domain stays in local processes).
    ``burst``: the burst section (``crosscheck.burst``): the proportional strain paths of
    ``burst_ratios`` (default -2) from ``burst_fractions`` (default 0.90) of each part's drained
    peak, c held below and past its peak, in the H-model, the FE specimen and the DEM sample.
    ``graph``: the DEM's stages that depend only on its biaxial test (the relaxations and probe
    runs of its domain, every run of its burst) as one pool of ``workers`` (``dem.pool``: the
    burst's staircase, the critical chain, first; the probes on the workers it leaves), not one
    after the other (``graph=False``, the order before); the outputs the same bits either way.
    conclusions.json's ``graph`` and report.md give every stage's start and end and the
    critical path (``critical_path``).
    ``verbose``: progress lines on stderr.
    """
    from common.io import atomic_open

    from dem.params import DemParams, load_params
    from dem.probes import directions
    from hmodel.params import load_params as load_hparams
    P = load_params(dem_params, option="--dem-params") if dem_params else DemParams()
    H = load_hparams(hmodel_params, option="--hmodel-params") if hmodel_params else None
    os.makedirs(out_dir, exist_ok=True)
    dflt = DEFAULT_FULL if full else DEFAULT_SMALL
    n = dflt["n"] if n is None else int(n)
    rate = dflt["rate"] if rate is None else float(rate)
    dem_max_steps = dflt["max_steps"] if dem_max_steps is None else int(dem_max_steps)
    log = say if verbose else quiet
    t_run = time.time()
    stages = []           # {name, start, end [s from the run's start], after: [names]}

    def stage(name, after, t0):
        stages.append({"name": name, "start": t0 - t_run, "end": time.time() - t_run,
                       "after": list(after)})
        return name

    t = time.time()
    log("H-model: drained path, point A, directional analysis, bifurcation domain")
    h = hmodel_part(alphas=directions() if dem_alphas is None else list(dem_alphas),
                    domain_sigma2=(100e3, 200e3, 400e3) if domain else (), workers=workers,
                    params=H)
    s_h = stage("H-model (path, probes, domain)", [], t)
    t = time.time()
    log(f"FE: {fem_mesh[0]} x {fem_mesh[1]} quads, n_dir {fem_n_dir}")
    fem = fem_part(os.path.join(out_dir, "fem"), nx=fem_mesh[0], ny=fem_mesh[1], n_dir=fem_n_dir,
                   params=H)
    s_fem = stage("FE specimen", [], t)
    dem = None
    jobs = []              # [(tag, make, stage name, after)] of the DEM's pool
    if not skip_dem:
        t = time.time()
        log(f"DEM: {n} disks, rate {rate}/s, 45 probes x 2")
        hb = None
        for d in h.get("domain", []):
            if abs(d.sigma2 - 200e3) < 1.0:
                peak = d.q_peak / d.p_peak
                hb = {"sigma2": d.sigma2, "eta_w2": d.q_w2 / d.p_w2,
                      "eta_w2sigma": d.q_w2sigma / d.p_w2sigma, "eta_peak": peak,
                      "eta_w2_fraction": d.q_w2 / d.p_w2 / peak}
        make_dem, finish_dem = dem_job(
            os.path.join(out_dir, "dem"), n=n, seed=seed, rate=rate, alphas=dem_alphas,
            max_steps=dem_max_steps, threads=threads, resume=resume,
            domain=(not full) if dem_domain is None else dem_domain, hmodel_boundary=hb,
            params=P, verbose=verbose)
        s_biax = stage("DEM compaction and biaxial test", [], t)
        jobs.append(("dem", make_dem, "DEM relaxations and probes (its domain)", [s_biax, s_h]))
    bparts = None
    if burst:
        from . import burst as cb
        t = time.time()
        bjobs, finish_burst = cb.burst_jobs(
            out_dir, os.path.join(out_dir, "dem", "biaxial") if not skip_dem else None,
            ratios=tuple(burst_ratios or cb.BURST_RATIOS),
            fractions=tuple(burst_fractions or cb.BURST_FRACTIONS), fem_mesh=fem_mesh,
            fem_n_dir=fem_n_dir, dem_rate=rate, log=log, verbose=verbose)
        stage("burst: material point and FE specimen", [], t)
        jobs += [(tag, make, f"DEM burst R={tag[0]:g} f={tag[1]:g} (path, staircase, probes)",
                  [s_biax]) for tag, make in bjobs]
    results = _run_dem_jobs(jobs, graph, workers, scheduler, t_run, stages)
    if not skip_dem:
        dem = finish_dem(results["dem"])
    if burst:
        bparts = finish_burst(results)
    timings = {st["name"]: st["end"] - st["start"] for st in stages}
    if dem:
        for k, v in dem["stage_times"].items():
            timings[f"  DEM {k}"] = v
    graph_info = critical_path(stages, time.time() - t_run)
    graph_info["mode"] = "graph" if graph else "sequential"
    c = conclusions(h, dem["probes"] if dem else None, fem, dem)
    figs = figures(out_dir, h, dem, fem)
    if bparts:
        d200 = [d for d in c["domain"] if abs(d["sigma2"] - 200e3) < 1.0]
        c["burst"] = cb.burst_conclusions(bparts, d200[0]["eta_w2"] if d200 else None,
                                          (fem["summary"] or {}).get("events"))
        figs["burst"] = cb.burst_figure(out_dir, bparts)
        figs["burst_w2"] = cb.w2_path_figure(out_dir, bparts)
        figs["burst_eq1"] = cb.burst_eq1_figure(
            out_dir, os.path.join(out_dir, "burst", "fem", "history.csv"),
            os.path.join(out_dir, "burst", "dem", "history.csv"))
    config = {"full": full, "dem_n": n, "dem_seed": seed, "dem_rate": rate,
              "dem_params": (os.path.abspath(dem_params) if dem_params else
                             "the paper's stated set (kn/D 32 GPa, kt/kn 0.42, 35 deg)"),
              "dem_params_values": P.replace(n=n, seed=seed).to_dict(),
              "hmodel_params": (os.path.abspath(hmodel_params) if hmodel_params else
                                "Table I (the FE at fem_n_dir orientations)"),
              "dem_probe_max_steps": dem_max_steps, "fem_mesh": list(fem_mesh),
              "fem_n_dir": fem_n_dir, "dem_eta_a_reached": dem["eta_a_reached"] if dem else None}
    with atomic_open(os.path.join(out_dir, "conclusions.json")) as f:
        json.dump({"conclusions": c, "timings": timings, "graph": graph_info, "config": config},
                  f, indent=1, default=str)
    # the parameters of the three parts, in the --params format (dem/biaxial/ and fem/ hold theirs
    # too): --dem-params DIR/dem_params.json repeats the DEM sample
    from hmodel.params import save_params as save_hparams

    from dem.params import save_params
    save_hparams(os.path.join(out_dir, "hmodel_params.json"), h["params"],
                 "python -m crosscheck: the H-model part (--hmodel-params repeats it; the FE "
                 "part: fem/params.json)")
    save_params(os.path.join(out_dir, "dem_params.json"), P.replace(n=n, seed=seed),
                "python -m crosscheck: the DEM sample (--dem-params repeats it)")
    write_report(out_dir, c, figs, timings, config, graph_info)
    return c, timings


def _run_dem_jobs(jobs, graph, workers, scheduler, t_run, stages):
    """The DEM's pooled stages ``jobs`` [(tag, make, name, after)]: together on one pool
    (``graph``), or the domain's then each burst's (one pool each, as before the graph). Each
    stage's start and end (its generator's first and last step) go to ``stages``. Returns {tag:
    result}."""
    from dem.pool import run_jobs

    def timed(make, name, after):
        def m(tasks):
            t0 = time.time()
            res = yield from make(tasks)
            stages.append({"name": name, "start": t0 - t_run, "end": time.time() - t_run,
                           "after": list(after)})
            return res
        return m

    timed_jobs = [(tag, timed(make, name, after)) for tag, make, name, after in jobs]
    if not timed_jobs:
        return {}
    if graph:
        # a chain on one thread: the other workers run side tasks (more threads than cores would
        # slow the chain, the critical path)
        return run_jobs(timed_jobs, workers, scheduler, None, 1 if len(timed_jobs) > 1 else None)
    out = {}
    dem = [j for j in timed_jobs if j[0] == "dem"]
    rest = [j for j in timed_jobs if j[0] != "dem"]
    if dem:
        out.update(run_jobs(dem, workers, scheduler))
    if rest:      # the burst's section ran on local processes before the graph
        out.update(run_jobs(rest, workers, None, None, None if len(rest) == 1 else 1))
    return out


def critical_path(stages, wall_time):
    """The stages' graph read back: ``stages`` [{name, start, end, after}] (seconds from the
    run's start; ``after``: the stages a stage waited for). The critical path is the chain that
    ends last, each link the stage its successor waited for that ended last, back to a stage
    that waited for none; the stages run in this process one after another count as a chain.
    Returns {"stages", "critical_path" (names, first to last), "wall_time", "busy" (the sum of
    the stages' own times: above ``wall_time`` when stages overlapped)}."""
    by = {s["name"]: s for s in stages}
    order = sorted(stages, key=lambda s: s["start"])
    path = []
    cur = max(stages, key=lambda s: s["end"]) if stages else None
    while cur is not None:
        path.append(cur["name"])
        # what it waited for: its stated dependencies and, in this process, the stage before it
        before = [by[a] for a in cur["after"] if a in by]
        prev = [s for s in order if s["end"] <= cur["start"] + 1e-9 and s is not cur]
        if prev:
            before.append(max(prev, key=lambda s: s["end"]))
        cur = max(before, key=lambda s: s["end"]) if before else None
    return {"stages": stages, "critical_path": path[::-1], "wall_time": wall_time,
            "busy": sum(s["end"] - s["start"] for s in stages)}
