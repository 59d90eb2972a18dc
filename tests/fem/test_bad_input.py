"""python -m fem biaxial: bad input is one line ``error: ...`` naming the option, exit code 2,
before anything is computed or written; outputs get the ordinary file mode; SIGTERM is one line
and exit 143 with the converged steps on disk (issue 10, sections 2-4)."""
import os

import meshio
import numpy as np
import pytest

import fem.__main__ as fcli
from fem.biaxial import BiaxialConfig, run_biaxial
from fem.output import plot_curve, read_curve
from common.io import file_mode
from tests._interrupt import interrupt_after


@pytest.fixture(scope="module")
def bad_mesh_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("meshes")
    (d / "text.vtk").write_text("hello\n")
    (d / "empty.vtk").write_bytes(b"")
    meshio.write(d / "nocells.vtk", meshio.Mesh(np.zeros((3, 3)), []))
    meshio.write(d / "lines.vtk", meshio.Mesh(np.array([[0, 0, 0], [1, 0, 0.0]]), [("line", np.array([[0, 1]]))]))
    return d


@pytest.mark.parametrize("argv,needles", [
    (["--nx", "100000", "--ny", "100000"], ["--nx / --ny", "GB of memory"]),
    (["--n-sphere", "0"], ["--n-sphere", ">= 1"]),
    (["--n-sphere", "-5"], ["--n-sphere", ">= 1"]),
    (["--imperfection", "band", "--imp-angle", "nan"], ["--imp-angle", "finite"]),
    (["--imperfection", "band", "--imp-size", "1e9"], ["--imp-size", "0 < value <= 1"]),
    (["--imperfection", "spot", "--imp-phi-g", "95"], ["--imp-phi-g", "0 < phi_g < 90"]),
    (["--imperfection", "spot", "--imp-phi-g", "nan"], ["--imp-phi-g", "finite"]),
    (["--sigma2", "0"], ["--sigma2", "> 0"]),
    (["--phi-g", "95"], ["--phi-g", "0 < phi_g < 90"]),
    (["--n-dir", "4"], ["--n-dir", ">= 8"]),
    (["--nx", "2.5"], ["--nx", "integer"]),
    (["--eps1-max", "0.7"], ["--eps1-max", "0 < value < 0.5"]),
    (["--d-eps1", "0"], ["--d-eps1"]),
    (["--rtol", "nan"], ["--rtol"]),
    (["--max-iter", "0"], ["--max-iter"]),
    (["--mesh-file", "MISSING.vtk"], ["--mesh-file", "no such file"]),
    (["--mesh-file", "MESHES/text.vtk"], ["--mesh-file", "not a mesh meshio can read"]),
    (["--mesh-file", "MESHES/empty.vtk"], ["--mesh-file", "not a mesh meshio can read"]),
    (["--mesh-file", "MESHES/nocells.vtk"], ["--mesh-file"]),
    (["--mesh-file", "MESHES/lines.vtk"], ["--mesh-file", "'quad' or 'triangle'"]),
])
def test_bad_option_is_one_line_before_any_computation(tmp_path, capsys, no_computation, bad_mesh_files,
                                                        argv, needles):
    out = tmp_path / "out"
    argv = [a.replace("MESHES", str(bad_mesh_files)).replace("MISSING", str(tmp_path / "missing"))
            for a in argv]
    assert fcli.main(["biaxial"] + argv + ["--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "\n" not in err and "Traceback" not in err, err
    assert "HParams" not in err, err
    for n in needles:
        assert n in err, (n, err)
    assert not out.exists()


def test_unusable_out_refused_before_any_computation(tmp_path, capsys, no_computation):
    f = tmp_path / "a_file"
    f.write_text("keep me")
    for out in (f, f / "sub", "/proc/granular_w2_test/out"):
        assert fcli.main(["biaxial", "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("error: --out") and "\n" not in err, err
    assert f.read_text() == "keep me"


@pytest.mark.parametrize("n", [0, -5])
def test_run_biaxial_refuses_n_sphere(tmp_path, n):
    with pytest.raises(ValueError, match="n_sphere"):
        run_biaxial(BiaxialConfig(nx=1, ny=2, n_dir=16, n_sphere=n), tmp_path)
    assert not os.listdir(tmp_path)


def test_outputs_have_the_ordinary_file_mode(homogeneous_run):
    for f in ("curve.csv", "fields.xdmf", "fields.h5", "curve.png", "summary.json", "newton.log"):
        assert (homogeneous_run.out_dir / f).stat().st_mode & 0o777 == file_mode(), f


def test_curve_png_marks_every_criterion(monkeypatch, tmp_path, homogeneous_run):
    """Local W2 and Rice marked beside the global criteria, sigma2 in the title, one marker size
    per criterion (those firing at the same step stay visible)."""
    import matplotlib.pyplot as plt
    figs = []
    monkeypatch.setattr(plt, "close", lambda fig=None: figs.append(fig))
    c = dict(homogeneous_run.curve)
    plot_curve(tmp_path / "c.png", c, title="test")
    ax = figs[-1].axes[0]
    labels = ax.get_legend_handles_labels()[1]
    assert any("local $W_2" in s for s in labels) and any("Rice" in s for s in labels)
    assert "sigma_2$ = 200 kPa" in ax.get_title()
    sizes = [line.get_markersize() for line in ax.lines if line.get_label().startswith("first")
             and len(line.get_xdata())]
    assert len(sizes) >= 3 and len(set(sizes)) == len(sizes)


def test_sigterm_is_one_line_and_exit_143(tmp_path):
    out = tmp_path / "run"
    rc, lines = interrupt_after(["fem", "biaxial", "--nx", "1", "--ny", "2", "--n-dir", "16",
                                 "--eps1-max", "0.4", "--d-eps1", "1e-5", "--n-sphere", "20",
                                 "--out", str(out)], "step    2")
    assert rc == 143
    assert len(lines) == 1 and lines[0].startswith("interrupted (SIGTERM) during load step"), lines
    c = read_curve(out / "curve.csv")                     # whole rows only, readable
    assert len(c["step"]) >= 3 and np.array_equal(c["step"], np.arange(len(c["step"])))
    k = int(c["step"][-1])                                # the line names the file's last row
    assert f"during load step {k + 1}, after step {k} (eps1 = " in lines[0], lines
    with meshio.xdmf.TimeSeriesReader(out / "fields.xdmf") as r:
        r.read_points_cells()
        assert r.num_steps >= 3
