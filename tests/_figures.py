"""Checks of a drawn matplotlib figure, shared by the tests of the figures (issue 32: "figures
that agree with their reports").

A figure is caught as it is saved (``catch``: the project's one writer ``common.io.save_figure``
still writes the PNG, and the figure is kept), drawn once at its saving dpi (``draw``), and read
back from matplotlib, in display pixels from the renderer:

- ``overlapping_texts``: no two texts overlap (titles, axis labels, tick labels, annotations,
  legend texts, figure texts): "1e-3 / 0 / -1e-3" piled at a symlog's zero is a case;
- ``undrawn_legend_entries``: every legend entry has an artist in the axes with data inside
  the view, which no later artist's filled marker hides; ``legend_over_data``: no legend box
  crosses a curve or a point;
- ``tick_labels``: the labels of an axis's ticks within its view (a log axis with one label);
- ``line_styles``: the line styles of the lines whose labels hold given words (for titles that
  say "solid: below, dashed: past");
- ``unitless_labels``: axis labels without a unit in brackets;
- ``texts_over_lines``: texts that a curve passes through (a point's label on its curve).
"""
from __future__ import annotations

import itertools
import re

import numpy as np
from matplotlib.lines import Line2D
from matplotlib.text import Text
from matplotlib.transforms import Bbox

SAVE_DPI = 120


def catch(monkeypatch):
    """{file name: figure} of every figure saved through ``common.io.save_figure`` (written as
    usual, and kept for the checks), also where a module imported the writer by name."""
    import common.io
    import hmodel.plots
    real = common.io.save_figure
    caught = {}

    def keep(fig, path, dpi=SAVE_DPI):
        real(fig, path, dpi=dpi)
        fig._saved_dpi = dpi
        caught[str(path).replace("\\", "/").rsplit("/", 1)[-1]] = fig

    monkeypatch.setattr(common.io, "save_figure", keep)
    monkeypatch.setattr(hmodel.plots, "save_figure", keep)
    return caught


def draw(fig):
    """Draw ``fig`` at the dpi it was saved with; returns the renderer."""
    if not hasattr(fig.canvas, "get_renderer"):        # closed once saved: a canvas again
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        FigureCanvasAgg(fig)
    fig.set_dpi(getattr(fig, "_saved_dpi", SAVE_DPI))
    fig.canvas.draw()
    return fig.canvas.get_renderer()


def _shown(text):
    return text.get_visible() and text.get_text().strip() != "" and text.figure is not None


def tick_labels(axis, renderer=None):
    """The Text of every labelled tick (major and minor) drawn on ``axis``: inside the view."""
    out = []
    lo, hi = sorted(axis.get_view_interval())
    tr = axis.get_transform()
    s_lo, s_hi = tr.transform([lo, hi])
    tol = 1e-9 * max(abs(s_hi - s_lo), 1e-300)
    for locs, ticks, fmt in ((axis.get_majorticklocs(), axis.get_major_ticks,
                              axis.major.formatter),
                             (axis.get_minorticklocs(), axis.get_minor_ticks,
                              axis.minor.formatter)):
        if len(locs) == 0:
            continue
        texts = fmt.format_ticks(locs)
        for tick, loc, txt in zip(ticks(len(locs)), locs, texts):
            s = tr.transform([loc])[0]
            if not (np.isfinite(s) and s_lo - tol <= s <= s_hi + tol) or not txt.strip():
                continue
            for lab in (tick.label1, tick.label2):
                if lab.get_visible() and tick.get_visible():
                    out.append(lab)
    return out


def _axes_texts(ax):
    texts = [ax.title, ax._left_title, ax._right_title, ax.xaxis.label, ax.yaxis.label]
    texts += tick_labels(ax.xaxis) + tick_labels(ax.yaxis)
    texts += [t for t in ax.texts]
    return texts


def all_texts(fig):
    """(owner, Text) of every text drawn in ``fig``: the axes' titles, labels, tick labels and
    texts, the legends' texts and titles, the figure's texts and suptitle."""
    out = []
    for ax in fig.axes:
        out += [(f"axes {ax.get_label() or fig.axes.index(ax)}", t) for t in _axes_texts(ax)]
    for leg in legends(fig):
        out += [("legend", t) for t in leg.get_texts()] + [("legend title", leg.get_title())]
    out += [("figure", t) for t in fig.texts]          # the suptitle among them
    seen, unique = set(), []
    for o, t in out:
        if id(t) not in seen and isinstance(t, Text) and _shown(t):
            seen.add(id(t))
            unique.append((o, t))
    return unique


def overlapping_texts(fig, shrink=0.5):
    """Pairs of texts whose boxes (less ``shrink`` pixels on each side) overlap:
    [(text a, text b)]; empty when none does."""
    r = draw(fig)
    items = []
    for owner, t in all_texts(fig):
        bb = t.get_window_extent(r)
        if bb.width > 0 and bb.height > 0:
            items.append((t.get_text(), Bbox.from_extents(bb.x0 + shrink, bb.y0 + shrink,
                                                          bb.x1 - shrink, bb.y1 - shrink)))
    return [(a, b) for (a, ba), (b, bb) in itertools.combinations(items, 2) if ba.overlaps(bb)]


def legends(fig):
    return [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None] + list(fig.legends)


def _data_artists(fig):
    """(axes, artist) of every line, collection and patch with data."""
    out = []
    for ax in fig.axes:
        out += [(ax, a) for a in ax.get_lines()]
        out += [(ax, a) for a in ax.collections]
        out += [(ax, a) for a in ax.patches]
    return out


def _points(ax, artist):
    """The artist's data points in display pixels, those inside the axes' box only."""
    if isinstance(artist, Line2D):
        xy = np.column_stack([np.asarray(artist.get_xdata(), float),
                              np.asarray(artist.get_ydata(), float)])
        if xy.size == 0:
            return np.empty((0, 2))
        pts = artist.get_transform().transform(xy)
    elif hasattr(artist, "get_offsets") and len(artist.get_offsets()):
        pts = artist.get_offset_transform().transform(np.asarray(artist.get_offsets(), float))
    else:
        path = artist.get_path() if hasattr(artist, "get_path") else None
        if path is None:
            return np.empty((0, 2))
        pts = artist.get_transform().transform(path.vertices)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    bb = ax.bbox
    inside = ((pts[:, 0] >= bb.x0 - 0.5) & (pts[:, 0] <= bb.x1 + 0.5)
              & (pts[:, 1] >= bb.y0 - 0.5) & (pts[:, 1] <= bb.y1 + 0.5))
    return pts[inside]


def _style(a):
    if isinstance(a, Line2D):
        return (tuple(np.round(np.atleast_1d(_rgba(a.get_color())), 3)), a.get_linestyle(),
                a.get_marker() if a.get_marker() not in (None, "") else "None")
    return None


def _rgba(c):
    from matplotlib.colors import to_rgba
    return to_rgba(c)


def _hidden(fig, ax, artist, pts):
    """Every point of a marker-only line lies under a larger filled marker of an artist drawn
    after it (the "all targets met" dot under the best set's star)."""
    if not isinstance(artist, Line2D) or artist.get_linestyle() != "None" or not len(pts):
        return False
    lines = ax.get_lines()
    after = [b for b in lines if (b.get_zorder(), lines.index(b))
             > (artist.get_zorder(), lines.index(artist))]
    px_pt = fig.dpi / 72.0
    own = 0.5 * artist.get_markersize() * px_pt
    for p in pts:
        covered = False
        for b in after:
            if b.get_marker() in (None, "", "None") or b.get_markerfacecolor() in ("none", "None"):
                continue
            if _rgba(b.get_markerfacecolor())[3] < 0.5:
                continue
            q = _points(ax, b)
            if len(q) and np.min(np.hypot(*(q - p).T)) + own <= 0.45 * b.get_markersize() * px_pt:
                covered = True
                break
        if not covered:
            return False
    return True


def undrawn_legend_entries(fig):
    """The legend entries (text) with no artist that draws them: an artist of the same label, or
    of the same colour, line style and marker, with data inside its axes' view and not hidden
    under another's filled marker."""
    draw(fig)
    arts = _data_artists(fig)
    missing = []
    for leg in legends(fig):
        for handle, text in zip(leg.legend_handles, leg.get_texts()):
            label = text.get_text()
            same = [(ax, a) for ax, a in arts if a.get_label() == label]
            if not same and _style(handle) is not None:
                same = [(ax, a) for ax, a in arts if _style(a) == _style(handle)]
            ok = False
            for ax, a in same:
                if not a.get_visible():
                    continue
                pts = _points(ax, a)
                if len(pts) and not _hidden(fig, ax, a, pts):
                    ok = True
                    break
            if not ok:
                missing.append(label)
    return missing


def legend_over_data(fig):
    """(legend entry count, label of the artist) of every legend drawn over a curve or a point
    of an axes it overlaps: empty when every legend lies off the data."""
    draw(fig)
    out = []
    for leg in legends(fig):
        box = leg.get_window_extent()
        for ax in fig.axes:
            if not box.overlaps(ax.bbox):
                continue
            for a in ax.get_lines() + list(ax.collections):
                if not a.get_visible():
                    continue
                if isinstance(a, Line2D) and a.get_linestyle() != "None" and len(a.get_xdata()) > 1:
                    path = a.get_transform().transform_path(a.get_path())
                    if path.intersects_bbox(box, filled=False):
                        out.append((len(leg.get_texts()), a.get_label()))
                        break
                pts = _points(ax, a)
                if np.any((pts[:, 0] > box.x0) & (pts[:, 0] < box.x1) & (pts[:, 1] > box.y0)
                          & (pts[:, 1] < box.y1)):
                    out.append((len(leg.get_texts()), a.get_label()))
                    break
    return out


def line_styles(ax, *words):
    """{line style} of the labelled lines of ``ax`` whose label holds every one of ``words``."""
    return {ln.get_linestyle() for ln in ax.get_lines()
            if all(w in ln.get_label() for w in words) and not ln.get_label().startswith("_")}


def unitless_labels(fig):
    """Axis labels (non-empty) without a unit in brackets "[...]"."""
    out = []
    for ax in fig.axes:
        for lab in (ax.xaxis.label, ax.yaxis.label):
            t = lab.get_text()
            if t.strip() and not re.search(r"\[[^\]]+\]", t):
                out.append(t)
    return out


def texts_over_lines(ax, texts=None):
    """The texts (default: the axes' annotations and texts) that a curve of ``ax`` passes
    through."""
    r = draw(ax.figure)
    texts = ax.texts if texts is None else texts
    paths = [ln.get_transform().transform_path(ln.get_path()) for ln in ax.get_lines()
             if ln.get_visible() and ln.get_linestyle() != "None" and len(ln.get_xdata()) > 1]
    return [t.get_text() for t in texts
            if any(p.intersects_bbox(Bbox(t.get_window_extent(r).get_points()), filled=False)
                   for p in paths)]


def assert_readable(fig, legend_off_data=True):
    """The checks every figure passes: no text over another, every legend entry drawn, (by
    default) no legend over the data, every axis label with its unit."""
    over = overlapping_texts(fig)
    assert over == [], f"texts over one another: {over}"
    undrawn = undrawn_legend_entries(fig)
    assert undrawn == [], f"legend entries drawn nowhere: {undrawn}"
    if legend_off_data:
        covered = legend_over_data(fig)
        assert covered == [], f"a legend over the data: {covered}"
    bare = unitless_labels(fig)
    assert bare == [], f"axis labels without a unit: {bare}"
