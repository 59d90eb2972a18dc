"""Plot helpers of every part (matplotlib, Agg): the paper's polar diagram of the second-order
work (``polar_axes``, ``polar_series``, the cone W2 <= 0 ``mark_cone`` and its zoom
``cone_zoom``, the plastic zone ``mark_plastic``), axes that read (``symlog_axis`` without
labels piled at zero, ``log_axis`` with several labels a decade, ``label_point`` beside its
curve). The figures themselves are the parts' (``hmodel.plots``, dem's and the cross-check's);
every one is saved by ``common.io.save_figure``.

Conventions: alpha_sigma measured from the d sigma2 axis (tan alpha_sigma = d sigma1 / d sigma2),
so polar diagrams put d sigma2 on the horizontal and d sigma1 on the vertical axis; the dashed
circle of radius 0.5 is W2 = 0.
"""
from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.ticker  # noqa: E402
import numpy as np  # noqa: E402

__all__ = ["polar_axes", "mark_cone", "mark_plastic", "cone_zoom", "needs_zoom", "polar_series",
           "symlog_axis", "log_axis", "label_point", "SpacedLocator",
           "ZOOM_BELOW_DEG", "CONE_COLOR", "LABEL_OFFSETS"]


# a cone narrower than this [deg] gets a second panel, W2 against alpha_sigma around it
ZOOM_BELOW_DEG = 30.0
CONE_COLOR = "C3"


def polar_axes(ax, rmax=1.6):
    """The paper's polar diagram on a matplotlib polar axes ``ax``: the angle is alpha_sigma
    [deg] from the d sigma2 axis, counter-clockwise (ticks every 30 deg), the radius 0.5 + W2
    (radial ticks labelled with W2), the dashed circle W2 = 0, for 0.5 + W2 up to ``rmax``."""
    ax.set_thetagrids(np.arange(0, 360, 30), [f"{a}°" for a in range(0, 360, 30)], fontsize=8)
    ax.set_ylim(0, rmax)
    ticks = [r for r in (0.0, 0.5, 1.0, 1.5, 2.0, 2.5) if r <= rmax]
    ax.set_yticks(ticks)
    ax.set_yticklabels([f"{r - 0.5:g}" for r in ticks], fontsize=7, color="0.35")
    ax.set_rlabel_position(112.5)             # W2 read along the 112.5 deg ray, off the data
    ax.grid(alpha=0.35)
    t = np.linspace(0, 2 * np.pi, 361)
    ax.plot(t, np.full_like(t, 0.5), "k--", lw=0.9, label=r"$W_2 = 0$ (radius 0.5)")


def _arc_text(cone) -> str:
    """'243.4°-249.2°' (one arc, or several joined by ', '; angles above 360 wrapped)."""
    return ", ".join(f"{a % 360:.1f}°-{b % 360:.1f}°" if b > a else f"{a % 360:.1f}°"
                     for a, b in cone)


def mark_cone(ax, cone, rmax, label=r"$W_2 \leq 0$", color=CONE_COLOR):
    """Shade the arcs ``cone`` ([[start, end], ...] of alpha_sigma [deg], ``probes.arcs``) as
    wedges from the centre to ``rmax`` on the polar axes ``ax``, edges drawn, and write their
    angles beside them. A single direction (start = end) is a ray."""
    for a, b in cone:
        th = np.radians(np.linspace(a, b, max(2, int(4 * (b - a)) + 2)))
        ax.fill_between(th, 0.0, rmax, color=color, alpha=0.3, lw=0, zorder=0)
        for edge in {a, b}:
            ax.plot([np.radians(edge)] * 2, [0.0, rmax], color=color, lw=1.0, zorder=1)
    if cone:
        # the text outside the circle, 25 deg clockwise of the first arc (off its tick label)
        mid = 0.5 * (cone[0][0] + cone[0][1])
        at = np.radians(mid - 25.0)
        ax.annotate(f"{label}\n{_arc_text(cone)}", (np.radians(mid), 0.8 * rmax),
                    xytext=(at, 1.25 * rmax), textcoords="data", va="center", fontsize=9,
                    ha="left" if np.cos(at) > 0.3 else "right" if np.cos(at) < -0.3 else "center",
                    color=color, fontweight="bold", annotation_clip=False,
                    arrowprops=dict(arrowstyle="->", color=color, lw=1.0))
        ax.plot([], [], "s", color=color, alpha=0.4, ms=9, label=f"{label}: {_arc_text(cone)}")


def mark_plastic(ax, plastic, rmax, color="0.55"):
    """The plastic zone (arcs of alpha_sigma [deg]) as a grey band at the rim of the polar axes."""
    for a, b in plastic:
        th = np.radians(np.linspace(a, b, max(2, int(b - a) + 2)))
        ax.fill_between(th, 0.93 * rmax, rmax, color=color, alpha=0.55, lw=0, zorder=0)
    if plastic:
        ax.plot([], [], "s", color=color, alpha=0.7, ms=9,
                label=f"plastic zone (rim): {_arc_text(plastic)}")


def cone_zoom(ax, series, cone, plastic=(), pad_deg=None, label=r"$W_2 \leq 0$",
              color=CONE_COLOR):
    """W2 against alpha_sigma around the cone (Cartesian ``ax``): the ``series`` ((label,
    alpha_sigma [deg], w2, style), as ``fig_polar_w2``) within the cone's arcs widened by
    ``pad_deg`` (default: the cone's width, at least 6 deg) on each side, the cone shaded with
    its angles on the axis (``label`` says what it is), the plastic zone grey, W2 = 0, the least
    W2 marked."""
    lo, hi = min(a for a, _ in cone), max(b for _, b in cone)
    pad = max(6.0, hi - lo) if pad_deg is None else pad_deg
    x0, x1 = lo - pad, hi + pad
    w_in = []
    for name, a, w, style in series:
        a = np.asarray(a, float)
        w = np.asarray(w, float)
        for shift in (0.0, 360.0, -360.0):         # a cone through 0 deg: both sides
            sel = (a + shift >= x0) & (a + shift <= x1)
            if sel.any():
                o = np.argsort(a[sel] + shift)
                ax.plot((a[sel] + shift)[o], w[sel][o], style, lw=1.3, ms=5,
                        label=name if shift == 0.0 else None)
                w_in.append(w[sel])
    for k, (a, b) in enumerate(plastic):
        ax.axvspan(a, b, color="0.55", alpha=0.15, lw=0, zorder=0,
                   label="plastic zone" if k == 0 else None)
    for k, (a, b) in enumerate(cone):
        ax.axvspan(a, b, color=color, alpha=0.3, lw=0, zorder=0, label=label if k == 0 else None)
        for edge in {a, b}:
            ax.axvline(edge, color=color, lw=0.9)
    ax.axhline(0.0, color="k", lw=0.8)
    w_all = np.concatenate(w_in) if w_in else np.zeros(1)
    w_all = w_all[np.isfinite(w_all)]
    if w_all.size:
        top = min(float(np.max(w_all)), 1.0)
        bottom = min(float(np.min(w_all)), 0.0)
        span = max(top - bottom, 0.05)
        ax.set_ylim(bottom - 0.15 * span, top + 0.1 * span)
    a0, w0 = series[0][1], np.asarray(series[0][2], float)
    k = int(np.nanargmin(w0))
    if w0[k] <= 0:
        ax.plot([a0[k]], [w0[k]], "v", color="k", ms=7, zorder=5)
        ax.annotate(f"least $W_2$ = {w0[k]:.3f}\nat {a0[k]:.1f}°", (a0[k], w0[k]),
                    textcoords="offset points", xytext=(10, -4), fontsize=8, va="top")
    ticks = sorted({round(t, 1) for t in np.arange(np.ceil(x0 / 5) * 5, x1 + 1e-9, 5.0)}
                   - {round(e, 0) for c in cone for e in c})
    edges = sorted({e for c in cone for e in c})
    ax.set_xticks(ticks + edges)
    ax.set_xticklabels([f"{t % 360:g}" for t in ticks] + [f"{e % 360:.1f}" for e in edges],
                       fontsize=8)
    for lab in ax.get_xticklabels()[len(ticks):]:
        lab.set_color(color)
        lab.set_fontweight("bold")
        lab.set_rotation(90)
    ax.set_xlim(x0, x1)
    ax.set_xlabel(r"$\alpha_\sigma$ [deg]")
    ax.set_ylabel(r"normalized second-order work $W_2$ [-]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7.5, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2, frameon=False)
    ax.set_title(f"zoom on the cone, {label}: {_arc_text(cone)}", fontsize=10, color=color)


def needs_zoom(cone) -> bool:
    return bool(cone) and sum(b - a for a, b in cone) < ZOOM_BELOW_DEG


def polar_series(ax, series, rmax):
    """Each (label, alpha_sigma [deg], w2, style) at angle alpha_sigma and radius 0.5 + w2,
    clipped to [0, rmax] (a clipped point is drawn on the rim or the centre)."""
    for label, a, w, style in series:
        a = np.asarray(a, float)
        o = np.argsort(a)
        r = np.clip(0.5 + np.asarray(w, float)[o], 0.0, rmax)
        ax.plot(np.radians(a[o]), r, style, label=label, lw=1.2, ms=5)


# -- axes that read: a symlog axis without labels piled at zero, log axes with several labels,
# a point's label beside its curve --------------------------------------------------------------
class SpacedLocator(matplotlib.ticker.Locator):
    """The ticks of ``base`` less those whose labels would overlap on screen: 0 is kept first,
    then the ticks farthest from 0, each only if it is at least ``gap`` label heights from every
    tick kept (a symlog axis's +-linthresh labels sit half a decade from 0 and pile up on its
    label otherwise). Decided at every draw from the axis's height in pixels, so a layout
    change cannot bring an overlap back. Vertical axes only (the labels' heights)."""

    def __init__(self, base, gap=1.6):
        self.base = base
        self.gap = gap

    def set_axis(self, axis):
        super().set_axis(axis)
        self.base.set_axis(axis)

    def tick_values(self, vmin, vmax):
        return self.base.tick_values(vmin, vmax)

    def __call__(self):
        ticks = np.asarray(self.base(), float)
        axis = self.axis
        if axis is None or axis.axis_name != "y" or ticks.size < 2:
            return ticks
        lo, hi = sorted(axis.get_view_interval())
        ticks = ticks[(ticks >= lo) & (ticks <= hi)]
        tr = axis.get_transform()
        s_lo, s_hi = tr.transform([lo, hi])
        height = axis.axes.bbox.height
        if not (height > 0 and s_hi > s_lo):
            return ticks
        px = (tr.transform(ticks) - s_lo) / (s_hi - s_lo) * height
        size = axis.get_major_ticks(1)[0].label1.get_size()          # [pt]
        need = self.gap * size * axis.axes.figure.dpi / 72.0
        order = sorted(range(len(ticks)), key=lambda k: (ticks[k] != 0, -abs(ticks[k])))
        kept = []
        for k in order:
            if all(abs(px[k] - px[j]) >= need for j in kept):
                kept.append(k)
        return np.sort(ticks[kept])


def symlog_axis(ax, linthresh):
    """A symmetric log y axis (linear within +-``linthresh``) whose tick labels never overlap
    (``SpacedLocator``), the minor ticks unlabelled."""
    from matplotlib.ticker import NullFormatter
    ax.set_yscale("symlog", linthresh=linthresh)
    ax.yaxis.set_major_locator(SpacedLocator(ax.yaxis.get_major_locator()))
    ax.yaxis.set_minor_formatter(NullFormatter())


def _short_sci(v, _pos=None):
    """2e9, 5e9, 1e10: a log axis's labels at 1, 2 and 5 of each decade."""
    if not (v > 0 and math.isfinite(v)):
        return ""
    e = math.floor(math.log10(v) + 1e-9)
    m = v / 10.0 ** e
    return f"{m:.0f}e{e}" if abs(m - round(m)) < 1e-6 else f"{v:.2g}"


def log_axis(ax, which="x"):
    """A log axis labelled at 1, 2 and 5 of every decade ("2e9", "5e9", "1e10"), so a range of
    about one decade gets several labels rather than the one of its decade."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter
    axis = ax.xaxis if which == "x" else ax.yaxis
    (ax.set_xscale if which == "x" else ax.set_yscale)("log")
    axis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
    axis.set_major_formatter(FuncFormatter(_short_sci))
    axis.set_minor_formatter(NullFormatter())


LABEL_OFFSETS = ((8, -16), (8, 6), (-16, 6), (-16, -16), (10, -5), (-20, -5), (-4, 10),
                 (-4, -20), (14, -28), (14, 16))     # [points] from the point, in this order


def label_point(ax, x, y, text, color="C3", offsets=LABEL_OFFSETS, **kw):
    """Write ``text`` beside the point (x, y) of ``ax`` where it crosses none of the axes'
    lines: the first of ``offsets`` whose text box no line passes through (the first offset if
    every one is crossed). Call it once the layout is final (after ``tight_layout``); returns
    the annotation."""
    from matplotlib.transforms import Bbox
    fig = ax.figure
    renderer = fig.canvas.get_renderer()
    paths = [ln.get_transform().transform_path(ln.get_path()) for ln in ax.get_lines()
             if ln.get_visible() and len(ln.get_xdata()) > 1 and ln.get_linestyle() != "None"]
    for off in offsets:
        t = ax.annotate(text, (x, y), textcoords="offset points", xytext=off, color=color, **kw)
        box = Bbox(t.get_window_extent(renderer).get_points()).expanded(1.15, 1.15)
        if not any(p.intersects_bbox(box, filled=False) for p in paths):
            return t
        t.remove()
    return ax.annotate(text, (x, y), textcoords="offset points", xytext=offsets[0], color=color,
                       **kw)
