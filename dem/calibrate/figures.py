"""The calibration's figures (``dem.calibrate``): calibration.png (the curves),
calibration_score.png (the score against each parameter, with the model's profile) and
calibration_search.png (the sets evaluated), and ``redraw_figures`` (the three again from a
finished calibration's files)."""
from __future__ import annotations

import json
import os

import numpy as np

from ..params import RENAMED, DemParams, migrate
from .report import censored_of
from .search import dense_points, make_space, model_of
from .targets import DILATANCY_STRAIN, PEAK_FRACTION, TOLERANCES, _fmt_figs, _fmt_values

SEED_COLORS = ("C3", "C1", "C6", "C5", "C8")     # the calibrated set's seeds, one colour each
START_SHADES = ("0.35", "0.65", "0.5", "0.8")    # the start set's seeds, greys


def _figure(out_dir, hcurve, hfig, start, best, check, start_label, space, check_mean=None):
    """calibration.png: q (left) and eps_v (right) against eps1 of the H-model, the start set
    (a grey per seed) and the best set (a colour per seed it was fitted on, the check seeds
    dashed), the points at 95 % of the peak (the sets' means of the seeds, the check seeds'
    mean, each check seed small) and the tolerance box of (eps1_95, 0.95 peak q) on the left;
    the best set's figures above; one legend below the panels, off the curves."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    fig, axes = plt.subplots(1, 2, figsize=(11, 5.6), layout="constrained")
    ends = [c["eps1"][-1] for c in start["curves"] + best["curves"]]
    x_end = max(ends + [1.3 * hfig["eps1_peak"]])
    keep = np.asarray(hcurve["eps1"]) <= x_end * (1 + 1e-9)
    hshown = {k: np.asarray(v)[keep] for k, v in hcurve.items()}
    seeds = [p["seed"] for p in best["seeds"]]
    start_seeds = [p["seed"] for p in start.get("seeds", [])] or seeds
    curves = [(hshown, "H-model (Table I)", "k", "-", 1.6)]
    curves += [(c, f"{start_label}, seed {s}", START_SHADES[i % len(START_SHADES)], "-", 0.9)
               for i, (s, c) in enumerate(zip(start_seeds, start["curves"]))]
    curves += [(c, f"calibrated set, seed {s} (fitted on)", SEED_COLORS[i % len(SEED_COLORS)],
                "-", 1.0) for i, (s, c) in enumerate(zip(seeds, best["curves"]))]
    check_label = (f"calibrated set, seed{'s' if len(check) > 1 else ''} "
                   f"{','.join(str(c['seed']) for c in check)} (dashed: not fitted on)")
    curves += [(c["curve"], check_label if i == 0 else "_nolegend_", "C0", "--", 0.8)
               for i, c in enumerate(check)]
    for c, label, col, ls, lw in curves:
        e = 100 * np.asarray(c["eps1"])
        axes[0].plot(e, np.asarray(c["q"]) / 1e3, ls, color=col, lw=lw, label=label)
        axes[1].plot(e, 100 * np.asarray(c["eps_v"]), ls, color=col, lw=lw, label=label)
    # the dilatancy ratio's lines: eps_v's least-squares line over [eps1_95, eps1_95 + 1 %]
    lines = [(hcurve, hfig.get("eps1_95"), "k")]
    lines += [(c, p.get("eps1_95"), SEED_COLORS[i % len(SEED_COLORS)])
              for i, (p, c) in enumerate(zip(best["seeds"], best["curves"]))]
    for c, e95, col in lines:
        e, v = np.asarray(c["eps1"], float), np.asarray(c["eps_v"], float)
        m = (e >= e95 - 1e-12) & (e <= e95 + DILATANCY_STRAIN + 1e-12) if e95 is not None else []
        if np.count_nonzero(m) >= 3:
            a, b = np.polyfit(e[m], v[m], 1)
            x = np.array([e[m][0], e[m][-1]])
            axes[1].plot(100 * x, 100 * (a * x + b), "-", color=col, lw=5, alpha=0.3,
                         solid_capstyle="butt")
    dots = [(hfig, "k", "o", 6), (start, START_SHADES[0], "o", 6), (best, "C3", "D", 6)]
    dots += [(c, "C0", "o", 3.5) for c in check]
    if check_mean is not None:
        dots.append((check_mean, "C0", "D", 6))
    for r, col, mk, ms in dots:
        axes[0].plot([100 * r["eps1_95"]], [PEAK_FRACTION * r["peak_q"] / 1e3], mk, color=col,
                     mec="k", mew=0.6, ms=ms, zorder=5)
    # the tolerance box of the point at 95 % of the peak
    e0, q0 = 100 * hfig["eps1_95"], PEAK_FRACTION * hfig["peak_q"] / 1e3
    te, tq = TOLERANCES["eps1_95"], TOLERANCES["peak_q"]
    axes[0].add_patch(plt.Rectangle((e0 * (1 - te), q0 * (1 - tq)), 2 * e0 * te, 2 * q0 * tq,
                                    fill=False, ls=":", ec="k", lw=0.8))
    for ax in axes:
        ax.set_xlim(0, 100 * x_end)
        ax.set_xlabel("axial strain eps1 [%]")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("q = s1 - s2 [kPa]")
    axes[1].set_ylabel("eps_v = eps1 + eps2 [%] (compression positive)")
    axes[0].set_title(f"deviatoric stress; dots: q at {PEAK_FRACTION:.0%} of the peak (the "
                      "DEM's: mean of the seeds),\ndotted box: its tolerances", fontsize=8)
    axes[1].set_title("volumetric strain of the same runs (eps_v < 0: dilation); broad lines: "
                      f"the slope read for the dilatancy ratio,\nover eps1_95 to eps1_95 + "
                      f"{100 * DILATANCY_STRAIN:g} % (H-model, the seeds fitted on)", fontsize=8)
    fig.suptitle(f"the best set {_fmt_values(space.names, best['values'])}, mean of the seeds "
                 f"{','.join(map(str, seeds))}:\n{_fmt_figs(best)}", fontsize=8)
    handles, labels = axes[0].get_legend_handles_labels()
    handles.append(Line2D([], [], ls="none", marker="D", color="C3", mec="k", mew=0.6, ms=6))
    labels.append(f"the best set at {PEAK_FRACTION:.0%} of its peak (mean of the seeds)")
    if check_mean is not None:
        handles.append(Line2D([], [], ls="none", marker="D", color="C0", mec="k", mew=0.6,
                              ms=6))
        labels.append("the same, mean of the check seeds (small dots: each of them)")
    fig.legend(handles, labels, loc="outside lower center", ncol=2, fontsize=7, frameon=False)
    _save(fig, out_dir, "calibration.png")


def _axis_label(name):
    from ..params import UNITS
    u = UNITS.get(name, "-")
    return f"{name} [{u}]"


def _score_figure(out_dir, space, records, best, model):
    """calibration_score.png: the score of every set against each varied parameter (filled
    green: all targets met, drawn over the best set's open star; a triangle: a set whose run
    stopped once decided, its score a bound from below), and the model's least
    predicted score over the other parameters; log parameters on log axes labelled at 1, 2, 5
    of each decade (``common.plots.log_axis``)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from common.plots import log_axis
    d = len(space.names)
    fig, axes = plt.subplots(1, d, figsize=(4.2 * d, 4.6), squeeze=False, layout="constrained")
    dense = dense_points(d, 1)
    pred = model.score(dense)
    sc = np.array([r["score"] for r in records])
    met = np.array([bool(r["met"]) for r in records])
    # a first run stopped once decided (--stop-decided-runs): its score a bound from below
    cut = np.array([bool(r.get("censored")) for r in records])
    for j, ax in enumerate(axes[0]):
        bins = np.linspace(0, 1, 41)
        k = np.clip(np.digitize(dense[:, j], bins) - 1, 0, 39)
        prof = np.array([pred[k == b].min() if np.any(k == b) else np.nan for b in range(40)])
        xc = [space.values_of_axis(j, 0.5 * (bins[b] + bins[b + 1])) for b in range(40)]
        ax.plot(xc, np.maximum(prof, 1e-3), "-", color="C7", lw=1.2,
                label="model: least predicted score over the others")
        x = np.array([r["values"][j] for r in records])
        ax.plot([best["values"][j]], [max(best["score"], 1e-3)], "*", mfc="none", mec="C3",
                mew=1.4, ms=16, label="best set (open star)", zorder=3)
        miss = ~met & ~cut
        ax.plot(x[miss], np.maximum(sc[miss], 1e-3), "o", mfc="none", color="C0", ms=5,
                label="sets evaluated: a target missed", zorder=4)
        if cut.any():
            ax.plot(x[cut], np.maximum(sc[cut], 1e-3), "^", mfc="none", color="C1", ms=6,
                    label="run stopped once decided: score at least", zorder=4)
        if met.any():
            ax.plot(x[met], np.maximum(sc[met], 1e-3), "o", color="C2", mec="k", mew=0.5,
                    ms=6, label="sets evaluated: all targets met", zorder=5)
        ax.set_yscale("log")
        if space.log[j]:
            log_axis(ax, "x")
        ax.set_xlabel(_axis_label(space.names[j]))
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("score sum (err / tol)^2 [-] (mean of the seeds)")
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=len(labels), fontsize=8,
               frameon=False)
    _save(fig, out_dir, "calibration_score.png")


def _search_figure(out_dir, space, records, best):
    """calibration_search.png: the sets evaluated in the plane of the first two parameters
    (colour: log10 of the score; numbers: the order), the best set starred; against the score
    when one parameter is varied. Log parameters on log axes labelled at 1, 2, 5 of each
    decade."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from common.plots import log_axis
    fig, ax = plt.subplots(figsize=(5.5, 4.3), layout="constrained")
    sc = np.array([r["score"] for r in records])
    x = np.array([r["values"][0] for r in records])
    if len(space.names) == 1:
        ax.plot(x, sc, "o", color="C0")
        ax.plot([best["values"][0]], [best["score"]], "*", color="C3", ms=12)
        ax.set_ylabel("score sum (err/tol)^2 [-]")
        ax.set_yscale("log")
    else:
        y = np.array([r["values"][1] for r in records])
        s = ax.scatter(x, y, c=np.log10(np.maximum(sc, 1e-6)), cmap="viridis_r", s=30)
        fig.colorbar(s, ax=ax, label="log10 score, sum (err/tol)^2 [-]")
        ax.plot([best["values"][0]], [best["values"][1]], "*", color="C3", ms=14)
        for r in records:
            ax.annotate(str(r["index"]), (r["values"][0], r["values"][1]), fontsize=6,
                        textcoords="offset points", xytext=(3, 3))
        ax.set_ylabel(_axis_label(space.names[1]))
        if space.log[1]:
            log_axis(ax, "y")
    ax.set_xlabel(_axis_label(space.names[0]))
    if space.log[0]:
        log_axis(ax, "x")
    ax.set_title("sets evaluated (numbers: order); star: best", fontsize=8)
    ax.grid(alpha=0.3)
    _save(fig, out_dir, "calibration_search.png")


def redraw_figures(out_dir):
    """calibration.png, calibration_search.png and calibration_score.png of a finished
    calibration drawn again from its calibration.csv, curves.csv and summary.json, without a
    run (the model of the figures refitted on the sets, as the run fits it): ``python -c "from
    dem.calibrate import redraw_figures; redraw_figures('DIR')"``."""
    from .. import io
    with open(os.path.join(out_dir, "summary.json")) as f:
        s = json.load(f)
    opts = s["options"]
    base = DemParams.from_dict(migrate(dict(opts["start_params"])))
    vary = [RENAMED.get(v, v) for v in opts["vary"]]
    bounds = {RENAMED.get(k, k): (v[0], v[1]) for k, v in opts["bounds"].items()}
    space = make_space(tuple(vary), base, bounds)
    _, rows = io.read_csv(os.path.join(out_dir, "calibration.csv"))
    hfig = s["target_figures"]
    records = []
    for r in rows:
        if r["kind"] != "dem":
            continue
        rec = dict(r, index=int(r["index"]), met=bool(r["met"]),
                   values=[r[n] for n in opts["vary"]])
        records.append(rec)
    _, crow = io.read_csv(os.path.join(out_dir, "curves.csv"))
    curves = {}
    for r in crow:
        c = curves.setdefault((r["curve"], r["seed"]), {"eps1": [], "q": [], "eps_v": []})
        for k in ("eps1", "q", "eps_v"):
            c[k].append(r[k])
    seeds = opts["seeds"]
    hcurve = next(c for (name, _), c in curves.items() if name == "hmodel")
    # a start set decided on its first run ran on that seed only
    ran = [sd for sd in seeds if ("dem_start", sd) in curves]
    start = dict(s["start"], curves=[curves[("dem_start", sd)] for sd in ran],
                 seeds=[{"seed": sd} for sd in ran])
    best = dict(s["best"], curves=[curves[("dem_calibrated", sd)] for sd in seeds],
                seeds=s["best_seeds"])
    check = [dict(c, curve=curves[("dem_calibrated_check", c["seed"])]) for c in s["check"]
             if ("dem_calibrated_check", c["seed"]) in curves]
    _figure(out_dir, hcurve, hfig, start, best, check, s.get("start_label", "DEM, start set"),
            space, s.get("check_mean"))
    _search_figure(out_dir, space, records, best)
    # a folder of before the dilatancy target (issue 34): its own figures
    names = [f for f in TOLERANCES if f in hfig and all(f in r for r in records)]
    for r in records:
        r["censored"] = censored_of(r.get("censored"))
    model = model_of(space, [(r["values"], r) for r in records], hfig, names)
    if model is not None:
        _score_figure(out_dir, space, records, best, model)


def _save(fig, out_dir, name):
    from common.io import save_figure       # the project's one atomic figure writer
    save_figure(fig, os.path.join(out_dir, name), dpi=120)
