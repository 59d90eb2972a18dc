"""A biaxial run interrupted after a checkpoint and resumed gives the same CSV."""
import pytest

from dem import experiment, io
from dem.params import DemParams


def test_biaxial_resume_equals_uninterrupted(tmp_path, monkeypatch):
    kw = dict(rate=0.5, eps_max=0.004, record_strain=1e-4, checkpoint_every=10,
              verbose=False, figures=False, vtk=False, eta_a=5.0)
    p = DemParams(n=100, seed=3)
    ref = experiment.run_biaxial(p, tmp_path / "a", **kw)

    calls = {"n": 0}
    real = experiment.record

    def flaky(sim):
        calls["n"] += 1
        if calls["n"] == 25:  # after the checkpoint at 20 rows
            raise KeyboardInterrupt
        return real(sim)

    monkeypatch.setattr(experiment, "record", flaky)
    with pytest.raises(KeyboardInterrupt):
        experiment.run_biaxial(p, tmp_path / "b", **kw)
    assert (tmp_path / "b" / "checkpoint.npz").exists()
    monkeypatch.setattr(experiment, "record", real)
    res = experiment.run_biaxial(p, tmp_path / "b", resume=True, **kw)
    _, rows_a = io.read_csv(tmp_path / "a" / "biaxial.csv")
    _, rows_b = io.read_csv(tmp_path / "b" / "biaxial.csv")
    assert len(rows_a) == len(rows_b) == len(ref.rows)
    assert rows_a == rows_b  # bit-identical values (repr round trip)
    assert not (tmp_path / "b" / "checkpoint.npz").exists()
