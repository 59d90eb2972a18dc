"""Bad input gives a clear error naming the parameter and its allowed range; a run that fails
leaves its converged steps on disk, complete and readable."""
import meshio
import numpy as np
import pytest

from fem.adapter import MaterialField
from fem.biaxial import BiaxialConfig, run_biaxial
from fem.mesh import rectangle, from_meshio
from fem.output import read_curve


@pytest.mark.parametrize("kw,name", [
    (dict(width=0.0), "width"), (dict(height=-1.0), "height"), (dict(nx=0), "nx"),
    (dict(ny=2.5), "ny"), (dict(kind="hex"), "kind"), (dict(width=float("nan")), "width")])
def test_bad_mesh_sizes(kw, name):
    with pytest.raises(ValueError, match=name) as e:
        rectangle(**kw)
    assert "allowed" in str(e.value)


def test_inverted_elements_rejected():
    pts = np.array([[0, 0], [1, 0], [2, 0], [0, 1], [1, 1], [2, 1]], dtype=float)
    good = np.array([[0, 1, 4, 3], [1, 2, 5, 4]])
    from_meshio(meshio.Mesh(pts, [("quad", good)]))                        # fine
    flipped = np.array([[0, 1, 4, 3], [1, 4, 5, 2]])                        # second one clockwise
    with pytest.raises(ValueError, match="inverted"):
        from_meshio(meshio.Mesh(pts, [("quad", flipped)]))
    bowtie = np.array([[0, 1, 4, 3], [1, 2, 4, 5]])                         # self-intersecting
    with pytest.raises(ValueError, match="inverted"):
        from_meshio(meshio.Mesh(pts, [("quad", bowtie)]))
    tri = np.array([[0, 1, 4], [0, 4, 3], [1, 4, 5]])                       # last one clockwise
    with pytest.raises(ValueError, match="inverted"):
        from_meshio(meshio.Mesh(pts, [("triangle", tri)]))


def test_mesh_file_roundtrip(tmp_path, params36):
    m = rectangle(0.05, 0.1, 2, 4)
    path = tmp_path / "spec.vtk"
    meshio.write(path, meshio.Mesh(m.p.T, [("quad", m.t.T)]))
    cfg = BiaxialConfig(mesh_file=str(path), n_dir=36, eps1_max=1e-3, d_eps1=5e-4, fields=False,
                        mp_reference=False)
    r = run_biaxial(cfg)
    assert len(r.curve["step"]) == 3 and r.problem.nel == 8


@pytest.mark.parametrize("kw,name", [
    (dict(d_eps1=-1e-4), "d_eps1"), (dict(d_eps1=0.2), "d_eps1"), (dict(eps1_max=0.0), "eps1_max"),
    (dict(n_dir=4), "n_dir"), (dict(phi_g=95.0), "phi_g"), (dict(kn=-1.0), "kn"),
    (dict(sigma2=0.0), "p0"), (dict(rtol=2.0), "rtol"), (dict(max_cutbacks=-1), "max_cutbacks"),
    (dict(imperfection="ring"), "kind"), (dict(imperfection="spot", imp_size=0.0), "size")])
def test_bad_run_options(tmp_path, kw, name):
    cfg = BiaxialConfig(**dict(dict(nx=1, ny=2, n_dir=16, eps1_max=1e-3, fields=False,
                                    mp_reference=False), **kw))
    with pytest.raises(ValueError, match=name) as e:
        run_biaxial(cfg, tmp_path)
    assert "allowed" in str(e.value)


def test_unconvergeable_step_keeps_converged_steps(tmp_path, monkeypatch):
    """The material starts failing (non-finite update) after 4 steps: every cut-back fails, the run
    raises RuntimeError naming the step and the remedies, and the 4 steps are on disk."""
    calls = {"n": 0, "armed": False}
    orig = MaterialField.trial

    def flaky(self, d_eps_fe):
        tr = orig(self, d_eps_fe)
        if calls.get("armed"):
            tr.sigma[...] = np.nan
        return tr

    orig_commit = MaterialField.commit

    def commit(self, trial):
        orig_commit(self, trial)
        calls["n"] += 1
        if calls["n"] == 4:
            calls["armed"] = True

    monkeypatch.setattr(MaterialField, "trial", flaky)
    monkeypatch.setattr(MaterialField, "commit", commit)
    cfg = BiaxialConfig(nx=2, ny=4, n_dir=16, eps1_max=0.01, d_eps1=5e-4, max_cutbacks=3,
                        mp_reference=False)
    with pytest.raises(RuntimeError, match=r"load step 5 .* did not converge even after 3 cut-backs") as e:
        run_biaxial(cfg, tmp_path)
    assert "d_eps1" in str(e.value) and "allowed" in str(e.value).lower()
    c = read_curve(tmp_path / "curve.csv")
    assert np.array_equal(c["step"], np.arange(5))              # row 0 + 4 converged steps
    assert np.allclose(c["eps1"], 5e-4 * np.arange(5))
    with meshio.xdmf.TimeSeriesReader(tmp_path / "fields.xdmf") as r:
        r.read_points_cells()
        assert r.num_steps == 5
        t, pd, cd = r.read_data(4)
        assert t == pytest.approx(2e-3)
    assert (tmp_path / "curve.png").exists()
    log = (tmp_path / "newton.log").read_text()
    assert log.count("failed") == 4 and "FAILED" in log


def test_real_nonconvergence_with_tiny_iteration_budget(tmp_path):
    """Without any injection: one Newton iteration allowed and no cut-back, a tolerance the
    first iterate cannot meet: RuntimeError, nothing but row 0 on disk."""
    cfg = BiaxialConfig(nx=2, ny=4, n_dir=16, eps1_max=0.01, d_eps1=1e-3, max_iter=1,
                        max_cutbacks=0, rtol=1e-15, mp_reference=False)
    with pytest.raises(RuntimeError, match="did not converge"):
        run_biaxial(cfg, tmp_path)
    c = read_curve(tmp_path / "curve.csv")
    assert np.array_equal(c["step"], [0])
