"""Rolling resistance (issue 12 §2): the elastic-plastic rolling moment of a contact
(k_r = rolling_stiffness * kt * R*^2, capped at mu_r R* fn), its history, its state files, and
that it leaves a run without it alone."""
import io as _io
import json
import math

import numba
import numpy as np
import pytest

from dem import io
from dem.params import DemParams
from dem.simulation import Simulation
from dem.walls import biaxial

BOX = np.array([-1.0, 1.0, -1.0, 1.0])
R = 0.01
OVERLAP = 1e-5


def _rolling_pair(mu_r, omegas, rolling_stiffness=1.0):
    """Two equal disks at a fixed overlap, spun at (+omega, -omega) every step: the contact
    point does not slip (w_i r_i + w_j r_j = 0), so only the rolling spring is loaded.
    Returns params, the moment history mr (on disk 0), the tangential history ft, the
    torques on both disks after each step."""
    p = DemParams(n=2, r_min=R, r_max=R, damping=0.0, rolling_friction=mu_r,
                  rolling_stiffness=rolling_stiffness)
    x = np.array([[0.0, 0.0], [0.0, 2 * R - OVERLAP]])
    sim = Simulation.new(p, x, np.array([R, R]), BOX)
    mr, ft, tq = [], [], []
    for om in omegas:
        sim.x[:] = x
        sim.v[:] = 0.0
        sim.w[:] = [om, -om]
        sim.run(1)
        mr.append(sim.pairs.mr[0])
        ft.append(sim.pairs.ft[0])
        tq.append(sim.fnet[:, 2].copy())
    return p, sim.dt, np.array(mr), np.array(ft), np.array(tq)


def test_rolling_moment_below_the_cap_is_the_elastic_spring():
    omega = 2.0
    p, dt, mr, ft, tq = _rolling_pair(10.0, [omega] * 50)     # cap far away
    rstar = R / 2
    kr = p.rolling_stiffness * p.kt * rstar ** 2
    n = np.arange(1, 51)
    expected = -kr * (2 * omega * dt) * n          # moment on disk 0 against w_0 - w_1
    assert np.allclose(mr, expected, rtol=1e-12, atol=0)
    # no slip at the contact point: the tangential spring stays unloaded
    assert np.all(np.abs(ft) < 1e-12 * p.kn * OVERLAP)
    # the moment is the disks' torque (equal and opposite), the only one here
    assert np.allclose(tq[:, 0], mr, rtol=1e-12, atol=0)
    assert np.allclose(tq[:, 1], -mr, rtol=1e-12, atol=0)


def test_rolling_moment_saturates_at_the_cap_and_unloads_elastically():
    mu_r = 0.05
    omega = 2.0
    steps = 400
    p, dt, mr, ft, tq = _rolling_pair(mu_r, [omega] * steps + [-omega] * 5)
    rstar = R / 2
    fn = p.kn * OVERLAP
    cap = mu_r * rstar * fn
    kr = p.rolling_stiffness * p.kt * rstar ** 2
    load = mr[:steps]
    assert np.all(np.abs(load) <= cap * (1 + 1e-12))
    k_sat = int(np.argmax(np.abs(load) >= cap * (1 - 1e-12)))
    assert 1 < k_sat < steps - 10                  # elastic first, then at the cap ...
    assert np.allclose(load[k_sat:], -cap, rtol=1e-12, atol=0)   # ... where it stays
    # reversing the rotation unloads along the elastic slope from the cap
    back = mr[steps:]
    assert np.allclose(np.diff(np.concatenate([[-cap], back])), kr * 2 * omega * dt,
                       rtol=1e-9, atol=0)


def test_elastic_probes_lift_the_rolling_cap_too():
    # cap_on = False (sliding prevented: the elastic probes) lifts both caps
    p = DemParams(n=2, r_min=R, r_max=R, damping=0.0, rolling_friction=0.05)
    x = np.array([[0.0, 0.0], [0.0, 2 * R - OVERLAP]])
    sim = Simulation.new(p, x, np.array([R, R]), BOX)
    sim.cap_on = False
    for _ in range(400):
        sim.x[:] = x
        sim.v[:] = 0.0
        sim.w[:] = [2.0, -2.0]
        sim.run(1)
    cap = 0.05 * (R / 2) * p.kn * OVERLAP
    assert abs(sim.pairs.mr[0]) > 2 * cap


def _run(state, steps=1500, nblocks=None, threads=None):
    nt = numba.get_num_threads()
    try:
        if threads:
            numba.set_num_threads(threads)
        s = Simulation(state)
        s.nblocks = nblocks
        s.set_control(biaxial(200e3, 2.0, s.ref_len))
        s.run(steps)
    finally:
        numba.set_num_threads(nt)
    return s


def _with_rolling(state, mu_r=0.1, stiffness=1.0):
    return state._replace(params=state.params.replace(rolling_friction=mu_r,
                                                      rolling_stiffness=stiffness), mu_r=mu_r)


def _same(a, b):
    for u, z in ((a.x, b.x), (a.v, b.v), (a.w, b.w), (a.theta, b.theta), (a.walls, b.walls),
                 (a.pairs.ft, b.pairs.ft), (a.pairs.mr, b.pairs.mr)):
        if not np.array_equal(u, z):
            return False
    return True


def test_zero_rolling_friction_leaves_the_run_alone(small_sample):
    # mu_r = 0: the rolling code is never entered, whatever the rolling stiffness: the same
    # bits, no moment history, no moment column
    a = _run(small_sample)
    b = _run(_with_rolling(small_sample, 0.0, 7.5))
    assert _same(a, b)
    assert not np.any(b.pairs.mr) and not np.any(b.fnet[:, 3])
    # and it does act when on: another trajectory, with moments
    c = _run(_with_rolling(small_sample))
    assert np.any(c.pairs.mr) and not np.array_equal(a.x, c.x)


def test_rolling_results_do_not_depend_on_threads_or_blocks(small_sample):
    st = _with_rolling(small_sample)
    runs = [_run(st, nblocks=None, threads=1), _run(st, nblocks=7, threads=1),
            _run(st, nblocks=7, threads=numba.config.NUMBA_NUM_THREADS)]
    assert runs[0].n_rebuilds >= 1 and np.any(runs[0].pairs.mr)
    for r in runs[1:]:
        assert _same(runs[0], r)


def test_rolling_history_saved_and_resumed_bit_identically(small_sample, tmp_path):
    sim = Simulation(_with_rolling(small_sample))
    sim.set_control(biaxial(200e3, 2.0, sim.ref_len))
    sim.run(300)
    io.save_state(tmp_path / "s.npz", sim.state())
    sim.run(1200)
    loaded, _ = io.load_state(tmp_path / "s.npz")
    assert loaded.mu_r == 0.1 and np.any(loaded.mr)
    sim2 = Simulation(loaded)
    sim2.run(1200)
    assert _same(sim, sim2)


def test_version_1_state_files_still_read(small_sample, tmp_path):
    # a file written before rolling resistance: no mr / mu_r, params without the rolling keys
    path = tmp_path / "new.npz"
    io.save_state(path, small_sample)
    with np.load(path) as z:
        d = {k: z[k] for k in z.files if k not in ("mr", "mu_r")}
    pd = json.loads(str(d["params"]))
    del pd["rolling_friction"], pd["rolling_stiffness"]
    d["params"] = np.array(json.dumps(pd))
    d["format_version"] = np.array(1)
    old = tmp_path / "v1.npz"
    buf = _io.BytesIO()
    np.savez(buf, **d)
    old.write_bytes(buf.getvalue())
    st, _ = io.load_state(old)
    assert st.params.rolling_friction == 0.0 and st.mu_r == 0.0
    assert st.mr.shape == st.ft.shape and not np.any(st.mr)
    assert _same(_run(st, 500), _run(small_sample, 500))
    # a version-2 file without its rolling history is not a state
    d2 = {k: v for k, v in np.load(path).items() if k != "mr"}
    bad = tmp_path / "bad.npz"
    buf = _io.BytesIO()
    np.savez(buf, **d2)
    bad.write_bytes(buf.getvalue())
    with pytest.raises(ValueError, match="mr"):
        io.load_state(bad)


def _fingerprint_before_rolling(state):
    # dem.probes.state_fingerprint as it was written before rolling resistance existed
    import hashlib
    h = hashlib.sha256()
    for a in (state.x, state.v, state.w, state.theta, state.r, state.walls, state.walls_ref,
              state.prev, state.x_ref, state.pi, state.pj, state.ft, state.ref_len):
        h.update(np.ascontiguousarray(a).tobytes())
    # DemParams.to_dict() of that time: the grain friction angle under its name then
    pd = {("friction_deg" if k == "phi_g" else k): v for k, v in state.params.to_dict().items()
          if k not in ("rolling_friction", "rolling_stiffness")}
    c = state.control      # its seven fields of that time (the tie's ratio came later)
    ctrl = [c.mode, c.s_from, c.s_to, c.ramp_start, c.ramp_len, c.rate, c.len0]
    h.update(json.dumps([pd, state.step, state.mu, state.cap_on, ctrl], default=str).encode())
    return h.hexdigest()


def test_fingerprint_of_a_state_without_rolling_is_the_one_before_rolling(small_sample):
    # the probe checkpoints of runs made before rolling resistance existed stay resumable: a
    # state without it (mu_r = 0, no moment history; any rolling_stiffness, which then changes
    # no bit) hashes as it did; with it, the rolling fields count
    from dem.probes import state_fingerprint
    fp = state_fingerprint(small_sample)
    assert fp == _fingerprint_before_rolling(small_sample)
    assert state_fingerprint(_with_rolling(small_sample, 0.0, 7.5)) == fp
    assert state_fingerprint(_with_rolling(small_sample)) != fp
    st = _run(_with_rolling(small_sample)).state()
    assert np.any(st.mr)
    assert state_fingerprint(st._replace(mr=np.zeros_like(st.mr))) != state_fingerprint(st)


@pytest.mark.parametrize("field, value", [("rolling_friction", -0.1),
                                          ("rolling_friction", math.nan),
                                          ("rolling_stiffness", 0.0),
                                          ("rolling_stiffness", math.inf)])
def test_rolling_parameters_are_validated(field, value):
    with pytest.raises(ValueError, match=field):
        DemParams(**{field: value})
