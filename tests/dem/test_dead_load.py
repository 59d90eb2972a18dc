"""The tied walls under a dead load (``walls.dead_load``, ``kernels._dead_load``; issue 24): one
dynamic degree of freedom, the platens' shortening U1, with the walls' generalized mass m_G under
a constant generalized force, integrated by the disks' leapfrog."""
import math
import os

import numpy as np
import pytest

from dem import io
from dem.ledger import Ledger
from dem.params import DemParams
from dem.probes import state_fingerprint
from dem.simulation import Simulation
from dem.walls import dead_load, generalized_force

R = 0.01


def _wall_on_a_spring(m_g, dt_safety=0.2, ov0=2e-5, a=1e-6, ratio=-2.0):
    """One disk between the y walls (overlap ov0 each), the x walls far: G = F1 = kn (ov0 +
    U1 / 2), a spring of stiffness kn / 2 on U1; the dead load kn (ov0 + a) puts its equilibrium
    at U1 = 2 a; the walls start at rest at U1 = 0."""
    p = DemParams(n=1, damping=0.15, dt_safety=dt_safety, r_min=R, r_max=R)
    yc = 0.5
    walls = np.array([0.0, 1.0, yc - R + ov0, yc + R - ov0])
    sim = Simulation.new(p, np.array([[0.5, yc]]), np.array([R]), walls)
    sim.set_control(dead_load(ratio, p.kn * (ov0 + a), m_g, sim.ref_len))
    return sim


def test_a_wall_on_a_spring_under_a_dead_load_oscillates_with_its_period():
    # m_G U1'' = G_held - kn (ov0 + U1 / 2): an undamped oscillation of U1 about 2 a, period
    # 2 pi sqrt(2 m_G / kn). The leapfrog's own frequency is 2 arcsin(w dt / 2) / dt: the
    # zero crossings of U1 - 2 a over 20 periods give it to 1e-6 (measured 2e-9); the exact
    # continuous period differs by (w dt)^2 / 24 = 3e-4 here and fails that bound, so the
    # check tells the integrator's period from the continuous one. The symmetric walls leave
    # the disk at rest (its Cundall damping then does nothing) and the amplitude stays a.
    m_g = 50.0
    sim = _wall_on_a_spring(m_g)
    p = sim.params
    w = math.sqrt(p.kn / 2 / m_g)
    u1 = []
    h0 = sim.walls[3] - sim.walls[2]
    n = int(20 * 2 * math.pi / w / sim.dt) + 2
    for _ in range(n):
        sim.run(1)
        u1.append(h0 - (sim.walls[3] - sim.walls[2]))
    u1 = np.array(u1) - 2e-6
    k = np.flatnonzero(np.diff(np.sign(u1)) != 0)
    t = (k + u1[k] / (u1[k] - u1[k + 1]) + 1) * sim.dt    # linear interpolation of each crossing
    period = 2 * np.mean(np.diff(t))
    leapfrog = 2 * math.pi / (2 * math.asin(w * sim.dt / 2) / sim.dt)
    assert abs(period / leapfrog - 1) < 1e-6, (period, leapfrog)
    assert abs(period / (2 * math.pi / w) - 1) > 1e-5
    assert abs(np.max(np.abs(u1)) / 2e-6 - 1) < 1e-3
    assert np.max(np.abs(sim.v)) < 1e-9


def test_the_ledger_of_a_dead_load_counts_the_walls_and_closes():
    # Under the dead load the walls are part of the system: E_c has their kinetic energy
    # 1/2 m_G U1'^2, W_ext is the dead load's work G_held dU1; the balance closes to round-off,
    # W2_ext = (G_held - G(0)) U1 exactly (G(0) the walls' force of the first step), and with
    # no dissipation the kinetic and elastic energies trade to O(dt^2) (split residual).
    sim = _wall_on_a_spring(50.0)
    g_held = sim.control.g_held
    led = Ledger(sim)
    h0 = sim.walls[3] - sim.walls[2]
    sim.run(1)
    g0 = led.lsc[7:11]
    g0 = generalized_force(g0, sim.control.ratio, sim.ref_len)
    ke_max = 0.0
    for _ in range(30):
        sim.run(37)
        rec = led.read()
        ke_max = max(ke_max, rec.ke)
        # U1 at the midpoint of the last step: the ledger's centred displacements sum to it
        u1 = h0 - (sim.walls[3] - sim.walls[2]) - 0.5 * (sim.prev[2] + sim.prev[3])
        assert rec.balance_residual < 1e-12 and rec.eq1_bookkeeping < 1e-12
        # (U1 from the walls' positions carries their rounding, 1.1e-16 m on coordinates of
        # 0.5 m, four of them: bound the force times 1e-15 m)
        assert abs(rec.w2_ext - (g_held - g0) * u1) <= abs(g_held - g0) * 1e-15
        assert abs(rec.w_ext - g_held * u1) <= g_held * 1e-15
    # the walls' kinetic energy is counted: its largest value over the checks (every 37 steps
    # of a 349-step period) is the oscillation's energy (kn / 2) (2 a)^2 / 2 = kn a^2 (a = 1e-6
    # m) to within the sampling, (1 - cos(pi 37 / 349)) < 6 %
    assert 0.9 < ke_max / (sim.params.kn * 1e-12) < 1.001
    assert rec.split_residual < 1e-3


def test_dead_load_state_round_trip_and_older_versions(tmp_path):
    # version 4 stores the wall mass; a state saved under the dead load continues to the bit
    sim = _wall_on_a_spring(50.0)
    sim.run(100)
    io.save_state(tmp_path / "s.npz", sim.state())
    st, _ = io.load_state(tmp_path / "s.npz")
    assert st.control == sim.control
    a, b = Simulation(st), sim
    a.run(200)
    b.run(200)
    assert np.array_equal(a.walls, b.walls) and np.array_equal(a.x, b.x)


def test_a_version_4_dead_load_file_loads_converted_and_continues_to_the_bit(tmp_path):
    # data/dead_load_v4.npz (data/README_reference.md): written by the code that held G_held in
    # the y axis's stress targets (format version 4). It loads with G_held in its own field and
    # stress targets 0, the control dead_load makes now, hashes as it did there, and runs on as
    # that code ran it, to the bit; saved again, it is a version-5 file of the same state
    st, meta = io.load_state(os.path.join(os.path.dirname(__file__), "data", "dead_load_v4.npz"))
    c = st.control
    assert c.g_held == meta["g_held"] < 0 and c.s_from == c.s_to == (0.0, 0.0)
    assert c == dead_load(c.ratio, meta["g_held"], c.wall_mass, c.len0)
    assert state_fingerprint(st) == meta["fingerprint"]
    other = st._replace(control=c._replace(g_held=c.g_held + 1.0))
    assert state_fingerprint(other) != meta["fingerprint"]
    sim = Simulation(st)
    sim.run(300)
    after = meta["arrays"]
    for k in ("walls", "prev", "x", "v"):
        assert np.array_equal(getattr(sim, k), after[k + "_300"]), k
    io.save_state(tmp_path / "v5.npz", st)
    with np.load(tmp_path / "v5.npz") as z:
        assert int(z["format_version"]) == 5 and float(z["ctrl_g_held"]) == c.g_held
        d = {k: z[k] for k in z.files if k != "ctrl_g_held"}
    assert io.load_state(tmp_path / "v5.npz")[0].control == c
    np.savez(tmp_path / "bad.npz", **d)                    # version 5 must carry it
    with pytest.raises(ValueError, match="ctrl_g_held"):
        io.load_state(tmp_path / "bad.npz")


@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, math.inf])
def test_dead_load_refuses_a_wall_mass_that_is_not_positive(bad):
    with pytest.raises(ValueError, match="wall_mass"):
        dead_load(-2.0, 1.0, bad, (1.0, 1.0))
