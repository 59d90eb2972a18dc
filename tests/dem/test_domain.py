"""`dem domain` end to end on a small sample: three states along the drained path, a reduced
set of directions; CSV columns, figures, resume bit-identical, a two-worker dask cluster."""
import csv
import json
import math

import pytest

from dem.domain import DOMAIN_COLUMNS
from dem.probes import COLUMNS as PROBE_COLUMNS

ALPHAS = ["0", "180", "240"]


@pytest.fixture(scope="module")
def biaxial_dir(tmp_path_factory):
    from dem.__main__ import main
    out = tmp_path_factory.mktemp("bx")
    main(["biaxial", "--n", "300", "--seed", "1", "--rate", "0.05", "--eps1-max", "0.02",
          "--out", str(out), "--no-vtk", "--save-fractions", "0.8,0.9,0.97"])
    return out


def _domain(biaxial_dir, out, *extra):
    from dem.__main__ import main
    main(["domain", "--biaxial", str(biaxial_dir), "--out", str(out), "--directions",
          ",".join(ALPHAS), "--workers", "1", "--no-hmodel", *extra])


def _read(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def test_states_along_the_path_are_listed(biaxial_dir):
    rows = _read(biaxial_dir / "states" / "states.csv")
    assert [r["target"] for r in rows] == ["f=0.8", "f=0.9", "f=0.97"]
    with open(biaxial_dir / "summary.json") as f:
        peak = json.load(f)["eta_max"]
    for r, f in zip(rows, (0.8, 0.9, 0.97)):
        # the first recorded state at or above the target: within one CSV row of it
        assert f * peak <= float(r["eta"]) < f * peak + 0.05
        assert (biaxial_dir / "states" / r["file"]).exists()
    assert not (biaxial_dir / "candidates").exists()


def test_domain_end_to_end_resume_and_dask(biaxial_dir, tmp_path, monkeypatch):
    out = tmp_path / "dom"
    _domain(biaxial_dir, out)
    rows = _read(out / "domain.csv")
    assert list(rows[0].keys()) == DOMAIN_COLUMNS
    assert len(rows) == 3
    etas = [float(r["eta"]) for r in rows]
    assert etas == sorted(etas)
    for r in rows:
        n = int(r["n_equilibrium"]) + int(r["n_failure"]) + int(r["n_undecided"])
        assert r["reference"] != "equilibrium" or n == 3
        assert 0.7 < float(r["eta_fraction"]) < 1.1
    probes = _read(out / "domain_probes.csv")
    assert list(probes[0].keys()) == ["state", "state_eta"] + PROBE_COLUMNS
    assert {p["outcome"] for p in probes} <= {"equilibrium", "failure", "undecided"}
    for name in ("fig_domain.png", "fig_domain_w2.png", "boundaries.json"):
        assert (out / name).stat().st_size > 0
    b = json.loads((out / "boundaries.json").read_text())
    assert b["eta_peak"] > 0 and "eta_lim_low" in b
    first = (out / "domain.csv").read_bytes()
    first_probes = (out / "domain_probes.csv").read_bytes()

    # resume: the last run of one state was lost; only that run is done again
    import dem.probes as probes_mod
    ck = out / "state_f0.900" / "probe_runs.jsonl"
    lines = ck.read_text().splitlines()
    ck.write_text("\n".join(lines[:-1]) + "\n")
    calls = []
    real = probes_mod._task
    monkeypatch.setattr(probes_mod, "_task", lambda t: calls.append(t[1:3]) or real(t))
    _domain(biaxial_dir, out, "--resume")
    assert len(calls) == 1
    assert (out / "domain.csv").read_bytes() == first
    assert (out / "domain_probes.csv").read_bytes() == first_probes
    monkeypatch.setattr(probes_mod, "_task", real)

    # a resume against other states is refused (the references belong to their states)
    from dem import io
    st, meta = io.load_state(out / "state_f0.900" / "stateR.npz")
    io.save_state(out / "state_f0.900" / "stateR.npz", st, meta=dict(meta, origin="other"))
    with pytest.raises(SystemExit) as e:
        _domain(biaxial_dir, out, "--resume")
    assert e.value.code == 2

    # the same rows on a two-worker dask cluster
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        out2 = tmp_path / "dask"
        from dem.__main__ import main
        main(["domain", "--biaxial", str(biaxial_dir), "--out", str(out2), "--directions",
              ",".join(ALPHAS), "--scheduler", cluster.scheduler_address, "--no-hmodel"])
    assert (out2 / "domain.csv").read_bytes() == first
    assert (out2 / "domain_probes.csv").read_bytes() == first_probes


def _row(state, eta, n_failure=0, min_w2=0.5, held=math.nan, failed=math.nan):
    return {"state": state, "eta": eta, "reference": "equilibrium", "probed": True,
            "n_failure": n_failure, "min_w2": min_w2, "eta_target_max_held": held,
            "eta_target_min_failed": failed}


def test_boundaries_and_an_eta_lim_that_depends_on_the_direction():
    from dem.domain import boundaries, eta_lim_text
    rows = [_row("a", 0.80, held=0.81), _row("b", 0.84, min_w2=0.04, held=0.851),
            _row("c", 0.86, n_failure=3, min_w2=0.01, held=0.8713, failed=0.8639)]
    b = boundaries(rows, 0.8844)
    assert b["lower_state"] == "c" and b["lower_why"] == "failure"
    assert b["last_stable_eta"] == 0.84
    assert math.isclose(b["lower_eta_fraction"], 0.86 / 0.8844)
    # the 2000-disk quick run: a target held (0.8713) above one that failed (0.8639): there is
    # no single limit, and the text says so instead of printing an inverted bracket
    assert not b["eta_lim_bracket_consistent"]
    assert "no single eta_lim" in eta_lim_text(b) and "0.8713" in eta_lim_text(b)
    b2 = boundaries(rows[:2] + [_row("c", 0.86, n_failure=3, held=0.86, failed=0.8639)], 0.8844)
    assert b2["eta_lim_bracket_consistent"]
    assert eta_lim_text(b2).startswith("eta_lim in [0.8600, 0.8639]")


def test_a_held_reference_counts_as_a_target_held_even_unprobed():
    # the full cross-check probes one state only: a state above it whose reference held at
    # constant stress still bounds eta_lim from below (the full run: f0.97 held at 0.8966 while
    # a probe target of 0.8942 from f0.95 ran away: no single eta_lim)
    from types import SimpleNamespace
    from dem.domain import boundaries, eta_lim_text, state_row
    st = lambda s1, s2: SimpleNamespace(control=SimpleNamespace(s_to=(s2, s1)))
    held = state_row("hi", {"eps1": "0.0027"}, 0.9233, "equilibrium", [], st(529000.0, 200000.0))
    assert held["probed"] is False and held["eta_target_max_held"] == held["eta"]
    failed = state_row("top", {"eps1": "0.0088"}, 0.9233, "failure", [], st(550000.0, 200000.0))
    assert failed["eta_target_min_failed"] == failed["eta"]
    assert math.isnan(failed["eta_target_max_held"])
    probed = _row("lo", 0.8836, n_failure=1, min_w2=0.099, held=0.8941, failed=0.8942)
    b = boundaries([probed, held, failed], 0.9233)
    assert b["eta_lim_low"] == held["eta"] and b["eta_lim_high"] == 0.8942
    assert not b["eta_lim_bracket_consistent"] and "no single eta_lim" in eta_lim_text(b)


def test_makespan_hands_each_run_to_the_first_free_worker():
    from dem.domain import makespan
    assert makespan([3, 1, 1, 1], 2) == 3          # 3 | 1 + 1 + 1
    assert makespan([1, 1, 1, 3], 2) == 4          # 1 + 1 | 1 + 3: the order matters
    assert makespan([2, 2, 2], 1) == 6 and makespan([2, 2, 2], 5) == 2 and makespan([], 3) == 0
    with pytest.raises(ValueError, match="workers"):
        makespan([1.0], 0)


def test_stage_steps_and_the_cluster_estimate(tmp_path, capsys):
    # a finished cross-check folder in miniature: two states, one probed (two directions)
    import importlib.util
    from dem.domain import stage_steps
    d = tmp_path / "xc" / "dem" / "domain"
    for name, first, last in (("state_f0.900", 100, 5100), ("state_f1.000", 200, 1200)):
        (d / name).mkdir(parents=True)
        (d / name / "reference_history.csv").write_text(
            f"step,kinetic_energy\n{first},1e-3\n{last},1e-9\n")
    (d / "state_f0.900" / "probes.csv").write_text(
        "alpha_sigma,steps,steps_elastic\n0,3000,1000\n180,9000,1000\n")
    assert stage_steps(d) == ([5000.0, 1000.0], [1000.0, 1000.0], [3000.0, 9000.0])
    (tmp_path / "xc" / "conclusions.json").write_text(json.dumps({"timings": {
        "FE specimen": 2.0, "DEM (2 disks)": 99.0, "  DEM compaction + biaxial test": 60.0,
        "  DEM relaxations and probes (this run)": 15.0}}))
    from pathlib import Path
    script = Path(__file__).resolve().parents[2] / "bench" / "cluster_estimate.py"
    spec = importlib.util.spec_from_file_location("cluster_estimate", script)
    m = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(m)
    m.main([str(tmp_path / "xc"), "--workers", "1,2", "--measured-workers", "1"])
    out = capsys.readouterr().out
    # one worker: 6000 + 2000 + 12000 steps in 15 s -> 1333 steps/s; two: 5000 + 1000 + 9000
    assert "1333 steps/s a worker" in out
    two = [line for line in out.splitlines() if line.split()[:1] == ["2"]][0].split()
    assert float(two[4]) == pytest.approx(15000 / (20000 / 15) / 60, abs=0.05)
    assert float(two[5]) == pytest.approx(float(two[4]) + 62 / 60, abs=0.05)


def test_the_cluster_estimate_replays_a_burst():
    # a staircase in miniature (steps): the start relaxed (10), a hold that settles (10), one
    # that fails (10: the past run); the loaded peak relaxed beside it (5); the below run (6)
    # and a baseline (3) when the staircase ends; a probe (4) of every equilibrium
    import importlib.util
    from pathlib import Path
    script = Path(__file__).resolve().parents[2] / "bench" / "cluster_estimate.py"
    spec = importlib.util.spec_from_file_location("cluster_estimate", script)
    m = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(m)
    run = {"path": 7, "chain": [("relax_start", 10), ("h0", 10), ("h1", 10)], "peak": 5,
           "holds": {0: ("stair", "equilibrium", 10), 1: ("stair", "failure", 10),
                     2: ("below", "equilibrium", 6), 3: ("baseline_past", "equilibrium", 3)},
           "probes": {k: 4 for k in ("relaxed_start", "relaxed_peak", "h0_end", "h2_end",
                                     "h3_end")}}
    assert m.replay_pool([run], None, 1) == 7 + 30 + 5 + 9 + 20
    # two workers: the path, then the chain on one (7-37), beside it the peak's relaxation
    # (7-12) and the probes as their states come (12-16, 17-21, 27-31); then the below run and
    # the baseline (37-43, 37-40) and the probes of their ends (40-44, 43-47)
    assert m.replay_pool([run], None, 2) == 47
    assert m.replay_pool([run], None, 8) == 47
    # with the cross-check's domain on the same pool (two relaxations of 6, then two elastic
    # runs of 4, then two sliding runs of 5): one after the other 15 + 47 steps on two workers;
    # on one pool the domain's runs take the worker the chain leaves: 51 (worked by hand, the
    # runs as dem.pool hands them out: the domain's first asked, the runs that start others
    # first, then first asked, first run)
    waves = ([6, 6], [4, 4], [5, 5])
    assert m.replay_pool([run], waves, 1) == 71 + 30
    assert sum(m.makespan(w, 2) for w in waves) == 15
    assert m.replay_pool([run], waves, 2) == 51
