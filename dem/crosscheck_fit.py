"""The H-model fitted to the project's 12,000-disk DEM curve, its directional analysis and
bifurcation domain beside the DEM's, as fractions of each peak and in eta (issue 19, part 2).

    python -m dem.crosscheck_fit [--dem docs/gallery/full] [--out docs/gallery/fit_dem12000]

runs, in order: ``python -m hmodel fit`` on DEM/biaxial.csv (OUT/params.json, fig_fit.png, ...);
``python -m hmodel probes`` with the fitted parameters at the fraction of the fitted model's peak
where the DEM's lower boundary lies (OUT/probes/); ``python -m hmodel domain`` at the fitted
confining stress (OUT/domain/); then, for every state of the DEM's domain
(DEM/domain12000/domain.csv, boundaries.json), the H-model's minimum second-order work at the
same fraction of its own peak and at the same eta, written to OUT/comparison.csv,
comparison.json, fig_comparison.png, fig_domain_pq.png and comparison.md (docs/fit.md).

Second-order work on both sides: the DEM's is ds.de / (|ds| |de|) of stress probes (Eulerian,
dem/probes.py); the H-model's is given both as its Lagrangian W2 = dPi:de / (|dPi| |de|) (the
paper's, spec/hmodel.md) and as ds.de / (|ds| |de|), the DEM's definition. This module reads the
DEM's files. A cross-check job (beside ``dem.crosscheck`` and ``dem.crosscheck_burst``, the
places of ``dem`` that import ``hmodel``), so that ``hmodel`` imports nothing of ``dem``.
"""
from __future__ import annotations

import csv
import json
import math
import os
import sys
import time

import numpy as np

from hmodel import cli, options as opt
from hmodel.experiment import biaxial_test, domain_point, state_at_eta
from hmodel.fit import _jsonable
from hmodel.io import atomic_open, read_csv, save_figure, write_csv
from hmodel.params import HParams, load_params
from hmodel.probes import arcs, directional_sweep, format_arcs, stress_probes

__all__ = ["read_dem_domain", "param_argv", "eulerian_w2", "hmodel_state", "compare", "main"]

# the fractions of the fitted model's peak eta where the H-model's minimum W2 is traced (figure)
TRACE_FRACTIONS = np.round(np.arange(0.80, 0.9951, 0.005), 3)


def _log(msg):
    print(f"[fit_dem] {msg}", file=sys.stderr, flush=True)


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


def param_argv(P: HParams) -> list:
    """The model options of ``python -m hmodel`` that give ``P`` (floats by repr: every bit)."""
    argv = ["--kn", repr(P.kn), "--kt", repr(P.kt), "--phi-g", repr(P.phi_g), "--r-g", repr(P.r_g),
            "--alpha0", repr(P.alpha0), "--n-dir", str(P.n_dir), "--fabric-a", repr(P.fabric_a),
            "--fabric-b", repr(P.fabric_b)]
    if P.thickness is not None:
        argv += ["--thickness", repr(P.thickness)]
    return argv


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


# -- figures and report ---------------------------------------------------------------------------
def _figures(c: dict, out: str, dem_curve: dict, fit_curve: dict):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    h, d = c["hmodel"], c["dem"]
    tr = c["trace"]
    st = c["states"]
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.6), constrained_layout=True)
    for ax, key, scale_h, xlabel in ((axes[0], "fraction", 1.0, r"fraction of the peak $\eta/\eta_{peak}$ [-]"),
                                     (axes[1], "eta", h["eta_peak"], r"stress ratio $\eta = q/p$ [-]")):
        xh = np.array([t["fraction"] for t in tr]) * scale_h
        ax.plot(xh, [t["min_w2_eulerian"] for t in tr], "C3-", label=r"H-model, min $\delta\sigma:\delta\varepsilon$ (DEM's $W_2$)")
        ax.plot(xh, [t["min_w2"] for t in tr], "C3--", lw=0.9, label=r"H-model, min $W_2$ Lagrangian")
        xs = np.array([s["dem_fraction"] if key == "fraction" else s["dem_eta"] for s in st])
        w = np.array([s["dem_min_w2"] for s in st])
        fail = np.array([s["dem_n_failure"] > 0 for s in st])
        ax.plot(xs[~fail], w[~fail], "ko", label="DEM, min $W_2$ (all probes settled)")
        ax.plot(xs[fail], w[fail], "kx", ms=9, mew=2, label="DEM, probes failed (run away)")
        lo = d["last_stable_fraction"] if key == "fraction" else d["last_stable_eta"]
        hi = d["lower_fraction"] if key == "fraction" else d["lower_eta"]
        ax.axvspan(lo, hi, color="0.85", zorder=0, label="DEM lower boundary (bracket)")
        xb = h["fraction_w2sigma"] if key == "fraction" else h["eta_w2sigma"]
        ax.axvline(xb, color="C3", ls=":", label=r"H-model first $W_2^\sigma \leq 0$")
        ax.axhline(0, color="k", lw=0.6)
        ax.set_xlabel(xlabel)
        ax.set_ylabel("minimum normalized second-order work [-]")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, loc="upper right")
    axes[0].set_title("as fractions of each peak")
    axes[1].set_title(f"in eta (peaks: DEM {d['eta_peak']:.4f}, H-model {h['eta_peak']:.4f})")
    ax = axes[2]
    ax.plot([t["fraction"] for t in tr], [t["alpha_min_w2_eulerian"] for t in tr], "C3-", label="H-model")
    ax.plot([s["dem_fraction"] for s in st], [s["dem_alpha_min_w2"] for s in st], "ko", label="DEM (sampled every 5 deg)")
    ax.set_xlabel(r"fraction of the peak $\eta/\eta_{peak}$ [-]")
    ax.set_ylabel(r"direction of the minimum, $\alpha_\sigma$ [deg]")
    ax.set_title("where the minimum lies")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    save_figure(fig, os.path.join(out, "fig_comparison.png"))

    fig, ax = plt.subplots(figsize=(6.5, 5))
    pd = 0.5 * (dem_curve["s1"] + dem_curve["s2"])
    ax.plot(pd / 1e3, dem_curve["q"] / 1e3, "-", color="0.6", lw=0.8, label="DEM drained path")
    ax.plot(np.asarray(fit_curve["p"]) / 1e3, np.asarray(fit_curve["q"]) / 1e3, "C3-", lw=1.2,
            label="H-model (fitted) drained path")
    for s in st:
        pq = s["h_same_fraction"]
        ax.plot(pq["p"] / 1e3, pq["q"] / 1e3, "C3.", ms=6)
    for s in st:
        # the DEM state itself, from its eta on its own path
        j = int(np.argmin(np.abs(dem_curve["eps1"] - s["dem_eps1"])))
        mk = "kx" if s["dem_n_failure"] > 0 else "ko"
        ax.plot(pd[j] / 1e3, dem_curve["q"][j] / 1e3, mk, ms=6)
    ax.plot(h["p_w2sigma"] / 1e3, h["q_w2sigma"] / 1e3, "C3s", ms=8, mfc="none", label=r"H-model first $W_2^\sigma \leq 0$")
    ax.plot(h["p_peak"] / 1e3, h["q_peak"] / 1e3, "C3v", label="H-model peak")
    ax.plot([], [], "ko", label="DEM states (settled)")
    ax.plot([], [], "kx", label="DEM state with failures")
    ps = [s["h_same_fraction"]["p"] for s in st] + [h["p_peak"]]
    qs = [s["h_same_fraction"]["q"] for s in st] + [h["q_peak"], float(np.max(dem_curve["q"]))]
    ax.set_xlim(min(ps) / 1e3 - 15, max(max(ps), float(np.max(pd))) / 1e3 + 5)
    ax.set_ylim(min(qs) / 1e3 - 25, max(qs) / 1e3 + 10)
    ax.set_xlabel("mean stress p = (s1 + s2)/2 [kPa]")
    ax.set_ylabel("deviatoric stress q = s1 - s2 [kPa]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("Near the peak: DEM states and the fitted H-model\n(red dots: H-model at the DEM states' fractions of its peak)", fontsize=10)
    save_figure(fig, os.path.join(out, "fig_domain_pq.png"))


def _direction_figures(c: dict, out: str) -> list:
    """fig_w2_by_direction.png: for every DEM state, its probes' W2 against alpha_sigma (settled:
    dots; failures: triangles on W2 = 0) and the H-model's at the same fraction of its peak
    (line); fig_polar_<state>.png, the same in the paper's polar diagram
    (``plots.fig_polar_w2``) for the DEM's last stable and first unstable states. Returns the
    names of the polar figures."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hmodel.plots import fig_polar_w2
    st, d = c["states"], c["dem"]
    fig, axes = plt.subplots(1, len(st), figsize=(3.6 * len(st), 3.8), sharey=True, constrained_layout=True)
    axes = np.atleast_1d(axes)
    names = []
    for ax, s in zip(axes, st):
        a_h, w_h = c["curves"][s["state"]]
        o = np.argsort(a_h)
        bd = s["by_direction"]
        a = np.array([b["alpha_sigma"] for b in bd])
        w = np.array([b["dem_w2"] for b in bd])
        fail = np.array([b["dem_outcome"] == "failure" for b in bd])
        ax.plot(a_h[o], w_h[o], "C3-", lw=1.1, label="H-model (fitted)")
        ax.plot(a[~fail], w[~fail], "ko", ms=4, label="DEM, settled")
        if fail.any():
            ax.plot(a[fail], np.zeros(fail.sum()), "C0^", ms=6, label="DEM, run away")
        ax.axhline(0, color="k", lw=0.6)
        ax.set_xlim(0, 360)
        ax.set_xticks(range(0, 361, 90))
        ax.set_ylim(-0.3, 1.1)
        ax.set_xlabel(r"$\alpha_\sigma$ [deg]")
        ax.set_title(f"{s['state']}: {s['dem_fraction']:.3f} of the peak", fontsize=9)
        ax.grid(alpha=0.3)
        if s["state"] in (d["last_stable_state"], d["lower_state"]):
            series = [("H-model (fitted), same fraction of its peak", a_h, w_h, "C3-"),
                      ("DEM, settled probes", a[~fail], w[~fail], "ko")]
            if fail.any():
                series.append(("DEM, failures (run away)", a[fail], np.zeros(fail.sum()), "C0^"))
            name = f"fig_polar_{s['state']}.png"
            fig_polar_w2(series, os.path.join(out, name),
                         title=(f"{s['state']}: {s['dem_fraction']:.3f} of each peak (DEM eta "
                                f"{s['dem_eta']:.4f}, H-model {s['h_same_fraction']['eta']:.4f})\n"
                                r"$W_2 = \delta\sigma:\delta\varepsilon / |\delta\sigma||\delta\varepsilon|$"))
            names.append(name)
    axes[0].set_ylabel(r"$\delta\sigma:\delta\varepsilon / |\delta\sigma||\delta\varepsilon|$ [-]")
    axes[-1].legend(fontsize=7, loc="lower left")
    save_figure(fig, os.path.join(out, "fig_w2_by_direction.png"))
    return names


def _markdown(c: dict, fit_summary: dict, argv_text: str) -> str:
    h, d = c["hmodel"], c["dem"]
    st = c["states"]
    fs = fit_summary
    L = ["## The H-model fitted to the 12,000-disk DEM: bifurcation domain on an equal footing", "",
         f"Regenerate: `{argv_text}` (docs/fit.md). The paper compared its H-model (Table I) with a DEM "
         "sample of other properties; here the H-model's parameters are fitted to the DEM's own drained "
         "curve, so both describe the same material before their directional analyses are compared.", "",
         "### The fit", "", "![fit](fig_fit.png)", "",
         f"Data: `{fs['data']}`, {fs['n_points']} points, sigma2 = {fs['sigma2'] / 1e3:.2f} kPa "
         f"({fs['sigma2_from']}); weights: q by 1/max|q|, eps_v by 1/max|eps_v|; no smoothing (the "
         f"stick-slip noise is correlated: lag-1 correlation of the residuals {fs['lag1_correlation']:.2f}, "
         f"variances inflated by {fs['variance_inflation']:.1f}).", "",
         "| parameter | fitted | 95 % interval | determined |", "|---|---|---|---|"]
    for nme, e in fs["fitted"].items():
        L.append(f"| {nme} [{e['unit']}] | {e['value']:.4g} | {e['ci95'][0]:.4g} to {e['ci95'][1]:.4g} | "
                 f"{'yes' if e['determined'] else 'no: ' + e['why']} |")
    g = fs["groups"]
    opt_ = fs["optima"]
    L += ["", f"Held (not determined by a drained curve): r_g = {fs['params']['r_g']:g} m, thickness 2 r_g; "
          f"the curve fixes kn/h = {g['kn_over_h']:.4g} Pa (kn/(p0 h) = {g['kn_over_p0h']:.4g}) and "
          f"kt/kn = {g['kt_over_kn']:.3g}. RMS misfit: q {fs['rms_q'] / 1e3:.2f} kPa "
          f"({fs['rms_q'] / h['q_peak']:.1%} of the "
          f"fitted peak q), eps_v {fs['rms_eps_v']:.2e}. {len(fs['starts'])} starts reached {len(opt_)} "
          f"distinct optima: " + "; ".join(f"cost {o['cost']:.4g} ({len(o['starts'])} "
                                          f"start{'s' if len(o['starts']) > 1 else ''}: "
                                          + ", ".join(f"{k_} {v:.4g}" for k_, v in o["end"].items()) + ")"
                                          for o in opt_[:3]) + ".", ""]
    L += ["### Peaks and the lower boundary of the bifurcation domain", "",
          "![comparison](fig_comparison.png)", "", "![domain](fig_domain_pq.png)", "",
          "![by direction](fig_w2_by_direction.png)", "",
          f"The fitted H-model's full directional analysis at the DEM's first unstable fraction "
          f"({c['probes_fraction']:.3f} of its peak, eta = {c['probes_eta']:.4f}): `probes/` (Figs. 3, 6-9, 11, "
          "probes.csv, summary.json); its domain at the fitted confining stress: `domain/`.", "",
          *[f"![{p[10:-4]}]({p})\n" for p in c.get("polar_figures", [])],
          "| | DEM (12,000 disks) | H-model (fitted) |", "|---|---|---|",
          f"| peak eta (p = (s1+s2)/2) | {d['eta_peak']:.4f} | {h['eta_peak']:.4f} |",
          f"| peak q [kPa] at eps1 [%] | {c['dem_q_peak'] / 1e3:.1f} at {100 * c['dem_eps1_peak']:.2f} | "
          f"{h['q_peak'] / 1e3:.1f} at {100 * h['eps1_peak']:.2f} |",
          f"| last state with every probe settled, W2 > 0 | eta {d['last_stable_eta']:.4f} "
          f"({d['last_stable_fraction']:.3f} of the peak) | |",
          f"| first state with W2 <= 0 or a failure | eta {d['lower_eta']:.4f} ({d['lower_fraction']:.3f}; "
          f"{d['lower_why']}) | |",
          f"| first W2_sigma <= 0 (ds:de, the DEM's W2) | | eta {h['eta_w2sigma']:.4f} "
          f"({h['fraction_w2sigma']:.3f} of the peak) |",
          f"| first W2 <= 0 (Lagrangian, the paper's) | | eta {h['eta_w2']:.4f} ({h['fraction_w2']:.3f}) |",
          f"| strength under stress control | {_eta_lim_text(d)} | "
          f"{h['eta_peak']:.4f} (its peak: a rate-independent material point holds any stress below it) |", ""]
    L += ["### Along the path, state by state", "",
          "DEM: minimum of ds.de/(|ds||de|) over its settled stress probes (21 directions, 5-30 deg apart). "
          "H-model: the same quantity, minimum over all directions (adaptive sweep) and over the DEM's 21 "
          "directions, at the same fraction of its own peak and at the same eta.", "",
          "| DEM state | eta (fraction) | DEM min W2 at deg | failures (deg) | H same fraction: min W2 at deg "
          "(at DEM directions) | H same eta: min W2 at deg |", "|---|---|---|---|---|---|"]
    for s in st:
        hf, he = s["h_same_fraction"], s["h_same_eta"]
        L.append(f"| {s['state']} | {s['dem_eta']:.4f} ({s['dem_fraction']:.3f}) | "
                 f"{s['dem_min_w2']:.3f} at {s['dem_alpha_min_w2']:.0f} | "
                 f"{', '.join(f'{a:.0f}' for a in s['dem_failure_directions']) or 'none'} | "
                 f"{hf['min_w2_eulerian']:.3f} at {hf['alpha_min_w2_eulerian']:.1f} "
                 f"({hf['min_w2_dem_directions']:.3f} at {hf['alpha_min_w2_dem_directions']:.0f}) | "
                 + (f"{he['min_w2_eulerian']:.3f} at {he['alpha_min_w2_eulerian']:.1f}" if he else "beyond its peak")
                 + " |")
    L += ["", "### What agrees and what does not", ""] + c["verdicts"] + [""]
    return "\n".join(L)


def _bracket(x, lo, hi):
    """'inside' the DEM's bracket (lo, hi], or 'below' / 'above' it by how much."""
    if lo < x <= hi:
        return "inside the bracket"
    return f"{'below' if x <= lo else 'above'} the bracket by {min(abs(x - lo), abs(x - hi)):.4f}"


def _eta_lim_text(d):
    """The DEM's strength under stress control in the DEM's own words (dem.domain, imported
    here only: the rest of this module reads the DEM's files)."""
    from .domain import eta_lim_text
    return eta_lim_text(d["boundaries"])


def verdicts(c: dict) -> list:
    """The statements of comparison.md, each decided from the numbers by the rule it states."""
    h, d = c["hmodel"], c["dem"]
    st = c["states"]
    out = []
    for what, key_h, lo, hi in (("as a fraction of the peak", "fraction", d["last_stable_fraction"], d["lower_fraction"]),
                                ("in eta", "eta", d["last_stable_eta"], d["lower_eta"])):
        xs, xl = h[f"{key_h}_w2sigma"], h[f"{key_h}_w2"]
        ok = lo < xs <= hi
        line = (f"- **Lower boundary {what}: {'agrees' if ok else 'differs'}** (rule: the H-model's first "
                f"W2_sigma <= 0, the DEM's definition of W2, inside the DEM's bracket). DEM: between "
                f"{lo:.4f} (every probe settled, W2 > 0) and {hi:.4f} ({d['lower_why']}). H-model: W2_sigma "
                f"{xs:.4f}, {_bracket(xs, lo, hi)}; W2 (Lagrangian) {xl:.4f}, {_bracket(xl, lo, hi)}.")
        if key_h == "eta":
            line += (f" The peaks differ by {h['eta_peak'] - d['eta_peak']:+.4f} in eta (H-model "
                     f"{h['eta_peak']:.4f}, DEM {d['eta_peak']:.4f}), their axial strains by a factor "
                     f"{h['eps1_peak'] / c['dem_eps1_peak']:.2f} ({100 * h['eps1_peak']:.2f} % against "
                     f"{100 * c['dem_eps1_peak']:.2f} %).")
        out.append(line)
    dirs = np.array(d["directions"])
    diffs, within = [], 0
    for s in st:
        a_d, a_h = s["dem_alpha_min_w2"], s["h_same_fraction"]["alpha_min_w2_eulerian"]
        step = float(np.min(np.abs(dirs[dirs != a_d] - a_d))) if dirs.size > 1 else math.inf
        diffs.append(abs(a_h - a_d))
        within += abs(a_h - a_d) <= step
    ok = within == len(st)
    out.append(f"- **Direction of the weakest response: {'agrees' if ok else f'agrees at {within} of {len(st)} states'}** "
               f"(rule: the H-model's direction of minimum W2 within one sampling step of the DEM's, 5 deg "
               f"near it). alpha_sigma of the minimum, DEM: "
               + ", ".join(f"{s['dem_alpha_min_w2']:.0f}" for s in st) + " deg; H-model at the same fractions: "
               + ", ".join(f"{s['h_same_fraction']['alpha_min_w2_eulerian']:.1f}" for s in st)
               + f" deg; largest difference {max(diffs):.1f} deg. Both in the third quadrant, both "
               "turning towards 245 deg as the peak nears.")
    sg = [(np.sign(s["dem_min_w2"]) == np.sign(s["h_same_fraction"]["min_w2_dem_directions"])) for s in st]
    ratio = [s["dem_min_w2"] / s["h_same_fraction"]["min_w2_dem_directions"] for s in st]
    out.append(f"- **Sign of the minimum W2 state by state: {'agrees' if all(sg) else 'differs'}; its size "
               f"differs** (DEM / H-model at the DEM's 21 directions, same fraction: "
               + "; ".join(f"{s['dem_fraction']:.3f}: {s['dem_min_w2']:.3f} / "
                           f"{s['h_same_fraction']['min_w2_dem_directions']:.3f}" for s in st)
               + f"; ratios {min(ratio):.2g} to {max(ratio):.2g}). The H-model's minimum falls steadily with "
               "eta; the DEM's does not (0.013 at 0.932, then 0.099 at 0.957: relaxed samples with their own "
               "stick-slip history). The DEM's W2 comes from finite stress probes of 2.5 kPa, the "
               "H-model's from rate probes.".replace("0.013 at 0.932, then 0.099 at 0.957", _dem_dip(st)))
    parts = []
    for s in st:
        bd = [b for b in s["by_direction"] if b["dem_outcome"] == "equilibrium" and np.isfinite(b["h_w2"])]
        dw = np.array([b["h_w2"] - b["dem_w2"] for b in bd])
        a = np.array([b["alpha_sigma"] for b in bd])
        weak = (a >= 215) & (a <= 245)
        parts.append(f"{s['state']}: RMS {np.sqrt(np.mean(dw ** 2)):.3f}, largest {np.max(np.abs(dw)):.3f} at "
                     f"{a[np.argmax(np.abs(dw))]:.0f} deg, {np.max(np.abs(dw[weak])):.3f} from 215 to 245 deg")
    last = st[-1]
    close = max(abs(b["h_w2"] - b["dem_w2"]) for b in last["by_direction"]
                if b["dem_outcome"] == "equilibrium" and 215 <= b["alpha_sigma"] <= 245)
    h_edge = max(arc[1] for arc in last["h_same_fraction"]["plastic_zone"]) % 360
    d_edge = max(b["alpha_sigma"] for b in last["by_direction"] if b["dem_plastic"] and b["alpha_sigma"] < 300)
    out.append(f"- **Direction by direction** (settled DEM probes against the H-model at the same fraction; "
               f"ds.de/(|ds||de|) on both sides): " + "; ".join(parts) + f". At {last['state']}, from 215 to "
               f"245 deg (the DEM's weakest directions) the two agree within {close:.3f}; the largest "
               f"differences lie at the edge of the plastic zone, which ends at {h_edge:.1f} deg in the "
               f"H-model and reaches {d_edge:.0f} deg in the DEM (its probes still slide there, W2 low, where "
               "the H-model's response is elastic, W2 high).")
    for s in st:
        if s["dem_n_failure"] == 0 and not s["dem_cone_w2"]:
            continue
        hf = s["h_same_fraction"]
        cone = hf["cone_w2_eulerian"]
        neg = sorted(a for a, w in hf["w2_at_dem_directions"].items() if w <= 0)
        dem_neg = sorted({a for arc in s["dem_cone_w2"] for a in arc})
        ok = neg == dem_neg
        out.append(f"- **Instability cone at {s['state']} ({s['dem_fraction']:.3f} of the peak): "
                   f"{'agrees' if ok else 'differs'}** (rule: the same sampled directions with W2 <= 0). "
                   f"DEM: W2 <= 0 at {', '.join(f'{a:.0f}' for a in dem_neg) or 'none'} deg among its settled "
                   f"probes; H-model: cone {format_arcs(cone)} deg, W2 <= 0 at "
                   f"{', '.join(f'{a:.0f}' for a in neg) or 'none'} deg of the DEM's directions.")
        if s["dem_n_failure"]:
            fw = [hf["w2_at_dem_directions"].get(float(a), math.nan) for a in s["dem_failure_directions"]]
            out.append(f"- **Failures outside the cone: the H-model has no counterpart.** There the DEM's probes "
                       f"in {', '.join(f'{a:.0f}' for a in s['dem_failure_directions'])} deg run away; the "
                       f"H-model's W2 in these directions is {min(fw):.3f} to {max(fw):.3f} (> 0). The DEM's "
                       f"runaways are its strength limit under stress control ({_eta_lim_text(d)}, "
                       f"docs/dem.md; the smallest target that failed at this state: eta = "
                       f"{s['dem_eta_target_min_failed']:.4f}); the H-model, rate-independent, holds any "
                       "stress below its peak.")
    return out


def _dem_dip(st):
    """Where the DEM's minimum W2 rises again along the path (text), or a plain statement."""
    for a, b in zip(st, st[1:]):
        if b["dem_min_w2"] > a["dem_min_w2"]:
            return (f"{a['dem_min_w2']:.3f} at {a['dem_fraction']:.3f}, then {b['dem_min_w2']:.3f} at "
                    f"{b['dem_fraction']:.3f}")
    return "it falls too, unevenly"


def main(argv=None) -> int:
    ap = opt.Parser(prog="python -m dem.crosscheck_fit",
                    description="fit the H-model to the DEM's drained curve and compare the bifurcation domains")
    ap.add_argument("--dem", default="docs/gallery/full",
                    help="folder of the DEM run: biaxial.csv and domain12000/{domain.csv,boundaries.json}")
    ap.add_argument("--out", default="docs/gallery/fit_dem12000", help="output folder")
    ap.add_argument("--starts", type=opt.integer(1), default=8, help="starts of the fit")
    ap.add_argument("--seed", type=opt.integer(0), default=0, help="seed of the starts")
    ap.add_argument("--n-dir", type=opt.integer(8), default=180, help="hexagon orientations of the H-model")
    ap.add_argument("--n-probes", type=opt.integer(8), default=360,
                    help="strain directions of each sweep [-] (default 360)")
    opt.add_quiet(ap)

    def run(args, stage):
        for f in ("biaxial.csv", "domain12000/domain.csv", "domain12000/boundaries.json",
                  "domain12000/domain_probes.csv"):
            if not os.path.isfile(os.path.join(args.dem, f)):
                raise opt.OptionError(f"--dem {args.dem}: no {f}: allowed the folder of a DEM run with "
                                      "its domain (docs/gallery/full)")
        opt.check_out_dir(args.out)
        t0 = time.time()
        log = (lambda m: None) if args.quiet else _log
        common = ["--n-dir", str(args.n_dir)] + (["--quiet"] if args.quiet else [])
        argv_fit = ["fit", "--data", os.path.join(args.dem, "biaxial.csv"), "--out", args.out,
                    "--starts", str(args.starts), "--seed", str(args.seed), *common]
        log("python -m hmodel " + " ".join(argv_fit))
        stage.at("the fit")
        code = cli.main(argv_fit)
        if code != 0:
            return code
        stage.wrote("the fit's files")
        P = load_params(os.path.join(args.out, "params.json"))
        with open(os.path.join(args.out, "summary.json")) as f:
            fit_summary = json.load(f)
        rows, bounds, dem_probes = read_dem_domain(args.dem)
        path = biaxial_test(P, P.p0, 1e-5, 0.03)
        _, _, e = path.invariants()
        f_a = bounds["lower_eta_fraction"]
        eta_a = float(f_a * e.max())
        pargs = param_argv(P) + ["--sigma2", repr(P.p0)]
        for sub, extra in (("probes", ["--eta-a", repr(eta_a), "--n-probes", str(args.n_probes)]),
                           ("domain", ["--n-probes", "180"])):
            argv_ = [sub, *extra, *pargs, "--out", os.path.join(args.out, sub)] + common[2:]
            log("python -m hmodel " + " ".join(argv_))
            stage.at(f"python -m hmodel {sub}")
            code = cli.main(argv_)
            if code != 0:
                return code
            stage.wrote(f"{sub}/")
        stage.at("the comparison")
        c = compare(P, rows, bounds, dem_probes, n=args.n_probes, progress=log)
        dem_curve = read_csv(os.path.join(args.dem, "biaxial.csv"))
        kd = int(np.argmax(dem_curve["q"]))
        c["dem_q_peak"], c["dem_eps1_peak"] = float(dem_curve["q"][kd]), float(dem_curve["eps1"][kd])
        c["probes_eta"] = eta_a
        c["probes_fraction"] = f_a
        c["verdicts"] = verdicts(c)
        c["second_optimum"] = _second_optimum(P, fit_summary, bounds)
        if c["second_optimum"]:
            c["verdicts"].append(c["second_optimum"]["text"])
        pp, qq, _ = path.invariants()
        _figures(c, args.out, dem_curve, {"p": pp, "q": qq})
        c["polar_figures"] = _direction_figures(c, args.out)
        cols = {"dem_eta": [s["dem_eta"] for s in c["states"]], "dem_fraction": [s["dem_fraction"] for s in c["states"]],
                "dem_min_w2": [s["dem_min_w2"] for s in c["states"]],
                "dem_alpha_min_w2": [s["dem_alpha_min_w2"] for s in c["states"]],
                "dem_n_failure": [s["dem_n_failure"] for s in c["states"]]}
        for tag in ("h_same_fraction", "h_same_eta"):
            for k_ in ("eta", "min_w2", "alpha_min_w2", "min_w2_eulerian", "alpha_min_w2_eulerian",
                       "min_w2_dem_directions", "alpha_min_w2_dem_directions"):
                cols[f"{tag}_{k_}"] = [s[tag][k_] if s[tag] else math.nan for s in c["states"]]
        write_csv(os.path.join(args.out, "comparison.csv"), cols)
        c["options"] = {k_: v for k_, v in vars(args).items()}
        c["wall_time_s"] = time.time() - t0
        with atomic_open(os.path.join(args.out, "comparison.json")) as f:
            json.dump(_jsonable({k_: v for k_, v in c.items() if k_ != "curves"}), f, indent=2)
        argv_text = "python -m dem.crosscheck_fit" + "".join(
            f" --{k_.replace('_', '-')} {v}" for k_, v in vars(args).items()
            if v != ap.get_default(k_))
        with atomic_open(os.path.join(args.out, "comparison.md")) as f:
            f.write(_markdown(c, fit_summary, argv_text) + "\n")
        stage.wrote("comparison.csv", "comparison.json", "comparison.md", "fig_comparison.png", "fig_domain_pq.png",
                    "fig_w2_by_direction.png", *c["polar_figures"])
        print("\n".join(c["verdicts"]))
        print(f"wrote {args.out}/comparison.md and the rest ({c['wall_time_s']:.0f} s)")
        return 0

    return opt.run_cli(ap, argv, run, errors=(ValueError,))


def _second_optimum(P: HParams, fit_summary: dict, bounds: dict):
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
              _bracket(frac, lo, hi).replace("the bracket", "the DEM's bracket")
              + ": the agreement above belongs to the best fit, not to any parameter set near the "
              "DEM's curve."))
    return {"end": o["end"], "cost": o["cost"], "eta_peak": dp.q_peak / dp.p_peak,
            "eta_w2sigma": dp.q_w2sigma / dp.p_w2sigma, "fraction_w2sigma": frac, "text": txt}


if __name__ == "__main__":
    sys.exit(main())
