"""The burst's figures (``dem.burst``): fig_burst_c.png, fig_burst_ke.png and
fig_burst_strain.png (``plot_burst``), fig_burst_k.png (``plot_k_path``)."""
from __future__ import annotations

import math
import os

import numpy as np

from point.burst_rule import RELEASE

from .options import SWITCHES
from .runs import H
from .theory import CLEARLY

OUTCOME_COLOR = {"equilibrium": "C2", "failure": "C3", "undecided": "0.5"}


def plot_burst(out_dir, combos, paths, stairs, runs, summary):
    """fig_burst_c.png: c against eps1 along every path (loaded, under strain control), the
    loaded peak (open star), the path's start and loaded peak relaxed at fixed strain (open
    circles), the staircase of holds from rest (each hold's end: green at equilibrium, red when
    it failed) and its c peak at rest (filled star), the below and past runs from their
    switches; fig_burst_ke.png: the backbone kinetic energy against the time since the switch
    (log axes: from rest it spans decades); fig_burst_strain.png: the strains since the switch
    against time (log axis)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from common.io import save_figure
    n = summary["n_disks"]
    fig, ax = plt.subplots(figsize=(8, 5), constrained_layout=True)
    for j, (r, f, _) in enumerate(combos):
        p = paths[(r, f)]
        col = f"C{j % 10}" if j % 10 not in (2, 3) else f"C{j % 10 + 5}"
        ax.plot(p.rows[:, 1] * 100, p.rows[:, 8] / 1e3, "-", lw=0.8, color=col,
                label=f"path R = {r:g} from {f:g} of the drained peak (strain control)")
        if p.peak is not None:
            ax.plot(p.rows[p.peak, 1] * 100, p.rows[p.peak, 8] / 1e3, "*", ms=12, mfc="w",
                    mec=col, mew=1.0)
        res = stairs.get((r, f))
        if res is None:
            continue
        for (row, _), x in zip(p.grid, res.relaxed.values()):
            ax.plot([p.rows[row, 1] * 100] * 2, [x.c_loaded / 1e3, x.c_rest / 1e3], "-",
                    color="0.5", lw=0.8)
            ax.plot(p.rows[row, 1] * 100, x.c_rest / 1e3, "o", ms=6, mfc="w", mec=col)
        for role, _, target, h in res.holds:
            if role == "stair" and h.outcome == "equilibrium":    # where it came to rest
                ax.plot(h.history[-1, 2] * 100, h.history[-1, 4] / 1e3, "s", ms=4,
                        color=OUTCOME_COLOR[h.outcome])
            elif role == "stair":                                 # the c it could not hold
                ax.plot(h.history[0, 2] * 100, target / 1e3, "x", ms=5,
                        color=OUTCOME_COLOR[h.outcome])
        if res.end == "past found":
            ax.plot(res.eps1_peak * 100, res.c_peak / 1e3, "*", ms=13, color=col, mec="k",
                    mew=0.5)
        for sw, mk in zip(SWITCHES, "ov"):
            if (r, f, sw) not in runs:
                continue
            h = runs[(r, f, sw)].history
            oc = runs[(r, f, sw)].outcome
            ax.plot(h[:, 2] * 100, h[:, 4] / 1e3, "-", lw=1.2, color=OUTCOME_COLOR[oc], alpha=0.7)
            ax.plot(h[0, 2] * 100, h[0, 4] / 1e3, mk, ms=8, mfc=OUTCOME_COLOR[oc], mec="k")
    ax.plot([], [], "*", mfc="w", mec="0.3", ms=10, label="c peak of the loaded path")
    ax.plot([], [], "o", mfc="w", mec="0.3", label="relaxed at fixed strain (drop: grey)")
    ax.plot([], [], "s", color=OUTCOME_COLOR["equilibrium"], ms=4,
            label="staircase from rest: held (end of each hold)")
    ax.plot([], [], "x", color=OUTCOME_COLOR["failure"], ms=5,
            label="staircase: the c a hold failed to hold")
    ax.plot([], [], "*", color="0.3", ms=10, mec="k", label="c peak at rest (largest c held)")
    ax.plot([], [], "o", mfc="w", mec="k", label="below switch (from rest)")
    ax.plot([], [], "v", mfc="w", mec="k", label="past switch: the peak at rest + dc")
    for oc, col in OUTCOME_COLOR.items():
        ax.plot([], [], "-", color=col, lw=1.5, label=f"run after the switch: {oc}")
    ax.set_xlabel(r"axial strain $\varepsilon_1$ [%]")
    ax.set_ylabel(r"$c = \sigma_1 + R\,\sigma_2$ [kPa]")
    ax.set_title(f"DEM ({n} disks): the proportional strain paths and the c-controlled runs\n"
                 r"$d\varepsilon_2 = R\,d\varepsilon_1$, compression positive", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    save_figure(fig, os.path.join(out_dir, "fig_burst_c.png"), dpi=120)

    # the kinetic energy, and its release against the held step's work (``growth``)
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 4.8), constrained_layout=True)
    for (r, f, sw), run in runs.items():
        h = run.history
        oc = run.outcome
        lab = f"R = {r:g}, f = {f:g}, {sw}: {oc}"
        ls = "-" if sw == "below" else "--"
        t = np.maximum(h[:, 1], 0.5 * h[1, 1] if len(h) > 1 else 1e-6)
        ax.loglog(t, np.maximum(h[:, 8], 1e-16), ls, color=OUTCOME_COLOR[oc], label=lab)
        w = h[:, H["w2_ext_held"]]
        ratio = np.where(w > 0, (h[:, 8] - h[0, 8]) / np.where(w > 0, w, 1.0), np.nan)
        bx.semilogx(t, ratio, ls, color=OUTCOME_COLOR[oc], label=lab)
    ax.axhline(summary["options"]["ke_tol"] * n, color="k", ls=":", lw=0.8,
               label="equilibrium bound (ke_tol x disks)")
    bx.axhline(RELEASE, color="k", ls=":", lw=0.8,
               label=f"release: E_c gained = {RELEASE:g} W2_ext (the sample gave back >= W2_ext)")
    bx.axhline(1.0, color="0.6", ls="-", lw=0.6)
    ax.set_ylabel("backbone kinetic energy [J]")
    bx.set_ylabel(r"$(E_c - E_c(0))\,/\,W_2^{ext}$, $W_2^{ext} = dG\,dU_1$ [-]")
    bx.set_yscale("symlog", linthresh=1.0)
    ax.set_title(f"DEM ({n} disks): kinetic energy of the disks with two contacts or more",
                 fontsize=10)
    bx.set_title("the kinetic energy gained against the work the held step put in\n"
                 "(solid: below, dashed: past)", fontsize=10)
    for x in (ax, bx):
        x.set_xlabel("time since the switch [s]")
        x.grid(alpha=0.3, which="both")
        if runs:
            x.legend(fontsize=7)
    if not runs:
        ax.text(0.5, 0.5, "no switched run (no peak at rest found)", ha="center",
                transform=ax.transAxes)
    save_figure(fig, os.path.join(out_dir, "fig_burst_ke.png"), dpi=120)

    fig, ax = plt.subplots(figsize=(8, 4.8), constrained_layout=True)
    for (r, f, sw), run in runs.items():
        h = run.history
        oc = run.outcome
        ls = "-" if sw == "below" else "--"
        ax.semilogy(h[1:, 1], np.abs(h[1:, 2] - h[0, 2]) * 100, ls, color=OUTCOME_COLOR[oc],
                    label=f"R = {r:g}, f = {f:g}, {sw}: {oc}, axial")
        ax.semilogy(h[1:, 1], np.abs(h[1:, 3] - h[0, 3]) * 100, ":", color=OUTCOME_COLOR[oc],
                    label=f"R = {r:g}, f = {f:g}, {sw}: lateral")
    ax.set_xlabel("time since the switch [s]")
    ax.set_ylabel(r"strain since the switch $|\Delta\varepsilon|$ [%]")
    ax.set_title(f"DEM ({n} disks): axial strain (solid: below, dashed: past) and lateral "
                 "strain (dotted) since the switch", fontsize=10)
    ax.grid(alpha=0.3, which="both")
    if runs:
        ax.legend(fontsize=7)
    else:
        ax.text(0.5, 0.5, "no switched run (no peak at rest found)", ha="center",
                transform=ax.transAxes)
    save_figure(fig, os.path.join(out_dir, "fig_burst_strain.png"), dpi=120)
    plot_k_path(os.path.join(out_dir, "fig_burst_k.png"), combos, stairs, n)


def plot_k_path(path, combos, stairs, n):
    """fig_burst_k.png: the kinematic probes of every path (``path_probe``) against the c at
    rest of the state probed: k_path [Pa] with its noise band (+-CLEARLY k_noise), the staircase's
    equilibria (filled), the other equilibria probed (open: the relaxed loaded peak, the below
    run's end, the baselines' ends), the zero crossing and the c peak at rest (the largest c the
    dead load held), so that the overshoot reads off."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from common.io import save_figure
    fig, ax = plt.subplots(figsize=(8, 5), constrained_layout=True)
    drawn = False
    for j, (r, f, _) in enumerate(combos):
        res = stairs.get((r, f))
        if res is None or not res.probes:
            continue
        col = f"C{j % 10}" if j % 10 not in (2, 3) else f"C{j % 10 + 5}"
        v = res.verdict
        stair = ["relaxed_start"] + [f"h{k}_end" for k, (ro, _, _, h) in enumerate(res.holds)
                                     if ro == "stair" and h.outcome == "equilibrium"]
        pts = [(res.probes[k].c_before, res.probes[k].k_path) for k in stair if k in res.probes]
        if pts:
            c, k = np.array(pts).T
            ax.plot(c / 1e3, k / 1e6, "o-", color=col, ms=5,
                    label=f"R = {r:g}, f = {f:g}: the staircase's equilibria ({v.get('verdict')})")
        other = [p for key, p in res.probes.items() if key not in stair]
        if other:
            ax.plot([p.c_before / 1e3 for p in other], [p.k_path / 1e6 for p in other], "o",
                    mfc="w", mec=col, ms=6, label="other equilibria probed (loaded peak relaxed, "
                                                  "below's end, baselines' ends)")
        noise = v.get("k_noise", math.nan)
        if math.isfinite(noise):
            ax.axhspan(-CLEARLY * noise / 1e6, CLEARLY * noise / 1e6, color=col, alpha=0.12,
                       label=f"noise band: +-{CLEARLY:g} x k_noise ({noise / 1e6:.2g} MPa)")
        if math.isfinite(v.get("c_cross", math.nan)):
            ax.axvline(v["c_cross"] / 1e3, color=col, ls="--", lw=1,
                       label=f"k_path = 0: c = {v['c_cross'] / 1e3:.2f} kPa")
        if math.isfinite(res.c_peak):
            ax.axvline(res.c_peak / 1e3, color="C3", ls=":", lw=1.2,
                       label=f"the largest c held at rest: {res.c_peak / 1e3:.2f} kPa "
                             f"(+{res.holds[res.switches['past']][2] - res.c_peak:g} Pa failed)"
                       if "past" in res.switches else "the largest c held at rest")
        drawn = True
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_xlabel("c at rest of the state probed [kPa]")
    ax.set_ylabel(r"$k_{path} = dc / d\varepsilon_1$ at rest [MPa]")
    ax.set_title(f"DEM ({n} disks): the path's static stiffness at rest, W2 = dc d eps1 "
                 "(kinematic probes)", fontsize=10)
    ax.grid(alpha=0.3)
    if drawn:
        ax.legend(fontsize=7, loc="best")
    else:
        ax.text(0.5, 0.5, "no kinematic probe (--no-probes, or no equilibrium)", ha="center",
                transform=ax.transAxes)
    save_figure(fig, path, dpi=120)
