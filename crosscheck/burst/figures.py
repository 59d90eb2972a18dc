"""The burst section's figures: the path's own W2 in the three parts (``w2_path_figure``), the
kinetic energy after the switch (``burst_figure``) and Eq. 1's terms of the FE and the DEM side
by side (``burst_eq1_figure``).
"""
from __future__ import annotations

import os

import numpy as np

from .part import LABEL

__all__ = ["w2_path_figure", "burst_figure", "burst_eq1_figure"]


def w2_path_figure(out, parts: dict, name="fig_burst_w2_path.png") -> str | None:
    """The path's own W2 in the three parts side by side: k_path = dc/d eps1 over its value at
    the path's start, against the rise of c, (c - c_start) / (c_peak - c_start) (each part's own
    peak: the DEM's at rest), the material point from its tangent, the FE from its static path,
    the DEM from its kinematic probes at rest. Where k_path crosses 0 W2 of the path vanishes;
    a part whose c peak lies past that (x > 1 - 0 crossing) held G past it."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from common.io import save_figure
    color = {"hmodel": "C0", "fem": "C1", "dem": "C3"}
    style = {"hmodel": "-", "fem": "--", "dem": "o-"}
    fig, ax = plt.subplots(figsize=(7.5, 5))
    drawn = False
    for part, p in parts.items():
        for w in p.get("w2_path") or []:
            c, k = np.asarray(w["c"], float), np.asarray(w["k"], float)
            if not len(k) or w.get("c_peak") is None or w["c_peak"] == w["c_start"] or k[0] == 0:
                continue
            x = (c - w["c_start"]) / (w["c_peak"] - w["c_start"])
            ax.plot(x, k / k[0], style[part], color=color[part], ms=5, lw=1.2,
                    label=f"{LABEL[part]}, R = {w['ratio']:g}, f = {w['start_fraction']:g}")
            drawn = True
    if not drawn:
        plt.close(fig)
        return None
    ax.axhline(0.0, color="k", lw=0.8)
    ax.axvline(1.0, color="0.5", ls=":", lw=1)
    ax.set_xlabel(r"$(c - c_{start}) / (c_{peak} - c_{start})$: the rise of c to each part's "
                  "peak (the DEM's at rest)")
    ax.set_ylabel(r"$k_{path} / k_{path}(start)$, $k_{path} = dc/d\varepsilon_1$")
    ax.set_title("The path's own second-order work W2 = dc d eps1: material point (tangent),\n"
                 "FE (static path), DEM (kinematic probes at rest)", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower left")
    save_figure(fig, os.path.join(out, name))
    return name


def burst_figure(out, parts: dict, name="fig_burst_ke.png") -> str:
    """E_c per volume [J/m^3] against the time since the switch [s], log axes, the three parts on
    one figure (colour: part; solid: past, dashed: below; the end marked by the outcome, as in
    ``hmodel.plots.fig_burst_ke``; the legend beside the axes)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from common.io import save_figure
    from hmodel.plots import END_MARK
    color = {"hmodel": "C0", "fem": "C1", "dem": "C3"}
    fig, ax = plt.subplots(figsize=(7.5, 5))
    ends = set()
    for part, p in parts.items():
        ax.plot([], [], "-", color=color[part], label=LABEL[part])
        for h in p["histories"]:
            t, ke = np.asarray(h["t"]), np.asarray(h["ke_density"])
            ok = (t > 0) & (ke > 0)
            if not ok.any():
                continue
            ax.loglog(t[ok], ke[ok], "-" if h["switch"] == "past" else "--", color=color[part],
                      lw=1.1)
            row = next((r for r in p["rows"] if (r["ratio"], r["start_fraction"], r["switch"])
                        == (h["ratio"], h["start_fraction"], h["switch"])), None)
            if row is not None:
                m, fc, _ = END_MARK.get(row["outcome"], END_MARK["undecided"])
                ax.plot(t[ok][-1], ke[ok][-1], m, mec="k", mfc=fc, ms=8, mew=1.4, zorder=5)
                ends.add(row["outcome"])
    ax.plot([], [], "k-", label="past the c peak (burst expected)")
    ax.plot([], [], "k--", label="below the c peak (equilibrium expected)")
    for m, fc, lab in (v for k, v in END_MARK.items() if k in ends):
        ax.plot([], [], m, ls="none", mec="k", mfc=fc, ms=8, mew=1.4, label=lab)
    ax.set_xlabel("time since the switch to c control [s]")
    ax.set_ylabel(r"kinetic energy per volume $E_c/V$ [J/m$^3$]")
    ax.set_title("The burst of kinetic energy (Eq. 1): c = s1 + R s2 held below / past its peak,\n"
                 "from rest (DEM: the disks with two contacts or more, a dead load on the walls)",
                 fontsize=9)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)   # off the data
    save_figure(fig, os.path.join(out, name))
    return name


def burst_eq1_figure(out, fem_history, dem_history, name="fig_burst_eq1.png") -> str | None:
    """Eq. 1's terms of the past runs against the time since the switch, the FE specimen's
    (history.csv of fem burst: E_c = W2_ext - W2_int - D, Newmark's discrete balance) beside the
    DEM sample's (history.csv of dem burst: E_c - E_c(0) = W2_ext - W2_int + W_damp + U0, the
    energy ledger), one panel each, symmetric log axes: who gives the kinetic energy. None when
    a part has no past run."""
    import csv

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from common.io import save_figure

    def past(path):
        if not path or not os.path.exists(path):
            return None
        with open(path) as f:
            rows = [r for r in csv.DictReader(f) if r["switch"] == "past"]
        if not rows:
            return None
        first = (rows[0]["ratio"], rows[0]["start_fraction"])
        rows = [r for r in rows if (r["ratio"], r["start_fraction"]) == first]
        return {k: np.array([float(r[k]) for r in rows]) for k in rows[0] if k != "switch"}

    fe, dm = past(fem_history), past(dem_history)
    if fe is None or dm is None:
        return None
    panels = [("FE perfect specimen: E_c = W2_ext - W2_int - D", fe["t"],
               [(fe["ke"], r"$E_c$", "k", 2.2), (fe["w2_ext"], r"$W_2^{ext}$", "C0", 1.4),
                (-fe["w2_int"], r"$-W_2^{int}$", "C3", 1.4),
                (-fe["damping"], r"$-D$ (Rayleigh damping)", "C2", 1.4)]),
              ("DEM sample: E_c - E_c(0) = W2_ext - W2_int + W_damp + U0", dm["t_ledger"],
               [(dm["dke"], r"$E_c - E_c(0)$", "k", 2.2), (dm["w2_ext"], r"$W_2^{ext}$", "C0", 1.4),
                (-dm["w2_int"], r"$-W_2^{int}$", "C3", 1.4),
                (dm["w_damp"], r"$W_{damp}$ (Cundall damping)", "C2", 1.4),
                (dm["u0"], r"$U_0$", "C4", 1.0)])]
    from common.plots import symlog_axis
    fig, axes = plt.subplots(1, 2, figsize=(11, 5.0), layout="constrained")
    for ax, (title, t, terms) in zip(axes, panels):
        for y, lab, col, lw in terms:
            ax.plot(t, y, "-", color=col, lw=lw, label=lab)
        big = max(float(np.max(np.abs(y))) for y, *_ in terms)
        symlog_axis(ax, max(1e-4 * big, 1e-15))         # no tick labels piled at 0
        ax.axhline(0, color="0.5", lw=0.6)
        ax.set_xlabel("time since the switch [s]")
        ax.set_ylabel("energy since the switch [J/m]" if "FE" in title else
                      "energy since the switch [J]")
        ax.set_title(f"past the c peak - {title}", fontsize=9)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=3,
                  frameon=False)                                   # below the panel, off the data
    save_figure(fig, os.path.join(out, name))
    return name
