"""Figures of the paper for the H-model (Figs. 3-11), PNG through matplotlib (Agg).

Conventions: compression positive; stresses in kPa on the axes; alpha_sigma measured from the
d sigma2 axis (tan alpha_sigma = d sigma1 / d sigma2), so polar diagrams put d sigma2 on the
horizontal and d sigma1 on the vertical axis; the dashed circle of radius 0.5 is W2 = 0.
"""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .io import save_figure  # noqa: E402

__all__ = ["fig_q_eps1", "fig_epsv_eps1", "fig_probes", "fig_stress_components", "fig_polar_w2",
           "fig_w2_split", "fig_domain", "fig_w2_normal_tangential", "polar_axes",
           "fig_burst_paths", "fig_burst_ke", "fig_burst_residual"]


def _mark(ax, x, y, label="A", marker="o", color="C3", offset=(6, -12)):
    ax.plot([x], [y], marker, color=color, zorder=5)
    ax.annotate(label, (x, y), textcoords="offset points", xytext=offset, color=color)


def _strain_curves(curves, path, point_a, title, yscale, ylabel, peak=None, end=None):
    """One quantity (scaled by ``yscale``) of drained-test curves against eps1 [%]; ``point_a``
    and ``peak``: None or (eps1 [-], value) to mark; ``end``: None or (eps1 [-], value, label):
    where the path ended without a static state (``PathResult.end``)."""
    fig, ax = plt.subplots(figsize=(6, 4.2))
    for label, e1, y in curves:
        ax.plot(100 * np.asarray(e1), yscale * np.asarray(y), label=label)
    if point_a is not None:
        _mark(ax, 100 * point_a[0], yscale * point_a[1])
    if peak is not None:
        _mark(ax, 100 * peak[0], yscale * peak[1], label=f"peak ({100 * peak[0]:.2f} %)",
              marker="v", color="k", offset=(8, -16))
    if end is not None:
        _mark(ax, 100 * end[0], yscale * end[1], label=end[2], marker="X", color="C1",
              offset=(-150, 10))
    ax.set_xlabel(r"axial strain $\varepsilon_1$ [%]")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    if len(curves) > 1:
        ax.legend()
    save_figure(fig, path)


def fig_q_eps1(curves, path, point_a=None, title="Drained biaxial test: deviatoric stress", peak=None,
               end=None):
    """Fig. 4 / 13: q = s1 - s2 [kPa] against eps1 [%]. ``curves``: list of (label, eps1, q);
    ``point_a``, ``peak``: None or (eps1 [-], q [Pa]) marked on the figure; ``end``: None or
    (eps1 [-], q [Pa], label), the end of a path without a static state beyond."""
    _strain_curves(curves, path, point_a, title, 1e-3,
                   r"deviatoric stress $q = \sigma_1 - \sigma_2$ [kPa]", peak=peak, end=end)


def fig_epsv_eps1(curves, path, point_a=None, title="Drained biaxial test: volumetric strain",
                  end=None):
    """Fig. 5 / 14: eps_v = eps1 + eps2 [%] (compression positive) against eps1 [%]; ``end`` as
    ``fig_q_eps1`` (eps_v for the value)."""
    _strain_curves(curves, path, point_a, title, 100.0,
                   r"volumetric strain $\varepsilon_v = \varepsilon_1 + \varepsilon_2$ [%] (contraction > 0)",
                   end=end)


def fig_probes(pr, path):
    """Fig. 3: strain probes and their stress responses (elastic / plastic)."""
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10.5, 4.8), constrained_layout=True)
    pl = np.asarray(pr.plastic, bool)
    de = pr.d_eps / np.linalg.norm(pr.d_eps[:, :2], axis=1)[:, None]
    ds = pr.d_sigma / 1e3
    for m, c, lab in ((~pl, "C0", "elastic"), (pl, "C3", "plastic")):
        a1.plot(de[m, 1], de[m, 0], ".", ms=3, color=c, label=lab)
        a2.plot(ds[m, 1], ds[m, 0], ".", ms=3, color=c, label=lab)
    a1.set_xlabel(r"$\delta\varepsilon_2 / |\delta\varepsilon|$")
    a1.set_ylabel(r"$\delta\varepsilon_1 / |\delta\varepsilon|$")
    a1.set_title(f"strain probes (|de| = {np.linalg.norm(pr.d_eps[0]):.1e})")
    a2.set_xlabel(r"$\delta\sigma_2$ [kPa]")
    a2.set_ylabel(r"$\delta\sigma_1$ [kPa]")
    a2.set_title("stress responses")
    for a in (a1, a2):
        a.axhline(0, color="k", lw=0.5)
        a.axvline(0, color="k", lw=0.5)
        a.set_aspect("equal", adjustable="datalim")
        a.legend(loc="best", fontsize=8)
        a.grid(alpha=0.3)
    save_figure(fig, path)


def fig_stress_components(pr, comp, path):
    """Figs. 6-7: normalized components T1, T2, T3 and d sigma of the stress increment along
    axis ``comp`` (0 axial, 1 lateral) against alpha_sigma [deg]."""
    o = np.argsort(pr.alpha_sigma)
    nrm = np.linalg.norm(pr.d_sigma[:, :2], axis=1)[o]
    a = pr.alpha_sigma[o]
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for arr, lab in ((pr.d_sigma, r"$\delta\sigma$"), (pr.dPi, r"$T_1 = \delta\Pi$"),
                     (pr.T2, r"$T_2$ (volume)"), (pr.T3, r"$T_3$ (geometry)")):
        ax.plot(a, arr[o, comp] / nrm, label=lab, lw=1.2)
    _shade_plastic(ax, pr)
    name = "axial" if comp == 0 else "lateral"
    ax.set_xlabel(r"$\alpha_\sigma$ [deg]")
    ax.set_ylabel(rf"normalized incremental {name} stress $\delta\sigma_{comp + 1}/\|\delta\sigma\|$ [-]")
    ax.set_xlim(0, 360)
    ax.set_xticks(range(0, 361, 45))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(f"Components of the {name} stress increment")
    save_figure(fig, path)


def _shade_plastic(ax, pr):
    a = np.asarray(pr.alpha_sigma)
    pl = np.asarray(pr.plastic, bool)
    if pl.any():
        o = np.argsort(a)
        a, pl = a[o], pl[o]
        start = None
        for k in range(len(a)):
            if pl[k] and start is None:
                start = a[k]
            if (not pl[k] or k == len(a) - 1) and start is not None:
                ax.axvspan(start, a[k], color="0.85", zorder=0)
                start = None
        ax.plot([], [], color="0.85", lw=6, label="plastic zone")


def polar_axes(ax, rmax=1.6):
    """The paper's polar frame: circle r = 0.5 (W2 = 0), d sigma2 horizontal, d sigma1 vertical."""
    t = np.linspace(0, 2 * np.pi, 361)
    ax.plot(0.5 * np.cos(t), 0.5 * np.sin(t), "k--", lw=0.8, label="W2 = 0")
    ax.axhline(0, color="k", lw=0.4)
    ax.axvline(0, color="k", lw=0.4)
    ax.set_aspect("equal")
    ax.set_xlim(-rmax, rmax)
    ax.set_ylim(-rmax, rmax)
    ax.set_xlabel(r"$\delta\sigma_2$ direction: $(0.5 + W_2)\cos\alpha_\sigma$")
    ax.set_ylabel(r"$\delta\sigma_1$ direction: $(0.5 + W_2)\sin\alpha_\sigma$")


def _polar_xy(alpha_deg, w):
    o = np.argsort(alpha_deg)
    a = np.radians(np.asarray(alpha_deg)[o])
    r = 0.5 + np.asarray(w)[o]
    return r * np.cos(a), r * np.sin(a)


def fig_polar_w2(series, path, title="Normalized second-order work", no_solution=None):
    """Fig. 8 / 15 / 16: polar diagram, point at angle alpha_sigma and radius 0.5 + W2.
    ``series``: list of (label, alpha_sigma [deg], w2, style). ``no_solution``: stress
    directions alpha_sigma [deg] whose stress probe has no static solution (no strain increment
    gives them: ``probes.stress_probes``), marked on the circle W2 = 0."""
    fig, ax = plt.subplots(figsize=(6, 6))
    polar_axes(ax, rmax=max(1.6, 0.6 + max(np.nanmax(s[2]) for s in series)))
    for label, a, w, style in series:
        x, y = _polar_xy(a, w)
        ax.plot(x, y, style, label=label, lw=1.2, ms=3)
    if no_solution is not None and len(no_solution):
        t = np.radians(np.asarray(no_solution, float))
        ax.plot(0.5 * np.cos(t), 0.5 * np.sin(t), "x", color="C1", ms=7, mew=1.5,
                label=f"stress probe without a static solution ({len(t)})")
    ax.legend(fontsize=8, loc="upper left")
    ax.set_title(title)
    save_figure(fig, path)


def fig_w2_split(pr, path):
    """Fig. 9: W2 and its Eulerian split W2_sigma + W2_V + W2_g against alpha_sigma."""
    o = np.argsort(pr.alpha_sigma)
    a = pr.alpha_sigma[o]
    fig, (ax, axz) = plt.subplots(1, 2, figsize=(11, 4.2))
    for arr, lab in ((pr.w2, r"$W_2$ (Lagrangian)"), (pr.w2_sigma, r"$W_2^\sigma$"),
                     (pr.w2_V, r"$W_2^V$"), (pr.w2_g, r"$W_2^g$")):
        ax.plot(a, arr[o], label=lab)
        axz.plot(a, arr[o], label=lab)
    _shade_plastic(ax, pr)
    for x in (ax, axz):
        x.axhline(0, color="k", lw=0.6)
        x.set_xlabel(r"$\alpha_\sigma$ [deg]")
        x.set_ylabel("normalized second-order work [-]")
        x.grid(alpha=0.3)
    ax.set_xlim(0, 360)
    ax.set_xticks(range(0, 361, 45))
    # the legend beside the two panels, never on the curves
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(1.1, -0.2), ncol=5, frameon=False)
    neg = (pr.w2_sigma <= 0) | (pr.w2 <= 0)
    if neg.any():
        lo, hi = pr.alpha_sigma[neg].min(), pr.alpha_sigma[neg].max()
        axz.set_xlim(lo - 8, hi + 8)
        axz.set_ylim(-0.3, 0.5)
        axz.set_title("zoom on the instability cone")
    else:
        axz.set_title("no direction with W2 <= 0")
    ax.set_title("Contributions to the second-order work")
    save_figure(fig, path)


def fig_w2_normal_tangential(pr, path, title="Micro second-order work: normal and tangential parts"):
    """Fig. 11 / 17: W2n and W2t (and their sum) against alpha_sigma."""
    o = np.argsort(pr.alpha_sigma)
    a = pr.alpha_sigma[o]
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    ax.plot(a, pr.w2n[o], label=r"$W_2^n$ (normal)")
    ax.plot(a, pr.w2t[o], label=r"$W_2^t$ (tangential)")
    ax.plot(a, pr.w2_micro[o], "k--", lw=0.8, label=r"$W_2^n + W_2^t$")
    _shade_plastic(ax, pr)
    ax.axhline(0, color="k", lw=0.6)
    ax.set_xlim(0, 360)
    ax.set_xticks(range(0, 361, 45))
    ax.set_xlabel(r"$\alpha_\sigma$ [deg]")
    ax.set_ylabel("normalized second-order work [-]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(title)
    save_figure(fig, path)


def fig_domain(points, path):
    """Fig. 10: bifurcation domain in (p, q) [kPa]: lower boundaries from the first W2 <= 0 and
    first W2_sigma <= 0 on drained paths, upper boundary the peak (plastic limit)."""
    P = {k: np.array([getattr(d, k) for d in points]) / 1e3 for k in points[0]._fields
         if k not in ("outcome", "end")}
    fig, ax = plt.subplots(figsize=(6, 4.6))
    ax.plot(P["p_peak"], P["q_peak"], "k-o", label="plastic limit (peak)")
    ax.plot(P["p_w2"], P["q_w2"], "C3-s", label=r"first $W_2 \leq 0$")
    ax.plot(P["p_w2sigma"], P["q_w2sigma"], "C0--^", label=r"first $W_2^\sigma \leq 0$")
    for k in range(len(points)):
        ax.plot([P["sigma2"][k], P["p_peak"][k]], [0, P["q_peak"][k]], ":", color="0.6", lw=0.8)
    ended = [k for k, d in enumerate(points) if d.outcome != "complete"]
    if ended:
        ax.plot(P["p_end"][ended], P["q_end"][ended], "X", color="C1", ms=9,
                label="drained path ends: no static state beyond")
    ax.set_xlabel("mean stress p = (s1 + s2)/2 [kPa]")
    ax.set_ylabel("deviatoric stress q = s1 - s2 [kPa]")
    ax.set_xlim(left=0)
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("Bifurcation domain (drained paths, dotted)")
    save_figure(fig, path)


_SWITCH_STYLE = {"below": ("o", "equilibrium expected"), "past": ("v", "burst expected")}
_OUTCOME_COLOR = {"equilibrium": "C2", "failure": "C3", "undecided": "0.5"}


def fig_burst_paths(drained, paths, rows, path, eta_w2=None, title=None):
    """The proportional strain paths of docs/burst.md. Left: eta against eps1 [%] (from the
    isotropic state) of the drained path and of every proportional path branching off it, each c
    peak marked, with the stress ratio of the first W2 = 0 of the directional analysis
    (``eta_w2``) dashed. Right: c - c_start [kPa] against eps1 - eps1_start [%] of each path,
    the peak and the switch states marked and coloured by the run's outcome.
    ``drained``: (eps1, eta) arrays; ``paths``: list of dicts with ratio, start_fraction,
    eps1_start, eps1 (from the start of the path), eta, c, k_peak (None if none); ``rows``: the
    burst.csv rows (ratio, start_fraction, switch, eps1_switch, c_switch, outcome); a path's
    optional p (mean stress) masks its stress-free states (p = 0: every hexagon open)."""
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4.8), constrained_layout=True)
    a1.plot(100 * np.asarray(drained[0]), drained[1], "k-", lw=1.4, label="drained path")
    ratios = sorted({p["ratio"] for p in paths}, reverse=True)
    col = {R: f"C{i % 10}" for i, R in enumerate(ratios)}
    fr = sorted({p["start_fraction"] for p in paths})
    ls = {f: ("-", "--", ":", "-.")[i % 4] for i, f in enumerate(fr)}
    for p in paths:
        R, f = p["ratio"], p["start_fraction"]
        e = 100 * (p["eps1_start"] + np.asarray(p["eps1"]))
        lab = f"R = {R:g}" if f == fr[0] else None
        # eta of a stress-free state (every hexagon open: p = 0) is not drawn
        eta = np.where(np.asarray(p["p"]) > 0, p["eta"], np.nan) if "p" in p else p["eta"]
        a1.plot(e, eta, ls[f], color=col[R], lw=1.0, label=lab)
        a2.plot(100 * np.asarray(p["eps1"]), (np.asarray(p["c"]) - p["c"][0]) / 1e3, ls[f],
                color=col[R], lw=1.0, label=f"R = {R:g}, start {f:g}")
        k = p["k_peak"]
        if k is not None:
            a1.plot(e[k], p["eta"][k], "^", color=col[R], ms=7, mec="k", mew=0.5)
    for r in rows:
        p = next(q for q in paths if q["ratio"] == r["ratio"] and q["start_fraction"] == r["start_fraction"])
        m = _SWITCH_STYLE[r["switch"]][0]
        a2.plot(100 * r["eps1_switch"], (r["c_switch"] - p["c"][0]) / 1e3, m, ms=8,
                color=_OUTCOME_COLOR.get(r["outcome"], "k"), mec="k", mew=0.6, zorder=5)
    if eta_w2 is not None and np.isfinite(eta_w2):
        a1.axhline(eta_w2, color="C3", ls="--", lw=0.9,
                   label=rf"first $W_2 = 0$ of the directional analysis ($\eta$ = {eta_w2:.3f})")
    a1.plot([], [], "^", color="0.4", mec="k", mew=0.5, label="peak of c on the path")
    for sw, (m, what) in _SWITCH_STYLE.items():
        a2.plot([], [], m, color="w", mec="k", label=f"switch {sw} ({what})")
    for oc, c in _OUTCOME_COLOR.items():
        a2.plot([], [], "s", color=c, label=oc)
    # the right panel around the peaks: a path still rising steeply (no peak) leaves it
    peaked = [p for p in paths if p["k_peak"] is not None]
    if peaked:
        e_pk = max(p["eps1"][p["k_peak"]] for p in peaked)
        rise = [p["c"][p["k_peak"]] - p["c"][0] for p in peaked]
        lo = min(min(np.min(np.asarray(p["c"])[np.asarray(p["eps1"]) <= 2 * e_pk] - p["c"][0])
                     for p in peaked), 0.0)
        a2.set_xlim(0, 100 * min(2.0 * max(e_pk, 1e-4), max(p["eps1"][-1] for p in paths)))
        a2.set_ylim(lo / 1e3 - 0.1 * max(rise) / 1e3, 1.5 * max(max(rise), 1.0) / 1e3)
    a1.set_xlabel(r"axial strain $\varepsilon_1$ [%]")
    a1.set_ylabel(r"stress ratio $\eta = q/p$ [-]")
    a1.set_title("drained path and proportional strain paths $d\\varepsilon_2 = R\\, d\\varepsilon_1$")
    a2.set_xlabel(r"$\varepsilon_1 - \varepsilon_1^{start}$ [%]")
    a2.set_ylabel(r"$c - c_{start}$ [kPa],  $c = \sigma_1 + R\,\sigma_2$")
    a2.set_title("the stress conjugate to the path (W2 = 0 at its peak)")
    for a in (a1, a2):
        a.grid(alpha=0.3)
        a.legend(fontsize=7)
    if title:
        fig.suptitle(title)
    save_figure(fig, path)


def fig_burst_ke(histories, path, title="Kinetic energy after the switch", unit="J/m",
                 time_unit=("ms", 1e3)):
    """E_c against the time since the switch, log axis, one panel per start state, every ratio
    and switch (colour the ratio, solid ``past``, dashed ``below``; the end marked by the outcome).
    ``histories``: list of dicts with ratio, start_fraction, switch, outcome, t [s], ke [J or J/m]."""
    fr = sorted({h["start_fraction"] for h in histories})
    ratios = sorted({h["ratio"] for h in histories}, reverse=True)
    col = {R: f"C{i % 10}" for i, R in enumerate(ratios)}
    fig, axes = plt.subplots(1, len(fr), figsize=(5.6 * len(fr), 4.4), squeeze=False,
                             constrained_layout=True)
    for ax, f in zip(axes[0], fr):
        for h in (h for h in histories if h["start_fraction"] == f):
            t = time_unit[1] * np.asarray(h["t"])
            ke = np.asarray(h["ke"], float)
            ok = ke > 0
            ax.plot(t[ok], ke[ok], "-" if h["switch"] == "past" else "--", color=col[h["ratio"]],
                    lw=1.1, label=f"R = {h['ratio']:g}, {h['switch']}: {h['outcome']}")
            if ok.any():
                ax.plot(t[ok][-1], ke[ok][-1], "x" if h["outcome"] == "failure" else "o",
                        color=_OUTCOME_COLOR.get(h["outcome"], "k"), ms=7)
        ax.set_yscale("log")
        ax.set_xlabel(f"time since the switch [{time_unit[0]}]")
        ax.set_ylabel(f"kinetic energy $E_c$ [{unit}]")
        ax.set_title(f"start at {f:g} of the drained peak $\\eta$")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    fig.suptitle(title)
    save_figure(fig, path)


def fig_burst_residual(histories, path, bound=1e-6, title="Energy balance of each time step"):
    """The relative residual of the discrete energy balance (Eq. 1, second-order form) at every
    step of every run, log axis, with the stated bound."""
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for i, h in enumerate(histories):
        r = np.asarray(h["energy_residual"], float)[1:]
        ax.semilogy(np.arange(1, len(r) + 1), np.maximum(r, 1e-18), lw=0.7, color=f"C{i % 10}",
                    label=f"R = {h['ratio']:g}, start {h['start_fraction']:g}, {h['switch']}")
    ax.axhline(bound, color="k", ls="--", lw=0.9, label=f"bound {bound:g}")
    ax.set_xlabel("time step after the switch")
    ax.set_ylabel(r"$|\Delta E_c - (\Delta W_2^{ext} - \Delta W_2^{int} - \Delta D)|$ / step scale [-]")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=6, ncol=2)
    ax.set_title(title)
    save_figure(fig, path)
