"""The burst's runs (``dem.burst``): the proportional strain path under strain control
(``proportional_path``), a state relaxed at fixed strain (``relax``), the kinematic probe of the
path at a state at rest (``path_probe``), and the tied run holding G under a dead load or c under
the servo (``hold``), with the growth of its kinetic energy (``growth``; ``ke_growth``, the
contract's column, is ``point.burst_rule``'s, applied to the backbone's kinetic energy); the
columns of their records."""
from __future__ import annotations

import math
import time
from collections import deque
from typing import NamedTuple

import numpy as np

from .. import kernels
from ..anatomy import ANATOMY_COLUMNS, UNSTABLE_WINDOW, contact_state
from ..ledger import COLUMNS as LEDGER_COLUMNS, EXTRA_COLUMNS as LEDGER_EXTRA_COLUMNS, Ledger
from ..settle import HISTORY_COLUMNS as SETTLE_COLUMNS, RULE_COLUMNS, settle, voigt_strain
from ..simulation import Simulation, State
from common.threads import ThreadChooser
# the contract's ke_growth column (docs/burst.md): one formula for the three parts, applied here
# to the backbone's kinetic energy at the checks (``dem.burst.report.burst_row``)
from point.burst_rule import ke_growth  # noqa: F401
from ..walls import strain_rate, tied
from .options import BurstOptions, confirm_peak

ONSET = 10.0          # the onset of a burst: the backbone's kinetic energy this many times its
                      # floor (one check after the switch: ``hold``)
UNLOADED = 0.05        # a path whose mean wall stress falls below this of its start has unloaded

# a path's records, then its energy ledger from the path's start (first order: the second-order
# terms of a path are not the experiment's)
PATH_LEDGER_COLUMNS = ["ke", "w_ext", "w_int", "w_damp", "e_elastic", "d_slip", "d_roll",
                       "balance_residual", "split_residual"]
PATH_COLUMNS = ["ratio", "start_fraction", "step", "eps1", "eps2", "s1", "s2", "p", "q", "eta",
                "c", "unbalanced"] + PATH_LEDGER_COLUMNS
# the ledger's columns (dem.ledger) but its "ke", which is the "ke" column already there
HOLD_LEDGER_COLUMNS = [c for c in LEDGER_COLUMNS + LEDGER_EXTRA_COLUMNS if c != "ke"]
# and the anatomy's (dem.anatomy) but its "w2_int_secant", which is the column of that name here
HOLD_ANATOMY_COLUMNS = [c for c in ANATOMY_COLUMNS if c != "w2_int_secant"]
HISTORY_COLUMNS = ["ratio", "start_fraction", "switch", "step", "t", "eps1", "eps2", "c",
                   "c_target", "stress_error", "ke", "ke_backbone", "unbalanced", "s1", "s2",
                   "strain_ratio", "w2_ext_held", "w2_walls", "w2_int_secant"] + \
    HOLD_LEDGER_COLUMNS + HOLD_ANATOMY_COLUMNS


class PathResult(NamedTuple):
    rows: np.ndarray          # (records, len(PATH_COLUMNS) - 2): PATH_COLUMNS from "step"
    peak: int | None          # row of the loaded c peak (None: no peak within the path)
    confirmed_by: str         # "drop", "strain", "" (no peak) or "unloaded"
    grid: list                # [(row, State)]: the start, then the loaded peak's (or the end's)
    steps: int                # time steps of the path
    wall_time: float          # [s]


def _record(sim, ratio):
    """One path record: step, eps1, eps2, s1, s2, p, q, eta, c, unbalanced (compression
    positive, axis 1 = y), then the ledger's PATH_LEDGER_COLUMNS."""
    snap = sim.snapshot()
    s2, s1 = sim.wall_stress(snap)
    e2, e1 = sim.strain()
    p, q = 0.5 * (s1 + s2), s1 - s2
    led = sim.ledger.read()
    return [sim.step, e1, e2, s1, s2, p, q, q / p if p > 0 else math.nan, s1 + ratio * s2,
            sim.unbalanced(snap)] + [getattr(led, c) for c in PATH_LEDGER_COLUMNS]


def proportional_path(state: State, ratio: float, opts: BurstOptions = BurstOptions(),
                      threads=None, progress=None) -> PathResult:
    """The proportional strain path d eps2 = R d eps1 from ``state`` at ``opts.rate`` (both
    axes strain controlled), recorded every ``opts.record_strain``, until the loaded c peak is
    confirmed, the path has gone ``opts.path_strain`` or it has unloaded (see the module doc).
    Keeps the start state and the loaded peak's (or, without a peak, the end's): the rest
    search starts from the first (``staircase``) and measures the overstress of the second."""
    t0 = time.time()
    sim = Simulation(state)
    if threads is not None:
        sim.threads = ThreadChooser(sim.n, threads)
    sim.set_control(strain_rate(ratio * opts.rate, opts.rate, sim.ref_len))
    Ledger(sim)
    every = max(1, int(round(opts.record_strain / (opts.rate * sim.dt))))
    rows = [_record(sim, ratio)]
    e_start, p_start = rows[0][1], rows[0][5]
    grid = [(0, sim.state())]
    peak, how, peak_state = 0, "", None
    while True:
        sim.run(every)
        rows.append(_record(sim, ratio))
        k = len(rows) - 1
        e1, c, p = rows[k][1], rows[k][8], rows[k][5]
        how = confirm_peak(c, e1, rows[peak][8], rows[peak][1], opts)
        if how == "new":
            peak, how, peak_state = k, "", sim.state()
        if not how and p < UNLOADED * p_start:
            how = "unloaded"
        if progress:
            progress(sim.step - state.step, rows[k], rows[peak])
        if how or e1 - e_start >= opts.path_strain:
            break
    rows = np.asarray(rows, float)
    if how == "unloaded":
        return PathResult(rows, None, how, [], sim.step - state.step, time.time() - t0)
    grid.append((peak, peak_state) if how and peak > 0 else (len(rows) - 1, sim.state()))
    return PathResult(rows, peak if how else None, how, grid, sim.step - state.step,
                      time.time() - t0)


# ----------------------------------------------------------------------------------------------
# From rest: a state relaxed at fixed strain, and the c peak at rest along the path
# ----------------------------------------------------------------------------------------------
class RelaxResult(NamedTuple):
    state: State              # the relaxed state (walls where they were)
    outcome: str              # dem.settle's: equilibrium, undecided (failure cannot happen here)
    steps: int
    c_loaded: float           # c before the relaxation [Pa]
    c_rest: float             # c of the relaxed state [Pa]
    eta_rest: float
    ke_end: float             # kinetic energy at the end [J]
    unbalanced_end: float
    history: np.ndarray       # dem.settle's history (rule and ledger columns)
    wall_time: float


def relax(state: State, ratio: float, opts: BurstOptions = BurstOptions(), threads=None,
          progress=None) -> RelaxResult:
    """``state`` relaxed at fixed strain (the walls still: ``walls.strain_rate`` at 0) until
    dem.settle's equilibrium: over a whole window the unbalanced ratio <= unbalanced_tol, the
    backbone kinetic energy <= ke_tol a disk and c's drift |c(t) - c(t - window)| <=
    stress_tol at every check (so two windows at least), capped at ``opts.relax_max_steps``
    (undecided then). The c a state keeps at rest: a state of a strain-controlled path carries
    the loading's rate overstress (docs/dem.md)."""
    from ..settle import window_steps
    t0 = time.time()
    sim = Simulation(state)
    if threads is not None:
        sim.threads = ThreadChooser(sim.n, threads)
    s2, s1 = sim.wall_stress()
    c_loaded = s1 + ratio * s2
    sim.set_control(strain_rate(0.0, 0.0, sim.ref_len))
    Ledger(sim)
    rule = opts.rule()._replace(max_steps=opts.relax_max_steps, fail_ratio=math.inf,
                                runaway_ratio=math.inf, fail_strain=math.inf)
    back = window_steps(sim.n, rule) // rule.check_every
    cs = []

    def drift(sx, sy):
        cs.append(sy + ratio * sx)
        return abs(cs[-1] - cs[-1 - back]) if len(cs) > back else math.inf

    res = settle(sim, None, rule, strain_scale=voigt_strain(sim, opts.strain_norm),
                 progress=progress, stress_error=drift)
    sim.ledger.detach()
    s2, s1 = sim.wall_stress()
    return RelaxResult(sim.state(), res.outcome, res.steps, c_loaded, s1 + ratio * s2,
                       (s1 - s2) / (0.5 * (s1 + s2)), sim.kinetic_energy(), res.unbalanced,
                       res.history, time.time() - t0)


def probe_rate_of(n_disks: int, dt: float, opts: BurstOptions) -> float:
    """The probe's axial strain rate [1/s]: ``opts.probe_rate``, or by the rule the rate at which
    the move of ``opts.probe_d_eps1`` lasts one equilibrium window (``dem.settle.window_steps``,
    which grows as the sample's width: the time a disturbance takes to cross it and die out).
    Measured (docs/gallery/burst/dem/README.md, dem12000/README.md): k_path converges as the rate
    falls, and the rate it needs falls with the size: at 2000 disks 0.001/s and 0.0003/s agree
    (+27.6 and +30.1 MPa at the below state), at 12,000 disks 0.001, 0.0003, 0.0001/s read -17.8,
    +13.0, +22.9 MPa at the below state; the rule gives 1.5e-4/s at 2000 and 6.2e-5/s at 12,000
    disks."""
    if opts.probe_rate is not None:
        return opts.probe_rate
    from ..settle import window_steps
    return opts.probe_d_eps1 / (window_steps(n_disks, opts.rule()) * dt)


class ProbeResult(NamedTuple):
    """A kinematic probe of the path at a state at rest (``path_probe``)."""
    key: str                  # the state probed (the staircase journal's key)
    c_state: float            # c of the state as given [Pa]
    c_before: float           # c at rest at the state's strain (relaxed at fixed strain) [Pa]
    c_after: float            # c at rest after the move along the path [Pa]
    eps1_before: float        # [-]
    d_eps1: float             # the axial strain of the move, from the walls [-]
    k_path: float             # (c_after - c_before) / d_eps1 [Pa]
    w2: float                 # the path's second-order work of the move, dc dU1 W t [J]
    outcome: str              # the two relaxations': "equilibrium" if both settled
    steps: int                # time steps: relaxation, move, relaxation
    wall_time: float          # [s]
    rate: float = math.nan    # the move's axial strain rate [1/s] (``probe_rate_of``)


def path_probe(state: State, ratio: float, opts: BurstOptions = BurstOptions(), threads=None,
               key: str = "") -> ProbeResult:
    """The second-order work of the path's own direction at a state at rest, measured without a
    burst (docs/burst.md, "The DEM: what its burst proves"): ``state`` relaxed at fixed
    strain (``relax``: c_before, the c it keeps at rest; its change from the state's c is a
    sample of the noise of c at rest), the tied walls then moved along the path, d eps2 = R
    d eps1, by ``opts.probe_d_eps1`` at the axial rate ``probe_rate_of`` (strain control:
    always controllable, whatever the sign of the answer), and relaxed again at fixed strain
    (c_after). The static stiffness of the path is k_path = dc / d eps1 [Pa], dc = c_after -
    c_before, d eps1 the walls' own; along the path W2 = d eps1 (d s1 + R d s2) = dc d eps1 per
    unit volume, so its sign is k_path's, and the probe's W2 = dc dU1 W t [J] (U1 = H0 eps1).
    The rate and the size of the move are a rule (docs/burst.md: slow enough that k_path no
    longer moves with the rate, small against the strain of the staircase's steps, large
    against the noise of c at rest)."""
    t0 = time.time()
    s2, s1 = Simulation(state).wall_stress()
    c_state = s1 + ratio * s2
    before = relax(state, ratio, opts, threads)
    sim = Simulation(before.state)
    if threads is not None:
        sim.threads = ThreadChooser(sim.n, threads)
    e0 = sim.strain()[1]
    rate = probe_rate_of(sim.n, sim.dt, opts)
    sim.set_control(strain_rate(ratio * rate, rate, sim.ref_len))
    moves = max(1, int(round(opts.probe_d_eps1 / (rate * sim.dt))))
    sim.run(moves)
    after = relax(sim.state(), ratio, opts, threads)
    e1 = Simulation(after.state).strain()[1]
    d = e1 - e0
    dc = after.c_rest - before.c_rest
    w = float(Simulation(after.state).size[0])
    outcome = ("equilibrium" if before.outcome == after.outcome == "equilibrium"
               else f"{before.outcome}/{after.outcome}")
    return ProbeResult(key, c_state, before.c_rest, after.c_rest, e0, d, dc / d,
                       dc * d * sim.ref_len[1] * w * sim.params.thickness, outcome,
                       before.steps + moves + after.steps, time.time() - t0, rate)


H = {c: k for k, c in enumerate(HISTORY_COLUMNS[3:])}    # a hold's history columns (from "step")


class HoldResult(NamedTuple):
    outcome: str
    steps: int
    history: np.ndarray       # (checks, len(HISTORY_COLUMNS) - 3): HISTORY_COLUMNS from "step"
    creep_rate: float         # [1/s] over the last window
    wall_time: float          # [s]
    hold: str = "servo"       # "dead_load" or "servo"
    ke_switch: float = math.nan   # the backbone's E_c at the switch [J]
    g_held: float = math.nan  # the held generalized force [N] (dead load)
    wall_mass: float = math.nan   # the walls' generalized mass m_G [kg] (dead load)
    end_state: State | None = None    # the state at the end
    onset_state: State | None = None  # the state at the onset of a burst (backbone E_c 10 x its
                                      # floor, ``ONSET``), None if it never came
    onset_step: int = -1              # its step since the switch
    onset_prev_state: State | None = None   # the states UNSTABLE_WINDOW checks before the onset
    end_prev_state: State | None = None     # and before the end (the anatomy's last increment)


def wall_work(sim, g0, walls0) -> float:
    """The walls' secant second-order work sum_w dF_w dU_w [J] since (wall forces ``g0`` (4,)
    [N], positions ``walls0`` (4,) [m]), dU_w the inward move of wall w."""
    snap = sim.snapshot()
    g = np.bincount(snap.ww, weights=snap.wf, minlength=4)
    inward = (sim.walls - walls0) * np.array([1.0, -1.0, 1.0, -1.0])
    return float(np.sum((g - g0) * inward))


def wall_mass_rule(sim, ratio, period_steps):
    """The walls' generalized mass m_G [kg] for the dead load: their period on the walls'
    contact stiffness with the disks held still, 2 pi sqrt(m_G / K), K = dG/dU1 = (k1 + k^2 k2)
    / 2 (k1, k2 the mean contact stiffness of the y and of the x walls, k = R W0 / H0; each y
    wall moves U1 / 2), is ``period_steps`` time steps: the leapfrog resolves it (it is stable
    up to w dt = 2; at 200 steps w dt = 0.031), and the walls answer faster than the sample's
    own slowest modes. An upper bound of the sample's stiffness makes it a lower bound of the
    period the walls then have on the sample."""
    wF, wK = np.zeros(4), np.zeros(4)
    pl = sim.pairs
    kernels.wall_forces(sim.x, sim.v, sim.r, sim.m, sim.walls, pl.cand_off, pl.cand,
                        np.zeros((sim.n, 2)), sim.params.kn, sim.params.normal_damping_ratio,
                        wF, wK, np.zeros((2, 0)))
    k = ratio * sim.ref_len[0] / sim.ref_len[1]
    stiff = 0.5 * (0.5 * (wK[2] + wK[3]) + k * k * 0.5 * (wK[0] + wK[1]))
    return stiff * (period_steps * sim.dt / (2 * math.pi)) ** 2


def hold(state: State, ratio: float, c_target: float, opts: BurstOptions = BurstOptions(),
         threads=None, progress=None) -> HoldResult:
    """The tied run from ``state``: d eps2 = R d eps1 kept and c held at ``c_target`` [Pa],
    decided by ``dem.settle`` (see the module doc). ``opts.hold``: "dead_load" (the walls one
    dynamic degree of freedom under G_held = G(state) + W t (c_target - c(state)), G the
    generalized force conjugate to the platens' shortening, ``walls.dead_load``; stress error
    |G - G_held| / (W t)) or "servo" (``walls.tied``, the servo holding c; stress error
    |c - c_target|). ``progress(steps, history row)``: after each check."""
    from ..walls import dead_load, generalized_force
    t0 = time.time()
    sim = Simulation(state)
    if threads is not None:
        sim.threads = ThreadChooser(sim.n, threads)
    snap0 = sim.snapshot()
    s2, s1 = sim.wall_stress(snap0)
    c_switch = s1 + ratio * s2
    a0 = contact_state(sim)
    g0, walls0 = np.bincount(snap0.ww, weights=snap0.wf, minlength=4), sim.walls.copy()
    step0, eps1_0 = sim.step, sim.strain()[1]
    t = sim.params.thickness
    d_g = sim.size[0] * t * (c_target - c_switch)     # dG [N]
    h0 = sim.ref_len[1]
    g_held = m_g = math.nan
    if opts.hold == "dead_load":
        g_held = generalized_force(g0, ratio, sim.ref_len) + d_g
        m_g = opts.wall_mass or wall_mass_rule(sim, ratio, opts.wall_period_steps)
        sim.set_control(dead_load(ratio, g_held, m_g, sim.ref_len))
        kx = ratio * sim.ref_len[0] / sim.ref_len[1]

        def error(sx, sy):
            w, h = sim.size
            return abs(kernels.generalized_force(sy * w * t, sx * h * t, kx) - g_held) / (w * t)
    else:
        sim.set_control(tied(ratio, c_target, c_target, sim.step, 0, sim.ref_len))

        def error(sx, sy):
            return abs(sy + ratio * sx - c_target)
    Ledger(sim)
    hist = []
    onset = []
    recent = deque([sim.state()], maxlen=UNSTABLE_WINDOW + 1)   # the increment's start states
    # settle's row: the rule's columns, the ledger's, the anatomy's; this history has its own
    # "ke" and takes the anatomy's secant W2_int in its "w2_int_secant"
    col = {c: k for k, c in enumerate(SETTLE_COLUMNS)}
    extra = [col[c] for c in HOLD_LEDGER_COLUMNS + HOLD_ANATOMY_COLUMNS]

    def check(steps, row):
        step, ke, keb, ub, e1, e2, s1_, s2_, err, ratio_ = row[:len(RULE_COLUMNS)]
        hist.append([step - step0, (step - step0) * sim.dt, e1, e2, s1_ + ratio * s2_, c_target,
                     err, ke, keb, ub, s1_, s2_, ratio_, d_g * h0 * (e1 - eps1_0),
                     wall_work(sim, g0, walls0), row[col["w2_int_secant"]]]
                    + [row[k] for k in extra])
        # the onset of a burst: the backbone's kinetic energy 10 times its floor, the level the
        # held step's first response leaves one check after the switch (from rest, that step
        # alone raises it 1e2-1e5 times, below as past, and decays below)
        now = sim.state()
        recent.append(now)                # recent[0]: UNSTABLE_WINDOW checks back (or the switch)
        if len(hist) > 2 and not onset and keb >= ONSET * max(hist[1][8], 1e-300):
            onset.append((step - step0, now, recent[0]))
        if progress:
            progress(steps, hist[-1])

    res = settle(sim, None, opts.rule(), strain_scale=voigt_strain(sim, opts.strain_norm),
                 progress=check, stress_error=error, contacts0=a0)
    sim.ledger.detach()
    # E_c at the switch: the backbone's (disks with two contacts or more), as the growth's
    return HoldResult(res.outcome, res.steps, np.asarray(hist, float), res.creep_rate,
                      time.time() - t0, opts.hold, hist[0][8], g_held, m_g, sim.state(),
                      onset[0][1] if onset else None, onset[0][0] if onset else -1,
                      onset[0][2] if onset else None, recent[0])


def growth(history, n_disks, ke_tol) -> dict:
    """The growth of a held run's backbone kinetic energy measured against what the held step
    put in (``hmodel.burst_rule.energy_release``, the one measure of the three parts: E_c
    gained since the switch over W2_ext = dG dU1, its largest value ``ke_w2ext_max``, the time
    ``t_release`` [s] it first passes ``RELEASE``, ``released``) and against the equilibrium
    bound: ``ke_end_over_bound``, the backbone E_c at the end over ke_tol x disks. Neither depends
    on the kinetic-energy floor of the start. ``history``: a hold's (HISTORY_COLUMNS from
    "step")."""
    from point.burst_rule import energy_release
    h = np.asarray(history, float)
    r = energy_release(h[:, 1], h[:, 8], h[:, H["w2_ext_held"]])
    return {"ke_w2ext_max": r["ratio_max"], "t_release": r["t_release"],
            "released": int(r["released"]), "ke_end_over_bound": float(h[-1, 8] / (ke_tol * n_disks))}
