"""The figures of the H-model fitted to the DEM: the minimum W2 along the path, the p-q plane
near the peak, W2 direction by direction and in the polar diagram (docs/fit.md)."""
from __future__ import annotations

import os

import numpy as np

from common.io import save_figure

__all__ = ["comparison_figures", "direction_figures"]


def comparison_figures(c: dict, out: str, dem_curve: dict, fit_curve: dict):
    """fig_comparison.png (the minimum W2 against the fraction of each peak and against eta, and
    its direction) and fig_domain_pq.png (the DEM states and the fitted H-model near the peak in
    the p-q plane) in ``out``: ``c`` the comparison (``compare`` with the run's additions),
    ``dem_curve`` the DEM's biaxial.csv columns, ``fit_curve`` the fitted model's drained p, q."""
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


def direction_figures(c: dict, out: str) -> list:
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
