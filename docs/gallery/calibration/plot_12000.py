"""The calibrated set at 12,000 disks against the H-model, beside the set fitted before issue 27
(the gallery's figure calibration_12000.png):

    python docs/gallery/calibration/plot_12000.py NEW/biaxial.csv OLD/biaxial.csv OUT.png \
        [NEW_LABEL OLD_LABEL]

NEW and OLD are `python -m dem biaxial --params calibrated.json --n 12000 --no-vtk --out DIR`
runs of this folder's calibrated.json and of before_issue27/calibrated.json.  The figures (peak
q, eps1 at 95 % of it, secant, dilatancy ratio) are read as `dem calibrate` reads them (dem.calibrate.curve_figures,
0.1 % window) and printed."""
import csv
import sys

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from dem.calibrate import PEAK_FRACTION, TOLERANCES, compare, curve_figures, hmodel_curve


def read(path):
    rows = list(csv.DictReader(open(path)))
    return (np.array([float(r["eps1"]) for r in rows]), np.array([float(r["q"]) for r in rows]),
            np.array([float(r["eps_v"]) for r in rows]))


def main(new, old, out, new_label="calibrated (issue 27)",
         old_label="the set before issue 27"):
    h = hmodel_curve()
    hf = curve_figures(h["eps1"], h["q"], 0.0, eps_v=h["eps_v"])
    fig, ax = plt.subplots(1, 2, figsize=(11, 5.0), layout="constrained")
    ax[0].plot(100 * np.asarray(h["eps1"]), np.asarray(h["q"]) / 1e3, "k-", lw=1.6,
               label="H-model (Table I)")
    ax[1].plot(100 * np.asarray(h["eps1"]), 100 * np.asarray(h["eps_v"]), "k-", lw=1.6)
    ax[0].plot([100 * hf["eps1_95"]], [PEAK_FRACTION * hf["peak_q"] / 1e3], "ko", ms=5)
    for path, label, col in ((new, new_label, "C3"), (old, old_label, "0.55")):
        e, q, ev = read(path)
        f = curve_figures(e, q, 0.001, eps_v=ev)
        c = compare(f, hf)
        text = ", ".join(f"{k} {c['err_' + k]:+.1%}" for k in TOLERANCES)
        print(f"{label}: peak q {f['peak_q'] / 1e3:.1f} kPa at {100 * f['eps1_peak']:.2f} %, "
              f"eps1_95 {100 * f['eps1_95']:.3f} %, secant {f['secant'] / 1e6:.1f} MPa, dilatancy ratio "
              f"{f['dilatancy']:.3f} ({text})")
        ax[0].plot(100 * e, q / 1e3, "-", color=col, lw=1.1, label=f"DEM 12,000 disks, {label}: {text}")
        ax[1].plot(100 * e, 100 * ev, "-", color=col, lw=1.1)
        ax[0].plot([100 * f["eps1_95"]], [PEAK_FRACTION * f["peak_q"] / 1e3], "o", color=col, ms=5)
        ax[0].plot([100 * f["eps1_peak"]], [f["peak_q"] / 1e3], "^", color=col, ms=6)
    e0, q0 = 100 * hf["eps1_95"], PEAK_FRACTION * hf["peak_q"] / 1e3
    te, tq = TOLERANCES["eps1_95"], TOLERANCES["peak_q"]
    ax[0].add_patch(plt.Rectangle((e0 * (1 - te), q0 * (1 - tq)), 2 * e0 * te, 2 * q0 * tq,
                                  fill=False, ls=":", ec="k", lw=0.8))
    ax[0].set_ylabel("q = s1 - s2 [kPa]")
    ax[1].set_ylabel("eps_v [%] (compression positive)")
    for a in ax:
        a.set_xlabel("axial strain eps1 [%]")
        a.set_xlim(0, 5.5)
        a.grid(alpha=0.3)
    fig.legend(*ax[0].get_legend_handles_labels(), loc="outside lower center", fontsize=7,
               frameon=False)
    ax[0].set_title("dots: q at 95 % of the peak (box: its tolerances); triangles: the peak",
                    fontsize=8)
    fig.savefig(out, dpi=120)


if __name__ == "__main__":
    main(*sys.argv[1:6])
