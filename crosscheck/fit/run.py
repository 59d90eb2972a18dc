"""The run of the H-model fitted to a DEM run, by library calls with an HParams record (issue 33:
no argv, nothing read back from disk).

``fit_to_curve``: the fit (``hmodel.fit.fit_curve``) of the DEM's drained curve, its files
written by ``hmodel.cli.write_fit``; ``hmodel_beside_the_dem``: the fitted record's directional
analysis at A (``hmodel.experiment.directional_analysis``, files by ``hmodel.cli.write_probes``)
and its bifurcation domain at its confining stress (``hmodel.experiment.bifurcation_domain``,
files by ``hmodel.cli.write_domain``); ``run_fit``: both, then the comparison with the DEM's
domain (``compare``), its figures and comparison.md.
"""
from __future__ import annotations

import json
import math
import os
import time

import numpy as np

from hmodel import fit as hfit
from hmodel.cli import write_domain, write_fit, write_probes
from point.experiment import biaxial_test, bifurcation_domain, directional_analysis
from hmodel.fit import _jsonable
from common.io import atomic_open, read_csv, write_csv
from common.options import Stage
from hmodel.params import HParams

from .compare import compare, read_dem_domain, second_optimum
from .figures import comparison_figures, direction_figures
from .report import markdown, verdicts

__all__ = ["fit_to_curve", "hmodel_beside_the_dem", "run_fit", "NotFittable", "DEM_FILES"]

# what a DEM run must hold for the comparison (``python -m crosscheck.fit --dem DIR``)
DEM_FILES = ("biaxial.csv", "domain12000/domain.csv", "domain12000/boundaries.json",
             "domain12000/domain_probes.csv")
# the domain's check of W2 along the drained path: strain directions of each check
DOMAIN_PROBES = 180


class NotFittable(RuntimeError):
    """The DEM's curve cannot be fitted (the fit's summary.json and fig_fit.png say why)."""


def fit_to_curve(data, out, n_dir=180, starts=8, seed=0, options=None, progress=None,
                 stage=None):
    """The H-model fitted to the drained curve of the CSV ``data`` (``hmodel.fit.fit_curve``:
    its default free parameters kn, kt, phi_g, alpha0, from Table I with ``n_dir`` orientations
    at the data's confining stress, ``starts`` starts of seed ``seed``), its files written in
    ``out`` (``hmodel.cli.write_fit``: params.json, fit.csv, residuals.csv, correlation.json,
    summary.json with ``options``, fig_fit.png). Returns (the FitResult, its summary, the curve)."""
    t0 = time.time()
    curve = hfit.read_curve(data)
    base = HParams(n_dir=n_dir, p0=curve.sigma2)
    say = progress or (lambda m: None)
    say(f"fit of {', '.join(hfit.DEFAULT_FREE)} to {data} ({curve.eps1.size} points, sigma2 = "
        f"{curve.sigma2:.6g} Pa: {curve.sigma2_from}), {starts} starts")
    res = hfit.fit_curve(curve, base, hfit.DEFAULT_FREE, n_starts=starts, seed=seed,
                         progress=progress)
    note = (f"python -m crosscheck.fit: fitted {', '.join(hfit.DEFAULT_FREE)} to {data}; the others "
            f"Table I's, n_dir {n_dir}, p0 the data's sigma2")
    summary = write_fit(out, curve, res, note, options, time.time() - t0, stage)
    return res, summary, curve


def hmodel_beside_the_dem(P: HParams, out, eta_a: float, n_probes: int = 360, note: str = "",
                          progress=None, stage=None):
    """The H-model of the record ``P`` (the fitted one) at the DEM's scale: its directional
    analysis at ``eta_a`` with ``n_probes`` strain probes (``out``/probes/) and its bifurcation
    domain at its confining stress P.p0 (``out``/domain/); each folder's params.json is ``P``,
    its note ``note``. Returns (the DirectionalAnalysis, the domain points)."""
    stage = stage or Stage()
    stage.at(f"the fitted H-model's directional analysis at eta = {eta_a:.4f}")
    da = directional_analysis(P, eta_a, n_probes=n_probes, progress=progress)
    write_probes(os.path.join(out, "probes"), P, eta_a, da, note)
    stage.wrote("probes/")
    stage.at("the fitted H-model's bifurcation domain")
    pts = bifurcation_domain(P, [P.p0], n_dir_probe=DOMAIN_PROBES, progress=progress)
    write_domain(os.path.join(out, "domain"), P, pts, note)
    stage.wrote("domain/")
    return da, pts


def run_fit(dem, out, starts=8, seed=0, n_dir=180, n_probes=360, options=None,
            regenerate="python -m crosscheck.fit", progress=None, stage=None) -> dict:
    """Fit the H-model to the DEM run ``dem``'s drained curve (``DEM_FILES``), run its
    directional analysis at the fraction of its peak where the DEM's lower boundary lies and its
    domain, compare both with the DEM's domain state by state, and write the comparison into
    ``out`` (comparison.csv, comparison.json, comparison.md, the figures). ``regenerate``: the
    command comparison.md names; ``options``: the run's, recorded. Returns the comparison (with
    its verdicts); raises ``NotFittable`` if the curve cannot be fitted."""
    stage = stage or Stage()
    log = progress or (lambda m: None)
    t0 = time.time()
    stage.at("the fit")
    res, fit_summary, curve = fit_to_curve(os.path.join(dem, "biaxial.csv"), out, n_dir, starts,
                                           seed, options, progress, stage)
    if res.status != "fitted":
        raise NotFittable(res.reason)
    log(hfit.format_result(res, curve))
    P = res.params
    rows, bounds, dem_probes = read_dem_domain(dem)
    path = biaxial_test(P, P.p0, 1e-5, 0.03)
    _, _, e = path.invariants()
    f_a = bounds["lower_eta_fraction"]
    eta_a = float(f_a * e.max())
    log(f"fitted model at {f_a:.3f} of its peak (eta = {eta_a:.4f}): directional analysis; "
        f"its domain at sigma2 = {P.p0:.6g} Pa")
    hmodel_beside_the_dem(P, out, eta_a, n_probes, f"parameters: fitted to {dem}/biaxial.csv "
                          f"({out}/params.json)", progress, stage)
    stage.at("the comparison")
    c = compare(P, rows, bounds, dem_probes, n=n_probes, progress=log)
    dem_curve = read_csv(os.path.join(dem, "biaxial.csv"))
    kd = int(np.argmax(dem_curve["q"]))
    c["dem_q_peak"], c["dem_eps1_peak"] = float(dem_curve["q"][kd]), float(dem_curve["eps1"][kd])
    c["probes_eta"] = eta_a
    c["probes_fraction"] = f_a
    c["verdicts"] = verdicts(c)
    c["second_optimum"] = second_optimum(P, fit_summary, bounds)
    if c["second_optimum"]:
        c["verdicts"].append(c["second_optimum"]["text"])
    pp, qq, _ = path.invariants()
    comparison_figures(c, out, dem_curve, {"p": pp, "q": qq})
    c["polar_figures"] = direction_figures(c, out)
    cols = {"dem_eta": [s["dem_eta"] for s in c["states"]], "dem_fraction": [s["dem_fraction"] for s in c["states"]],
            "dem_min_w2": [s["dem_min_w2"] for s in c["states"]],
            "dem_alpha_min_w2": [s["dem_alpha_min_w2"] for s in c["states"]],
            "dem_n_failure": [s["dem_n_failure"] for s in c["states"]]}
    for tag in ("h_same_fraction", "h_same_eta"):
        for k_ in ("eta", "min_w2", "alpha_min_w2", "min_w2_eulerian", "alpha_min_w2_eulerian",
                   "min_w2_dem_directions", "alpha_min_w2_dem_directions"):
            cols[f"{tag}_{k_}"] = [s[tag][k_] if s[tag] else math.nan for s in c["states"]]
    write_csv(os.path.join(out, "comparison.csv"), cols)
    c["options"] = dict(options or {})
    c["wall_time_s"] = time.time() - t0
    with atomic_open(os.path.join(out, "comparison.json")) as f:
        json.dump(_jsonable({k_: v for k_, v in c.items() if k_ != "curves"}), f, indent=2)
    with atomic_open(os.path.join(out, "comparison.md")) as f:
        f.write(markdown(c, fit_summary, regenerate) + "\n")
    stage.wrote("comparison.csv", "comparison.json", "comparison.md", "fig_comparison.png",
                "fig_domain_pq.png", "fig_w2_by_direction.png", *c["polar_figures"])
    return c
