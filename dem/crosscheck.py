"""The cross-check: H-model, finite elements and DEM side by side (paper sections 3-5).

``run_crosscheck`` runs
  1. the H-model directional analysis at its point A (eta = 1.029, Table I), its bifurcation
     domain (W2 and W2_sigma boundaries), and its stress probes in the DEM's 45 directions;
  2. the FE biaxial specimen (a coarse mesh: its perfect specimen follows the material point);
  3. the DEM experiment on a small sample (the paper's 12,000 disks with ``full=True``):
     compaction, drained biaxial test, 45 stress probes at its point A, each twice;
and writes the figures side by side, ``conclusions.json`` and ``report.md`` stating each
conclusion of the paper's section 5 as it comes out of this run.

This is the one module of ``dem`` that imports ``hmodel`` and ``fem`` (lazily): the DEM kernel
itself depends on neither. ``conclusions`` is a pure function of the three results, so the tests
can assert on it.
"""
from __future__ import annotations

import json
import os
import sys
import time

import numpy as np

__all__ = ["run_crosscheck", "conclusions", "hmodel_part", "fem_part", "dem_part", "write_report"]


def _log(msg):
    print(f"[crosscheck] {msg}", file=sys.stderr, flush=True)


# -- the three parts ---------------------------------------------------------------------------
def hmodel_part(eta_a=1.029, sigma2=200e3, alphas=None, domain_sigma2=(100e3, 200e3, 400e3),
                n_dir=180, workers=None):
    """H-model at A: path, adaptive strain-probe sweep, stress probes in ``alphas`` [deg],
    bifurcation domain. Returns a dict of arrays (SI, compression positive)."""
    from hmodel import HParams
    from hmodel.experiment import biaxial_test, bifurcation_domain, state_at_eta
    from hmodel.probes import directional_sweep, stress_probes

    P = HParams(n_dir=n_dir, p0=sigma2)
    path = biaxial_test(P, sigma2, 1e-5, 0.05)
    rA, sA = state_at_eta(P, eta_a, sigma2)
    sw = directional_sweep(sA, P, n=360)
    out = {"params": P, "path": path, "pathA": rA, "sweep": sw}
    if alphas is not None:
        out["stress_probes"] = stress_probes(sA, P, alphas, sigma_norm=2.5e3, sweep=sw)
    out["domain"] = bifurcation_domain(P, domain_sigma2, workers=workers) if domain_sigma2 else []
    return out


def fem_part(out_dir, nx=4, ny=8, n_dir=72, eps1_max=0.03):
    """FE biaxial specimen (coarse mesh, no field output). Returns its curve (dict of arrays)."""
    from fem.biaxial import BiaxialConfig, run_biaxial
    cfg = BiaxialConfig(nx=nx, ny=ny, n_dir=n_dir, eps1_max=eps1_max, d_eps1=1e-4, fields=False,
                        n_sphere=200)
    res = run_biaxial(cfg, out_dir=out_dir)
    return {"curve": res.curve, "events": res.events, "summary": res.summary, "n_dir": n_dir}


def dem_part(out_dir, n=1000, seed=1, rate=0.05, workers=None, eta_a=1.029, threads=None,
             alphas=None, max_steps=None, resume=False):
    """DEM: compaction, drained biaxial test, probes at A (default: the paper's 45 directions,
    each twice; ``max_steps`` caps each probe run, reported in the rows when hit).

    ``threads``: Numba threads of the compaction and the biaxial test (default: all; the
    results do not depend on it); the probes run one thread each in ``workers`` processes.
    ``resume``: keep what an interrupted run in ``out_dir`` finished (the biaxial test or its
    checkpoint, the relaxed reference state, the probe runs already on disk).
    """
    import numba

    from . import io
    from .experiment import COLUMNS, BiaxialResult, run_biaxial
    from .params import DemParams
    from .probes import ProbeOptions, directions, prepare_reference, run_probes

    numba.set_num_threads(min(threads or numba.config.NUMBA_NUM_THREADS,
                              numba.config.NUMBA_NUM_THREADS))
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
        _log(f"DEM: biaxial test taken from {bdir} ({len(rows)} rows)")
    else:
        res = run_biaxial(DemParams(n=n, seed=seed), bdir, rate=rate, eta_a=eta_a, vtk=False,
                          resume=resume)
    opts = ProbeOptions() if max_steps is None else ProbeOptions(max_steps=int(max_steps))
    t_probes0 = time.time()
    pdir = os.path.join(out_dir, "probes")
    os.makedirs(pdir, exist_ok=True)
    ref_path = os.path.join(pdir, "stateR.npz")
    checkpoint = os.path.join(pdir, "probe_runs.jsonl")
    if resume and os.path.exists(ref_path):
        stateR, meta = io.load_state(ref_path)
        ok = bool(meta.get("converged"))
        if not ok:
            # an earlier relaxation hit its cap: go on relaxing from where it stopped
            _log("DEM: the saved reference is not in equilibrium: relaxing it further")
            stateR, ok, steps, ub = prepare_reference(stateR, opts, verbose=True)
            io.save_state(ref_path, stateR, meta={"converged": ok, "unbalanced": ub})
            if os.path.exists(checkpoint):
                os.remove(checkpoint)
    else:
        if os.path.exists(checkpoint):
            os.remove(checkpoint)
        state, _ = io.load_state(res.state_a_path)
        _log("DEM: relaxing A under stress control (the reference of the probes)")
        stateR, ok, steps, ub = prepare_reference(state, opts, verbose=True)
        io.save_state(ref_path, stateR, meta={"converged": ok, "unbalanced": ub})
    _log(f"DEM: reference state converged={ok}")
    t_relaxed = time.time()
    _log(f"DEM: probes ({pdir}, every finished run in {os.path.basename(checkpoint)})")
    probes = run_probes(stateR, directions() if alphas is None else list(alphas), opts,
                        workers=workers, verbose=True, checkpoint=checkpoint)
    from .probes import COLUMNS as PROBE_COLUMNS, plot_probes
    io.write_csv(os.path.join(pdir, "probes.csv"), PROBE_COLUMNS,
                 [[int(r[k]) if isinstance(r[k], bool) else r[k] for k in PROBE_COLUMNS]
                  for r in probes])
    plot_probes(probes, pdir)
    stages = {"compaction + biaxial test (when it ran)": res.wall_time,
              "relaxation of A (this run)": t_relaxed - t_probes0,
              "probes (this run)": time.time() - t_relaxed}
    return {"biaxial_rows": res.rows, "state_a": res.state_a_path, "eta_a_reached": res.eta_a_reached,
            "compaction": res.compaction, "probes": probes, "reference_converged": bool(ok),
            "stage_times": stages}


# -- conclusions -------------------------------------------------------------------------------
def _zone_stats(w2, micro, plastic):
    d = np.abs(np.asarray(w2) - np.asarray(micro))
    pl = np.asarray(plastic, bool)
    f = lambda x: {"mean": float(np.mean(x)), "max": float(np.max(x)), "n": int(x.size)} if x.size else None
    return {"elastic": f(d[~pl]), "plastic": f(d[pl])}


def conclusions(h: dict, dem_rows: list | None, fem: dict | None) -> dict:
    """The paper's section-5 conclusions as numbers, for each model."""
    from hmodel.probes import arcs
    sw = h["sweep"]
    c = {"hmodel": {}, "dem": None, "fem": None, "domain": []}
    hm = c["hmodel"]
    neg = sw.w2 <= 0
    hm["cone_w2"] = arcs(sw.alpha_sigma, neg)
    hm["cone_w2sigma"] = arcs(sw.alpha_sigma, sw.w2_sigma <= 0)
    hm["plastic_zone"] = arcs(sw.alpha_sigma, sw.plastic)
    hm["min_w2"] = float(sw.w2.min())
    hm["alpha_min_w2"] = float(sw.alpha_sigma[np.argmin(sw.w2)])
    hm["cone_in_third_quadrant"] = bool(neg.any() and np.all((sw.d_sigma[neg, 0] < 0) & (sw.d_sigma[neg, 1] < 0)))
    hm["micro_minus_macro"] = _zone_stats(sw.w2, sw.w2_micro, sw.plastic)
    hm["w2n_min"] = float(sw.w2n.min())
    hm["w2t_max_in_cone"] = float(sw.w2t[neg].max()) if neg.any() else None
    hm["w2n_min_in_cone"] = float(sw.w2n[neg].min()) if neg.any() else None
    pA, qA, etaA = h["pathA"].invariants()
    p, q, eta = h["path"].invariants()
    hm["eta_A"] = float(etaA[-1])
    hm["eps1_A"] = float(h["pathA"].eps[-1, 0])
    hm["eta_peak"] = float(eta[np.argmax(q)])
    hm["eps1_peak"] = float(h["path"].eps[np.argmax(q), 0])
    hm["q_peak"] = float(q.max())
    for d in h.get("domain", []):
        c["domain"].append({"sigma2": d.sigma2, "eta_w2": d.q_w2 / d.p_w2, "eta_w2sigma": d.q_w2sigma / d.p_w2sigma,
                            "eta_peak": d.q_peak / d.p_peak, "q_w2": d.q_w2, "q_w2sigma": d.q_w2sigma,
                            "q_peak": d.q_peak,
                            "rel_shift_q": (d.q_w2 - d.q_w2sigma) / d.q_w2})
    if dem_rows:
        g = lambda k: np.array([r[k] for r in dem_rows], float)
        a, w2, mic = g("alpha_sigma"), g("w2"), g("w2_micro")
        w2n, w2t, pl = g("w2n"), g("w2t"), g("plastic").astype(bool)
        conv = g("converged").astype(bool) & g("converged_elastic").astype(bool)
        # A probe stopped at the step cap has no equilibrium end (the stress increment exceeds
        # what the sample carries, as in directions of increasing q near the peak): its W2 is
        # that of a dynamic state, so the W2 statistics use the probes that reached equilibrium.
        ok = conv
        ka = np.flatnonzero(ok)
        k = int(ka[np.argmin(w2[ok])])
        negd = ok & (w2 <= 0)
        low = ok & (w2 <= w2[k] + 0.1)            # the low-W2 cone (within 0.1 of the minimum)
        c["dem"] = {
            "n_probes": int(a.size), "n_not_converged": int((~conv).sum()),
            "alpha_not_converged": [float(x) for x in a[~conv]],
            "cone_w2": arcs(a[ok], negd[ok]), "min_w2": float(w2[k]), "alpha_min_w2": float(a[k]),
            "min_in_third_quadrant": bool(180.0 <= a[k] <= 270.0),
            "low_w2_cone": arcs(a[ok], low[ok]),
            "plastic_zone": arcs(a, pl),
            "micro_minus_macro": _zone_stats(w2[ok], mic[ok], pl[ok]),
            "micro_below_macro_in_plastic_zone": bool((pl & ok).any() and np.mean(mic[pl & ok] - w2[pl & ok]) < 0),
            "w2n_min": float(w2n[ok].min()),
            "w2t_max_in_plastic_zone": float(w2t[pl & ok].max()) if (pl & ok).any() else None,
            "w2t_at_min_w2": float(w2t[k]), "w2n_at_min_w2": float(w2n[k]),
        }
    if fem is not None:
        from hmodel.driver import drained_biaxial, isotropic_state, run_path
        from hmodel.params import HParams
        cur = fem["curve"]
        P = HParams(n_dir=fem["n_dir"])
        e1 = np.asarray(cur["eps1"], float)
        r = run_path(isotropic_state(P), P, drained_biaxial(1e-4), int(round(e1[-1] / 1e-4)))
        qm = np.interp(e1, r.eps[:, 0], r.sigma[:, 0] - r.sigma[:, 1])
        qf = np.asarray(cur["q"], float)
        c["fem"] = {"max_rel_q_diff_vs_material_point": float(np.max(np.abs(qf - qm)) / np.max(qm)),
                    "eps1_peak": float(e1[np.argmax(qf)]), "events": fem.get("events")}
    return c


# -- figures and report ------------------------------------------------------------------------
def _angle_axes(ax):
    """W2 against alpha_sigma: the frame shared by the side-by-side figures."""
    ax.axhline(0, color="k", lw=0.6)
    ax.set_xlim(0, 360)
    ax.set_xticks(range(0, 361, 45))
    ax.set_xlabel("alpha_sigma [deg] (tan = d sigma1 / d sigma2)")
    ax.set_ylabel("normalized second-order work [-]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)


def _figures(out, h, dem, fem):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hmodel.io import save_figure
    from hmodel.plots import polar_axes

    figs = {}
    sw = h["sweep"]
    o = np.argsort(sw.alpha_sigma)
    rows = dem["probes"] if dem else None
    # a probe without equilibrium has no W2 (Eq. 15 needs equilibrium at both ends): NaN, so
    # that the curves break there, and the count in the legend
    conv = lambda k: [float(r[k]) if r["converged"] else np.nan for r in rows]
    n_failed = sum(1 for r in rows if not r["converged"]) if rows else 0
    failed_note = f" ({n_failed} without equilibrium not drawn)" if n_failed else ""

    def polar(ax, a_deg, w, style, label):
        a = np.radians(np.asarray(a_deg, float))
        r = 0.5 + np.asarray(w, float)
        ax.plot(r * np.cos(a), r * np.sin(a), style, label=label, ms=4, lw=1.2)

    # stress-strain (Figs. 4-5 and 13-14)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.3), constrained_layout=True)
    p, q, _ = h["path"].invariants()
    e = h["path"].eps
    a1.plot(100 * e[:, 0], q / 1e3, label="H-model material point")
    a2.plot(100 * e[:, 0], 100 * (e[:, 0] + e[:, 1]), label="H-model material point")
    if fem is not None:
        cur = fem["curve"]
        a1.plot(100 * np.asarray(cur["eps1"]), np.asarray(cur["q"]) / 1e3, "--", label=f"FE specimen (n_dir {fem['n_dir']})")
        if "eps2_mean" in cur:
            ev = np.asarray(cur["eps1"]) + np.asarray(cur["eps2_mean"])
            a2.plot(100 * np.asarray(cur["eps1"]), 100 * ev, "--", label="FE specimen")
    if dem is not None:
        from .experiment import COLUMNS
        arr = np.array(dem["biaxial_rows"], float)
        col = {k: arr[:, COLUMNS.index(k)] for k in ("eps1", "eps_v", "q")}
        a1.plot(100 * col["eps1"], col["q"] / 1e3, label="DEM sample")
        a2.plot(100 * col["eps1"], 100 * col["eps_v"], label="DEM sample")
    for ax, yl in ((a1, "deviatoric stress q = s1 - s2 [kPa]"), (a2, "volumetric strain eps_v [%] (contraction > 0)")):
        ax.set_xlabel("axial strain eps1 [%]")
        ax.set_ylabel(yl)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        ax.set_xlim(0, 5)
    a1.set_title("Drained biaxial test at 200 kPa (Figs. 4 and 13)")
    a2.set_title("Volumetric response (Figs. 5 and 14)")
    figs["stress_strain"] = "fig_stress_strain.png"
    save_figure(fig, os.path.join(out, figs["stress_strain"]))

    # polar W2 (Figs. 8 and 15)
    fig, axs = plt.subplots(1, 2, figsize=(11, 5.6), constrained_layout=True)
    for ax in axs:
        polar_axes(ax, rmax=1.6)
    polar(axs[0], sw.alpha_sigma[o], sw.w2[o], "C3-", "H-model W2 (strain-probe sweep)")
    if "stress_probes" in h:
        sp = h["stress_probes"]
        polar(axs[0], sp.probe.alpha_sigma, sp.probe.w2, "ko", "H-model, DEM directions")
    axs[0].set_title("H-model at A (Fig. 8)")
    if rows:
        a = [r["alpha_sigma"] for r in rows] + [rows[0]["alpha_sigma"]]
        polar(axs[1], a, conv("w2") + conv("w2")[:1], "C0o-",
              f"DEM W2 ({len(rows)} stress probes{failed_note})")
    axs[1].set_title("DEM at A (Fig. 15)")
    for ax in axs:
        ax.legend(fontsize=8, loc="upper left")
    figs["polar_w2"] = "fig_polar_w2.png"
    save_figure(fig, os.path.join(out, figs["polar_w2"]))

    # micro against macro (Fig. 16, and the H-model identity)
    fig, axs = plt.subplots(1, 2, figsize=(11, 4.3), constrained_layout=True)
    axs[0].plot(sw.alpha_sigma[o], sw.w2[o], label="macro W2 = V dPi:de")
    axs[0].plot(sw.alpha_sigma[o], sw.w2_micro[o], "--", label="micro: sum of df.dl over contacts")
    axs[0].set_title("H-model: micro and macro W2 (identical to round-off)")
    if rows:
        a = np.array([r["alpha_sigma"] for r in rows])
        axs[1].plot(a, conv("w2"), "o-", label="macro W2 (walls)" + failed_note)
        axs[1].plot(a, conv("w2_micro"), "s--", label="micro: sum df.dl over grain contacts")
        pl = np.array([r["plastic"] for r in rows], bool)
        axs[1].plot(a[pl], np.array(conv("w2"))[pl], "x", color="C3", label="plastic probe")
    axs[1].set_title("DEM (Fig. 16)")
    for ax in axs:
        _angle_axes(ax)
    figs["micro_macro"] = "fig_micro_macro.png"
    save_figure(fig, os.path.join(out, figs["micro_macro"]))

    # normal and tangential parts (Figs. 11 and 17)
    fig, axs = plt.subplots(1, 2, figsize=(11, 4.3), constrained_layout=True)
    axs[0].plot(sw.alpha_sigma[o], sw.w2n[o], label="W2n (normal)")
    axs[0].plot(sw.alpha_sigma[o], sw.w2t[o], label="W2t (tangential)")
    axs[0].plot(sw.alpha_sigma[o], sw.w2[o], "k:", lw=0.8, label="W2")
    axs[0].set_title("H-model (Fig. 11)")
    if rows:
        a = np.array([r["alpha_sigma"] for r in rows])
        axs[1].plot(a, conv("w2n"), "o-", label="W2n (normal)" + failed_note)
        axs[1].plot(a, conv("w2t"), "s-", label="W2t (tangential)")
        axs[1].plot(a, conv("w2"), "k:", lw=0.8, label="W2 macro")
    axs[1].set_title("DEM (Fig. 17)")
    for ax in axs:
        _angle_axes(ax)
    figs["normal_tangential"] = "fig_normal_tangential.png"
    save_figure(fig, os.path.join(out, figs["normal_tangential"]))

    if h.get("domain"):
        from hmodel.plots import fig_domain
        figs["domain"] = "fig_domain.png"
        fig_domain(h["domain"], os.path.join(out, figs["domain"]))
    return figs


DEFAULT_SMALL = {"n": 1000, "rate": 0.05, "max_steps": 100_000}
DEFAULT_FULL = {"n": 12000, "rate": 0.01, "max_steps": 400_000}


def write_report(out, c: dict, figs: dict, timings: dict, config: dict):
    """report.md: every figure embedded and the paper's section-5 conclusions in numbers."""
    from hmodel.io import atomic_open
    from hmodel.probes import format_arcs
    hm, dm, fm = c["hmodel"], c["dem"], c["fem"]
    L = ["# Cross-check: H-model, finite elements and DEM", "",
         f"Configuration: {json.dumps(config)}", "",
         "Conventions: compression positive; alpha_sigma with tan(alpha_sigma) = d sigma1 / d sigma2; "
         "W2 normalized by |d sigma||d eps| (H-model: |dPi||d eps|).", "",
         "## Stress-strain curves", "", f"![stress-strain]({figs['stress_strain']})", "",
         f"- H-model: peak q = {hm['q_peak'] / 1e3:.1f} kPa at eps1 = {100 * hm['eps1_peak']:.2f} % "
         f"(eta = {hm['eta_peak']:.4f}); point A (eta = {hm['eta_A']:.4f}) at eps1 = {100 * hm['eps1_A']:.2f} %, before the peak."]
    if fm:
        L.append(f"- FE specimen (perfect, coarse mesh) against the material point with the same "
                 f"orientations: max |q_FE - q_mp| / q_max = {fm['max_rel_q_diff_vs_material_point']:.2e}; "
                 f"FE peak at eps1 = {100 * fm['eps1_peak']:.2f} %.")
    if dm is not None:
        L.append(f"- DEM sample: see the curve; its A is the state where the directional analysis was run "
                 f"(eta_A reached: {config.get('dem_eta_a_reached')}).")
    L += ["", "## Second-order work at A", "", f"![polar W2]({figs['polar_w2']})", "",
          f"![micro and macro]({figs['micro_macro']})", "",
          f"![normal and tangential parts]({figs['normal_tangential']})", ""]
    if "domain" in figs:
        L += [f"![bifurcation domain]({figs['domain']})", ""]
    L += ["## The paper's conclusions (section 5), as they come out of this run", ""]
    # 1. instability cone
    s = (f"1. **Instability cone in the third quadrant.** H-model: W2 <= 0 for alpha_sigma in "
         f"{format_arcs(hm['cone_w2'])} deg (third quadrant: {hm['cone_in_third_quadrant']}), "
         f"minimum W2 = {hm['min_w2']:.3f} at {hm['alpha_min_w2']:.1f} deg, inside the plastic zone "
         f"{format_arcs(hm['plastic_zone'])} deg.")
    if dm:
        nc = dm["alpha_not_converged"]
        s += (f" DEM ({dm['n_probes']} probes; {len(nc)} reached no equilibrium within the step cap"
              + (f" (alpha_sigma = {', '.join(f'{x:.0f}' for x in nc)} deg: the sample fails under "
                 f"these increments) and are left out of the W2 statistics" if nc else "")
              + f"): W2 <= 0 for {format_arcs(dm['cone_w2']) if dm['cone_w2'] else 'no direction'}; minimum W2 = {dm['min_w2']:.3f} at "
              f"{dm['alpha_min_w2']:.0f} deg (third quadrant: {dm['min_in_third_quadrant']}); low-W2 cone "
              f"(within 0.1 of the minimum) {format_arcs(dm['low_w2_cone'])} deg; plastic zone "
              f"{format_arcs(dm['plastic_zone'])} deg.")
    L.append(s)
    # 2. micro vs macro
    mm = hm["micro_minus_macro"]
    s = (f"2. **Micro sum against macro W2.** H-model: max |W2 - sum df.dl| = "
         f"{mm['elastic']['max']:.1e} (elastic zone), {mm['plastic']['max']:.1e} (plastic zone): "
         f"the identity holds to round-off in the absence of inertia.")
    if dm:
        d = dm["micro_minus_macro"]
        fz = lambda z: f"mean {z['mean']:.3f}, max {z['max']:.3f} over {z['n']} probes" if z else "no probe"
        s += (f" DEM: |W2 - micro| {fz(d['elastic'])} in the elastic zone and {fz(d['plastic'])} in the "
              f"plastic zone; the micro sum is {'below' if dm['micro_below_macro_in_plastic_zone'] else 'not below'} "
              f"the macro W2 on average in the plastic zone (paper: the macro W2 exceeds the micro sum there).")
    L.append(s)
    # 3. normal / tangential
    s = (f"3. **The tangential part drives the vanishing.** H-model: min W2n = {hm['w2n_min']:.3f} (> 0 everywhere); "
         f"inside the cone max W2t = {hm['w2t_max_in_cone']:.3f} (< 0) while W2n >= {hm['w2n_min_in_cone']:.3f}."
         if hm["w2t_max_in_cone"] is not None else
         f"3. **Tangential part.** H-model: min W2n = {hm['w2n_min']:.3f}; no cone at this A.")
    if dm:
        s += (f" DEM: min W2n = {dm['w2n_min']:.3f}; max W2t in the plastic zone = "
              f"{dm['w2t_max_in_plastic_zone']:.3f}; at the minimum of W2, W2n = {dm['w2n_at_min_w2']:.3f} "
              f"and W2t = {dm['w2t_at_min_w2']:.3f}.")
    L.append(s)
    # 4. domain
    if c["domain"]:
        parts = [f"sigma2 = {d['sigma2'] / 1e3:.0f} kPa: eta = {d['eta_w2']:.3f} (W2), {d['eta_w2sigma']:.3f} "
                 f"(W2_sigma), peak {d['eta_peak']:.3f}; q moves by {100 * d['rel_shift_q']:.1f} %"
                 for d in c["domain"]]
        L.append("4. **Bifurcation domain: W2 against W2_sigma.** First direction with W2 <= 0 on the drained "
                 "path, against W2_sigma <= 0: " + "; ".join(parts) + ". The W2_sigma domain is slightly "
                 "larger and the boundary moves little: the geometric terms barely shift it.")
    L += ["", "## Wall times", ""] + [f"- {k}: {v:.1f} s" for k, v in timings.items()] + [""]
    with atomic_open(os.path.join(out, "report.md")) as f:
        f.write("\n".join(L))


def run_crosscheck(out_dir, full=False, n=None, seed=1, rate=None, workers=None, skip_dem=False,
                   fem_mesh=(4, 8), fem_n_dir=72, domain=True, dem_alphas=None,
                   dem_max_steps=None, threads=None, resume=False):
    """Run all three parts and write figures, conclusions.json and report.md in ``out_dir``.

    Default: 1000 disks at 0.05/s (minutes); ``full``: the paper's 12,000 disks at 0.01/s.
    ``dem_alphas`` [deg] replaces the 45 probe directions, ``dem_max_steps`` the probe cap;
    ``threads`` and ``resume``: see ``dem_part`` (the H-model and FE parts always rerun).
    """
    from hmodel.io import atomic_open

    from .probes import directions
    os.makedirs(out_dir, exist_ok=True)
    dflt = DEFAULT_FULL if full else DEFAULT_SMALL
    n = dflt["n"] if n is None else int(n)
    rate = dflt["rate"] if rate is None else float(rate)
    dem_max_steps = dflt["max_steps"] if dem_max_steps is None else int(dem_max_steps)
    timings = {}
    t = time.time()
    _log("H-model: drained path, point A, directional analysis, bifurcation domain")
    h = hmodel_part(alphas=directions() if dem_alphas is None else list(dem_alphas),
                    domain_sigma2=(100e3, 200e3, 400e3) if domain else (), workers=workers)
    timings["H-model (path, probes, domain)"] = time.time() - t
    t = time.time()
    _log(f"FE: {fem_mesh[0]} x {fem_mesh[1]} quads, n_dir {fem_n_dir}")
    fem = fem_part(os.path.join(out_dir, "fem"), nx=fem_mesh[0], ny=fem_mesh[1], n_dir=fem_n_dir)
    timings["FE specimen"] = time.time() - t
    dem = None
    if not skip_dem:
        t = time.time()
        _log(f"DEM: {n} disks, rate {rate}/s, 45 probes x 2")
        dem = dem_part(os.path.join(out_dir, "dem"), n=n, seed=seed, rate=rate, workers=workers,
                       alphas=dem_alphas, max_steps=dem_max_steps, threads=threads,
                       resume=resume)
        n_runs = 2 * len(dem["probes"])
        timings[f"DEM ({n} disks: compaction, biaxial, {n_runs} probe runs)"] = time.time() - t
        for k, v in dem["stage_times"].items():
            timings[f"  DEM {k}"] = v
    c = conclusions(h, dem["probes"] if dem else None, fem)
    figs = _figures(out_dir, h, dem, fem)
    config = {"full": full, "dem_n": n, "dem_seed": seed, "dem_rate": rate,
              "dem_probe_max_steps": dem_max_steps, "fem_mesh": list(fem_mesh),
              "fem_n_dir": fem_n_dir, "dem_eta_a_reached": dem["eta_a_reached"] if dem else None}
    with atomic_open(os.path.join(out_dir, "conclusions.json")) as f:
        json.dump({"conclusions": c, "timings": timings, "config": config}, f, indent=1, default=str)
    write_report(out_dir, c, figs, timings, config)
    return c, timings
