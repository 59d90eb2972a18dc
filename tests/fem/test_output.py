"""Outputs: curve.csv, fields.xdmf (+ .h5) read back with meshio, figure, summary."""
import json

import meshio
import numpy as np

from fem.output import CURVE_COLUMNS, MODE_FIELDS, read_curve


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
