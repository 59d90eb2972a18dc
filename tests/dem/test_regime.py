"""The granular regime (``dem.regime``): a set outside it refused before a run (one line naming
kn/D and the stiffness number, exit 2, nothing written) unless --allow-soft, which the summary
records; during a run a state no packing can be (a NaN, a disk outside the walls, the walls
crossed, a porosity outside (0, 1), an overlap beyond the bound) stops it with a named outcome,
one line, exit 1, the state kept; the watch only reads: a trajectory is the same without it.

Each check is injected once: a soft set (the issue's command), a disk placed outside, a NaN
velocity, the walls crossed, the radii grown past the box, two disks pushed into each other."""
import json
import math

import numpy as np
import pytest

from tests._cli import run_dem as _run

from dem import regime as R
from dem.params import DemParams
from dem.simulation import Simulation

# the command: kn/D in the wrong unit (1e7 for 3.2e10), stiffness number 0.85
SOFT = ["biaxial", "--n", "300", "--kn-over-d", "1e7", "--eps1-max", "0.02"]


def test_stiffness_number_and_the_bound():
    p = DemParams()
    # kn / (sigma2 t): the paper's set at 200 kPa, and the kn/D 1e7 (3200 times softer)
    assert R.stiffness_number(p, 200e3) == pytest.approx(32e9 * 0.017 / 200e3, rel=1e-15)
    assert R.stiffness_number(p, 200e3) == pytest.approx(2720, rel=1e-12)
    soft = p.replace(kn_over_d=1e7)
    assert R.stiffness_number(soft, 200e3) == pytest.approx(0.85, rel=1e-12)
    g = R.regime(p, 200e3)
    assert g["inside"] and not g["allow_soft"] and g["expected_overlap"] == 1 / g["stiffness_number"]
    R.check_regime(p, 200e3)                            # the paper's set passes
    R.check_regime(p.replace(kn_over_d=2e9), 200e3)     # the calibration's softest (170)
    with pytest.raises(R.SoftContactError, match="stiffness number kn/\\(sigma2 t\\) = 0.85"):
        R.check_regime(soft, 200e3)
    assert not R.check_regime(soft, 200e3, allow_soft=True)["inside"]
    # the bound is KAPPA_MIN: just above passes, just below is refused
    edge = R.KAPPA_MIN * 200e3 / 0.017
    R.check_regime(p.replace(kn_over_d=edge * (1 + 1e-9)), 200e3)
    with pytest.raises(R.SoftContactError):
        R.check_regime(p.replace(kn_over_d=edge * (1 - 1e-9)), 200e3)


def test_soft_set_refused_in_one_line_exit_2_nothing_written(tmp_path, capsys):
    out = tmp_path / "D"
    code, err = _run(SOFT + ["--out", str(out)], capsys)
    assert code == 2 and len(err) == 1 and err[0].startswith("error: --kn-over-d 1e+07"), err
    assert "kn/D" in err[0] and "stiffness number" in err[0] and "= 0.85" in err[0]
    assert "--allow-soft" in err[0] and "kn/D >= 1.18e+09" in err[0]
    assert not out.exists()


def test_soft_set_run_anyway_stops_on_an_escaped_disk_exit_1(tmp_path, capsys):
    """The issue's command with --allow-soft: the walls sweep through the soft packing during
    the compaction; the first disk out stops the run (a second), the state kept, no result."""
    from dem import io
    out = tmp_path / "D"
    code, err = _run(SOFT + ["--out", str(out), "--allow-soft", "--quiet"], capsys)
    assert code == 1 and len(err) == 1, err
    assert err[0].startswith("stopped: unsound state (disk_outside_walls) at step ")
    assert "unsound_state.npz" in err[0]
    st, meta = io.load_state(out / "unsound_state.npz")
    assert meta["outcome"] == "disk_outside_walls" and meta["step"] > 0
    w = st.walls
    assert np.any((st.x[:, 0] < w[0]) | (st.x[:, 0] > w[1]) | (st.x[:, 1] < w[2])
                  | (st.x[:, 1] > w[3]))
    # nothing that looks like a result: no curve, no summary, no compacted state
    assert not (out / "summary.json").exists() and not (out / "biaxial.csv").exists()
    assert not (out / "compacted.npz").exists()
    assert json.loads((out / "params.json").read_text())    # what it finished stays readable


def test_allow_soft_is_recorded_in_the_summary(tmp_path, capsys):
    """A soft but sound set (stiffness number 50: refused, then run with --allow-soft): the
    summary records the regime it ran in."""
    from dem.__main__ import main
    out = tmp_path / "S"
    argv = ["biaxial", "--n", "60", "--kn-over-d", "5.88e8", "--eps1-max", "0.001",
            "--save-fractions", "0.9", "--no-vtk", "--quiet", "--out", str(out)]
    code, err = _run(argv, capsys)
    assert code == 2 and "stiffness number" in err[0]
    assert main(argv + ["--allow-soft"]) in (0, None)
    g = json.loads((out / "summary.json").read_text())["regime"]
    assert g["allow_soft"] is True and g["inside"] is False
    assert g["stiffness_number"] == pytest.approx(50.0, rel=1e-2)


def test_a_soft_state_refused_by_probes(small_sample, tmp_path, capsys):
    from dem import io
    st = small_sample._replace(params=small_sample.params.replace(kn_over_d=1e7))
    io.save_state(tmp_path / "soft.npz", st)
    out = tmp_path / "P"
    code, err = _run(["probes", "--state", str(tmp_path / "soft.npz"), "--out", str(out)], capsys)
    assert code == 2 and len(err) == 1 and "--state" in err[0] and "stiffness number" in err[0]
    assert not out.exists()


def test_a_calibration_whose_softest_set_is_soft_is_refused(tmp_path, capsys):
    out = tmp_path / "C"
    code, err = _run(["calibrate", "--vary", "kn_over_d", "--bounds", "kn_over_d=1e8:3.2e10",
                      "--out", str(out)], capsys)
    assert code == 2 and len(err) == 1 and "the softest set of the search" in err[0], err
    assert "stiffness number" in err[0] and not out.exists()


# -- during a run: each unsound state injected once ------------------------------------------
def _sim(state):
    sim = Simulation(state)
    from common.threads import ThreadChooser
    sim.threads = ThreadChooser(sim.n, 1)
    return sim


def _stopped(sim, outcome, steps=5):
    with pytest.raises(R.UnsoundState) as e:
        sim.run(steps)
    assert e.value.outcome == outcome and str(e.value).startswith(f"unsound state ({outcome})")
    assert "\n" not in str(e.value)
    return e.value


def test_a_nan_velocity_stops_the_run_and_the_state_is_kept(small_sample, tmp_path):
    from dem import io
    sim = _sim(small_sample)
    sim.v[17, 1] = math.nan
    e = _stopped(sim, "non_finite_state")
    assert "velocity" in str(e) and e.step == small_sample.step + 5
    path = io.save_unsound(e, tmp_path)
    st, meta = io.load_state(path)
    assert meta["outcome"] == "non_finite_state" and not np.all(np.isfinite(st.v))
    # the exception crosses a process boundary (probe workers, dask) with its state
    import pickle
    back = pickle.loads(pickle.dumps(e))
    assert back.outcome == e.outcome and str(back) == str(e) and back.state.x.shape == st.x.shape


def test_a_disk_placed_outside_the_walls_stops_the_run(small_sample):
    sim = _sim(small_sample)
    sim.x[42] = [sim.walls[1] + 3 * sim.r[42], 0.5 * (sim.walls[2] + sim.walls[3])]
    e = _stopped(sim, "disk_outside_walls")
    assert "disk 42" in str(e)


def test_walls_crossed_and_a_porosity_past_zero(small_sample):
    sim = _sim(small_sample)
    sim.walls[1] = sim.walls[0] - 1e-3
    with pytest.raises(R.UnsoundState, match="walls_crossed"):
        R.watch_run(sim)
    sim = _sim(small_sample)
    sim.r *= 2.5                              # the disks' area beyond the box's, centres inside
    sim.rebuild()                             # (radii change before a rebuild: dem.sample)
    with pytest.raises(R.UnsoundState) as e:
        R.watch_run(sim)
    assert e.value.outcome == "porosity_out_of_range" and "porosity -" in str(e.value)


def test_an_overlap_beyond_the_bound_stops_a_snapshot(small_sample):
    sim = _sim(small_sample)
    snap = sim.snapshot()                     # the compacted sample: far below the bound
    i, j = int(snap.ci[0]), int(snap.cj[0])
    d = min(sim.r[i], sim.r[j]) * 2
    rel = snap.fn / (sim.params.kn * 2 * np.minimum(sim.r[snap.ci], sim.r[snap.cj]))
    assert rel.max() < 0.05 * R.OVERLAP_MAX
    # push j into i until they overlap by 0.6 of the smaller diameter
    n = (sim.x[j] - sim.x[i]) / np.linalg.norm(sim.x[j] - sim.x[i])
    sim.x[j] = sim.x[i] + n * (sim.r[i] + sim.r[j] - 0.6 * d)
    with pytest.raises(R.UnsoundState) as e:
        sim.snapshot()
    assert e.value.outcome == "overlap_beyond_bound" and f"disks {i} and {j}" in str(e.value)
    sim.watch = False                         # an unsound state can still be inspected
    sim.snapshot()


def test_the_watch_never_moves_a_trajectory(small_sample):
    a, b = _sim(small_sample), _sim(small_sample)
    b.watch = False
    for s in (a, b):
        s.run(300)
        s.snapshot()
        s.run(300)
    for name in ("x", "v", "w", "theta", "walls", "prev"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name


# -- the cross-check's DEM: the same rules ----------------------------------------------------
def test_the_crosscheck_refuses_a_soft_dem_set_before_any_part_runs(tmp_path, capsys):
    """A soft --dem-params is refused by ``python -m crosscheck`` before the H-model's and the
    FE's parts run (they took minutes before the DEM refused it): one line naming the file,
    kn/D and the stiffness number, exit 2, no folder; with --no-dem the file is not the DEM's
    sample, so it is not judged."""
    from dem.params import save_params
    soft = tmp_path / "soft.json"
    save_params(soft, DemParams().replace(kn_over_d=1e7))
    out = tmp_path / "X"
    code, err = _run(["crosscheck", "--dem-params", str(soft), "--out", str(out)], capsys)
    assert code == 2 and len(err) == 1, err
    assert err[0].startswith(f"error: --dem-params {soft}: the stiffness number kn/(sigma2 t) "
                             "= 0.85 (kn/D 1e+07 Pa"), err
    assert "granular packings only" in err[0] and "--allow-soft" in err[0]
    assert not out.exists()


def test_the_crosscheck_stops_on_an_unsound_dem_state_in_one_line(tmp_path, capsys, monkeypatch):
    """A NaN velocity injected into the cross-check's DEM compaction (the first watch of its
    run): one line naming the outcome, exit 1, the state kept in the DEM's folder, never a
    traceback (it was one before). The H-model's and FE's parts run first (about 20 s)."""
    from dem import io, simulation

    real = simulation.watch_run

    def poisoned(sim):
        sim.v[7, 0] = np.nan
        return real(sim)

    monkeypatch.setattr(simulation, "watch_run", poisoned)
    out = tmp_path / "X"
    code, err = _run(["crosscheck", "--n", "300", "--no-domain", "--no-burst", "--workers", "1",
                      "--quiet", "--out", str(out)], capsys)
    assert code == 1 and len(err) == 1, err
    assert err[0].startswith("stopped: unsound state (non_finite_state) at step "), err
    kept = out / "dem" / R.KEPT
    assert str(kept) in err[0]
    st, meta = io.load_state(kept)
    assert meta["outcome"] == "non_finite_state" and np.isnan(st.v[7, 0])
