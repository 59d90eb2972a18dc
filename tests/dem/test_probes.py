"""Second-order work bookkeeping and the CLI end to end on a tiny sample."""
import csv
import math

import numpy as np
import pytest

from dem.probes import ProbeOptions, directions, prepare_reference, run_probe


def test_directions_match_paper():
    a = directions()
    assert len(a) == 45
    q3 = [v for v in a if 180 <= v <= 270]
    assert np.allclose(np.diff(q3), 5) and q3[0] == 180 and q3[-1] == 270
    assert all(v % 10 == 0 for v in a if not 180 <= v <= 270)


def test_elastic_probe_micro_equals_macro(small_sample):
    # Sliding prevented, from an equilibrium (isotropic, stable) state: the response is
    # elastic; in this 200-disk random packing a couple of near-zero-force contacts may
    # open/close (they are counted in the union with f = 0 at the missing end), so the
    # premise checked is "< 1 % of the contacts change".  Then sum over all contacts (internal +
    # wall) of df.dl plus the unbalanced term of Eq. 14 equals V ds:de up to (i) the
    # Eulerian geometric term ~ |s| |de| / |ds| ~ 200e3 * 1e-5 / 2.5e3 < 1e-3 and (ii)
    # the residual non-equilibrium at both ends (unbalanced ratio < 1e-4).  Tolerance 0.01
    # on the normalized W2 (values are O(1)).
    opts = ProbeOptions()
    R, res = prepare_reference(small_sample, opts)
    assert res.outcome == "equilibrium"
    for alpha in (0.0, 135.0, 225.0):
        r = run_probe(R, alpha, sliding=False, opts=opts)
        assert r["converged"]
        assert r["n_created"] + r["n_lost"] < 0.01 * r["n_contacts_R"]
        total = r["w2_micro"] + r["w2_walls"] + r["w2_unbalanced"]
        assert abs(total - r["w2"]) < 0.01, r
        # the split is exact: W2n + W2t = sum df.dl (same contacts)
        assert math.isclose(r["w2n"] + r["w2t"], r["w2_micro"], rel_tol=1e-9, abs_tol=1e-12)
        # normal springs are elastic: positive normal part
        assert r["w2n"] > 0
        # the measured stress increment is the requested one within the stress tolerance
        ds = np.array([r["ds1"], r["ds2"]])
        a = math.radians(alpha)
        assert np.allclose(ds, 2500 * np.array([math.sin(a), math.cos(a)]), atol=2 * 25.0)


def test_elastic_strain_is_reversible_direction(small_sample):
    # opposite stress increments give opposite elastic strains (linear elasticity):
    # |de(alpha) + de(alpha+180)| small compared with |de|; tolerance 5 % (equilibrium
    # tolerance of each probe ~ 1 % of the strain).
    R, _ = prepare_reference(small_sample)
    a = run_probe(R, 30.0, sliding=False)
    b = run_probe(R, 210.0, sliding=False)
    da = np.array([a["de1"], a["de2"]])
    db = np.array([b["de1"], b["de2"]])
    assert np.linalg.norm(da + db) < 0.05 * np.linalg.norm(da)
    assert np.linalg.norm(da) > 0


def test_cli_biaxial_and_probes(tmp_path):
    from dem.__main__ import main
    out = tmp_path / "bx"
    main(["biaxial", "--n", "150", "--seed", "2", "--out", str(out), "--rate", "0.1",
          "--eps1-max", "0.01", "--eta-a", "0.3", "--no-vtk"])
    with open(out / "biaxial.csv") as f:
        rows = list(csv.DictReader(f))
    for col in ("eps1", "eps2", "eps_v", "s1", "s2", "p", "q", "eta"):
        assert col in rows[0]
    last = rows[-1]
    assert float(last["eps1"]) >= 0.01 - 1e-3
    assert abs(float(last["s2"]) - 200e3) < 0.05 * 200e3  # lateral stress held
    for r in rows[1:]:
        s1, s2 = float(r["s1"]), float(r["s2"])
        assert math.isclose(float(r["q"]), s1 - s2) and math.isclose(float(r["p"]), (s1 + s2) / 2)
    assert float(last["q"]) > 0
    assert (out / "stateA.npz").exists() and (out / "fig13_q.png").exists()
    assert (out / "fig14_epsv.png").exists()
    out2 = tmp_path / "pr"
    main(["probes", "--state", str(out / "stateA.npz"), "--out", str(out2), "--step-q3", "90",
          "--step-other", "90", "--workers", "2", "--max-steps", "20000"])
    with open(out2 / "probes.csv") as f:
        prow = list(csv.DictReader(f))
    assert [float(r["alpha_sigma"]) for r in prow] == [0.0, 90.0, 180.0, 270.0]
    for c in ("w2", "w2_micro", "w2n", "w2t", "w2_unbalanced", "plastic", "converged"):
        assert c in prow[0]
    for name in ("fig15_w2.png", "fig16_w2_micro.png", "fig17_w2_nt.png"):
        assert (out2 / name).exists()
    # --resume: every run is in the checkpoint, so nothing runs again and the CSV is the same
    first = (out2 / "probes.csv").read_text()
    main(["probes", "--state", str(out / "stateA.npz"), "--out", str(out2), "--step-q3", "90",
          "--step-other", "90", "--workers", "2", "--max-steps", "20000", "--resume"])
    assert (out2 / "probes.csv").read_text() == first


@pytest.fixture(scope="module")
def reference(small_sample):
    R, res = prepare_reference(small_sample)
    assert res.outcome == "equilibrium"
    return R


def _same_rows(a, b):
    assert len(a) == len(b)
    for ra, rb in zip(a, b):
        assert ra.keys() == rb.keys()
        for k in ra:
            va, vb = ra[k], rb[k]
            assert va == vb or (isinstance(va, float) and math.isnan(va) and math.isnan(vb)), k


def test_probe_checkpoint_resumes_without_rerunning(reference, tmp_path, monkeypatch):
    import dem.probes as probes
    alphas = [45.0, 225.0]
    ck = tmp_path / "runs.jsonl"
    full = probes.run_probes(reference, alphas, workers=1, verbose=False, checkpoint=str(ck))
    lines = ck.read_text().splitlines()
    assert len(lines) == 1 + 4          # header + 2 directions x (sliding, no sliding)
    # an interrupted sweep: two runs on disk, the third cut in the middle of its line
    ck.write_text("\n".join(lines[:3]) + "\n" + lines[3][: len(lines[3]) // 2])
    calls = []
    real = probes._task
    monkeypatch.setattr(probes, "_task", lambda t: calls.append(t[1:3]) or real(t))
    resumed = probes.run_probes(reference, alphas, workers=1, verbose=False, checkpoint=str(ck))
    assert len(calls) == 2              # only the two runs that were not on disk
    _same_rows(full, resumed)           # bit-for-bit the uninterrupted result
    assert len(ck.read_text().splitlines()) == 5
    # a checkpoint of another state is refused, never mixed in
    other = reference._replace(x=reference.x + 1e-9)
    with pytest.raises(ValueError, match="another state"):
        probes.run_probes(other, alphas, workers=1, verbose=False, checkpoint=str(ck))


def test_probes_on_a_dask_cluster_equal_local_runs(reference):
    distributed = pytest.importorskip("distributed")
    from dem.probes import run_probes
    alphas = [45.0, 225.0]
    local = run_probes(reference, alphas, workers=1, verbose=False)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        remote = run_probes(reference, alphas, scheduler=cluster.scheduler_address,
                            verbose=False)
    _same_rows(local, remote)           # where a probe ran does not change its result


def test_checkpoint_with_another_cap_keeps_the_decided_runs(reference, tmp_path):
    # a run is deterministic and the cap only truncates it: with a larger cap the decided runs
    # are kept and only the undecided ones run again; with a smaller one, runs decided beyond it
    # run again (and give undecided).  Two sweeps: one whose cap cuts every run short (all
    # undecided), one that lets them end; the caps are chosen from the runs' own lengths.
    import json
    import dem.probes as probes
    ck = tmp_path / "runs.jsonl"
    big = ProbeOptions(max_steps=400_000)
    probes.run_probes(reference, [45.0, 225.0], big, workers=1, verbose=False, checkpoint=str(ck))
    recs = [json.loads(l) for l in ck.read_text().splitlines()[1:]]
    assert {r["outcome"] for r in recs} == {"equilibrium"}
    # a run's steps count its ramp, the cap does not
    shortest = min(r["steps"] for r in recs) - big.ramp_steps
    longest = max(r["steps"] for r in recs) - big.ramp_steps
    kept = probes.read_checkpoint(str(ck), reference, big._replace(max_steps=longest))
    assert len(kept) == len(recs)                         # decided within the new cap: kept
    assert probes.read_checkpoint(str(ck), reference, big._replace(max_steps=shortest - 1)) == {}
    small = ProbeOptions(max_steps=shortest // 2)
    ck2 = tmp_path / "runs_small.jsonl"
    probes.run_probes(reference, [45.0, 225.0], small, workers=1, verbose=False,
                      checkpoint=str(ck2))
    recs2 = [json.loads(l) for l in ck2.read_text().splitlines()[1:]]
    assert {r["outcome"] for r in recs2} == {"undecided"}
    assert probes.read_checkpoint(str(ck2), reference, big) == {}   # undecided: run again
    assert len(probes.read_checkpoint(str(ck2), reference, small)) == len(recs2)
    with pytest.raises(ValueError, match="other"):
        probes.read_checkpoint(str(ck), reference, small._replace(stress_tol=10.0))
