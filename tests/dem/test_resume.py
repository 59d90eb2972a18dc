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


def test_crosscheck_dem_part_resumes_what_an_interrupted_run_finished(tmp_path, monkeypatch):
    # A cross-check interrupted during its probes: the rerun with resume=True takes the
    # finished biaxial test, the relaxed reference and the probe runs from disk, runs only
    # the missing probe run, and returns the same rows as the uninterrupted run.
    import dem.probes as probes
    from dem import crosscheck
    kw = dict(n=150, seed=2, rate=0.2, alphas=[45.0, 225.0], max_steps=20_000, workers=1,
              eta_a=0.3, threads=1)
    ref = crosscheck.dem_part(str(tmp_path), **kw)
    ck = tmp_path / "probes" / "probe_runs.jsonl"
    lines = ck.read_text().splitlines()
    ck.write_text("\n".join(lines[:-1]) + "\n")       # the last run was lost
    calls = []
    real = probes._task
    monkeypatch.setattr(probes, "_task", lambda t: calls.append(t[1:3]) or real(t))
    monkeypatch.setattr(experiment, "run_biaxial", lambda *a, **k: pytest.fail("biaxial rerun"))
    res = crosscheck.dem_part(str(tmp_path), resume=True, **kw)
    assert calls == [(225.0, False)]
    assert res["probes"] == ref["probes"]
    assert res["eta_a_reached"] == ref["eta_a_reached"]
    assert len(res["biaxial_rows"]) == len(ref["biaxial_rows"])
    assert all(a == b for ra, rb in zip(res["biaxial_rows"], ref["biaxial_rows"]) for a, b in zip(ra, rb))
