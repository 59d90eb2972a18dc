"""The anatomy of a burst (``dem.anatomy``): the contact state of a Simulation, the anatomy
columns on hand-made cases with known answers (two disks, a chain, a star, contacts created and
lost, the backbone, walls, the increment of the unstable contacts), the clusters against a
brute-force union-find, a 300-disk sample sheared by moving walls against an independent
per-contact reference and the walls' Eq. 14, the contact state taken at one time (the last
step's positions), the sliding flag against the kernel's own Coulomb decision, the velocity
fluctuation, the VTU files read back and the figure."""
import math
import os

import numpy as np
import pytest

from dem import kernels
from dem.anatomy import (ANATOMY_COLUMNS, INWARD, SLIDE_TOL, ContactState, anatomy, branches,
                         contact_state, contact_work, increment_on, own_work, plot_anatomy,
                         split_keys, step_positions, unstable_clusters, velocity_fluctuation,
                         wall_velocities, write_anatomy_vtk)
from dem.params import DemParams
from dem.simulation import Simulation
from common.threads import ThreadChooser
from dem.walls import strain_rate
from tests.dem.test_kernel_reference import _law

BOX = np.array([-10.0, 10.0, -10.0, 10.0])


# ------------------------------------------------------------------------------------------
# Hand-made contact states: the positions at 0 and now, each contact's force chosen so that its
# own W2 has a chosen sign and value
# ------------------------------------------------------------------------------------------
def _key(c, n):
    """(i, j) grain contact or (p, "w", wall) wall contact -> key."""
    return c[0] * (n + 4) + (n + c[2] if c[1] == "w" else c[1])


def _state(n, x, forces, sliding=(), walls=BOX):
    """A ContactState of ``forces`` {contact: force on the first disk (2,)} at positions x."""
    x = np.asarray(x, float)
    items = sorted((_key(c, n), np.asarray(f, float), c in sliding) for c, f in forces.items())
    keys = np.array([k for k, _, _ in items], np.int64).reshape(-1)
    force = np.array([f for _, f, _ in items]).reshape(-1, 2)
    br = branches(keys, x, walls)
    nrm = br / np.linalg.norm(br, axis=1)[:, None]
    fn = -np.sum(force * nrm, 1)
    ft = force[:, 1] * nrm[:, 0] - force[:, 0] * nrm[:, 1]
    sl = np.array([s for _, _, s in items], bool)
    return ContactState(keys, force, br, nrm, fn, ft, np.zeros(len(keys)), sl,
                        np.zeros(len(keys), bool), x, np.asarray(walls, float))


def _pair(n, x0, x1, signs, scale=5.0, walls=BOX, sliding=()):
    """States at 0 and now with the contacts of ``signs`` {contact: +1 / -1}: f(0) = -10 n(0)
    and f = f(0) + sign scale dl, so that each contact's own W2 is sign scale |dl|^2 (the
    expected values are returned)."""
    f0, f1, w2 = {}, {}, {}
    for c, sg in signs.items():
        k = np.array([_key(c, n)])
        l0, l1 = branches(k, np.asarray(x0, float), walls)[0], branches(k, np.asarray(x1, float), walls)[0]
        f0[c] = -10.0 * l0 / np.linalg.norm(l0)
        f1[c] = f0[c] + sg * scale * (l1 - l0)
        w2[c] = sg * scale * float((l1 - l0) @ (l1 - l0))
    return _state(n, x0, f0, walls=walls), _state(n, x1, f1, sliding, walls), w2


def test_two_disks_known_answers():
    # l(0) = (2, 0), l = (1.9, 0.1): dl = (-0.1, 0.1); f(0) = (-10, 0), f = (-12, 3): df = (-2, 3)
    x0, x1 = [[0, 0], [2, 0]], [[0, 0], [1.9, 0.1]]
    s0 = _state(2, x0, {(0, 1): (-10, 0)})
    s = _state(2, x1, {(0, 1): (-12, 3)})
    a = anatomy(s0, s, 2)
    assert list(a) == ANATOMY_COLUMNS
    # n(0) = (1, 0): normal part (-2)(-0.1), tangential part 3 (0.1)
    assert a["w2n_int"] == pytest.approx(0.2, rel=1e-12)
    assert a["w2t_int"] == pytest.approx(0.3, rel=1e-12)
    assert a["w2_int_secant"] == pytest.approx(0.5, rel=1e-12)
    assert (a["n_unstable"], a["n_clusters"], a["largest_cluster"]) == (0, 0, 0)
    assert (a["contacts_lost"], a["contacts_created"]) == (0, 0)
    assert a["sliding_share"] == 0.0
    # each disk has one contact: no backbone
    assert math.isnan(a["coordination"])
    # the tangential force reversed: 3 -> -3 gives w2t = -0.3, w2 = -0.1 < 0
    s = _state(2, x1, {(0, 1): (-12, -3)}, sliding={(0, 1)})
    a = anatomy(s0, s, 2)
    assert a["w2t_int"] == pytest.approx(-0.3, rel=1e-12)
    assert a["w2_int_secant"] == pytest.approx(-0.1, rel=1e-12)
    assert (a["n_unstable"], a["n_clusters"], a["largest_cluster"]) == (1, 1, 1)
    assert a["sliding_share"] == 1.0


def test_the_unstable_contacts_are_those_of_the_last_increment():
    # since 0 the contact is loaded (w2 = +0.5 > 0, stable); over the increment from s_prev
    # (the force (-13, 5) at l = (1.95, 0.05)) to now, df = (1, -2), dl = (-0.05, 0.05):
    # w2 = -0.15 < 0, unstable; the secant columns stay the ones since 0
    x0, xp, x1 = [[0, 0], [2, 0]], [[0, 0], [1.95, 0.05]], [[0, 0], [1.9, 0.1]]
    s0 = _state(2, x0, {(0, 1): (-10, 0)})
    sp = _state(2, xp, {(0, 1): (-13, 5)})
    s = _state(2, x1, {(0, 1): (-12, 3)})
    since0, inc = anatomy(s0, s, 2), anatomy(s0, s, 2, sp)
    assert since0["n_unstable"] == 0 and (inc["n_unstable"], inc["n_clusters"]) == (1, 1)
    for k in ("w2n_int", "w2t_int", "w2_int_secant", "contacts_lost", "sliding_share"):
        assert inc[k] == since0[k], k
    assert own_work(sp, s).w2[0] == pytest.approx(-0.15, rel=1e-12)
    # with a threshold: unstable only below -tau; the raw count keeps it
    a = anatomy(s0, s, 2, sp, tau=0.2)
    assert (a["n_unstable_raw"], a["n_unstable"], a["n_clusters"]) == (1, 0, 0)
    assert anatomy(s0, s, 2, sp, tau=0.1)["n_unstable"] == 1
    with pytest.raises(ValueError, match="tau"):
        anatomy(s0, s, 2, sp, tau=-1.0)
    w2, label = increment_on(own_work(s0, s).keys, sp, s, 2)
    assert w2 == pytest.approx([-0.15], rel=1e-12) and label.tolist() == [0]
    assert [x.tolist() for x in increment_on(own_work(s0, s).keys, None, s, 2)] == [[0.0], [-1]]
    with pytest.raises(ValueError, match="n_disks"):
        anatomy(s0, s, 2, _state(3, [[0, 0], [2, 0], [4, 0]], {(0, 1): (-10, 0)}))


def test_contacts_created_and_lost_count_with_zero_force_at_the_missing_end():
    # three disks; (0, 1) is lost, (1, 2) stays, (0, 2) is created
    x0 = [[0, 0], [2, 0], [1, 1.8]]
    x1 = [[0, 0], [2.2, 0], [1, 1.6]]
    s0 = _state(3, x0, {(0, 1): (-10, 0), (1, 2): (3, -6)})
    s = _state(3, x1, {(1, 2): (4, -7), (0, 2): (-2, -4)})
    a = anatomy(s0, s, 3)
    assert (a["contacts_lost"], a["contacts_created"]) == (1, 1)
    # lost: df = (10, 0), dl = (0.2, 0); created: df = (-2, -4), dl = (0, -0.2);
    # kept: df = (1, -1), dl = l(1,2): (-1.2, 1.6) - (-1, 1.8) = (-0.2, -0.2)
    w2 = {"lost": 10 * 0.2, "created": -4 * -0.2, "kept": 1 * -0.2 + -1 * -0.2}
    assert a["w2_int_secant"] == pytest.approx(sum(w2.values()), rel=1e-12)
    ow = own_work(s0, s)
    assert ow.present.tolist() == [False, True, True] and ow.existed.tolist() == [True, False, True]
    assert ow.w2 == pytest.approx([w2["lost"], w2["created"], w2["kept"]], rel=1e-12)
    # the split on n(0): for the created contact n(0) is its branch at 0 from the positions at 0,
    # (1, 1.8) / |.|
    n0 = np.array([1, 1.8]) / math.hypot(1, 1.8)
    dfc, dlc = np.array([-2, -4]), np.array([0, -0.2])
    t0 = np.array([-n0[1], n0[0]])
    w2n = 10 * 0.2 + (dfc @ n0) * (dlc @ n0) + (np.array([1, -1]) @ _unit(-1, 1.8)) * (
        np.array([-0.2, -0.2]) @ _unit(-1, 1.8))
    assert a["w2n_int"] == pytest.approx(w2n, rel=1e-12)
    assert a["w2n_int"] + a["w2t_int"] == pytest.approx(a["w2_int_secant"], rel=1e-12)
    assert (dfc @ t0) * (dlc @ t0) != 0      # the created contact has a tangential part


def _unit(a, b):
    return np.array([a, b]) / math.hypot(a, b)


def _moved(x0, seed):
    return np.asarray(x0, float) + np.random.default_rng(seed).uniform(-0.05, 0.05, (len(x0), 2))


def test_a_chain_is_one_cluster_until_a_link_is_stable():
    x0 = [[2.0 * k, 0.0] for k in range(5)]
    x1 = _moved(x0, 1)
    links = [(k, k + 1) for k in range(4)]
    s0, s, w2 = _pair(5, x0, x1, {c: -1 for c in links})
    a = anatomy(s0, s, 5)
    assert (a["n_unstable"], a["n_clusters"], a["largest_cluster"]) == (4, 1, 4)
    assert a["w2_int_secant"] == pytest.approx(sum(w2.values()), rel=1e-12)
    assert a["w2_int_secant"] < 0
    s0, s, _ = _pair(5, x0, x1, {(0, 1): -1, (1, 2): -1, (2, 3): 1, (3, 4): -1})
    a = anatomy(s0, s, 5)
    assert (a["n_unstable"], a["n_clusters"], a["largest_cluster"]) == (3, 2, 2)
    label, sizes = unstable_clusters(own_work(s0, s).keys, own_work(s0, s).w2 < 0, 5)
    assert sizes.tolist() == [2, 1] and label.tolist() == [0, 0, -1, 1]
    # the chain's backbone: disks 1-3 have two contacts, C_b = (1, 2), (2, 3): z = 2 * 2 / 3
    assert a["coordination"] == pytest.approx(4 / 3, rel=1e-15)


def test_a_star_through_one_disk_is_one_cluster():
    # disk 0 at the centre touching 1..6; a separate pair (7, 8) far away
    ang = np.arange(6) * np.pi / 3
    x0 = np.vstack([[0, 0], np.column_stack([2 * np.cos(ang), 2 * np.sin(ang)]), [[6, 6], [8, 6]]])
    x1 = _moved(x0, 2)
    signs = {(0, k): -1 for k in range(1, 7)}
    signs[(7, 8)] = -1
    s0, s, w2 = _pair(9, x0, x1, signs)
    a = anatomy(s0, s, 9)
    assert (a["n_unstable"], a["n_clusters"], a["largest_cluster"]) == (7, 2, 6)
    # one spoke stable: the other five still meet at disk 0
    signs[(0, 3)] = 1
    s0, s, _ = _pair(9, x0, x1, signs)
    assert [anatomy(s0, s, 9)[k] for k in ("n_unstable", "n_clusters", "largest_cluster")] == [6, 2, 5]


def test_wall_contacts_count_as_unstable_join_their_disks_cluster_and_make_the_backbone():
    # a triangle 0-1-2, disk 3 touching 2 only (a rattler), then touching the left wall too
    x0 = [[0, 0], [2, 0], [1, 1.7], [1, 3.6]]
    x1 = _moved(x0, 3)
    walls = np.array([0.5, 10.0, -10.0, 10.0])     # the left wall 0.5 m left of disk 3
    tri = {(0, 1): 1, (1, 2): 1, (0, 2): -1, (2, 3): -1}
    s0, s, w2 = _pair(4, x0, x1, tri, walls=walls)
    a = anatomy(s0, s, 4)
    # backbone {0, 1, 2}: C_b = 3, z = 2 * 3 / 3; the contact (2, 3) is not between two of them;
    # the unstable (0, 2) and (2, 3) share disk 2
    assert a["coordination"] == pytest.approx(2.0, rel=1e-15)
    assert (a["n_unstable"], a["n_clusters"], a["largest_cluster"]) == (2, 1, 2)
    tri[(3, "w", 0)] = -1
    s0, s, w2 = _pair(4, x0, x1, tri, walls=walls, sliding={(0, 2)})
    a = anatomy(s0, s, 4)
    assert a["sliding_share"] == 0.25         # of the four grain contacts, not of all five
    # the wall contact: unstable, in the cluster of its disk 3 (linked to (2, 3) through disk 3,
    # which (0, 2) joins through disk 2), counted as a wall contact; disk 3 (one grain and one
    # wall contact) joins the backbone: N_b = 4, C_b = 4
    assert (a["n_unstable"], a["n_clusters"], a["largest_cluster"]) == (3, 1, 3)
    assert a["n_unstable_walls"] == 1
    assert a["coordination"] == pytest.approx(2.0, rel=1e-15)
    assert a["w2_int_secant"] == pytest.approx(sum(w2.values()), rel=1e-12)
    assert a["w2n_int"] + a["w2t_int"] == pytest.approx(sum(v for c, v in w2.items() if c[1] != "w"),
                                                        rel=1e-12)


def test_two_contacts_on_one_wall_are_not_linked_through_it():
    # disks 0 and 1 far apart, each on the left wall, both wall contacts unstable: two clusters
    x0 = [[1.0, 0.0], [1.0, 6.0]]
    x1 = _moved(x0, 4)
    walls = np.array([0.5, 10.0, -10.0, 10.0])
    s0, s, _ = _pair(2, x0, x1, {(0, "w", 0): -1, (1, "w", 0): -1}, walls=walls)
    a = anatomy(s0, s, 2)
    assert (a["n_unstable"], a["n_unstable_walls"], a["n_clusters"], a["largest_cluster"]) == \
        (2, 2, 2, 1)


def test_states_of_another_number_of_disks_are_refused():
    s0 = _state(2, [[0, 0], [2, 0]], {(0, 1): (-10, 0)})
    with pytest.raises(ValueError, match="n_disks"):
        anatomy(s0, s0, 3)
    s3 = _state(3, [[0, 0], [2, 0], [4, 0]], {(0, 1): (-10, 0)})
    with pytest.raises(ValueError, match="one sample"):
        own_work(s0, s3)


def _union_find(keys, unstable, n):
    """Clusters of the unstable contacts, grain and wall, by brute force: union-find over every
    pair of unstable contacts that share a disk (a wall contact has its one disk; a wall is not a
    disk).  Returns the clusters as sorted lists of contact rows."""
    i, j, grain = split_keys(keys, n)
    disks = lambda a: {i[a], j[a]} if grain[a] else {i[a]}
    nodes = [a for a in range(len(keys)) if unstable[a]]
    parent = {a: a for a in nodes}

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for u in range(len(nodes)):
        for v in range(u + 1, len(nodes)):
            a, b = nodes[u], nodes[v]
            if disks(a) & disks(b):
                parent[find(a)] = find(b)
    groups = {}
    for a in nodes:
        groups.setdefault(find(a), []).append(a)
    return sorted((sorted(g) for g in groups.values()), key=lambda g: (-len(g), g[0]))


@pytest.mark.parametrize("share", [0.1, 0.3, 0.5, 0.8])
def test_clusters_match_a_brute_force_union_find(small_sample, share):
    sim = Simulation(small_sample)
    s = contact_state(sim)
    rng = np.random.default_rng(int(share * 10))
    unstable = rng.random(len(s.keys)) < share       # wall contacts among them
    _, _, grain = split_keys(s.keys, sim.n)
    assert np.any(unstable & ~grain)
    label, sizes = unstable_clusters(s.keys, unstable, sim.n)
    ref = _union_find(s.keys, unstable, sim.n)
    assert sizes.tolist() == [len(g) for g in ref]
    # the same partition, numbered by decreasing size then first contact
    assert [sorted(np.flatnonzero(label == c).tolist()) for c in range(len(ref))] == ref
    assert np.all(label[~unstable] == -1)


# ------------------------------------------------------------------------------------------
# Real samples
# ------------------------------------------------------------------------------------------
def test_contact_state_of_two_disks_and_a_wall():
    p = DemParams(n=3)
    r = np.full(3, 0.01)
    # disks 0 and 1 overlap by 1e-4 m along (0.6, 0.8); disk 2 overlaps the top wall by 2e-4 m
    x = np.array([[0.0, 0.0], [0.6 * 0.0199, 0.8 * 0.0199], [0.1, 0.0902]])
    walls = np.array([-0.05, 0.2, -0.05, 0.1])
    sim = Simulation.new(p, x, r, walls)
    s = contact_state(sim)
    n = 3
    assert s.keys.tolist() == [0 * (n + 4) + 1, 2 * (n + 4) + n + 3]
    nrm = np.array([0.6, 0.8])
    assert s.normal[0] == pytest.approx(nrm, rel=1e-12)
    assert s.branch[0] == pytest.approx(0.0199 * nrm, rel=1e-12)
    assert s.fn[0] == pytest.approx(p.kn * 1e-4, rel=1e-9)
    assert s.force[0] == pytest.approx(-p.kn * 1e-4 * nrm, rel=1e-9)     # pushes 0 away from 1
    assert s.ft[0] == 0.0 and not s.sliding[0]
    assert s.normal[1].tolist() == [0.0, 1.0]
    assert s.branch[1] == pytest.approx([0.0, 0.0098], rel=1e-9)
    assert s.force[1] == pytest.approx([0.0, -p.kn * 2e-4], rel=1e-9)    # the top wall pushes down
    assert s.fn[1] == pytest.approx(p.kn * 2e-4, rel=1e-9)


def _sheared(state, mu=None, rolling=0.0):
    """A Simulation of ``state`` (on one thread) with its walls moving: x walls open, y walls
    close at 0.5 and 2 /s (contacts slide, open and close).  ``mu``, ``rolling``: another
    friction, rolling resistance."""
    if rolling:
        state = state._replace(params=state.params.replace(rolling_friction=rolling), mu_r=rolling)
    if mu is not None:
        state = state._replace(mu=mu)
    sim = Simulation(state)
    sim.threads = ThreadChooser(sim.n, 1)
    sim.set_control(strain_rate(-0.5, 2.0, sim.ref_len))
    return sim


@pytest.fixture(scope="module")
def sample300():
    from dem.sample import compact
    sim, rep = compact(DemParams(n=300, seed=5))
    assert rep.converged
    return sim.state()


def _at_step(sim):
    """The last step's positions, walls and contacts, computed here: x - dt v, the walls back by
    their last inward move, ``kernels.contact_snapshot`` there; and the disks' net forces."""
    xs = sim.x - sim.dt * sim.v
    ws = sim.walls - np.array([1.0, -1.0, 1.0, -1.0]) * sim.prev
    pl = sim.pairs
    snap = kernels.contact_snapshot(xs, sim.r, pl.pi, pl.pj, pl.ft, ws, sim.params.kn)
    ci, cj, fx, fy, _, wp, ww, wf = snap
    return xs, ws, snap, kernels.net_forces(sim.n, xs, ci, cj, fx, fy, wp, ww, wf)


def _reference(at0, at, n):
    """The anatomy since 0 by an independent per-contact reference: dictionaries keyed by the
    disks (as ``dem.probes.run_probe`` builds its sums), plain loops, union-find; ``at0``,
    ``at``: ``_at_step`` at 0 and now."""
    (x0, walls0, snap0, _), (x, walls, snap, _) = at0, at
    snap0 = dict(zip(("ci", "cj", "fx", "fy", "fn", "wp", "ww", "wf"), snap0))
    snap = dict(zip(("ci", "cj", "fx", "fy", "fn", "wp", "ww", "wf"), snap))
    from types import SimpleNamespace
    snap0, snap = SimpleNamespace(**snap0), SimpleNamespace(**snap)
    c0 = {(int(i), int(j)): np.array([fx, fy]) for i, j, fx, fy in zip(snap0.ci, snap0.cj, snap0.fx, snap0.fy)}
    c1 = {(int(i), int(j)): np.array([fx, fy]) for i, j, fx, fy in zip(snap.ci, snap.cj, snap.fx, snap.fy)}
    w0 = {(int(p), int(w)): f for p, w, f in zip(snap0.wp, snap0.ww, snap0.wf)}
    w1 = {(int(p), int(w)): f for p, w, f in zip(snap.wp, snap.ww, snap.wf)}
    zero = np.zeros(2)
    w2n = w2t = w2w = 0.0
    own = {}
    for (i, j) in set(c0) | set(c1):
        df = c1.get((i, j), zero) - c0.get((i, j), zero)
        l0, l1 = x0[j] - x0[i], x[j] - x[i]
        dl = l1 - l0
        nc = l0 / np.linalg.norm(l0)
        tc = np.array([-nc[1], nc[0]])
        w2n += (df @ nc) * (dl @ nc)
        w2t += (df @ tc) * (dl @ tc)
        own[(i, j)] = df @ dl
    for (p, w) in set(w0) | set(w1):
        sgn = 1.0 if w % 2 == 0 else -1.0       # the force on the disk along the wall's axis
        ax = w // 2
        dfw = sgn * (w1.get((p, w), 0.0) - w0.get((p, w), 0.0))
        dlw = (walls[w] - x[p, ax]) - (walls0[w] - x0[p, ax])
        w2w += dfw * dlw
        own[(p, n + w)] = dfw * dlw
    bad = [c for c, v in own.items() if v < 0]
    keys = np.sort(np.array([i * (n + 4) + j for i, j in bad], np.int64).reshape(-1))
    clusters = _union_find(keys, np.ones(len(keys), bool), n)
    cnt = np.zeros(n, int)
    for i, j in c1:
        cnt[i] += 1
        cnt[j] += 1
    for p, _ in w1:
        cnt[p] += 1
    nb = int(np.sum(cnt >= 2))
    cb = sum(1 for i, j in c1 if cnt[i] >= 2 and cnt[j] >= 2)
    return {"grain_now": len(c1), "contacts_lost": len(set(c0) - set(c1)), "contacts_created": len(set(c1) - set(c0)),
            "coordination": 2 * cb / nb, "n_unstable": len(bad),
            "n_unstable_walls": sum(1 for c in bad if c[1] >= n),
            "n_clusters": len(clusters), "largest_cluster": max(map(len, clusters), default=0),
            "w2n_int": w2n, "w2t_int": w2t, "w2_int_secant": w2n + w2t + w2w}


def test_a_sheared_sample_against_eq14_and_a_per_contact_reference(sample300):
    sim = _sheared(sample300)
    sim.run(1)                       # a first step: the step positions differ from the present
    at0 = at_prev = _at_step(sim)
    s0 = s_prev = contact_state(sim)
    seen = {"lost": 0, "created": 0, "clusters": 0, "increments": 0}
    for _ in range(8):
        sim.run(500)
        s = contact_state(sim)
        a = anatomy(s0, s, sim.n)
        at = _at_step(sim)
        # the unstable contacts of the increment (since the last check) against the reference's
        inc, ref_inc = anatomy(s0, s, sim.n, s_prev), _reference(at_prev, at, sim.n)
        for k in ("n_unstable", "n_unstable_walls", "n_clusters", "largest_cluster"):
            assert inc[k] == ref_inc[k], k
        assert inc["n_unstable_raw"] == inc["n_unstable"]          # tau = 0
        seen["increments"] += 0 < inc["n_unstable"] != a["n_unstable"]
        at_prev, s_prev = at, s
        # the paper's Eq. 14 (secant) at the step's positions: the contacts' sum is the walls'
        # second-order work less the unbalanced forces' sum_p dF_p . dx_p, to round-off
        g = [np.bincount(z[2][6], weights=z[2][7], minlength=4) for z in (at0, at)]
        w_walls = float(np.sum((g[1] - g[0]) * (at[1] - at0[1]) * INWARD))
        unb = float(np.sum((at[3] - at0[3]) * (at[0] - at0[0])))
        cw = contact_work(s0, s)
        assert cw == pytest.approx(a["w2_int_secant"], rel=1e-12)   # one sum in two orders
        assert abs(cw - (w_walls - unb)) <= 1e-10 * (abs(cw) + abs(w_walls) + abs(unb))
        ref = _reference(at0, at, sim.n)
        for k in ("contacts_lost", "contacts_created", "n_unstable", "n_unstable_walls",
                  "n_clusters", "largest_cluster"):
            assert a[k] == ref[k], k
        assert a["coordination"] == pytest.approx(ref["coordination"], rel=1e-15)
        _, _, g = split_keys(s.keys, sim.n)
        assert a["sliding_share"] == np.count_nonzero(s.sliding[g]) / ref["grain_now"]
        # sums of a few hundred terms of either sign: round-off relative to their magnitudes
        scale = np.abs(own_work(s0, s).w2).sum()
        for k in ("w2n_int", "w2t_int", "w2_int_secant"):
            assert abs(a[k] - ref[k]) <= 1e-12 * scale, k
        seen["lost"] += a["contacts_lost"] > 0
        seen["created"] += a["contacts_created"] > 0
        seen["clusters"] += a["n_clusters"] > 1
    assert sim.n_rebuilds > 0                    # the keys went through neighbour-list rebuilds
    assert min(seen.values()) > 0, seen          # the cases the reference must meet occurred
    assert 0 < a["sliding_share"] < 1


def _kernel_decisions(sim, rolling):
    """Per grain-contact key of the next step: whether the kernel's law caps the tangential
    force (the one-loop reference step's ``_law``) and, with rolling resistance, the moment."""
    p = sim.params
    pl = sim.pairs
    out = {}
    for k in range(len(pl.pi)):
        i, j = int(pl.pi[k]), int(pl.pj[k])
        dx, dy = sim.x[j] - sim.x[i]
        dv = sim.v[j] - sim.v[i]
        rs = sim.r[i] + sim.r[j]
        _, _, _, capped = _law(dx, dy, rs, dv[0], dv[1], sim.w[i] * sim.r[i] + sim.w[j] * sim.r[j],
                               pl.ft[k], 0.0, p.kn, p.kt, sim.mu, sim.cap_on, 0.0, sim.dt)
        roll = False
        if rolling and dx * dx + dy * dy < rs * rs:
            rstar = sim.r[i] * sim.r[j] / rs
            m_trial = pl.mr[k] - p.rolling_stiffness * p.kt * rstar ** 2 * (sim.w[i] - sim.w[j]) * sim.dt
            roll = sim.cap_on and abs(m_trial) > sim.mu_r * rstar * p.kn * (rs - math.hypot(dx, dy))
        out[i * (sim.n + 4) + j] = (capped, roll)
    return out


@pytest.mark.parametrize("rolling", [0.0, 0.05])
def test_the_sliding_flag_is_the_kernels_coulomb_decision(sample300, rolling):
    # a low friction so that many contacts slide; after 1500 steps of shear, one more step: the
    # flags of contact_state are the caps the kernel's law applied in that step
    sim = _sheared(sample300, mu=0.1, rolling=rolling)
    sim.run(1500)
    dec = _kernel_decisions(sim, rolling)
    sim.run(1)
    s = contact_state(sim)
    _, _, grain = split_keys(s.keys, sim.n)
    keys = s.keys[grain]
    exp = np.array([dec[int(k)][0] for k in keys])
    assert exp.sum() >= 10 and (~exp).sum() >= 10
    assert np.array_equal(s.sliding[grain], exp)
    if rolling:
        exp_r = np.array([dec[int(k)][1] for k in keys])
        assert exp_r.sum() >= 5
        assert np.array_equal(s.rolling[grain], exp_r)
    else:
        assert not s.rolling.any()
    # against the normal force at the current positions instead of the step's, the sliding
    # contacts would not be found: that is why contact_state goes back one step (its fn is the
    # step's, which the flag and the force share)
    i, j, _ = split_keys(keys, sim.n)
    fn_now = sim.params.kn * (sim.r[i] + sim.r[j] - np.hypot(*(sim.x[j] - sim.x[i]).T))
    naive = np.abs(s.ft[grain]) >= (1 - SLIDE_TOL) * sim.mu * fn_now
    assert not np.array_equal(naive, exp)
    assert np.array_equal(np.abs(s.ft[grain]) >= (1 - SLIDE_TOL) * sim.mu * s.fn[grain], exp)
    # the elastic probes' law (cap off): nothing slides
    sim.cap_on = False
    assert not contact_state(sim).sliding.any()


def test_force_is_minus_fn_n_plus_ft_t_and_keys_are_sorted(sample300):
    sim = _sheared(sample300, rolling=0.05)
    sim.run(1000)
    s = contact_state(sim)
    assert np.all(np.diff(s.keys) > 0)
    t = np.column_stack([-s.normal[:, 1], s.normal[:, 0]])
    fmax = np.abs(s.force).max()
    assert np.abs(s.force - (-s.fn[:, None] * s.normal + s.ft[:, None] * t)).max() <= 1e-12 * fmax
    assert np.abs(np.hypot(s.normal[:, 0], s.normal[:, 1]) - 1).max() <= 1e-15
    assert np.all(np.sum(s.branch * s.normal, 1) > 0)                 # the normal along l
    assert np.abs(s.moment).max() > 0
    # one time: the positions, walls, branches and normal forces of the last step's force
    # evaluation (x - dt v, the walls back by their last move), not of the present
    xs, ws, snap, _ = _at_step(sim)
    assert np.array_equal(s.x, xs) and np.array_equal(s.walls, ws)
    assert not np.array_equal(s.x, sim.x) and not np.array_equal(s.walls, sim.walls)
    assert np.array_equal(s.branch, np.asarray(branches(s.keys, xs, ws)))
    i, j, grain = split_keys(s.keys, sim.n)
    d = np.hypot(*(xs[j[grain]] - xs[i[grain]]).T)
    assert np.allclose(s.fn[grain], sim.params.kn * (sim.r[i[grain]] + sim.r[j[grain]] - d),
                       rtol=1e-9, atol=0)
    assert len(s.keys) == len(snap[0]) + len(snap[5])
    assert np.array_equal(step_positions(sim)[0], xs)


# ------------------------------------------------------------------------------------------
# The velocity fluctuation, the VTU files, the figure
# ------------------------------------------------------------------------------------------
def test_the_affine_field_of_the_walls(sample300):
    sim = _sheared(sample300)
    sim.run(200)
    vw = wall_velocities(sim)
    # strain control: each wall moves at rate L0 / 2, inward positive; the x walls open (-0.5)
    # and the y walls close (2 /s)
    w0, h0 = sim.ref_len
    assert vw == pytest.approx([-0.25 * w0, 0.25 * w0, h0, -h0], rel=1e-12)
    # disks moving with the affine field have no fluctuation; a disk at a wall moves with it
    wl = sim.walls
    sim.v[:, 0] = vw[0] + (sim.x[:, 0] - wl[0]) * (vw[1] - vw[0]) / (wl[1] - wl[0])
    sim.v[:, 1] = vw[2] + (sim.x[:, 1] - wl[2]) * (vw[3] - vw[2]) / (wl[3] - wl[2])
    assert np.abs(velocity_fluctuation(sim)).max() <= 1e-15 * np.abs(vw).max()
    # the field in the paper's words: the box's centre, plus the walls' strain rate times
    # (x - centre), compression (walls moving in) negative
    cen = 0.5 * (wl[[0, 2]] + wl[[1, 3]])
    rate = (vw[[1, 3]] - vw[[0, 2]]) / (wl[[1, 3]] - wl[[0, 2]])
    assert rate[1] < 0 < rate[0]
    v_aff = 0.5 * (vw[[0, 2]] + vw[[1, 3]]) + (sim.x - cen) * rate
    sim.v[:] = v_aff + 1e-3
    assert velocity_fluctuation(sim) == pytest.approx(np.full((sim.n, 2), 1e-3), rel=1e-9)


def test_the_vtu_files_read_back(sample300, tmp_path):
    import meshio
    sim = _sheared(sample300)
    s0 = contact_state(sim)
    sim.run(2000)
    sp = contact_state(sim)
    sim.run(1000)
    paths = write_anatomy_vtk(tmp_path, "past_onset", sim, s0, sp)
    assert [os.path.basename(p) for p in paths] == ["disks_past_onset.vtu", "contacts_past_onset.vtu"]
    assert sorted(os.listdir(tmp_path)) == ["contacts_past_onset.vtu", "disks_past_onset.vtu"]
    d = meshio.read(paths[0])
    assert np.array_equal(d.points[:, :2], sim.x)
    assert np.array_equal(d.point_data["radius"], sim.r)
    assert np.array_equal(d.point_data["velocity_fluctuation"][:, :2], velocity_fluctuation(sim))
    assert np.array_equal(d.point_data["spin"], sim.w)
    s = contact_state(sim)
    snap = sim.snapshot()
    cnt = np.bincount(snap.ci, minlength=sim.n) + np.bincount(snap.cj, minlength=sim.n) + \
        np.bincount(snap.wp, minlength=sim.n)
    assert np.array_equal(d.point_data["n_contacts"], cnt)
    c = meshio.read(paths[1])
    ow = own_work(s0, s)
    i, j, grain = split_keys(ow.keys, sim.n)
    lines = c.cells_dict["line"]
    assert np.array_equal(lines, np.column_stack([i[grain], j[grain]]))
    cd = {k: v[0] for k, v in c.cell_data.items()}
    assert np.array_equal(cd["w2"], ow.w2[grain])
    assert np.array_equal(cd["w2_sign"], np.sign(ow.w2[grain]))
    assert np.array_equal(cd["present"], ow.present[grain])
    assert (cd["present"] == 0).sum() > 0             # lost contacts are drawn, with no force
    assert np.all(cd["normal_force"][cd["present"] == 0] == 0)
    now = np.searchsorted(s.keys, ow.keys[grain][cd["present"] == 1])
    assert np.array_equal(cd["normal_force"][cd["present"] == 1], s.fn[now])
    assert np.array_equal(cd["sliding"][cd["present"] == 1], s.sliding[now])
    assert np.allclose(cd["force"][cd["present"] == 1],
                       np.hypot(s.force[now, 0], s.force[now, 1]), rtol=1e-12)
    # the increment (sp to now): its own W2 and clusters on the contacts at 0 or now
    inc = own_work(sp, s)
    lab, sizes = unstable_clusters(inc.keys, inc.w2 < 0, sim.n)
    at = {int(k): a for a, k in enumerate(inc.keys)}
    exp_w2 = [inc.w2[at[int(k)]] if int(k) in at else 0.0 for k in ow.keys[grain]]
    exp_lab = [lab[at[int(k)]] if int(k) in at else -1 for k in ow.keys[grain]]
    assert np.array_equal(cd["w2_increment"], exp_w2)
    assert np.array_equal(cd["cluster"], exp_lab)
    assert (cd["cluster"] == 0).sum() <= sizes[0] and (cd["cluster"] == 0).sum() > 0
    assert not np.array_equal(np.sign(cd["w2_increment"]), cd["w2_sign"])
    # without the increment: the clusters of the secant since 0, w2_increment 0
    write_anatomy_vtk(tmp_path / "s", "since0", sim, s0)
    c = {k: v[0] for k, v in meshio.read(tmp_path / "s" / "contacts_since0.vtu").cell_data.items()}
    label, sizes = unstable_clusters(ow.keys, ow.w2 < 0, sim.n)
    assert np.array_equal(c["cluster"], label[grain]) and not c["w2_increment"].any()
    # a tag that is not a file name part is refused before anything is written
    with pytest.raises(ValueError, match="tag="):
        write_anatomy_vtk(tmp_path / "sub", "../x", sim, s0)
    assert not (tmp_path / "sub").exists()


def test_the_figure(sample300, tmp_path):
    sim = _sheared(sample300)
    s0 = contact_state(sim)
    sim.run(1000)
    a = Simulation(sim.state())
    sim.run(2000)
    path = tmp_path / "anatomy.png"
    plot_anatomy(path, [("below", a, s0), ("past", sim, s0, contact_state(a))])
    with open(path, "rb") as f:
        assert f.read(8) == b"\x89PNG\r\n\x1a\n"
    assert os.listdir(tmp_path) == ["anatomy.png"]
    with pytest.raises(ValueError, match="panels"):
        plot_anatomy(tmp_path / "none.png", [])
