"""The cross-check run: the three parts (``crosscheck.parts``), the burst section
(``crosscheck.burst``), the conclusions, the figures and the report, written into one folder
(``python -m crosscheck --out DIR``; docs/crosscheck.md).
"""
from __future__ import annotations

import json
import os
import time

from .conclusions import conclusions
from .figures import figures
from .parts import dem_part, fem_part, hmodel_part, quiet, say
from .report import write_report

__all__ = ["run_crosscheck", "DEFAULT_SMALL", "DEFAULT_FULL"]

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
                   burst_ratios=None, burst_fractions=None, verbose=True):
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
    timings = {}
    log = say if verbose else quiet
    t = time.time()
    log("H-model: drained path, point A, directional analysis, bifurcation domain")
    h = hmodel_part(alphas=directions() if dem_alphas is None else list(dem_alphas),
                    domain_sigma2=(100e3, 200e3, 400e3) if domain else (), workers=workers,
                    params=H)
    timings["H-model (path, probes, domain)"] = time.time() - t
    t = time.time()
    log(f"FE: {fem_mesh[0]} x {fem_mesh[1]} quads, n_dir {fem_n_dir}")
    fem = fem_part(os.path.join(out_dir, "fem"), nx=fem_mesh[0], ny=fem_mesh[1], n_dir=fem_n_dir,
                   params=H)
    timings["FE specimen"] = time.time() - t
    dem = None
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
        dem = dem_part(os.path.join(out_dir, "dem"), n=n, seed=seed, rate=rate, workers=workers,
                       alphas=dem_alphas, max_steps=dem_max_steps, threads=threads,
                       resume=resume, domain=(not full) if dem_domain is None else dem_domain,
                       hmodel_boundary=hb, params=P, scheduler=scheduler, verbose=verbose)
        n_runs = 2 * sum(len(r) for r in dem["probes_by_state"].values())
        timings[f"DEM ({n} disks: compaction, biaxial, {len(dem['domain_rows'])} relaxations, "
                f"{n_runs} probe runs)"] = time.time() - t
        for k, v in dem["stage_times"].items():
            timings[f"  DEM {k}"] = v
    bparts = None
    if burst:
        from . import burst as cb
        t = time.time()
        bparts = cb.burst_part(out_dir, os.path.join(out_dir, "dem", "biaxial") if dem else None,
                               ratios=tuple(burst_ratios or cb.BURST_RATIOS),
                               fractions=tuple(burst_fractions or cb.BURST_FRACTIONS),
                               fem_mesh=fem_mesh, fem_n_dir=fem_n_dir, dem_rate=rate,
                               workers=workers, log=log, verbose=verbose)
        timings["burst (H-model, FE, DEM)"] = time.time() - t
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
        json.dump({"conclusions": c, "timings": timings, "config": config}, f, indent=1, default=str)
    # the parameters of the three parts, in the --params format (dem/biaxial/ and fem/ hold theirs
    # too): --dem-params DIR/dem_params.json repeats the DEM sample
    from hmodel.params import save_params as save_hparams

    from dem.params import save_params
    save_hparams(os.path.join(out_dir, "hmodel_params.json"), h["params"],
                 "python -m crosscheck: the H-model part (--hmodel-params repeats it; the FE "
                 "part: fem/params.json)")
    save_params(os.path.join(out_dir, "dem_params.json"), P.replace(n=n, seed=seed),
                "python -m crosscheck: the DEM sample (--dem-params repeats it)")
    write_report(out_dir, c, figs, timings, config)
    return c, timings
