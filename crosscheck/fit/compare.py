"""The comparison of the fitted H-model with the DEM's bifurcation domain, in numbers (no file
written but by ``read_dem_domain``'s reading): the DEM's domain files, the H-model's state at a
stress ratio, the comparison state by state and direction by direction, the fit's second optimum.

Second-order work on both sides: the DEM's is ds.de / (|ds| |de|) of stress probes (Eulerian,
dem/probes.py); the H-model's is given both as its Lagrangian W2 = dPi:de / (|dPi| |de|) (the
paper's, docs/hmodel.md) and as ds.de / (|ds| |de|), the DEM's definition (``eulerian_w2``).
"""
from __future__ import annotations

import csv
import json
import math
import os

import numpy as np

from point.experiment import biaxial_test, domain_point, state_at_eta
from hmodel.params import HParams
from point.probes import arcs, directional_sweep, stress_probes

from .report import bracket

__all__ = ["read_dem_domain", "eulerian_w2", "hmodel_state", "compare", "second_optimum",
           "TRACE_FRACTIONS"]

# the fractions of the fitted model's peak eta where the H-model's minimum W2 is traced (figure)
TRACE_FRACTIONS = np.round(np.arange(0.80, 0.9951, 0.005), 3)


def read_dem_domain(dem_dir) -> tuple[list, dict, list]:
    """The DEM's domain: rows of DEM/domain12000/domain.csv (numbers as floats, the JSON columns
    decoded), boundaries.json, and the probes of domain_probes.csv (state, alpha_sigma [deg],
    outcome, w2, plastic)."""
    d = os.path.join(dem_dir, "domain12000")
    with open(os.path.join(d, "domain_probes.csv"), newline="") as f:
        probes = [{"state": r["state"], "alpha_sigma": float(r["alpha_sigma"]), "outcome": r["outcome"],
                   "w2": float(r["w2"]), "plastic": r["plastic"] == "1"} for r in csv.DictReader(f)]
    with open(os.path.join(d, "domain.csv"), newline="") as f:
        rows = []
        for r in csv.DictReader(f):
            row = {}
            for k, v in r.items():
                if k in ("cone_w2", "failure_directions"):
                    row[k] = json.loads(v) if v else []
                elif k in ("state", "reference"):
                    row[k] = v
                elif k == "probed":
                    row[k] = v == "True"
                else:
                    row[k] = float(v)
            rows.append(row)
    with open(os.path.join(d, "boundaries.json")) as f:
        bounds = json.load(f)
    return rows, bounds, probes


def eulerian_w2(d_sigma, d_eps):
    """ds.de / (|ds| |de|) of the in-plane principal components (rows (n, >= 2)): the DEM's
    normalized second-order work (dem/probes.py)."""
    ds, de = np.asarray(d_sigma)[:, :2], np.asarray(d_eps)[:, :2]
    return np.sum(ds * de, axis=1) / (np.linalg.norm(ds, axis=1) * np.linalg.norm(de, axis=1))


def hmodel_state(P: HParams, eta: float, n: int = 360, dem_directions=None, curve=False) -> dict:
    """The H-model's state on the drained path at ``eta`` (P.p0 the confining stress): the minimum
    over all directions (adaptive strain-probe sweep of ``n``) of W2 (Lagrangian) and of
    ds.de/(|ds||de|) with the direction alpha_sigma [deg] of each, the cone W2 <= 0, the plastic
    zone, and the minimum of ds.de/(|ds||de|) over the stress directions ``dem_directions`` [deg]
    (the DEM's probes); with ``curve`` also the sweep's alpha_sigma and ds.de/(|ds||de|)
    (arrays, key 'curve')."""
    r, s = state_at_eta(P, eta)
    sw = directional_sweep(s, P, n=n)
    wE = eulerian_w2(sw.d_sigma, sw.d_eps)
    k, kE = int(np.argmin(sw.w2)), int(np.argmin(wE))
    p, q, e = r.invariants()
    out = {"eta": float(e[-1]), "eps1": float(r.eps[-1, 0]), "p": float(p[-1]), "q": float(q[-1]),
           "min_w2": float(sw.w2[k]), "alpha_min_w2": float(sw.alpha_sigma[k]),
           "min_w2_eulerian": float(wE[kE]), "alpha_min_w2_eulerian": float(sw.alpha_sigma[kE]),
           "cone_w2": arcs(sw.alpha_sigma, sw.w2 <= 0), "cone_w2_eulerian": arcs(sw.alpha_sigma, wE <= 0),
           "plastic_zone": arcs(sw.alpha_sigma, sw.plastic)}
    if curve:
        out["curve"] = (sw.alpha_sigma, wE)
    if dem_directions is not None:
        sp = stress_probes(s, P, dem_directions, sweep=sw)
        ok = sp.n_solutions > 0
        w = eulerian_w2(sp.probe.d_sigma[ok], sp.probe.d_eps[ok])
        j = int(np.argmin(w))
        out.update(min_w2_dem_directions=float(w[j]),
                   alpha_min_w2_dem_directions=float(sp.alpha_sigma_target[ok][j]),
                   w2_at_dem_directions=dict(zip((float(a) for a in sp.alpha_sigma_target[ok]),
                                                 (float(v) for v in w))),
                   dem_directions_without_solution=[float(a) for a in sp.alpha_sigma_target[~ok]])
    return out


def compare(P: HParams, dem_rows: list, dem_bounds: dict, dem_probes: list, n: int = 360,
            progress=None) -> dict:
    """Everything the comparison reports (no file written): the fitted model's peak and domain
    point at its confining stress, the H-model at each DEM state's fraction of the peak and at
    its eta, direction by direction beside the DEM's probes, and the trace of the H-model's
    minimum W2 over ``TRACE_FRACTIONS``. The H-model's sweeps at the same fractions are under
    'curves' (arrays: dropped from the JSON)."""
    say = progress or (lambda m: None)
    path = biaxial_test(P, P.p0, 1e-5, 0.03)
    p, q, e = path.invariants()
    k = int(np.argmax(e))
    eta_peak = float(e[k])
    say(f"fitted model: peak eta = {eta_peak:.4f} at eps1 = {path.eps[k, 0]:.4%}; domain point")
    dp = domain_point(P, P.p0)
    dem_dirs = [float(a) for a in dem_bounds.get("directions", [])]
    states, curves = [], {}
    for r in dem_rows:
        if not r["probed"]:
            continue
        f = r["eta"] / dem_bounds["eta_peak"]
        row = {"state": r["state"], "dem_eta": r["eta"], "dem_fraction": f, "dem_eps1": r["eps1"],
               "dem_min_w2": r["min_w2"], "dem_alpha_min_w2": r["alpha_min_w2"],
               "dem_n_failure": int(r["n_failure"]), "dem_failure_directions": r["failure_directions"],
               "dem_cone_w2": r["cone_w2"], "dem_eta_target_min_failed": r["eta_target_min_failed"]}
        row["h_same_fraction"] = hf = hmodel_state(P, f * eta_peak, n, dem_dirs, curve=True)
        curves[r["state"]] = hf.pop("curve")
        row["by_direction"] = [
            {"alpha_sigma": pr["alpha_sigma"], "dem_outcome": pr["outcome"], "dem_plastic": pr["plastic"],
             "dem_w2": pr["w2"] if pr["outcome"] == "equilibrium" else math.nan,
             "h_w2": hf["w2_at_dem_directions"].get(pr["alpha_sigma"], math.nan)}
            for pr in dem_probes if pr["state"] == r["state"]]
        row["h_same_eta"] = hmodel_state(P, r["eta"], n, dem_dirs) if r["eta"] < eta_peak else None
        say(f"{r['state']}: DEM min W2 {r['min_w2']:.3f}, H-model at the same fraction "
            f"{row['h_same_fraction']['min_w2_eulerian']:.3f}")
        states.append(row)
    trace = []
    for f in TRACE_FRACTIONS:
        h = hmodel_state(P, float(f) * eta_peak, n)
        trace.append({"fraction": float(f), **{k_: h[k_] for k_ in ("eta", "min_w2", "alpha_min_w2",
                                                                   "min_w2_eulerian", "alpha_min_w2_eulerian")}})
    b = dem_bounds
    last_stable = next((s for s in reversed(states) if s["dem_eta"] < b["lower_eta"]), None)
    return {
        "params": {k_: getattr(P, k_) for k_ in ("kn", "kt", "phi_g", "r_g", "alpha0", "p0", "n_dir")},
        "hmodel": {"eta_peak": eta_peak, "q_peak": float(q[k]), "p_peak": float(p[k]),
                   "eps1_peak": float(path.eps[k, 0]),
                   "eta_w2": dp.q_w2 / dp.p_w2, "eta_w2sigma": dp.q_w2sigma / dp.p_w2sigma,
                   "fraction_w2": dp.q_w2 / dp.p_w2 / eta_peak,
                   "fraction_w2sigma": dp.q_w2sigma / dp.p_w2sigma / eta_peak,
                   "eps1_w2": dp.eps1_w2, "eps1_w2sigma": dp.eps1_w2sigma,
                   "p_w2": dp.p_w2, "q_w2": dp.q_w2, "p_w2sigma": dp.p_w2sigma, "q_w2sigma": dp.q_w2sigma},
        "dem": {"eta_peak": b["eta_peak"], "lower_state": b["lower_state"], "lower_eta": b["lower_eta"],
                "lower_fraction": b["lower_eta_fraction"], "lower_why": b["lower_why"],
                "last_stable_eta": b["last_stable_eta"],
                "last_stable_fraction": b["last_stable_eta"] / b["eta_peak"],
                "last_stable_state": last_stable["state"] if last_stable else None,
                "eta_lim": [b["eta_lim_low"], b["eta_lim_high"]], "directions": dem_dirs,
                "boundaries": b},
        "states": states, "trace": trace, "curves": curves,
    }


def second_optimum(P: HParams, fit_summary: dict, bounds: dict):
    """The next-best distinct optimum of the fit (if any): its lower boundary as a fraction of its
    peak, to say whether the conclusion rests on the choice between optima."""
    opts = fit_summary.get("optima") or []
    if len(opts) < 2:
        return None
    o = opts[1]
    P2 = P.replace(**o["end"])
    dp = domain_point(P2, P2.p0)
    frac = dp.q_w2sigma / dp.p_w2sigma / (dp.q_peak / dp.p_peak)
    lo, hi = bounds["last_stable_eta"] / bounds["eta_peak"], bounds["lower_eta_fraction"]
    inside = lo < frac <= hi
    txt = (f"- **The second optimum of the fit** (cost {o['cost']:.4g} against {opts[0]['cost']:.4g}, "
           + ", ".join(f"{k} {v:.4g}" for k, v in o["end"].items())
           + f"): peak eta {dp.q_peak / dp.p_peak:.4f}, first W2_sigma <= 0 at eta "
           f"{dp.q_w2sigma / dp.p_w2sigma:.4f}, {frac:.3f} of its peak: "
           + ("inside the DEM's bracket too." if inside else
              bracket(frac, lo, hi).replace("the bracket", "the DEM's bracket")
              + ": the agreement above belongs to the best fit, not to any parameter set near the "
              "DEM's curve."))
    return {"end": o["end"], "cost": o["cost"], "eta_peak": dp.q_peak / dp.p_peak,
            "eta_w2sigma": dp.q_w2sigma / dp.p_w2sigma, "fraction_w2sigma": frac, "text": txt}
