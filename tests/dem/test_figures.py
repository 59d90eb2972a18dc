"""The DEM's figures say what their reports say (issue 32), each drawn from a small result and
read back from matplotlib (``tests/_figures.py``): the energy ledger (``fig_ledger.png`` of
``dem probes``, ``fig_burst_ledger.png`` of ``dem burst``, the cross-check's
``fig_burst_eq1.png``), Figs. 13-14 of ``dem biaxial``, and the three figures of ``dem
calibrate``. (The burst's strain and anatomy figures are checked on the burst run of
tests/dem/test_burst_cli.py and on the anatomy's own test.)"""
from __future__ import annotations

import csv
import json
import math
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from tests import _figures as F

GALLERY = Path(__file__).resolve().parents[2] / "docs" / "gallery"


@pytest.fixture
def caught(monkeypatch):
    return F.catch(monkeypatch)


# -- the energy ledger ------------------------------------------------------------------------
def _ledger_history(kind, n=300, seed=0):
    """Eq. 1's terms of a run since its start, spanning decades as the real ones do: a settled
    probe (terms ~1e-4 J, E_c - E_c(0) changing sign) or a runaway (terms ~10 J)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 0.3, n)
    big = 1e-4 if kind == "settled" else 20.0
    w2_ext = big * (1 - np.exp(-t / 0.01))
    w2_int = -big * 1.5 * np.tanh(t / 0.05)
    w_damp = -big * 2.4 * np.tanh(t / 0.04)
    u0 = 1e-2 * big * np.sqrt(t / 0.3)
    dke = w2_ext - w2_int + w_damp + u0 + 1e-3 * big * rng.standard_normal(n)
    return {"t_ledger": t, "dke": dke, "w2_ext": w2_ext, "w2_int": w2_int, "w_damp": w_damp,
            "u0": u0}


def _rows(d, columns):
    return [[d.get(c, np.zeros_like(d["t_ledger"]))[k] for c in columns]
            for k in range(len(d["t_ledger"]))]


def _check_ledger(fig):
    F.assert_readable(fig)
    for ax in fig.axes:
        assert ax.get_yscale() == "symlog"
        labels = [t.get_text() for t in F.tick_labels(ax.yaxis)]
        assert "$\\mathdefault{0}$" in labels or "0" in labels, labels   # 0 is labelled
        assert len(labels) >= 4
        assert ax.get_ylabel().endswith("[J]")
    # one legend for the panels, every term in it
    (leg,) = F.legends(fig)
    assert len(leg.get_texts()) == 6


def test_the_ledger_of_two_runs(caught, tmp_path):
    from dem.ledger import plot_ledger
    cols = ["t_ledger", "dke", "w2_ext", "w2_int", "w_damp", "u0"]
    plot_ledger(tmp_path / "fig_burst_ledger.png",
                [("R = -2, f = 0.9, below: equilibrium (2000 disks)",
                  _rows(_ledger_history("settled"), cols), cols),
                 ("R = -2, f = 0.9, past: failure (2000 disks)",
                  _rows(_ledger_history("runaway"), cols), cols)])
    _check_ledger(caught["fig_burst_ledger.png"])


def test_the_ledger_of_the_probes_quotes_a_normalized_w2(caught, tmp_path):
    """fig_ledger.png: the settled probe's W2 in the title is the normalized one, and says so
    (the axis below is in J)."""
    from dem.probes import HISTORY_COLUMNS, plot_probe_ledger
    rows = [{"alpha_sigma": 240.0, "outcome": "equilibrium", "w2": 0.009, "ke_peak": 1e-4,
             "history": _rows(_ledger_history("settled"), HISTORY_COLUMNS)},
            {"alpha_sigma": 195.0, "outcome": "failure", "w2": math.nan, "ke_peak": 3.0,
             "history": _rows(_ledger_history("runaway", seed=1), HISTORY_COLUMNS)}]
    plot_probe_ledger(rows, tmp_path / "fig_ledger.png", "2000 disks, $\\sigma_2$ = 201 kPa")
    fig = caught["fig_ledger.png"]
    _check_ledger(fig)
    titles = [ax.get_title() for ax in fig.axes]
    quoted = [t for t in titles if re.search(r"W2 = [-0-9.]", t)]
    assert quoted and all("normalized W2" in t and "[-]" in t for t in quoted), titles
    assert all("2000 disks" in t for t in titles)


def test_the_cross_checks_eq1_figure(caught, tmp_path):
    """fig_burst_eq1.png of ``dem crosscheck``: the FE's terms beside the DEM's, symlog axes."""
    from crosscheck.burst.figures import burst_eq1_figure
    fe, dm = _ledger_history("settled"), _ledger_history("runaway")
    fe_cols = {"t": fe["t_ledger"], "ke": np.abs(fe["dke"]), "w2_ext": fe["w2_ext"],
               "w2_int": fe["w2_int"], "damping": -fe["w_damp"]}
    for name, cols in (("fem.csv", fe_cols), ("dem.csv", dm)):
        with open(tmp_path / name, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["ratio", "start_fraction", "switch"] + list(cols))
            for k in range(len(dm["t_ledger"])):
                w.writerow([-2, 0.9, "past"] + [v[k] for v in cols.values()])
    assert burst_eq1_figure(str(tmp_path), str(tmp_path / "fem.csv"),
                            str(tmp_path / "dem.csv")) == "fig_burst_eq1.png"
    fig = caught["fig_burst_eq1.png"]
    F.assert_readable(fig)
    for ax in fig.axes:
        assert ax.get_yscale() == "symlog" and len(F.tick_labels(ax.yaxis)) >= 4


# -- Figs. 13-14 of dem biaxial -------------------------------------------------------------------
def _biaxial_rows():
    """biaxial.csv rows (step, time, eps1, eps2, eps_v, s1, s2, p, q) of a curve that rises,
    then holds a noisy plateau, and point A at its knee."""
    e1 = np.linspace(0.0, 0.033, 400)
    q = 310e3 * np.tanh(e1 / 0.0012) + 6e3 * np.sin(e1 * 4000) * (e1 > 0.004)
    ev = 0.0005 * np.sin(np.minimum(e1, 0.002) / 0.002 * np.pi) - 0.7 * np.maximum(e1 - 0.001, 0)
    s2 = np.full_like(e1, 200e3)
    s1 = s2 + q
    rows = [[k, k * 1e-3, a, ev_ - a, ev_, b, c, 0.5 * (b + c), b - c]
            for k, (a, ev_, b, c) in enumerate(zip(e1, ev, s1, s2))]
    k = 40
    a_row = {"eps1": e1[k], "q": q[k], "eps_v": ev[k], "eta": q[k] / (s1[k] + s2[k])}
    return rows, a_row


def test_fig13_and_fig14_name_the_run_and_label_a_off_the_curve(caught, tmp_path):
    from dem.experiment import plot_biaxial
    rows, a_row = _biaxial_rows()
    plot_biaxial(rows, a_row, tmp_path, n=2000, sigma2=200e3, rate=0.01)
    for name in ("fig13_q.png", "fig14_epsv.png"):
        fig = caught[name]
        F.assert_readable(fig)
        (ax,) = fig.axes
        title = ax.get_title()
        assert "2000 disks" in title and "200 kPa" in title and "0.01 /s" in title, title
        (a,) = [t for t in ax.texts if t.get_text() == "A"]
        assert F.texts_over_lines(ax, [a]) == [], name          # "A" beside the curve, not on it


def test_fig13_redrawn_from_a_folder(caught, tmp_path):
    """``redraw_figures``: the figures of a finished folder from its biaxial.csv and summary."""
    import json

    from dem import io
    from dem.experiment import COLUMNS, redraw_figures
    rows, a_row = _biaxial_rows()
    io.write_csv(tmp_path / "biaxial.csv", COLUMNS, [r + [0.0] * (len(COLUMNS) - len(r))
                                                     for r in rows])
    (tmp_path / "summary.json").write_text(json.dumps({"A": a_row, "n": 300, "rate": 0.05,
                                                       "confining": 1e5}))
    redraw_figures(tmp_path)
    assert "300 disks" in caught["fig13_q.png"].axes[0].get_title()
    assert (tmp_path / "fig14_epsv.png").stat().st_size > 10_000


# -- dem calibrate ----------------------------------------------------------------------------------
def _check_calibration_figures(caught, s):
    fig = caught["calibration.png"]
    F.assert_readable(fig)
    left, right = fig.axes
    # each panel's title describes that panel
    assert "dots" in left.get_title() and "dots" not in right.get_title()
    assert "volumetric" in right.get_title() and right.get_ylabel().startswith("eps_v")
    # one colour per seed of the best set, the check seeds dashed as their label says
    colours = {ln.get_label(): ln.get_color() for ln in left.get_lines()}
    fitted = [c for lab, c in colours.items() if "calibrated set, seed" in lab
              and "(fitted on)" in lab]
    n_fit = len(s["options"]["seeds"])
    assert len(fitted) == n_fit and len(set(fitted)) == n_fit
    assert F.line_styles(left, "dashed: not fitted on") == {"--"}
    assert F.line_styles(left, "(fitted on)") == {"-"}
    # the check's verdict, the check seeds' mean, drawn as a diamond of the check's colour
    diamonds = [ln for ln in left.get_lines() if ln.get_marker() == "D" and ln.get_color() == "C0"]
    assert len(diamonds) == (1 if s.get("check_mean") else 0)

    fig = caught["calibration_score.png"]
    F.assert_readable(fig)
    labels = [t.get_text() for t in F.legends(fig)[0].get_texts()]
    # a set that met every target is drawn (not hidden under the best set's star)
    assert ("sets evaluated: all targets met" in labels) == bool(s["met"])
    kn = fig.axes[0]
    assert kn.get_xscale() == "log" and len(F.tick_labels(kn.xaxis)) >= 2

    fig = caught["calibration_search.png"]
    F.assert_readable(fig)
    assert fig.axes[0].get_xscale() == "log" and len(F.tick_labels(fig.axes[0].xaxis)) >= 2


def test_the_calibration_figures(tmp_path, caught):
    from tests.dem.test_calibrate import _run
    s = _run(tmp_path)
    assert s["met"]
    _check_calibration_figures(caught, s)
    # drawn again from the folder's files, without a run: the same checks pass
    from dem.calibrate import redraw_figures
    caught.clear()
    redraw_figures(tmp_path)
    _check_calibration_figures(caught, s)


# -- the gallery's results, drawn again from their files --------------------------------------------
def _copy(src, dst, names):
    dst.mkdir(parents=True, exist_ok=True)
    for n in names:
        shutil.copy(src / n, dst / n)
    return dst


def test_the_gallerys_figures_redrawn_from_their_files(caught, tmp_path):
    """The real results behind the gallery's figures (docs/gallery/calibration/,
    burst/dem/biaxial/, burst/dem/), drawn again as the gallery's were, pass the same checks:
    the calibration's legend off the low-strain curves, the met set visible, several labels on
    kn/D; Fig. 13's A off its noisy curve; the burst ledger's zero."""
    from dem.calibrate import redraw_figures as calibration
    from dem.experiment import redraw_figures as biaxial
    from dem.ledger import redraw_burst_ledger
    d = _copy(GALLERY / "calibration", tmp_path / "cal",
              ["calibration.csv", "curves.csv", "summary.json"])
    calibration(d)
    _check_calibration_figures(caught, json.loads((d / "summary.json").read_text()))
    d = _copy(GALLERY / "burst" / "dem" / "biaxial", tmp_path / "bx",
              ["biaxial.csv", "summary.json"])
    biaxial(d)
    for name in ("fig13_q.png", "fig14_epsv.png"):
        F.assert_readable(caught[name])
        ax = caught[name].axes[0]
        assert F.texts_over_lines(ax, [t for t in ax.texts if t.get_text() == "A"]) == []
    d = _copy(GALLERY / "burst" / "dem", tmp_path / "burst",
              ["history.csv", "burst.csv", "summary.json"])
    redraw_burst_ledger(d)
    _check_ledger(caught["fig_burst_ledger.png"])
