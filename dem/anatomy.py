"""The anatomy of a burst at the grain scale: which contacts give up second-order work, where,
and how they gather (``docs/dem.md``, "The anatomy of a burst").

Hadda, Nicot, Wan & Darve (2015, 2D DEM, drained and proportional strain paths): the contacts
whose own second-order work is negative ("unstable contacts") gather in clusters; a sustained
growth of the clusters goes with localized failure, small clusters whose growth stops with
diffuse failure.  Nicot et al. (2014): the macroscopic W2 equals the sum over the contacts
(paper Eq. 15); failure comes with contacts opening and sliding.

* ``contact_state(sim) -> ContactState``: the grain and wall contacts of a ``Simulation`` at one
  instant, the positions of the last step's force evaluation (``step_positions``: the force,
  the branch and the sliding flag of one time), keyed so that the keys survive the
  neighbour-list rebuilds (grain i (N + 4) + j with i < j, wall p (N + 4) + N + w), with the
  force on the first disk, the branch, the unit normal, the normal and tangential forces, the
  rolling moment and whether the contact slides (and rolls) at its cap; and the positions and
  walls of that instant.
* ``anatomy(s0, s, n_disks, s_prev) -> dict`` of the ``ANATOMY_COLUMNS``: what changed between
  t = 0 (``s0``) and now, and the unstable contacts of the last increment (``s_prev`` to now,
  ``UNSTABLE_WINDOW`` checks: Hadda et al.'s d f . d l over a small loading increment).
* ``contact_work(s0, s)``: the paper's Eq. 15 sum between two instants.
* ``write_anatomy_vtk`` (ParaView: disks with their velocity fluctuation, contacts with their own
  W2) and ``plot_anatomy`` (the sample, its negative-W2 contacts, its clusters and velocity
  fluctuation, one panel per state).

Conventions (as ``dem.probes`` and ``dem.burst``): f the force on the first disk by the second
(or by the wall) [N], l the branch from the first disk to the second, x_j - x_i (wall: from the
disk to the wall along the wall's axis) [m]; a contact's own second-order work between two
instants a and b is w2_c = (f(b) - f(a)) . (l(b) - l(a)) [J], over the union of the contacts at
a and b, f = 0 where a contact is absent, its branch then the one the positions give (paper
Eq. 15); an elastic contact being loaded gives w2_c > 0.  These functions run at the checks
only (every 1000 steps): NumPy, no kernel of their own.

**Unstable contacts above their noise.** Counted over the whole time since t = 0 (a secant over
1e5 steps and ~1 % of strain) with the threshold at exactly 0, a packing held without any change
of load showed 16 % of its contacts "unstable" (300 disks): the count was noise. Hadda et al.
take a contact's d f . d l over a small loading increment; here the increment is the last
``UNSTABLE_WINDOW`` checks (5000 steps at the checks' 1000), and the noise of the count is
measured on the same state held with no change of load (``dem.burst``: each switch's
``baseline`` run), whose counts are reported beside the run's, with the excess.
"""
from __future__ import annotations

import math
import os
import re
from typing import NamedTuple

import numpy as np

# the history columns of a check (``dem burst``'s history.csv, ``dem probes``'
# probe_histories.csv), in this order; ``anatomy`` returns exactly these keys
ANATOMY_COLUMNS = ["sliding_share", "contacts_lost", "contacts_created", "coordination",
                   "n_unstable_raw", "n_unstable", "n_unstable_walls", "n_clusters",
                   "largest_cluster", "w2n_int", "w2t_int", "w2_int_secant"]
# the increment of the unstable contacts: the last this many checks (``dem.settle``)
UNSTABLE_WINDOW = 5
# an unstable contact's d f . d l is below -UNSTABLE_TAU times the contacts' energy scale at the
# start, mean fn^2 / kn (``energy_scale``): for a contact loaded along its normal, d f . d l ~
# kn dl^2, so the threshold is a relative change of its overlap of about 1 % over the increment.
# Measured at 2000 disks (the 2000-disk staircase's last equilibrium, increments of 5000 steps
# over 0.42 s): held with no change of load, 740-1050 contacts of 2940 have d f . d l < 0 (the raw
# count), 7-298 below -1e-8, 0-63 below -1e-6 (a slip), 0-1 below -1e-4 of the scale; held at
# +100 Pa (it bursts), 468 below -1e-4 at the first increment, 728-1123 after
UNSTABLE_TAU = 1e-4
INWARD = np.array([1.0, -1.0, 1.0, -1.0])     # a wall's inward direction along its axis

# A contact slides when |f_t| >= (1 - SLIDE_TOL) mu fn, fn the normal force of the step that set
# f_t (positions x - dt v).  Those positions are the kernel's to a rounding of x (1e-16 m
# against overlaps of 1e-9 - 1e-5 m).  Measured on a 1000-disk sample flowing under stress
# control (three checks): the sliding contacts' |f_t| / mu fn lie within 5e-10 of 1, the
# nearest others below 1 - 4e-4; against the normal force at the current positions instead, no
# contact lies within 1e-4 of 1 and the ratios reach 2.0 (fn moves by kn v dt in a step).
SLIDE_TOL = 1e-6


class ContactState(NamedTuple):
    """The contacts of a Simulation at one instant (copies; K contacts, N disks), sorted by key.

    keys (K,) int64: grain contact i (N + 4) + j (i < j), wall contact p (N + 4) + N + w (w the
    wall index: 0 left, 1 right, 2 bottom, 3 top); force (K, 2) on the first disk [N]; branch
    (K, 2) [m]; normal (K, 2) the unit normal from the first disk to the second (to the wall);
    fn (K,) normal force [N] (>= 0, compression), ft (K,) tangential force [N] along
    t = z x n = (-n_y, n_x) (0 at the frictionless walls), so force = -fn n + ft t; moment (K,)
    rolling moment on the first disk [N m] (0 without rolling resistance and at walls);
    sliding (K,) |f_t| at the Coulomb cap mu fn (``SLIDE_TOL``; never with the cap off, the
    elastic probes'; never at walls); rolling (K,) |M| at its cap mu_r R* fn (the same rule;
    never without rolling resistance); x (N, 2) disk positions [m]; walls (4,) wall positions
    [x_left, x_right, y_bottom, y_top] [m]."""
    keys: np.ndarray
    force: np.ndarray
    branch: np.ndarray
    normal: np.ndarray
    fn: np.ndarray
    ft: np.ndarray
    moment: np.ndarray
    sliding: np.ndarray
    rolling: np.ndarray
    x: np.ndarray
    walls: np.ndarray


def _at_cap(value, limit):
    """|value| at its cap ``limit`` (> 0) to ``SLIDE_TOL``."""
    return (limit > 0.0) & (np.abs(value) >= (1.0 - SLIDE_TOL) * limit)


def step_positions(sim):
    """The positions (N, 2) and walls (4,) [m] of the last step's force evaluation, x(n) and
    walls(n) when ``sim`` is at x(n+1): the leapfrog's x(n+1) = x(n) + dt v(n+1/2) gives x - dt v,
    the walls' last move ``prev`` (inward) gives walls - INWARD prev.  The tangential forces and
    rolling moments the pair list holds were set there."""
    return sim.x - sim.dt * sim.v, sim.walls - INWARD * sim.prev


def contact_state(sim) -> ContactState:
    """The contacts of ``sim`` at the positions of the last step's force evaluation
    (``step_positions``), as a ContactState: the grain contacts that touch there, with the
    tangential force and rolling moment that step set (the pair list's history) and the normal
    force kn overlap there, and the wall contacts there; the branches, positions and walls of
    that instant too, so that force, branch and sliding flag belong to one time (with the
    normal dashpot, whose force needs v(n-1/2), its part of the sliding test is taken at
    v(n+1/2): the flag is then approximate; the forces are the elastic parts)."""
    from . import kernels
    p = sim.params
    n, base = sim.n, sim.n + 4
    xs, ws = step_positions(sim)
    pl = sim.pairs
    ci, cj, fx, fy, fn, wp, ww, wf = kernels.contact_snapshot(xs, sim.r, pl.pi, pl.pj, pl.ft,
                                                              ws, p.kn)
    # the snapshot keeps the pair list's order, which is sorted by (pi, pj): each contact's pair
    # index (its rolling history) by a search on the keys
    k = np.searchsorted(pl.pi.astype(np.int64) * base + pl.pj, ci * base + cj)
    branch_g = xs[cj] - xs[ci]
    normal_g = branch_g / np.hypot(branch_g[:, 0], branch_g[:, 1])[:, None]
    force_g = np.column_stack([fx, fy])
    ft_g = pl.ft[k].copy()
    mr_g = pl.mr[k].copy()
    # the normal force of the step that set f_t and M (the kernel's _normal_force)
    ds = branch_g
    rs = sim.r[ci] + sim.r[cj]
    fn_s = fn.copy()
    if p.normal_damping_ratio > 0.0:
        meff = sim.m[ci] * sim.m[cj] / (sim.m[ci] + sim.m[cj])
        vn = np.sum((sim.v[cj] - sim.v[ci]) * ds, axis=1) / np.hypot(ds[:, 0], ds[:, 1])
        fn_s = np.maximum(fn_s - 2.0 * p.normal_damping_ratio * np.sqrt(p.kn * meff) * vn, 0.0)
    if sim.cap_on:
        sliding_g = _at_cap(ft_g, sim.mu * fn_s)
        rstar = sim.r[ci] * sim.r[cj] / rs
        rolling_g = (_at_cap(mr_g, sim.mu_r * rstar * fn_s) if sim.mu_r > 0.0
                     else np.zeros(len(ci), bool))
    else:
        sliding_g = rolling_g = np.zeros(len(ci), bool)
    # wall contacts: the normal along the wall's axis, towards the wall
    axis = ww // 2
    towards = np.where(ww % 2 == 0, -1.0, 1.0)          # left and bottom walls lie at lower x, y
    rows = np.arange(len(wp))
    normal_w = np.zeros((len(wp), 2))
    normal_w[rows, axis] = towards
    branch_w = np.zeros((len(wp), 2))
    branch_w[rows, axis] = ws[ww] - xs[wp, axis]
    force_w = -wf[:, None] * normal_w
    keys = np.concatenate([ci * base + cj, wp * base + n + ww])
    order = np.argsort(keys, kind="stable")
    cat = lambda g, w: np.concatenate([g, w])[order]
    zw = np.zeros(len(wp))
    return ContactState(keys[order], cat(force_g, force_w), cat(branch_g, branch_w),
                        cat(normal_g, normal_w), cat(fn, wf), cat(ft_g, zw),
                        cat(mr_g, zw), cat(sliding_g, zw.astype(bool)),
                        cat(rolling_g, zw.astype(bool)), xs, ws)


def branches(keys, x, walls):
    """Branch (K, 2) of each contact key [m] at positions ``x`` (N, 2) and ``walls`` (4,): x_j -
    x_i, or from the disk to its wall along the wall's axis."""
    n = len(x)
    i, j = keys // (n + 4), keys % (n + 4)
    out = np.zeros((len(keys), 2))
    g = j < n
    out[g] = x[j[g]] - x[i[g]]
    w = ~g
    wl = j[w] - n
    out[np.flatnonzero(w), wl // 2] = walls[wl] - x[i[w], wl // 2]
    return out


def split_keys(keys, n_disks):
    """(i, j, grain) of contact keys: the first disk, the second disk or N + wall, and whether
    it is a grain contact."""
    base = n_disks + 4
    i, j = keys // base, keys % base
    return i, j, j < n_disks


class OwnWork(NamedTuple):
    """Each contact's own secant second-order work between two ContactStates, over the union of
    their contacts (K,): keys (sorted), df and dl (K, 2) [N, m], l0 (K, 2) the branch at 0 [m],
    w2 = df . dl (K,) [J], present (K,) whether the contact exists now, existed (K,) at 0."""
    keys: np.ndarray
    df: np.ndarray
    dl: np.ndarray
    l0: np.ndarray
    w2: np.ndarray
    present: np.ndarray
    existed: np.ndarray


def own_work(s0: ContactState, s: ContactState) -> OwnWork:
    """w2_c = (f - f(0)) . (l - l(0)) of every contact at 0, now or both (f = 0 where absent;
    the branches from the positions of each instant, those of absent contacts included): the
    terms of the paper's Eq. 15 (secant), which ``contact_work`` sums."""
    if len(s0.x) != len(s.x):
        raise ValueError(f"contact states of {len(s0.x)} and {len(s.x)} disks; allowed: the "
                         "states of one sample")
    keys = np.concatenate([s0.keys, s.keys])
    keys.sort()
    keys = keys[np.concatenate([[True], keys[1:] != keys[:-1]])]   # np.union1d, 5x faster here
    a0, a1 = np.searchsorted(keys, s0.keys), np.searchsorted(keys, s.keys)
    present = np.zeros(len(keys), bool)
    existed = np.zeros(len(keys), bool)
    present[a1] = True
    existed[a0] = True
    f0 = np.zeros((len(keys), 2))
    f1 = np.zeros((len(keys), 2))
    f0[a0] = s0.force
    f1[a1] = s.force
    df = f1 - f0

    def branch_of(st, at, there):
        # a state's own branches where the contact exists, the positions' elsewhere (the same
        # numbers: x_j - x_i, wall - x_p)
        out = np.empty((len(keys), 2))
        out[at] = st.branch
        out[~there] = branches(keys[~there], st.x, st.walls)
        return out

    l0 = branch_of(s0, a0, existed)
    dl = branch_of(s, a1, present) - l0
    return OwnWork(keys, df, dl, l0, _dot(df, dl), present, existed)


def energy_scale(s: ContactState, kn: float) -> float:
    """The contacts' energy scale [J]: mean fn^2 / kn over the contacts of ``s`` (twice a mean
    contact's normal elastic energy; 0 without contacts), the unit of ``UNSTABLE_TAU``."""
    return float(np.mean(np.square(s.fn)) / kn) if len(s.fn) else 0.0


def contact_work(s0: ContactState, s: ContactState) -> float:
    """sum_c df . dl [J] between two instants (paper Eq. 15, secant) over the grain and wall
    contacts at either (``own_work``). By Eq. 14 it equals the walls' secant second-order work
    less sum_p dF_p . dx_p (the unbalanced forces'), at the positions of the two instants."""
    return float(np.sum(own_work(s0, s).w2))


def _dot(a, b):
    """Row-wise dot product of (K, 2) arrays (np.sum(a * b, 1), 3x faster)."""
    return a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1]


def unstable_clusters(keys, unstable, n_disks):
    """The clusters of unstable contacts, grain and wall alike: connected components of the
    graph whose nodes are the contacts flagged ``unstable`` and whose edges join two contacts
    that share a disk (a wall contact has one disk; the wall is not a node: two contacts on one
    wall are not linked through it).  Two contacts share a disk exactly when they are edges of
    one connected component of the disks' graph restricted to the grain contacts, a wall
    contact then belonging to its disk's component, so the components are found on the disks
    (scipy.sparse.csgraph; no contact-to-contact graph, whose edges grow as the square of the
    contacts a disk has).  Returns (label (K,) int: the cluster of each contact, -1 for the
    others, clusters numbered by decreasing size then first contact; sizes (clusters,) in
    contacts, decreasing)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    i, j, grain = split_keys(np.asarray(keys), n_disks)
    sel = np.flatnonzero(np.asarray(unstable, bool))
    label = np.full(len(keys), -1, np.int64)
    if len(sel) == 0:
        return label, np.zeros(0, np.int64)
    sg = sel[grain[sel]]
    g = coo_matrix((np.ones(len(sg)), (i[sg], j[sg])), shape=(n_disks, n_disks)).tocsr()
    _, comp = connected_components(g, directed=False)
    c = comp[i[sel]]
    sizes = np.bincount(c)
    first = np.full(len(sizes), len(sel))
    np.minimum.at(first, c, np.arange(len(sel)))
    used = np.flatnonzero(sizes)
    ranked = used[np.lexsort((first[used], -sizes[used]))]
    rank = np.empty(len(sizes), np.int64)
    rank[ranked] = np.arange(len(ranked))
    label[sel] = rank[c]
    return label, sizes[ranked]


def contact_counts(s: ContactState, n_disks):
    """Contacts per disk (N,), grain and wall."""
    i, j, grain = split_keys(s.keys, n_disks)
    return np.bincount(i, minlength=n_disks) + np.bincount(j[grain], minlength=n_disks)


def anatomy(s0: ContactState, s: ContactState, n_disks, s_prev: ContactState | None = None,
            tau: float = 0.0) -> dict:
    """The anatomy of the contacts between t = 0 (``s0``) and now (``s``), and of the last
    increment (``s_prev`` to now; None: since 0), the ``ANATOMY_COLUMNS`` of a check (``tau``
    [J] >= 0: the threshold of an unstable contact; in a run UNSTABLE_TAU x ``energy_scale`` at
    the start, ``dem.settle``):

    * ``sliding_share``: the grain contacts at the Coulomb cap now over the grain contacts now
      (NaN without any);
    * ``contacts_lost``, ``contacts_created``: grain contacts at 0 and not now, now and not at 0;
    * ``coordination``: the backbone's coordination number 2 C_b / N_b, N_b the disks with two
      contacts or more now (wall contacts counted, as ``dem.settle.backbone_kinetic_energy``'s
      backbone), C_b the grain contacts now between two of them (one pass: a disk left with one
      contact by its neighbours' exclusion stays in; NaN with no backbone);
    * ``n_unstable_raw``: the contacts, grain and wall, whose own second-order work over the
      increment is negative, w2_c = (f - f(prev)) . (l - l(prev)) < 0, over the union of the
      contacts at ``s_prev`` and now (``own_work``: Hadda et al.'s d f . d l): mostly noise;
      ``n_unstable``: those with w2_c < -``tau``, the unstable contacts; ``n_unstable_walls``:
      the wall contacts among them;
    * ``n_clusters``, ``largest_cluster``: the clusters of those unstable contacts, grain and
      wall (linked through shared disks, ``unstable_clusters``): their number and the largest's
      size in contacts (0 and 0 without any);
    * ``w2n_int``, ``w2t_int`` [J]: the grain contacts' sum of w2_c split on the normal at 0,
      sum (df . n0)(dl . n0) and sum (df . t0)(dl . t0), n0 = l(0) / |l(0)| (the branch at 0 of
      the positions at 0, for a contact created since as well), t0 = z x n0, as ``dem.probes``'
      w2n, w2t; ``w2_int_secant`` [J]: w2n_int + w2t_int + the wall contacts' w2_c, the paper's
      Eq. 15 sum since 0 (secant), ``contact_work``.
    ``n_disks``: N of the states (their keys are built on it)."""
    if not (len(s0.x) == len(s.x) == n_disks) or (s_prev is not None and len(s_prev.x) != n_disks):
        raise ValueError(f"n_disks={n_disks!r}; allowed: the states' number of disks "
                         f"({len(s0.x)}, {len(s.x)})")
    ow = own_work(s0, s)
    _, _, grain = split_keys(ow.keys, n_disks)
    l0 = ow.l0[grain]
    n0 = l0 / np.hypot(l0[:, 0], l0[:, 1])[:, None]
    t0 = np.column_stack([-n0[:, 1], n0[:, 0]])
    dfg, dlg = ow.df[grain], ow.dl[grain]
    w2n = float(np.sum(_dot(dfg, n0) * _dot(dlg, n0)))
    w2t = float(np.sum(_dot(dfg, t0) * _dot(dlg, t0)))
    w2w = float(np.sum(ow.w2[~grain]))
    if not (math.isfinite(tau) and tau >= 0):
        raise ValueError(f"tau={tau!r}; allowed range: tau >= 0 [J] (finite)")
    inc = ow if s_prev is None else own_work(s_prev, s)
    unstable = inc.w2 < -tau
    _, _, inc_grain = split_keys(inc.keys, n_disks)
    _, sizes = unstable_clusters(inc.keys, unstable, n_disks)
    _, j_now, g_now = split_keys(s.keys, n_disks)
    n_now = int(np.count_nonzero(g_now))
    cnt = contact_counts(s, n_disks)
    i_now = s.keys[g_now] // (n_disks + 4)
    backbone = cnt >= 2
    n_b = int(np.count_nonzero(backbone))
    c_b = int(np.count_nonzero(backbone[i_now] & backbone[j_now[g_now]]))
    return {"sliding_share": (float(np.count_nonzero(s.sliding[g_now])) / n_now if n_now
                              else math.nan),
            "contacts_lost": int(np.count_nonzero(grain & ow.existed & ~ow.present)),
            "contacts_created": int(np.count_nonzero(grain & ow.present & ~ow.existed)),
            "coordination": 2.0 * c_b / n_b if n_b else math.nan,
            "n_unstable_raw": int(np.count_nonzero(inc.w2 < 0.0)),
            "n_unstable": int(np.count_nonzero(unstable)),
            "n_unstable_walls": int(np.count_nonzero(unstable & ~inc_grain)),
            "n_clusters": int(len(sizes)),
            "largest_cluster": int(sizes[0]) if len(sizes) else 0,
            "w2n_int": w2n, "w2t_int": w2t, "w2_int_secant": w2n + w2t + w2w}



# ----------------------------------------------------------------------------------------------
# The field of velocities, the VTU files for ParaView and the figure
# ----------------------------------------------------------------------------------------------
def wall_velocities(sim):
    """Each wall's velocity along its axis (4,) [m/s]: its last step's move (``sim.prev``, the
    servo's or the strain control's inward move, the same half step as the disks' velocities
    v(n+1/2)) over dt."""
    return sim.prev * INWARD / sim.dt


def velocity_fluctuation(sim):
    """v - v_affine (N, 2) [m/s]: the disks' velocities less the affine field of the walls,
    v_affine,a = v_lo + (x_a - w_lo) (v_hi - v_lo) / (w_hi - w_lo) along each axis a (w_lo,
    w_hi the walls of that axis, v_lo, v_hi their velocities, ``wall_velocities``): the velocity
    of the box's centre plus (x - centre) times the walls' strain rate (v_hi - v_lo) / (w_hi -
    w_lo), negative when the walls move in (compression)."""
    vw = wall_velocities(sim)
    lo, hi = sim.walls[[0, 2]], sim.walls[[1, 3]]
    v_aff = vw[[0, 2]] + (sim.x - lo) * ((vw[[1, 3]] - vw[[0, 2]]) / (hi - lo))
    return sim.v - v_aff


def increment_on(keys, s_prev: ContactState | None, s: ContactState, n_disks, tau=0.0):
    """The last increment's own second-order work (``own_work(s_prev, s)``) and its clusters of
    unstable contacts (``unstable_clusters``) on the contact ``keys`` (sorted; e.g. the union of
    the contacts at 0 and now): (w2 (K,) [J], 0 for a key absent from the increment; label (K,),
    -1 for a stable or absent one: unstable below -``tau``). ``s_prev`` None: nothing (zeros,
    -1)."""
    w2 = np.zeros(len(keys))
    label = np.full(len(keys), -1, np.int64)
    if s_prev is None:
        return w2, label
    inc = own_work(s_prev, s)
    lab, _ = unstable_clusters(inc.keys, inc.w2 < -tau, n_disks)
    at = np.searchsorted(inc.keys, keys)
    ok = (at < len(inc.keys)) & (inc.keys[np.minimum(at, len(inc.keys) - 1)] == keys)
    w2[ok] = inc.w2[at[ok]]
    label[ok] = lab[at[ok]]
    return w2, label


def write_anatomy_vtk(out_dir, tag, sim, s0: ContactState, s_prev: ContactState | None = None,
                      tau=None):
    """``out_dir/disks_{tag}.vtu`` and ``out_dir/contacts_{tag}.vtu`` (meshio, written atomically
    as ``dem.io`` writes; ParaView opens them).  Returns their paths.

    Disks: a vertex at each centre, point data ``radius`` [m], ``velocity`` and
    ``velocity_fluctuation`` (``velocity_fluctuation``) [m/s] (3 components, z = 0), ``spin``
    [rad/s], ``n_contacts`` (grain and wall contacts now), ``backbone`` (1 with two contacts or
    more).  Contacts: a line between the two disks' centres now for every grain contact at t = 0
    (``s0``) or now (a contact lost since has zero force), cell data ``w2`` its own secant
    second-order work since 0 [J] (``own_work``), ``w2_sign`` (-1, 0, 1), ``w2_increment`` its
    own second-order work over the last increment (``s_prev`` to now, Hadda et al.'s d f . d l;
    0 without ``s_prev``), ``cluster`` (its cluster of unstable contacts of the increment, w2
    below -``tau`` (default UNSTABLE_TAU x ``energy_scale`` of ``s0``), 0 the largest, -1 for a
    stable one: ``unstable_clusters``; with no ``s_prev``, of the secant since 0), ``present`` (1 now, 0 lost), ``sliding`` (1 at the Coulomb cap), ``rolling`` (1 at the
    rolling cap), ``normal_force`` [N], ``tangential_force`` |f_t| [N], ``force`` |f| [N]."""
    import meshio

    from .io import _atomic_meshio
    if not re.fullmatch(r"[A-Za-z0-9_.+-]+", str(tag)):
        raise ValueError(f"tag={tag!r}; allowed: letters, digits and _ . + - (a file name part)")
    n = sim.n
    s = contact_state(sim)
    ow = own_work(s0, s)
    if tau is None:
        tau = UNSTABLE_TAU * energy_scale(s0, sim.params.kn)
    w2_inc, label = increment_on(ow.keys, s_prev, s, n, tau)
    if s_prev is None:
        label, _ = unstable_clusters(ow.keys, ow.w2 < 0.0, n)
    i, j, grain = split_keys(ow.keys, n)
    now = np.searchsorted(s.keys, ow.keys[grain])
    present = ow.present[grain]

    def pick(a):            # a field of the contacts now, 0 for those lost since 0
        out = np.zeros(len(now), a.dtype)
        out[present] = a[now[present]]
        return out

    fn, ft = pick(s.fn), pick(np.abs(s.ft))
    pts = np.column_stack([sim.x, np.zeros(n)])
    z = lambda v: np.column_stack([v, np.zeros(n)])
    cnt = contact_counts(s, n)
    disks = meshio.Mesh(pts, [("vertex", np.arange(n).reshape(-1, 1))],
                        point_data={"radius": sim.r.copy(), "velocity": z(sim.v),
                                    "velocity_fluctuation": z(velocity_fluctuation(sim)),
                                    "spin": sim.w.copy(), "n_contacts": cnt.astype(np.int32),
                                    "backbone": (cnt >= 2).astype(np.int32)})
    w2 = ow.w2[grain]
    cells = {"w2": w2, "w2_sign": np.sign(w2).astype(np.int32), "w2_increment": w2_inc[grain],
             "cluster": label[grain].astype(np.int32), "present": present.astype(np.int32),
             "sliding": pick(s.sliding).astype(np.int32),
             "rolling": pick(s.rolling).astype(np.int32), "normal_force": fn,
             "tangential_force": ft, "force": np.hypot(fn, ft)}
    contacts = meshio.Mesh(pts, [("line", np.column_stack([i[grain], j[grain]]))],
                           cell_data={k: [np.asarray(v)] for k, v in cells.items()})
    paths = (os.path.join(out_dir, f"disks_{tag}.vtu"), os.path.join(out_dir, f"contacts_{tag}.vtu"))
    _atomic_meshio(paths[0], disks)
    _atomic_meshio(paths[1], contacts)
    return paths


def coarse_fluctuation(sim, s: ContactState, per_cell=9, max_cells=24):
    """The velocity fluctuation (``velocity_fluctuation``) of the backbone disks (two contacts or
    more in ``s``), mass-weighted mean over the cells of a grid of about ``per_cell`` disks
    each, at most ``max_cells`` along the box's longer side: (cx, cy, mean) with the cell
    centres (ny, nx) [m] and the means (ny, nx, 2) [m/s] (0 in a cell without backbone disks).
    Per disk, the fluctuation of a dense sample is a noise of neighbours moving against each
    other; the cell means show the pattern."""
    n = sim.n
    wl = sim.walls
    w, h = wl[1] - wl[0], wl[3] - wl[2]
    side = min(math.sqrt(n / per_cell), max_cells * min(w, h) / max(w, h))
    nx = max(1, int(round(side * math.sqrt(w / h))))
    ny = max(1, int(round(side * math.sqrt(h / w))))
    ix = np.clip(((sim.x[:, 0] - wl[0]) / w * nx).astype(np.int64), 0, nx - 1)
    iy = np.clip(((sim.x[:, 1] - wl[2]) / h * ny).astype(np.int64), 0, ny - 1)
    m = np.where(contact_counts(s, n) >= 2, sim.m, 0.0)
    dv = velocity_fluctuation(sim)
    cell = iy * nx + ix
    mass = np.bincount(cell, weights=m, minlength=nx * ny)
    mean = np.zeros((nx * ny, 2))
    for a in range(2):
        mean[:, a] = np.bincount(cell, weights=m * dv[:, a], minlength=nx * ny)
    mean[mass > 0] /= mass[mass > 0, None]
    cx, cy = np.meshgrid(wl[0] + (np.arange(nx) + 0.5) * w / nx,
                         wl[2] + (np.arange(ny) + 0.5) * h / ny)
    return cx, cy, mean.reshape(ny, nx, 2)


def plot_anatomy(path, panels, dpi=150):
    """One PNG at ``path`` with a panel per (title, sim, s0[, s_prev]) of ``panels``: the disks
    (light fill), the walls, the grain contacts (at 0 or now, drawn between the centres now) with
    a positive own second-order work thin and grey, the negative ones thick and red, the largest
    cluster of those in dark blue (over the last increment, ``s_prev`` to now, when ``s_prev`` is
    given: the unstable contacts of ``anatomy``; otherwise the secant since 0), and the velocity
    fluctuation of the backbone disks as arrows (cell means, ``coarse_fluctuation``), scaled per
    panel (the 90th percentile 0.9 cell long; the key gives the scale; an arrow longer than 2.5
    cells is drawn 2.5 cells long, in orange).  The panel's title carries its ``anatomy``
    figures.  ``panels``: [(title, Simulation now, ContactState at 0[, ContactState at the
    increment's start])], one or more (ValueError if none)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import EllipseCollection, LineCollection

    from common.io import save_figure
    if not panels:
        raise ValueError("panels: allowed: one (title, sim, s0) or more")
    w, h = panels[0][1].size
    width = min(7.0, 14.0 / len(panels))
    fig, axes = plt.subplots(1, len(panels), figsize=(width * len(panels), width * h / w + 1.0),
                             squeeze=False, constrained_layout=True)
    for ax, (title, sim, s0, *rest) in zip(axes[0], panels):
        n = sim.n
        s_prev = rest[0] if rest else None
        s = contact_state(sim)
        tau = UNSTABLE_TAU * energy_scale(s0, sim.params.kn) if s_prev is not None else 0.0
        a = anatomy(s0, s, n, s_prev, tau)
        ow = own_work(s0, s)
        if s_prev is None:
            w2, (label, _) = ow.w2, unstable_clusters(ow.keys, ow.w2 < 0.0, n)
        else:
            w2, label = increment_on(ow.keys, s_prev, s, n, tau)
        i, j, grain = split_keys(ow.keys, n)
        seg = np.stack([sim.x[i[grain]], sim.x[j[grain]]], axis=1)
        neg, lab = w2[grain] < -tau, label[grain]
        # thinner lines for larger samples: 2000 disks and fewer as drawn here, 12,000 at 0.45
        lw = max(0.45, min(1.0, math.sqrt(2000 / n)))
        ax.add_collection(EllipseCollection(2 * sim.r, 2 * sim.r, 0.0, units="xy",
                                            offsets=sim.x, offset_transform=ax.transData,
                                            facecolors="0.93", edgecolors="0.75",
                                            linewidths=0.2 * lw))
        ax.add_collection(LineCollection(seg[~neg], colors="0.55", linewidths=0.35 * lw))
        ax.add_collection(LineCollection(seg[neg & (lab != 0)], colors="C3", linewidths=1.1 * lw))
        ax.add_collection(LineCollection(seg[lab == 0], colors="navy", linewidths=max(1.5, 2.0 * lw)))
        wl = sim.walls
        ax.plot([wl[0], wl[1], wl[1], wl[0], wl[0]], [wl[2], wl[2], wl[3], wl[3], wl[2]],
                "k-", lw=1.5)
        cx, cy, mv = coarse_fluctuation(sim, s)
        ref = float(np.quantile(np.hypot(mv[:, :, 0], mv[:, :, 1]), 0.9))
        if ref > 0:
            # the 90th percentile of the cell means is drawn 0.9 cell long
            cell = (wl[1] - wl[0]) / cx.shape[1]
            # a few cells far above the rest (a local slip) would cross the panel: drawn 2.5
            # cells long, in orange
            mag = np.hypot(mv[:, :, 0], mv[:, :, 1])
            cap = 2.5 / 0.9 * ref
            clip = mag > cap
            mv = mv * np.where(clip, cap / np.where(clip, mag, 1.0), 1.0)[:, :, None]
            q = ax.quiver(cx, cy, mv[:, :, 0], mv[:, :, 1], angles="xy", scale_units="xy",
                          scale=ref / (0.9 * cell), width=0.003, zorder=4,
                          color=np.where(clip, "C1", "k").ravel().tolist())
            q.set_clip_on(True)           # an arrow at the box's edge stays in its own panel
            q.set_clip_box(ax.bbox)
            key = float(f"{ref:.1g}")
            ax.quiverkey(q, 0.45, -0.025, key, f"{key:g} m/s",
                         labelpos="E", coordinates="axes", fontproperties={"size": 7})
        ax.set_xlim(wl[0] - 0.02 * (wl[1] - wl[0]), wl[1] + 0.02 * (wl[1] - wl[0]))
        ax.set_ylim(wl[2] - 0.02 * (wl[3] - wl[2]), wl[3] + 0.02 * (wl[3] - wl[2]))
        ax.set_aspect("equal")
        ax.set_axis_off()
        over = (f"< -{UNSTABLE_TAU:.0e} fn²/kn (last increment)" if s_prev is not None
                else "< 0 since 0")
        ax.set_title(f"{title}\nunstable (w2 {over}): {a['n_unstable']} of {len(ow.keys)}\n"
                     f"{a['n_clusters']} clusters, largest {a['largest_cluster']}; sliding "
                     f"{100 * a['sliding_share']:.1f} %, z = {a['coordination']:.2f}\n"
                     f"W2_int (secant since 0) = {a['w2_int_secant']:.3g} J", fontsize=7.5)
    ax = axes[0][0]
    ax.plot([], [], "-", color="0.55", lw=0.6, label="contact, stable")
    ax.plot([], [], "-", color="C3", lw=1.1, label="unstable: own W2 below the threshold")
    ax.plot([], [], "-", color="navy", lw=2.0, label="largest cluster of unstable contacts")
    ax.plot([], [], "k>", ms=5, label="velocity less the walls' affine field (backbone, cell means)")
    ax.plot([], [], ">", color="C1", ms=5, label="... shortened to 2.5 cells")
    fig.legend(loc="outside lower center", ncol=4, fontsize=7, frameon=False)
    save_figure(fig, path, dpi=dpi)
