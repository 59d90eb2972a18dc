"""The cross-check's figures: the H-model, the FE specimen and the DEM side by side (the paper's
Figs. 4-5, 8, 11, 13-17), drawn from the parts' results (``crosscheck.parts``).
"""
from __future__ import annotations

import os

import numpy as np

__all__ = ["figures", "polar_figure", "OUTCOME_MARKS"]


def _angle_axes(ax):
    """W2 against alpha_sigma: the frame shared by the side-by-side figures."""
    ax.axhline(0, color="k", lw=0.6)
    ax.set_xlim(0, 360)
    ax.set_xticks(range(0, 361, 45))
    ax.set_xlabel("alpha_sigma [deg] (tan = d sigma1 / d sigma2)")
    ax.set_ylabel("normalized second-order work [-]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)


# how a DEM probe without a W2 is drawn (on W2 = 0): (outcome, marker, colour, label)
OUTCOME_MARKS = (("failure", "^", "C3", "DEM failure (runaway)"),
                 ("undecided", "s", "C7", "DEM undecided (cap)"))


def polar_figure(path, h, rows, dem_title="DEM (Fig. 15)"):
    """fig_polar_w2.png: the H-model at A (``h``: ``hmodel_part``'s, its sweep and, if any, its
    stress probes in the DEM's directions) and the DEM's probes (``rows``: probes.csv rows, or
    None) in the paper's polar diagram (``hmodel.plots``), each with its cone (H-model: W2 <= 0;
    DEM: failure or W2 <= 0) shaded and its angles written and its plastic zone at the rim, and,
    where the H-model's cone is narrow, a third panel of W2 against alpha_sigma around it with
    both parts. A DEM W2 is drawn only for an equilibrium probe (clipped to [-0.5, 1.1])."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from common.io import save_figure
    from common.plots import cone_zoom, mark_cone, mark_plastic, needs_zoom, polar_axes, polar_series
    from point.probes import arcs
    rmax = 1.6
    sw = h["sweep"]
    cone_h, plastic_h = arcs(sw.alpha_sigma, sw.w2 <= 0), arcs(sw.alpha_sigma, sw.plastic)
    series_h = [("H-model W2 (strain-probe sweep)", sw.alpha_sigma, sw.w2, "C3-")]
    if "stress_probes" in h:
        sp = h["stress_probes"]
        series_h.append(("H-model, DEM directions", sp.probe.alpha_sigma, sp.probe.w2, "ko"))
    zoom = needs_zoom(cone_h)
    fig = plt.figure(figsize=(17.5 if zoom else 12, 6.9))
    gs = fig.add_gridspec(1, 3 if zoom else 2, width_ratios=[1, 1, 0.95] if zoom else [1, 1])
    ax = fig.add_subplot(gs[0, 0], projection="polar")
    polar_axes(ax, rmax)
    mark_plastic(ax, plastic_h, rmax)
    mark_cone(ax, cone_h, rmax)
    polar_series(ax, series_h, rmax)
    ax.set_title("H-model at A (Fig. 8)", pad=28)
    axes = [ax]
    series_d = []
    ax = fig.add_subplot(gs[0, 1], projection="polar")
    polar_axes(ax, rmax)
    if rows:
        outc = np.array([r["outcome"] for r in rows])
        a = np.array([float(r["alpha_sigma"]) for r in rows])
        eq = outc == "equilibrium"
        w = np.array([float(r["w2"]) if e else np.nan for r, e in zip(rows, eq)])
        cone_d = arcs(a, (outc == "failure") | (eq & (np.nan_to_num(w, nan=1.0) <= 0)))
        mark_plastic(ax, arcs(a, np.array([bool(r["plastic"]) for r in rows]) & eq), rmax)
        mark_cone(ax, cone_d, rmax, label=r"failure or $W_2 \leq 0$")
        o = np.argsort(a)
        loop_a, loop_w = np.append(a[o], a[o][0] + 360.0), np.append(w[o], w[o][0])
        series_d.append((f"DEM W2 ({len(rows)} stress probes; clipped to [-0.5, 1.1])", loop_a,
                         np.clip(loop_w, -0.5, rmax - 0.5), "C0o-"))
        for kind, m, col, lab in OUTCOME_MARKS:
            sel = outc == kind
            if sel.any():
                series_d.append((lab, a[sel], np.zeros(sel.sum()), col + m))
        polar_series(ax, series_d, rmax)
        if not cone_d:
            ax.plot([], [], " ", label=r"every probe settled with $W_2 > 0$")
    ax.set_title(dem_title, pad=28)
    axes.append(ax)
    for ax in axes:
        ax.legend(fontsize=7.5, loc="upper center", bbox_to_anchor=(0.5, -0.08), ncol=2,
                  frameon=False)
    if zoom:
        cone_zoom(fig.add_subplot(gs[0, 2]), series_h + series_d, cone_h, plastic_h, pad_deg=15.0)
    fig.tight_layout()
    save_figure(fig, path)


def figures(out, h, dem, fem) -> dict:
    """The side-by-side figures of the report in ``out`` (``h``, ``dem``, ``fem``: the parts'
    results, ``dem`` and ``fem`` None when not run): the drained curves (Figs. 4-5, 13-14), W2 in
    the polar diagram (Figs. 8, 15), micro against macro (Fig. 16), normal and tangential parts
    (Figs. 11, 17), the H-model's bifurcation domain and the DEM's (copied from its folder).
    Returns {key: file name} for ``write_report``."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from common.io import save_figure

    figs = {}
    sw = h["sweep"]
    o = np.argsort(sw.alpha_sigma)
    rows = dem["probes"] if dem else None
    # a probe without equilibrium has no W2 (Eq. 15 needs equilibrium at both ends): NaN, so
    # that the curves break there, and the count in the legend
    conv = lambda k: [float(r[k]) if r["outcome"] == "equilibrium" else np.nan for r in rows]
    outc = np.array([r["outcome"] for r in rows]) if rows else np.array([])
    a_dem = np.array([r["alpha_sigma"] for r in rows]) if rows else np.array([])
    failed_note = ""
    state_note = (f", state {dem['comparison']['state']} (eta {dem['comparison']['eta_R']:.3f})"
                  if dem else "")

    def outcome_marks(ax):
        """Failures (ran away: W2 <= 0 in the limit) as red triangles on W2 = 0, undecided
        probes as grey squares on W2 = 0."""
        for kind, m, col, lab in OUTCOME_MARKS:
            sel = outc == kind
            if sel.any():
                ax.plot(a_dem[sel], np.zeros(sel.sum()), m, color=col, label=lab)

    # stress-strain (Figs. 4-5 and 13-14)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.3), constrained_layout=True)
    p, q, _ = h["path"].invariants()
    e = h["path"].eps
    a1.plot(100 * e[:, 0], q / 1e3, label="H-model material point")
    a2.plot(100 * e[:, 0], 100 * (e[:, 0] + e[:, 1]), label="H-model material point")
    ends = [100 * e[-1, 0]]
    rA = h["pathA"]
    eA = 100 * rA.eps[-1, 0]
    qA = (rA.sigma[-1, 0] - rA.sigma[-1, 1]) / 1e3
    a1.plot([eA], [qA], "o", color="C0", mfc="none", ms=8, label=f"H-model A (eta {h.get('eta_a', 1.029):g})")
    a2.plot([eA], [100 * (rA.eps[-1, 0] + rA.eps[-1, 1])], "o", color="C0", mfc="none", ms=8)
    if fem is not None:
        cur = fem["curve"]
        a1.plot(100 * np.asarray(cur["eps1"]), np.asarray(cur["q"]) / 1e3, "--", label=f"FE specimen (n_dir {fem['n_dir']})")
        ends.append(100 * float(np.asarray(cur["eps1"])[-1]))
        if "eps2_mean" in cur:
            ev = np.asarray(cur["eps1"]) + np.asarray(cur["eps2_mean"])
            a2.plot(100 * np.asarray(cur["eps1"]), 100 * ev, "--", label="FE specimen")
    if dem is not None:
        from dem.experiment import COLUMNS
        arr = np.array(dem["biaxial_rows"], float)
        col = {k: arr[:, COLUMNS.index(k)] for k in ("eps1", "eps_v", "q", "eta")}
        lab = f"DEM sample ({dem.get('n', '?')} disks, {dem.get('rate', '?')}/s)"
        a1.plot(100 * col["eps1"], col["q"] / 1e3, label=lab, color="C2")
        a2.plot(100 * col["eps1"], 100 * col["eps_v"], label=lab, color="C2")
        ends.append(100 * float(col["eps1"][-1]))
        # the DEM state of the comparison: the first recorded row at its eta
        k = int(np.argmax(col["eta"] >= dem["comparison"]["eta_R"] - 1e-12))
        a1.plot([100 * col["eps1"][k]], [col["q"][k] / 1e3], "s", color="C2", mfc="none", ms=8,
                label=f"DEM comparison state ({dem['comparison']['state']})")
        a2.plot([100 * col["eps1"][k]], [100 * col["eps_v"][k]], "s", color="C2", mfc="none", ms=8)
    for ax, yl in ((a1, "deviatoric stress $q = s_1 - s_2$ [kPa]"),
                   (a2, r"volumetric strain $\varepsilon_v$ [%] (contraction > 0)")):
        ax.set_xlabel(r"axial strain $\varepsilon_1$ [%]")
        ax.set_ylabel(yl)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        ax.set_xlim(0, min(ends))     # every curve ends at the same strain
    a1.set_title("Drained biaxial test at 200 kPa (Figs. 4 and 13)")
    a2.set_title("Volumetric response (Figs. 5 and 14)")
    figs["stress_strain"] = "fig_stress_strain.png"
    save_figure(fig, os.path.join(out, figs["stress_strain"]))

    # polar W2 (Figs. 8 and 15)
    figs["polar_w2"] = "fig_polar_w2.png"
    polar_figure(os.path.join(out, figs["polar_w2"]), h, rows, f"DEM (Fig. 15){state_note}")

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
        outcome_marks(axs[1])
    axs[1].set_title(f"DEM (Fig. 16){state_note}")
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
        outcome_marks(axs[1])
    axs[1].set_title(f"DEM (Fig. 17){state_note}")
    for ax in axs:
        _angle_axes(ax)
    figs["normal_tangential"] = "fig_normal_tangential.png"
    save_figure(fig, os.path.join(out, figs["normal_tangential"]))

    if h.get("domain"):
        from hmodel.plots import fig_domain
        figs["domain"] = "fig_domain.png"
        fig_domain(h["domain"], os.path.join(out, figs["domain"]))
    if dem is not None:
        import shutil
        for src, key in (("fig_domain.png", "dem_domain"), ("fig_domain_w2.png", "dem_domain_w2")):
            p = os.path.join(dem["domain_dir"], src)
            if os.path.exists(p):
                figs[key] = f"fig_dem_{src[4:]}"
                shutil.copyfile(p, os.path.join(out, figs[key]))
    return figs
