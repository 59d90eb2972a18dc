"""Orchestration: a `Simulation` holds the arrays and calls the kernels.

`State` is an immutable snapshot (copies) of everything needed to continue a run
bit-for-bit: particles, walls, servo memory, the pair list with tangential history,
the neighbour-list reference positions, the step counter and the control.
"""
from __future__ import annotations

import math
import time
from typing import NamedTuple

import numba
import numpy as np

from common.threads import ThreadChooser

from . import kernels
from .neighbours import build_pair_list, finish_pair_list
from .params import DemParams
from .regime import watch_contacts, watch_run
from .walls import Control, wall_stress


class State(NamedTuple):
    params: DemParams
    x: np.ndarray          # (N,2) [m]
    v: np.ndarray          # (N,2) [m/s]
    w: np.ndarray          # (N,) [rad/s]
    theta: np.ndarray      # (N,) [rad]
    r: np.ndarray          # (N,) [m]
    walls: np.ndarray      # (4,) [x_left, x_right, y_bottom, y_top] [m]
    walls_ref: np.ndarray  # (4,) walls at the last neighbour rebuild
    prev: np.ndarray       # (4,) last servo displacement [m]
    x_ref: np.ndarray      # (N,2) positions at the last neighbour rebuild
    pi: np.ndarray         # (P,) int32
    pj: np.ndarray         # (P,) int32
    ft: np.ndarray         # (P,) tangential history [N]
    mr: np.ndarray         # (P,) rolling-moment history [N m] (moment on pi; zeros without rolling)
    step: int
    time: float
    mu: float              # current friction coefficient (reduced during compaction)
    mu_r: float            # current rolling friction (0 during compaction)
    cap_on: bool           # Coulomb cap active (False = sliding prevented)
    control: Control
    ref_len: np.ndarray    # (2,) (W0, H0) reference lengths for strains [m]


# the ledger's arrays when it is off (``kernels.advance``: an empty lsc turns it off)
_NO_LEDGER = (np.zeros(0), np.zeros((6, 0)), np.zeros((0, 3)))


class Snapshot(NamedTuple):
    """Contacts and derived measures at one configuration (see kernels.contact_snapshot)."""
    ci: np.ndarray
    cj: np.ndarray
    fx: np.ndarray
    fy: np.ndarray
    fn: np.ndarray
    wp: np.ndarray
    ww: np.ndarray
    wf: np.ndarray


class Simulation:
    """Mutable simulation; all heavy loops are in `kernels`."""

    def __init__(self, state: State):
        p = state.params
        self.params = p
        c = lambda a, dt=float: np.array(a, dtype=dt, copy=True)
        self.x, self.v, self.w, self.theta = c(state.x), c(state.v), c(state.w), c(state.theta)
        self.r = c(state.r)
        self.m = p.mass(self.r)
        self.inertia = p.inertia(self.r)
        self.walls, self.walls_ref, self.prev = c(state.walls), c(state.walls_ref), c(state.prev)
        self.x_ref = c(state.x_ref)
        self.step = int(state.step)
        self.time = float(state.time)
        self.mu = float(state.mu)
        self.mu_r = float(state.mu_r)
        self.cap_on = bool(state.cap_on)
        self.control = state.control
        self.ref_len = c(state.ref_len)
        self.damping = p.damping
        self.dt = p.dt
        n = len(self.r)
        self.fext = np.zeros((n, 2))
        self.fnet = np.zeros((n, 4))   # fx, fy, torque, rolling moments
        self.disp2 = np.zeros(n)
        self.wF = np.zeros(4)
        self.wK = np.zeros(4)
        # The list is rebuilt from the *reference* positions so that a loaded state gets
        # exactly the candidate lists the original run had.
        self.pairs = finish_pair_list(self.x_ref, self.r, self.walls_ref, p.skin,
                                      c(state.pi, np.int32), c(state.pj, np.int32), c(state.ft),
                                      c(state.mr))
        self.n_rebuilds = 0
        self.solid = solid_area(self.r)     # the disks' area [m^2] (the watch's porosity)
        self.vmax_override = None  # wall speed cap override [m/s] (compaction only)
        # blocks of disks run concurrently: None = one per thread of the chosen count (the
        # bits are the same either way); a test may force any number
        self.nblocks = None
        self.threads = ThreadChooser(n)
        # the energy ledger (dem.ledger.Ledger attaches itself here); it only reads the run
        self.ledger = None
        # the watch of the granular regime (dem.regime: after every chunk of steps and at every
        # snapshot); it only reads the run. False: a state loaded to be inspected
        self.watch = True

    # ------------------------------------------------------------------------------
    @classmethod
    def new(cls, params: DemParams, x, r, walls, mu=None, control=None, mu_r=None):
        """Fresh simulation at rest from positions x (N,2), radii r (N,), walls (4,); mu,
        mu_r: friction and rolling friction to start with (default: the params')."""
        x = np.asarray(x, float)
        r = np.asarray(r, float)
        walls = np.asarray(walls, float)
        validate_geometry(x, r, walls)
        n = len(r)
        st = State(params, x, np.zeros((n, 2)), np.zeros(n), np.zeros(n), r, walls,
                   walls.copy(), np.zeros(4), x.copy(), np.zeros(0, np.int32),
                   np.zeros(0, np.int32), np.zeros(0), np.zeros(0), 0, 0.0,
                   params.mu if mu is None else mu,
                   params.rolling_friction if mu_r is None else mu_r, True,
                   control if control is not None else Control(),
                   np.array([walls[1] - walls[0], walls[3] - walls[2]]))
        sim = cls(st)
        sim.rebuild()
        return sim

    def rebuild(self):
        """Rebuild the pair list at the current positions, carrying the contact histories."""
        pl = self.pairs
        self.pairs = build_pair_list(self.x, self.r, self.walls, self.params.skin,
                                     pl.pi, pl.pj, pl.ft, pl.mr)
        self.x_ref[:] = self.x
        self.walls_ref[:] = self.walls
        self.fext[:] = 0.0
        self.n_rebuilds += 1
        self.solid = solid_area(self.r)     # the radii change only before a rebuild (compact)

    def _needs_rebuild(self):
        hs = 0.5 * self.params.skin
        return (np.abs(self.walls - self.walls_ref).max() > hs) or (self.disp2.max() > hs * hs)

    # ------------------------------------------------------------------------------
    def run(self, nsteps: int):
        """Advance nsteps time steps under the current control."""
        p = self.params
        # advance's records (kernels.Disks, WallState, Servo, Law) as plain tuples in their
        # order: so they cost nothing beside the flat list they replaced (kernels.advance)
        disks = (self.x, self.v, self.w, self.theta, self.r, self.m, self.inertia, self.fext,
                 self.fnet, self.x_ref, self.disp2)
        ws = (self.walls, self.walls_ref, self.prev, self.wF, self.wK)
        servo = self.control.arrays() + (p.thickness, p.servo_gain, p.servo_smoothing,
                                         self.vmax_override or p.servo_vmax)
        law = (p.kn, p.kt, self.mu, self.cap_on, p.normal_damping_ratio,
               p.rolling_stiffness * p.kt, self.mu_r, self.damping, self.dt)
        left = int(nsteps)
        while left > 0:
            nth, chunk = self.threads.next(left)
            if self.nblocks is None:
                numba.set_num_threads(nth)
                nblocks = nth
            else:   # a forced split runs on the threads the caller set
                nblocks = int(self.nblocks)
            t0 = time.perf_counter()
            done = kernels.advance(chunk, disks, tuple(self.pairs), ws, servo, law, self.step,
                                   0.5 * p.skin, nblocks, self.ledger.arrays()
                                   if self.ledger is not None else _NO_LEDGER)
            self.threads.record(nth, done * self.n, time.perf_counter() - t0)
            left -= done
            self.step += done
            self.time = self.step * self.dt
            if self.watch:      # before a rebuild, which a NaN or a disk outside would upset
                watch_run(self)
            if self._needs_rebuild():
                self.rebuild()

    def set_control(self, control: Control):
        self.control = control

    # ------------------------------------------------------------------------------
    def state(self) -> State:
        """Immutable copy of everything needed to continue the run."""
        c = np.copy
        pl = self.pairs
        return State(self.params, c(self.x), c(self.v), c(self.w), c(self.theta), c(self.r),
                     c(self.walls), c(self.walls_ref), c(self.prev), c(self.x_ref),
                     c(pl.pi), c(pl.pj), c(pl.ft), c(pl.mr), self.step, self.time, self.mu,
                     self.mu_r, self.cap_on, self.control, c(self.ref_len))

    def snapshot(self) -> Snapshot:
        """The contacts now (``kernels.contact_snapshot``), their overlaps watched
        (``dem.regime.watch_contacts``) unless ``watch`` is off."""
        pl = self.pairs
        snap = Snapshot(*kernels.contact_snapshot(self.x, self.r, pl.pi, pl.pj, pl.ft,
                                                  self.walls, self.params.kn))
        if self.watch:
            watch_contacts(self, snap)
        return snap

    # Measures ------------------------------------------------------------------------
    @property
    def n(self):
        return len(self.r)

    @property
    def size(self):
        """(W, H) box size [m]."""
        return np.array([self.walls[1] - self.walls[0], self.walls[3] - self.walls[2]])

    @property
    def volume(self):
        w, h = self.size
        return w * h * self.params.thickness

    def porosity(self):
        """1 - the disks' area over the box's (``solid_fraction``)."""
        return 1.0 - solid_fraction(self.r, self.walls)

    def wall_stress(self, snap: Snapshot | None = None):
        """(s_xx, s_yy) [Pa], compression positive, from the wall forces at the current
        positions."""
        snap = snap or self.snapshot()
        wF = np.bincount(snap.ww, weights=snap.wf, minlength=4)
        return wall_stress(wF, self.walls, self.params.thickness)

    def love_weber(self, snap: Snapshot | None = None):
        """Love-Weber stress (2,2) [Pa], compression positive: -(1/V) sum over particles of
        sum_c f_c (x) (x_c - x_p), wall contacts included (paper Eq. 12-13)."""
        snap = snap or self.snapshot()
        s = kernels.particle_stress(self.x, self.r, snap.ci, snap.cj, snap.fx, snap.fy,
                                    snap.wp, snap.ww, snap.wf)
        return -s.sum(axis=0) / self.volume

    def strain(self):
        """(eps_xx, eps_yy) engineering strains from the walls, compression positive."""
        return (self.ref_len - self.size) / self.ref_len

    def unbalanced(self, snap: Snapshot | None = None):
        """Unbalanced-force ratio: mean |net force| / mean |contact force| (0 if no contact)."""
        snap = snap or self.snapshot()
        f = kernels.net_forces(self.n, self.x, snap.ci, snap.cj, snap.fx, snap.fy,
                               snap.wp, snap.ww, snap.wf)
        fc = np.concatenate([np.hypot(snap.fx, snap.fy), snap.wf])
        if fc.size == 0 or fc.mean() == 0:
            return 0.0
        return float(np.hypot(f[:, 0], f[:, 1]).mean() / fc.mean())

    def kinetic_energy(self):
        """Kinetic energy of the disks [J] (``kinetic_energy``)."""
        return kinetic_energy(self.m, self.inertia, self.v, self.w)


def kinetic_energy(m, inertia, v, w) -> float:
    """Kinetic energy [J] of disks of masses ``m``, rotational inertias ``inertia`` (N,),
    velocities ``v`` (N,2) and spins ``w`` (N,): 1/2 sum(m |v|^2 + I w^2). The one definition
    (``Simulation.kinetic_energy``, the backbone's of ``dem.settle``)."""
    return 0.5 * float(np.sum(m[:, None] * v ** 2) + np.sum(inertia * w ** 2))


def confining_stress(state) -> float:
    """The confining stress [Pa] of a state (for ``dem.regime.check_regime``): the smaller of its
    two wall stresses at its positions (sigma2 of the biaxial test it comes from), or the stress
    its control holds an axis at (``walls.STRESS``) where that is larger: a state's stresses come
    from its own kn, and a soft kn puts a packing of stiff grains at a small stress that the run
    then raises."""
    from .walls import STRESS
    sim = Simulation(state)
    sim.watch = False           # a state to be judged, not a run
    c = state.control
    held = [abs(float(c.s_to[k])) for k in (0, 1) if c.mode[k] == STRESS]
    return max([float(min(sim.wall_stress()))] + held)


def solid_area(r) -> float:
    """The disks' area sum(pi r^2) [m^2] (radii ``r``)."""
    return math.pi * float(np.sum(r ** 2))


def solid_fraction(r, walls) -> float:
    """The disks' area over the box's, sum(pi r^2) / (W H) [-], ``walls`` = [x_left, x_right,
    y_bottom, y_top]: one minus the porosity (``Simulation.porosity``, the compaction's start;
    the watch of ``dem.regime`` divides ``Simulation.solid``, the same area kept since the last
    rebuild, by the box's)."""
    return solid_area(r) / ((walls[1] - walls[0]) * (walls[3] - walls[2]))


def validate_geometry(x, r, walls):
    """ValueError for impossible inputs (negative radius, crossed walls, shapes)."""
    if x.ndim != 2 or x.shape[1] != 2 or r.ndim != 1 or len(r) != len(x):
        raise ValueError(f"positions must be (N,2) and radii (N,); got {x.shape} and {r.shape}")
    if len(r) == 0:
        raise ValueError("n=0 particles; allowed range: n >= 1")
    if not np.all(np.isfinite(r)) or np.any(r <= 0):
        raise ValueError(f"radius must be > 0 [m]; got min radius {float(np.min(r))!r}")
    if not np.all(np.isfinite(x)):
        raise ValueError("positions must be finite")
    if walls.shape != (4,) or not np.all(np.isfinite(walls)):
        raise ValueError("walls must be 4 finite numbers [x_left, x_right, y_bottom, y_top]")
    if walls[1] <= walls[0] or walls[3] <= walls[2]:
        raise ValueError(f"walls overlap: walls={walls.tolist()}; allowed range: "
                         "x_left < x_right and y_bottom < y_top")


def compile_kernels():
    """Compile (or load from Numba's cache) every kernel a run uses, on a 4-disk sample, so that
    the first compilation stays out of the timings a command reports."""
    p = DemParams(n=4)
    r = np.full(4, p.r_max)
    x = np.array([[1, 1], [3, 1], [1, 3], [3, 3]], float) * p.r_max
    sim = Simulation.new(p, x, r, np.array([0.0, 4.0, 0.0, 4.0]) * p.r_max)
    sim.threads = ThreadChooser(sim.n, 1)
    sim.run(2)
    snap = sim.snapshot()
    sim.love_weber(snap)
    sim.unbalanced(snap)
