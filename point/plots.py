"""Figures of the paper for the material point of any law (Figs. 3-11; the H-model's and
Drucker-Prager's alike), PNG through matplotlib (Agg); the plot helpers they share with dem and
the cross-check (polar diagram, axes) are ``common.plots``.

Conventions: compression positive; stresses in kPa on the axes; alpha_sigma measured from the
d sigma2 axis (tan alpha_sigma = d sigma1 / d sigma2), so polar diagrams put d sigma2 on the
horizontal and d sigma1 on the vertical axis; the dashed circle of radius 0.5 is W2 = 0.
"""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from common.io import save_figure  # noqa: E402
from common.plots import (cone_zoom, mark_cone, mark_plastic, needs_zoom, polar_axes,  # noqa: E402
                          polar_series)

__all__ = ["fig_q_eps1", "fig_epsv_eps1", "fig_probes", "fig_stress_components", "fig_polar_w2",
           "fig_w2_split", "fig_domain", "fig_w2_normal_tangential", "cone_of",
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


def fig_stress_components(pr, comp, path, split=True):
    """Figs. 6-7: normalized components T1, T2, T3 and d sigma of the stress increment along
    axis ``comp`` (0 axial, 1 lateral) against alpha_sigma [deg]; ``split`` False: d sigma alone
    (a law without the Lagrangian split of the increment)."""
    o = np.argsort(pr.alpha_sigma)
    nrm = np.linalg.norm(pr.d_sigma[:, :2], axis=1)[o]
    a = pr.alpha_sigma[o]
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    parts = ((pr.d_sigma, r"$\delta\sigma$"), (pr.dPi, r"$T_1 = \delta\Pi$"),
             (pr.T2, r"$T_2$ (volume)"), (pr.T3, r"$T_3$ (geometry)"))
    for arr, lab in parts if split else parts[:1]:
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


def cone_of(alpha_deg, w2):
    """The arcs of alpha_sigma [deg] where ``w2`` <= 0 (``probes.arcs``; NaN counts as > 0)."""
    from .probes import arcs
    w = np.asarray(w2, float)
    return arcs(np.asarray(alpha_deg, float), np.isfinite(w) & (w <= 0))


def fig_polar_w2(series, path, title="Normalized second-order work", cone=None, plastic=None,
                 no_solution=None):
    """Fig. 8 / 15 / 16: the polar diagram, each point at angle alpha_sigma and radius 0.5 + W2
    (the dashed circle is W2 = 0), with the cone W2 <= 0 shaded and its angles written, the
    plastic zone at the rim, and where the cone is narrow (< common.plots.ZOOM_BELOW_DEG) a second panel of
    W2 against alpha_sigma around it. ``series``: list of (label, alpha_sigma [deg], w2,
    style); ``cone``, ``plastic``: arcs [[start, end], ...] of alpha_sigma [deg] (default for
    the cone: where the first series has w2 <= 0; for the plastic zone: none drawn);
    ``no_solution``: stress directions alpha_sigma [deg] whose stress probe has no static
    solution (no strain increment gives them: ``probes.stress_probes``), marked x on the circle
    W2 = 0."""
    cone = cone_of(series[0][1], series[0][2]) if cone is None else cone
    plastic = plastic or []
    zoom = needs_zoom(cone)
    fig = plt.figure(figsize=(12.5 if zoom else 7, 6.6))
    gs = fig.add_gridspec(1, 2 if zoom else 1, width_ratios=[1.15, 1] if zoom else [1])
    ax = fig.add_subplot(gs[0, 0], projection="polar")
    rmax = max(1.6, 0.6 + max(float(np.nanmax(s[2])) for s in series))
    polar_axes(ax, rmax)
    mark_plastic(ax, plastic, rmax)
    mark_cone(ax, cone, rmax)
    polar_series(ax, series, rmax)
    if no_solution is not None and len(no_solution):
        t = np.radians(np.asarray(no_solution, float))
        ax.plot(t, np.full(len(t), 0.5), "x", color="C1", ms=7, mew=1.5,
                label=f"stress probe without a static solution ({len(t)})")
    if not cone:
        ax.plot([], [], " ", label=r"$W_2 > 0$ in every direction probed")
    ax.set_title("angle: $\\alpha_\\sigma$ (tan = d$\\sigma_1$/d$\\sigma_2$), radius: 0.5 + $W_2$",
                 fontsize=8, pad=26)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, frameon=False)
    if zoom:
        cone_zoom(fig.add_subplot(gs[0, 1]), series, cone, plastic)
    fig.suptitle(title)
    fig.tight_layout()
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
_OUTCOME_COLOR = {"equilibrium": "C2", "failure": "C3", "undecided": "0.5", "not_converged": "C4"}


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


# the end of a run after the switch, by its outcome (black: apart from the colours of the ratios)
END_MARK = {"failure": ("x", "k", "end: failure"), "equilibrium": ("o", "none", "end: equilibrium"),
            "undecided": ("s", "none", "end: undecided (at the cap)"),
            "not_converged": ("D", "none", "end: not converged (the integrator, not a burst)")}


def fig_burst_ke(histories, path, title="Kinetic energy after the switch", unit="J/m",
                 time_unit=("ms", 1e3)):
    """Top row: E_c against the time since the switch, log axis, one panel per start state,
    every ratio and switch (colour the ratio, solid ``past``, dashed ``below``), the end of each
    run marked by its outcome (``END_MARK``). Bottom row: the growth measure, the energy release
    (E_c - E_c(0)) / W2_ext (``burst_rule.release_ratio``) against t / T1, with RELEASE and 1
    (W2_int = 0) drawn, the time it passed RELEASE starred. One legend below the panels.
    ``histories``: list of dicts with ratio, start_fraction, switch, outcome, t [s], ke, w2_ext
    [J or J/m] and T1 [s]."""
    from matplotlib.lines import Line2D
    from .burst_rule import RELEASE, energy_release, release_ratio
    fr = sorted({h["start_fraction"] for h in histories})
    ratios = sorted({h["ratio"] for h in histories}, reverse=True)
    col = {R: f"C{i % 10}" for i, R in enumerate(ratios)}
    fig, axes = plt.subplots(2, len(fr), figsize=(5.6 * len(fr), 9.4), squeeze=False)
    ends = set()
    for ax, ar, f in zip(axes[0], axes[1], fr):
        for h in (h for h in histories if h["start_fraction"] == f):
            t = time_unit[1] * np.asarray(h["t"])
            ke = np.asarray(h["ke"], float)
            ok = ke > 0
            ls = "-" if h["switch"] == "past" else "--"
            ax.plot(t[ok], ke[ok], ls, color=col[h["ratio"]], lw=1.1)
            if ok.any():
                m, fc, _ = END_MARK.get(h["outcome"], ("s", "none", ""))
                ax.plot(t[ok][-1], ke[ok][-1], m, mec="k", mfc=fc, color="k", ms=8, mew=1.4,
                        zorder=5)
                ends.add(h["outcome"])
            r = release_ratio(ke, h["w2_ext"])
            tt = np.asarray(h["t"]) / h["T1"]
            pos = np.isfinite(r) & (r > 0)
            ar.plot(tt[pos], r[pos], ls, color=col[h["ratio"]], lw=1.1)
            rel = energy_release(h["t"], ke, h["w2_ext"])
            if rel["released"]:
                ar.plot(rel["t_release"] / h["T1"], RELEASE, "*", color=col[h["ratio"]], ms=11,
                        mec="k", mew=0.6, zorder=5)
        ax.set_yscale("log")
        ax.set_xlabel(f"time since the switch [{time_unit[0]}]")
        ax.set_ylabel(f"kinetic energy $E_c$ [{unit}]")
        ax.set_title(f"start at {f:g} of the drained peak $\\eta$")
        ar.axhline(RELEASE, color="k", ls="--", lw=0.9)
        ar.axhline(1.0, color="0.5", ls=":", lw=0.8)
        ar.set_yscale("log")
        ar.set_xlabel("time since the switch t / T1 [-]")
        ar.set_ylabel(r"energy release $(E_c - E_c(0)) / W_{2,ext}$ [-]")
        for a in (ax, ar):
            a.grid(alpha=0.3, which="both")
    handles = [Line2D([], [], color=col[R], lw=2, label=f"R = {R:g}") for R in ratios]
    handles += [Line2D([], [], color="k", ls="-", label="past the c peak (burst expected)"),
                Line2D([], [], color="k", ls="--", label="below the c peak (equilibrium expected)")]
    handles += [Line2D([], [], ls="none", marker=END_MARK[o][0], mec="k", mfc=END_MARK[o][1],
                       color="k", ms=8, mew=1.4, label=END_MARK[o][2])
                for o in END_MARK if o in ends]
    handles += [Line2D([], [], color="k", ls="--", lw=0.9,
                       label=f"RELEASE = {RELEASE:g} (star: when it was passed)"),
                Line2D([], [], color="0.5", ls=":", lw=0.8, label="1: W2_int = 0 (Eq. 1)")]
    rows = -(-len(handles) // 5)
    fig.legend(handles=handles, loc="lower center", ncol=min(len(handles), 5), fontsize=8,
               frameon=False)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout(rect=(0, 0.02 + 0.025 * rows, 1, 1))
    save_figure(fig, path)


def fig_burst_residual(histories, path, bound=1e-6, title="Energy balances of each time step"):
    """Left: Newmark's own balance of every step of every run, ``newton_work`` (the work of the
    Newton residual: an identity of the scheme), log axis, with ``bound``. Right: the energy
    check that the scheme cannot satisfy by itself (``burst_rule.EnergyCheck``), |energy_check|
    over the run's largest second-order energy, against t / T1. ``histories``: dicts with
    ratio, start_fraction, switch, t [s], T1 [s], newton_work, energy_check, ke_mid, w2_ext,
    w2_int_stress, damping_mid."""
    fig, (ax, ac) = plt.subplots(1, 2, figsize=(12, 4.4))
    for i, h in enumerate(histories):
        lab = f"R = {h['ratio']:g}, start {h['start_fraction']:g}, {h['switch']}"
        r = np.asarray(h["newton_work"], float)[1:]
        ax.semilogy(np.arange(1, len(r) + 1), np.maximum(r, 1e-18), lw=0.7, color=f"C{i % 10}",
                    label=lab)
        scale = max(float(np.max(h["ke_mid"])), float(np.max(np.abs(h["w2_ext"]))),
                    float(np.max(np.abs(h["w2_int_stress"]))), float(np.max(h["damping_mid"])))
        e = np.abs(np.asarray(h["energy_check"], float)[1:]) / (scale if scale > 0 else 1.0)
        ac.semilogy(np.asarray(h["t"])[1:] / h["T1"], np.maximum(e, 1e-18), lw=0.7,
                    color=f"C{i % 10}", label=lab)
    ax.axhline(bound, color="k", ls="--", lw=0.9, label=f"bound {bound:g}")
    ax.set_xlabel("time step after the switch")
    ax.set_ylabel(r"$|\Delta E_c - (\Delta W_2^{ext} - \Delta W_2^{int} - \Delta D)|$ / scale [-]")
    ax.set_title("Newmark's own balance: the work of the Newton residual", fontsize=9)
    ac.set_xlabel("time since the switch t / T1 [-]")
    ac.set_ylabel(r"$|E_c^{mid} - (\Phi_n + \Phi_{n+1})/2|$ / the run's largest $W_2$ [-]")
    ac.set_title("the energy check (O(dt$^2$)): $E_c$ of the velocity field with the density\n"
                 r"against $\Phi = W_2^{ext} - W_2^{int}$(stress, strain)$ - D$", fontsize=9)
    for a in (ax, ac):
        a.grid(alpha=0.3, which="both")
        a.legend(fontsize=6, ncol=2)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    save_figure(fig, path)
