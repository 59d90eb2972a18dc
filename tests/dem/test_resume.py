"""A biaxial run interrupted after a checkpoint and resumed gives the same CSV."""
import numpy as np
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
    # eta_a = 5 is never reached: the fallback A (first state at 0.97 of the peak eta) and the
    # states along the path come from states kept before the interruption too, and are the
    # uninterrupted run's to the bit
    assert not ref.eta_a_reached and res.state_a_path
    for rel in ["stateA.npz"] + ["states/" + r["file"] for r in
                                 io.read_csv(tmp_path / "a" / "states" / "states.csv")[1]]:
        sa, ma = io.load_state(tmp_path / "a" / rel)
        sb, mb = io.load_state(tmp_path / "b" / rel)
        assert ma == mb and sa.step == sb.step
        assert all(np.array_equal(x, y) for x, y in zip(sa[1:13], sb[1:13]))
    assert ((tmp_path / "a" / "states" / "states.csv").read_bytes()
            == (tmp_path / "b" / "states" / "states.csv").read_bytes())
    assert not (tmp_path / "b" / "candidates").exists()


def test_biaxial_stopped_by_its_stop_function_then_resumed_equals_uninterrupted(tmp_path):
    # the calibration's in-run stop: a run stopped at a row that is no checkpoint's (17, the
    # checkpoints every 10) writes its checkpoint there and returns what ``stop`` said; resumed
    # without ``stop``, it ends on the rows of the run never stopped, bit for bit
    kw = dict(rate=0.5, eps_max=0.004, record_strain=1e-4, checkpoint_every=10,
              verbose=False, figures=False, vtk=False, eta_a=5.0)
    p = DemParams(n=100, seed=3)
    ref = experiment.run_biaxial(p, tmp_path / "a", **kw)
    seen = []

    def stop(rows):
        seen.append(len(rows))
        return {"at": len(rows)} if len(rows) == 17 else None      # rows[0]: the start

    cut = experiment.run_biaxial(p, tmp_path / "b", stop=stop, **kw)
    assert cut.stopped == {"at": 17} and len(cut.rows) == 17 and seen == list(range(2, 18))
    assert cut.rows == ref.rows[:17] and cut.state_a_path is None
    assert (tmp_path / "b" / "checkpoint.npz").exists()
    assert not (tmp_path / "b" / "summary.json").exists()
    _, rows_b = io.read_csv(tmp_path / "b" / "biaxial.csv")
    assert len(rows_b) == 17
    res = experiment.run_biaxial(p, tmp_path / "b", resume=True, **kw)
    assert res.stopped is None and res.rows == ref.rows
    assert res.wall_time >= cut.wall_time          # the stopped part's time counted
    _, rows_a = io.read_csv(tmp_path / "a" / "biaxial.csv")
    _, rows_b = io.read_csv(tmp_path / "b" / "biaxial.csv")
    assert rows_a == rows_b
    assert not (tmp_path / "b" / "checkpoint.npz").exists()
    # a stop function that never stops leaves the run as it is
    never = experiment.run_biaxial(p, tmp_path / "c", stop=lambda rows: None, **kw)
    assert never.stopped is None and never.rows == ref.rows


def test_crosscheck_dem_part_resumes_what_an_interrupted_run_finished(tmp_path, monkeypatch):
    # A cross-check interrupted during its probes: the rerun with resume=True takes the
    # finished biaxial test, the relaxed reference and the probe runs from disk, runs only
    # the missing probe run, and returns the same rows as the uninterrupted run.
    import dem.probes as probes
    import crosscheck
    kw = dict(n=150, seed=2, rate=0.2, alphas=[45.0, 225.0], max_steps=20_000, workers=1,
              eta_a=0.3, threads=1, domain=False)
    ref = crosscheck.dem_part(str(tmp_path), **kw)
    ck = tmp_path / "domain" / ref["comparison"]["state"] / "probe_runs.jsonl"
    lines = ck.read_text().splitlines()
    ck.write_text("\n".join(lines[:-1]) + "\n")       # the last run was lost
    calls = []
    real = probes._task
    monkeypatch.setattr(probes, "_task", lambda t: calls.append(t[1:3]) or real(t))
    monkeypatch.setattr(experiment, "run_biaxial", lambda *a, **k: pytest.fail("biaxial rerun"))
    res = crosscheck.dem_part(str(tmp_path), resume=True, **kw)
    assert calls == [(225.0, True)]          # sliding runs come last (after their elastic ones)
    assert res["probes"] == ref["probes"]
    assert res["comparison"] == ref["comparison"]
    assert res["eta_a_reached"] == ref["eta_a_reached"]
    assert len(res["biaxial_rows"]) == len(ref["biaxial_rows"])
    assert all(a == b for ra, rb in zip(res["biaxial_rows"], ref["biaxial_rows"]) for a, b in zip(ra, rb))
