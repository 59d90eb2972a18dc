"""What the figures show: the polar W2 diagrams (the cone W2 <= 0 shaded and labelled with its
angles, the plastic zone, a zoom where the cone is narrow, angle ticks), the burst figure's
legend and end markers, and ``fmt``, the numbers of the output lines (issue 26). The figures
are caught before they are written (``save_figure``) and read back from matplotlib."""
from __future__ import annotations

import math

import matplotlib.collections as mcoll
import numpy as np
import pytest

from hmodel import plots
from common.io import fmt


@pytest.fixture
def figures(monkeypatch):
    got = []
    monkeypatch.setattr(plots, "save_figure", lambda fig, path: got.append(fig))
    return got


def _texts(fig):
    return [t.get_text() for ax in fig.axes for t in ax.texts]


def _labels(ax):
    return ax.get_legend_handles_labels()[1]


def _series(lo, hi, depth=0.1):
    """A W2 that dips below zero exactly on (lo, hi) [deg], sampled every 0.1 deg."""
    a = np.arange(0.0, 360.0, 0.1)
    mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    w = np.where(np.abs(a - mid) < 3 * half, depth * ((a - mid) ** 2 / half ** 2 - 1), 0.4)
    w = np.where(np.abs(a - mid) < half, w, np.abs(w) + 0.05)
    return a, w


def test_narrow_cone_is_shaded_labelled_and_zoomed(figures):
    a, w = _series(243.4, 249.2)
    plastic = [[68.4, 257.7]]
    plots.fig_polar_w2([("W2", a, w, "C0-")], "x.png", cone=[[243.4, 249.2]], plastic=plastic)
    (fig,) = figures
    polar, zoom = fig.axes
    assert polar.name == "polar" and zoom.name != "polar"
    # angle ticks every 30 deg, labelled in degrees
    assert [t.get_text() for t in polar.get_xticklabels()][:4] == ["0°", "30°", "60°", "90°"]
    # the cone: a shaded wedge and its angles written beside it and in the legend
    assert any("243.4°-249.2°" in t for t in _texts(fig))
    assert any("243.4°-249.2°" in s for s in _labels(polar))
    assert any(isinstance(c, mcoll.PolyCollection) for c in polar.collections)
    assert any("plastic zone" in s and "68.4°-257.7°" in s for s in _labels(polar))
    # the zoom: around the cone, its edges as ticks, W2 = 0 and the least W2 marked
    x0, x1 = zoom.get_xlim()
    assert x0 < 243.4 and x1 > 249.2 and x1 - x0 < 30
    ticks = [t.get_text() for t in zoom.get_xticklabels()]
    assert "243.4" in ticks and "249.2" in ticks
    assert any(t.startswith("least $W_2$ = -0.1") for t in _texts(fig))


def test_no_cone_no_zoom_and_it_is_said(figures):
    a = np.arange(0.0, 360.0, 1.0)
    plots.fig_polar_w2([("W2", a, 0.3 + 0.1 * np.cos(np.radians(a)), "C0-")], "x.png")
    (fig,) = figures
    assert len(fig.axes) == 1
    assert r"$W_2 > 0$ in every direction probed" in _labels(fig.axes[0])


def test_wide_cone_has_no_zoom(figures):
    a, w = _series(200.0, 260.0)
    plots.fig_polar_w2([("W2", a, w, "C0-")], "x.png")         # the cone from the series
    (fig,) = figures
    assert len(fig.axes) == 1
    assert any("200.0°-260.0°" in t or "200.1°-259.9°" in t for t in _texts(fig))


def test_cone_through_zero_degrees():
    """An arc that runs through 0 deg (probes.arcs ends it above 360) is written wrapped and
    zoomed on both sides of 0."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from common import plots
    assert plots._arc_text([[350.0, 370.0]]) == "350.0°-10.0°"
    a = np.arange(0.0, 360.0, 1.0)
    w = np.where((a >= 350) | (a <= 10), -0.05, 0.5)
    fig, ax = plt.subplots()
    plots.cone_zoom(ax, [("W2", a, w, "C0-")], [[350.0, 370.0]])
    x0, x1 = ax.get_xlim()
    assert x0 < 350 and x1 > 370
    xs = np.concatenate([np.atleast_1d(line.get_xdata()) for line in ax.lines])
    assert xs.min() < 345 and xs.max() > 375          # both sides of 0 deg drawn
    ticks = [t.get_text() for t in ax.get_xticklabels()]
    assert "350.0" in ticks and "10.0" in ticks and "370.0" not in ticks
    plt.close(fig)


def test_burst_ke_legend_is_off_the_data_with_the_end_markers(figures):
    t = np.linspace(0, 0.01, 50)
    w2 = 1e-8 * (1 - np.exp(-300 * t))
    hist = [{"ratio": -2.0, "start_fraction": 0.9, "switch": "below", "outcome": "equilibrium",
             "t": t, "ke": 1e-8 * np.exp(-300 * t) + 1e-15, "w2_ext": w2, "T1": 1e-3},
            {"ratio": -2.0, "start_fraction": 0.9, "switch": "past", "outcome": "failure",
             "t": t, "ke": 1e-8 * np.exp(500 * t), "w2_ext": w2, "T1": 1e-3}]
    plots.fig_burst_ke(hist, "x.png")
    (fig,) = figures
    assert all(ax.get_legend() is None for ax in fig.axes)       # no legend on the data
    (legend,) = fig.legends
    labels = [x.get_text() for x in legend.get_texts()]
    assert "end: equilibrium" in labels and "end: failure" in labels and "R = -2" in labels
    # the second row: the growth measure, RELEASE drawn, the past run starred where it passed it
    assert len(fig.axes) == 2 and "energy release" in fig.axes[1].get_ylabel()
    assert any(line.get_marker() == "*" for line in fig.axes[1].lines)
    # the legend lies below the axes
    fig.canvas.draw()
    box = legend.get_window_extent()
    assert all(box.y1 <= ax.get_window_extent().y0 for ax in fig.axes)


@pytest.mark.parametrize("value, spec, missing, text", [
    (math.nan, ".4f", "none", "none"),
    (None, "10.4f", "none", "      none"),
    (math.inf, ".4f", "never", "never"),
    (-1e-9, "+.3f", "none", "0.000"),
    (-1e-9, "10.4f", "none", "    0.0000"),
    (-4e-4, "+.3f", "none", "0.000"),
    (-6e-4, "+.3f", "none", "-0.001"),
    (-0.5, "+.3f", "none", "-0.500"),
    (0.99768, ".4f", "none", "0.9977"),
    (-2e-5, ".2e", "none", "-2.00e-05"),
    (3, "d", "none", "3"),
])
def test_fmt(value, spec, missing, text):
    assert fmt(value, spec, missing) == text
