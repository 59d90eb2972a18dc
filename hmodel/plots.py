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
           "fig_w2_split", "fig_domain", "fig_w2_normal_tangential", "polar_axes"]


def _mark(ax, x, y, label="A", marker="o", color="C3", offset=(6, -12)):
    ax.plot([x], [y], marker, color=color, zorder=5)
    ax.annotate(label, (x, y), textcoords="offset points", xytext=offset, color=color)


def _strain_curves(curves, path, point_a, title, yscale, ylabel, peak=None):
    """One quantity (scaled by ``yscale``) of drained-test curves against eps1 [%]; ``point_a``
    and ``peak``: None or (eps1 [-], value) to mark."""
    fig, ax = plt.subplots(figsize=(6, 4.2))
    for label, e1, y in curves:
        ax.plot(100 * np.asarray(e1), yscale * np.asarray(y), label=label)
    if point_a is not None:
        _mark(ax, 100 * point_a[0], yscale * point_a[1])
    if peak is not None:
        _mark(ax, 100 * peak[0], yscale * peak[1], label=f"peak ({100 * peak[0]:.2f} %)",
              marker="v", color="k", offset=(8, -16))
    ax.set_xlabel(r"axial strain $\varepsilon_1$ [%]")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    if len(curves) > 1:
        ax.legend()
    save_figure(fig, path)


def fig_q_eps1(curves, path, point_a=None, title="Drained biaxial test: deviatoric stress", peak=None):
    """Fig. 4 / 13: q = s1 - s2 [kPa] against eps1 [%]. ``curves``: list of (label, eps1, q);
    ``point_a``, ``peak``: None or (eps1 [-], q [Pa]) marked on the figure."""
    _strain_curves(curves, path, point_a, title, 1e-3,
                   r"deviatoric stress $q = \sigma_1 - \sigma_2$ [kPa]", peak=peak)


def fig_epsv_eps1(curves, path, point_a=None, title="Drained biaxial test: volumetric strain"):
    """Fig. 5 / 14: eps_v = eps1 + eps2 [%] (compression positive) against eps1 [%]."""
    _strain_curves(curves, path, point_a, title, 100.0,
                   r"volumetric strain $\varepsilon_v = \varepsilon_1 + \varepsilon_2$ [%] (contraction > 0)")


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


def fig_polar_w2(series, path, title="Normalized second-order work"):
    """Fig. 8 / 15 / 16: polar diagram, point at angle alpha_sigma and radius 0.5 + W2.
    ``series``: list of (label, alpha_sigma [deg], w2, style)."""
    fig, ax = plt.subplots(figsize=(6, 6))
    polar_axes(ax, rmax=max(1.6, 0.6 + max(np.nanmax(s[2]) for s in series)))
    for label, a, w, style in series:
        x, y = _polar_xy(a, w)
        ax.plot(x, y, style, label=label, lw=1.2, ms=3)
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
    P = {k: np.array([getattr(d, k) for d in points]) / 1e3 for k in points[0]._fields}
    fig, ax = plt.subplots(figsize=(6, 4.6))
    ax.plot(P["p_peak"], P["q_peak"], "k-o", label="plastic limit (peak)")
    ax.plot(P["p_w2"], P["q_w2"], "C3-s", label=r"first $W_2 \leq 0$")
    ax.plot(P["p_w2sigma"], P["q_w2sigma"], "C0--^", label=r"first $W_2^\sigma \leq 0$")
    for k in range(len(points)):
        ax.plot([P["sigma2"][k], P["p_peak"][k]], [0, P["q_peak"][k]], ":", color="0.6", lw=0.8)
    ax.set_xlabel("mean stress p = (s1 + s2)/2 [kPa]")
    ax.set_ylabel("deviatoric stress q = s1 - s2 [kPa]")
    ax.set_xlim(left=0)
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("Bifurcation domain (drained paths, dotted)")
    save_figure(fig, path)
