"""Outputs: curve.csv, fields.xdmf (+ .h5) read back with meshio, figure, summary."""
import json

import meshio
import numpy as np
import pytest

from fem.output import CURVE_COLUMNS, MODE_FIELDS, read_curve
from tests._interrupt import HANG_S


def test_csv(homogeneous_run):
    out = homogeneous_run.out_dir
    c = read_curve(out / "curve.csv")
    with open(out / "curve.csv") as f:
        header = f.readline().strip().split(",")
    assert header == CURVE_COLUMNS
    n = len(c["step"])
    assert n == 61 and np.array_equal(c["step"], np.arange(n))
    assert c["eps1"][-1] == np.float64(0.03) or abs(c["eps1"][-1] - 0.03) < 1e-12
    assert np.allclose(c["q"], c["s1"] - c["s2"]) and np.allclose(c["p"], 0.5 * (c["s1"] + c["s2"]))
    assert np.allclose(c["eta"][1:], c["q"][1:] / c["p"][1:])
    assert set(np.unique(c["det_k_sign"])) <= {-1, 0, 1}
    assert np.all(c["newton_iters"][1:] >= 1)


def test_xdmf_reads_back_every_step(homogeneous_run):
    out = homogeneous_run.out_dir
    prob = homogeneous_run.problem
    n = len(homogeneous_run.curve["step"])
    with meshio.xdmf.TimeSeriesReader(out / "fields.xdmf") as r:
        points, cells = r.read_points_cells()
        assert r.num_steps == n
        assert points.shape[0] == prob.mesh.p.shape[1]
        assert cells[0].type == "quad" and cells[0].data.shape == (prob.nel, 4)
        times = []
        for k in range(r.num_steps):
            t, pd, cd = r.read_data(k)
            times.append(t)
            assert pd["displacement"].shape == (points.shape[0], 3)
            for name in MODE_FIELDS:                  # the same point fields at every step
                assert pd[name].shape == (points.shape[0], 3)
            for name in ("stress_tension_positive", "strain_tension_positive"):
                assert cd[name][0].shape == (prob.nel, 9)     # 3 x 3 tensors, row by row
            assert "stress" not in cd and "strain" not in cd  # no field without its sign convention
            for name in ("det_D", "det_Ds", "lam_min_Ds", "w2_min", "rice_min",
                         "sliding_fraction", "open_fraction", "q", "p"):
                assert cd[name][0].shape == (prob.nel,)
        assert np.allclose(times, homogeneous_run.curve["eps1"])
        # last step: top nodes moved down by eps1 * H, homogeneous axial stress = -s1 (tension +)
        t, pd, cd = r.read_data(n - 1)
        top = np.isclose(points[:, 1], prob.height)
        assert np.allclose(pd["displacement"][top, 1], -0.03 * prob.height, rtol=1e-10)
        sig = cd["stress_tension_positive"][0].reshape(-1, 3, 3)
        eps = cd["strain_tension_positive"][0].reshape(-1, 3, 3)
        # tension positive: the compressed axis is negative, -s1 and -eps1; p, q compression +
        assert np.allclose(sig[:, 1, 1], -homogeneous_run.curve["s1"][-1], rtol=1e-8)
        assert np.allclose(sig[:, 0, 0], -200e3, rtol=1e-8)
        assert np.allclose(eps[:, 1, 1], -0.03, rtol=1e-10)
        assert np.allclose(cd["p"][0], -0.5 * (sig[:, 0, 0] + sig[:, 1, 1]), rtol=1e-12)
        assert np.allclose(cd["q"][0], sig[:, 0, 0] - sig[:, 1, 1], rtol=1e-12)
        assert np.all(sig[:, 2, :] == 0) and np.all(sig[:, :, 2] == 0)          # plane, 2-D model
        assert np.allclose(sig, np.swapaxes(sig, 1, 2)) and np.allclose(eps, np.swapaxes(eps, 1, 2))
        assert np.all((cd["sliding_fraction"][0] >= 0) & (cd["sliding_fraction"][0] <= 1))


def test_figure_and_summary(homogeneous_run):
    out = homogeneous_run.out_dir
    png = (out / "curve.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000
    s = json.loads((out / "summary.json").read_text())
    assert s["completed"] is True
    ev = s["events"]
    assert ev["det_k_f"]["row"] is not None
    assert abs(ev["det_k_f"]["eps1"] - s["material_point"]["eps1_peak"]) <= 1e-3
    # the newton log has one line per step with its residual history
    lines = [l for l in (out / "newton.log").read_text().splitlines() if l[:1].isdigit()]
    assert len(lines) == 60


def _fields(n_nodes=6, n_cells=2, k=0):
    pd = {"displacement": np.full((n_nodes, 3), float(k))}
    cd = {"q": [np.arange(n_cells, dtype=float) + k]}
    return pd, cd


def _mesh():
    pts = np.array([[0, 0], [1, 0], [2, 0], [0, 1], [1, 1], [2, 1]], dtype=float)
    return pts, [("quad", np.array([[0, 1, 4, 3], [1, 2, 5, 4]]))]


def _steps(path):
    with meshio.xdmf.TimeSeriesReader(path) as r:
        r.read_points_cells()
        return [r.read_data(k) for k in range(r.num_steps)]


def test_xdmf_rewrite_throttled_and_complete_at_close(tmp_path):
    """Between rewrites the XML on disk is the last one written (readable, fewer steps) while
    fields.h5 holds every step; ``close`` rewrites it with every step; xml_every = 0 rewrites
    after every step."""
    from fem.output import FieldWriter
    pts, cells = _mesh()
    w = FieldWriter(tmp_path / "f.xdmf", pts, cells, xml_every=1e9)
    for k in range(3):
        w.write(0.1 * k, *_fields(k=k))
        assert _steps(tmp_path / "f.xdmf") == []          # not rewritten yet, still readable
    import h5py
    with h5py.File(tmp_path / "f.h5", "r") as h:           # flushed after every step
        assert len(h.keys()) == 2 + 3 * 2
    w.close()
    st = _steps(tmp_path / "f.xdmf")
    assert [t for t, _, _ in st] == [0.0, 0.1, 0.2]
    assert all(np.array_equal(pd["displacement"], _fields(k=k)[0]["displacement"])
               for k, (_, pd, _) in enumerate(st))
    w = FieldWriter(tmp_path / "g.xdmf", pts, cells, xml_every=0.0)
    for k in range(3):
        w.write(0.1 * k, *_fields(k=k))
        assert len(_steps(tmp_path / "g.xdmf")) == k + 1
    w.close()


def test_killed_writer_leaves_a_readable_pair(tmp_path):
    """A process killed outright (SIGKILL: no close, no finally) between two XML rewrites: the
    pair is readable and holds the steps of the last rewrite, with their data."""
    import subprocess
    import sys
    script = f"""
import os, signal, sys
import numpy as np
sys.path.insert(0, {str(__import__('pathlib').Path(__file__).parents[2])!r})
from tests.fem.test_output import _fields, _mesh
from fem.output import FieldWriter
w = FieldWriter({str(tmp_path / 'f.xdmf')!r}, *_mesh(), xml_every=0.0)
for k in range(2):
    w.write(0.1 * k, *_fields(k=k))
w.xml_every = 1e9
for k in range(2, 5):
    w.write(0.1 * k, *_fields(k=k))
os.kill(os.getpid(), signal.SIGKILL)
"""
    p = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=HANG_S)
    assert p.returncode == -9, p.stderr
    st = _steps(tmp_path / "f.xdmf")
    assert [t for t, _, _ in st] == [0.0, 0.1]
    for k, (_, pd, cd) in enumerate(st):
        assert np.array_equal(pd["displacement"], _fields(k=k)[0]["displacement"])
        assert np.array_equal(cd["q"][0], _fields(k=k)[1]["q"][0])


@pytest.mark.parametrize("rows", [1, 4])
def test_interrupted_run_lists_every_converged_step(tmp_path, monkeypatch, rows):
    """Ctrl-C (KeyboardInterrupt) after row 0 or in the middle of a run whose XML would not be
    rewritten before the end: run_biaxial's ``finally`` closes the writer, so fields.xdmf lists
    every row of curve.csv, readable. A row is written while the next step is checked, and its
    progress line comes after that: the interrupt at the line of row k finds row k + 1 complete
    (its global check returned), and it is written too."""
    from fem.biaxial import BiaxialConfig, run_biaxial
    from fem.output import FieldWriter
    monkeypatch.setattr(FieldWriter, "XML_EVERY", 1e9)
    seen = []

    def progress(line):
        if line.startswith("step "):
            seen.append(line)
            if len(seen) == rows:
                raise KeyboardInterrupt
    cfg = BiaxialConfig(nx=1, ny=2, n_dir=16, eps1_max=0.01, d_eps1=1e-3, n_sphere=20,
                        mp_reference=False)
    with pytest.raises(KeyboardInterrupt):
        run_biaxial(cfg, tmp_path, progress=progress)
    c = read_curve(tmp_path / "curve.csv")
    st = _steps(tmp_path / "fields.xdmf")
    assert len(c["step"]) == rows + 1 and len(st) == rows + 1
    assert np.array_equal(c["step"], np.arange(rows + 1))
    assert np.array_equal([t for t, _, _ in st], c["eps1"])


def test_criteria_table_is_aligned(homogeneous_run):
    """Every number of the criteria table starts in the same column, whatever the label's
    length (the force-controlled det K row was one column off)."""
    from fem.biaxial import format_summary
    lines = format_summary(homogeneous_run.summary).splitlines()
    header, rows = lines[0], [line for line in lines[1:] if "not reached" not in line]
    col = header.index("eps1 [%]") + len("eps1 [%]")           # the eps1 column's right edge
    assert len(rows) >= 5
    for line in rows:
        eps1 = line[:col].split()[-1]
        float(eps1)
        assert line[col] == " " and line[col - len(eps1) - 1] == " ", line


def test_mode_figure_says_perfect_and_scales_the_arrows(homogeneous_run, monkeypatch, tmp_path):
    """mode_ks.png of a perfect specimen says so (no 'red: imperfection'), and its arrows
    have a colour scale."""
    import matplotlib.pyplot as plt
    from fem.output import plot_mode
    figs = []
    monkeypatch.setattr(plt, "close", lambda fig=None: figs.append(fig))
    prob = homogeneous_run.problem
    u = np.random.default_rng(0).standard_normal(prob.ndofs)
    plot_mode(tmp_path / "m.png", prob, u, title="t")
    fig = figs[-1]
    titles = [ax.get_title() for ax in fig.axes]
    assert any("perfect specimen" in t for t in titles)
    assert not any("imperfection" in t for t in titles)
    bars = [ax.get_ylabel() for ax in fig.axes]
    assert any("|u| / max" in b for b in bars) and any("|eps| / max" in b for b in bars)
