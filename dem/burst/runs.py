"""Failure made to happen in the DEM, from rest under a dead load: the proportional strain path,
its conjugate stress held past its peak at rest, and the burst of kinetic energy (paper Eq. 1;
``docs/burst.md``, ``docs/dem.md``).

From a state of the drained biaxial path (``dem biaxial --save-fractions``), the walls impose the
proportional strain path d eps2 = R d eps1 (R < 0: lateral extension) at the axial strain rate of
the biaxial test (``walls.strain_rate``, both axes strain controlled; engineering strains on the
biaxial test's reference lengths) while the stress conjugate to it, c = s1 + R s2 (wall stresses,
compression positive), is recorded: along the path W2 = d eps1 dc, so W2 = 0 where c peaks.

* **The loaded peak** (``proportional_path``): the largest c recorded, confirmed once the path
  has gone ``peak_strain`` (0.5 %) of axial strain beyond it without a larger one, or c has
  fallen from it by ``peak_drop`` (150 kPa): the DEM's c is noisy, with stick-slip falls of up to
  62 kPa that it recovers within a few tenths of a percent (``docs/dem.md``). A path that
  unloads (its mean wall stress below ``UNLOADED`` of its start: the walls have left the grains,
  as along R = -2.5) ends without a peak and without runs. Under strain control at the test's
  rate this peak carries the loading's rate overstress: it is an upper bound of what the
  sample holds at rest.
* **The peak at rest** (``staircase``): the path's start state relaxed at fixed strain
  (``relax``: the walls still, until dem.settle's equilibrium and a c that no longer drifts),
  then G held by steps under a dead load, each hold from the previous equilibrium (so from
  rest): a step that settles moves the staircase up, one that fails is halved, down to ``dc``;
  the c peak at rest is the last c held, and the failing hold of +dc from it is the ``past``
  run. ``below``: from the first equilibrium of the staircase whose c reaches c_rest(start) +
  ``below_rise`` (c_peak_rest - c_rest(start)), held at its c + dc. The loaded peak's state is
  relaxed too (rest.csv: its c at rest and the drop from the loaded c). Relaxing the path's
  states at fixed strain and holding the largest of their c + dc was tried first: at 2000 disks
  that hold settled (docs/dem.md: a state relaxed at fixed strain keeps less c than the sample
  can hold).
* **The dead load** (``walls.dead_load``): the walls, tied, are one dynamic degree of freedom,
  the platens' shortening U1, of generalized mass m_G (``wall_mass_rule``: their period on their
  contact stiffness is ``wall_period_steps`` steps), under the constant generalized force
  G_held = G(switch) + W t dc: m_G U1'' = G_held - G, no servo, no speed limit, no damping on
  the walls; W2_ext = dG dU1 exactly. ``hold="servo"`` keeps the servo on c instead.
* **The runs** (``hold``) end by ``dem.settle``'s rule: equilibrium over a window (unbalanced
  force, the stress error |G - G_held| / (W t) (servo: |c - c_target|) <= stress_tol, strain
  drift, backbone kinetic energy); failure when the strain since the switch passes
  ``fail_strain`` or runs away (``runaway_ratio`` times the elastic strain of ``strain_norm``)
  with the stress error above ``runaway_stress`` and the kinetic energy not decaying; undecided
  at the cap.

Every check records (history.csv): total and backbone kinetic energy [J], unbalanced ratio,
strains, wall stresses, c, c_target, |c - c_target|, ``w2_ext_held`` = dG dU1 (dG = W_s t dc,
U1 = H0 eps1 the platens' shortening: what the held step puts in if G were held exactly), the
walls' own secant second-order work sum_w dF_w dU_w, ``w2_int_secant``, the paper's contact sum
sum_c df . dl over the grain and wall contacts since the switch (Eq. 15 form, secant; by Eq. 14
it is the walls' less sum_p dF_p . dx_p), and the energy ledger from the switch (``dem.ledger``):
the walls' work, the contact work and its split into stored and dissipated energy, the Cundall
damping's work, and Eq. 1 in second-order form, E_c - E_c(0) = W2_ext - W2_int + W_damp + U0,
closed to round-off (``w2_ext``, ``w2_int``, ``u0``, ``eq1_bookkeeping``).
"""
from __future__ import annotations

import json
import math
import os
import sys
import time
from collections import deque
from typing import NamedTuple

import numpy as np

from hmodel.burst import check_ratio
from hmodel.burst_rule import RELEASE

from . import kernels
from .anatomy import ANATOMY_COLUMNS, UNSTABLE_WINDOW, contact_state
from .ledger import COLUMNS as LEDGER_COLUMNS, EXTRA_COLUMNS as LEDGER_EXTRA_COLUMNS, Ledger
from .settle import HISTORY_COLUMNS as SETTLE_COLUMNS, RULE_COLUMNS, SettleRule, settle, voigt_strain
from .simulation import Simulation, State
from .threads import ThreadChooser
from .walls import strain_rate, tied

SWITCHES = ("below", "past")
ONSET = 10.0          # the onset of a burst: the backbone's kinetic energy this many times its
                      # floor (one check after the switch: ``hold``)
HOLDS = ("dead_load", "servo")
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
BURST_COLUMNS = ["ratio", "start_fraction", "eta_start", "eta_peak_c", "fraction_peak_c",
                 "eps1_peak_c", "c_start", "c_peak", "peak_confirmed_by", "switch",
                 "eta_switch", "eps1_switch", "c_switch", "dc", "c_target", "outcome",
                 "ke_growth", "ke_max", "ke_backbone_max", "w2_ext_end", "w2_walls_end",
                 "w2_int_end", "t_end", "steps", "de1_end", "de2_end", "creep_rate",
                 "unbalanced_end", "path_steps", "n_disks", "w2_ext_held_end",
                 "w2_int_secant_end", "w_damp_end", "u0_end", "eq1_bookkeeping", "ke_switch",
                 "c_rest", "c_loaded", "hold", "c_peak_loaded", "eta_peak_loaded", "wall_mass",
                 "g_held", "holds", "rest_search",
                 # the growth against the held step's work and the equilibrium bound (``growth``)
                 "ke_w2ext_max", "t_release", "released", "ke_end_over_bound",
                 # the kinematic probe at the switch's start, the path's verdict (``staircase``)
                 "k_path_switch", "k_noise", "c_cross", "overshoot_c", "overshoot_eps1",
                 "verdict",
                 # the anatomy: unstable contacts of the increment, against the baseline run
                 # (the switch's state held with no change of load), and at the burst's onset
                 "n_unstable_max", "unstable_noise_mean", "unstable_noise_max",
                 "n_unstable_excess", "largest_cluster_max", "largest_cluster_noise_max",
                 "t_onset", "n_unstable_onset", "largest_cluster_onset", "sliding_share_onset",
                 "sliding_share_switch", "n_unstable_raw_max", "unstable_raw_noise_max"]


class BurstOptions(NamedTuple):
    """The path, the switches and the rule of the runs (SI; strains compression positive)."""
    rate: float = 0.01              # axial strain rate of the path [1/s] (the biaxial test's)
    path_strain: float = 0.03       # the path ends this axial strain from its start [-]
    record_strain: float = 5e-6     # axial strain between two records of the path [-]
    peak_drop: float = 150e3        # c this far below its largest confirms the peak [Pa]
    peak_strain: float = 5e-3       # or the path this far (eps1) beyond it [-]
    below_rise: float = 0.5         # below: first c >= c_start + below_rise (c_peak - c_start)
    dc: float = 100.0               # the held step of c [Pa] (4 x stress_tol: resolvable)
    unbalanced_tol: float = 1e-4    # equilibrium: unbalanced ratio at every check of the window
    stress_tol: float = 25.0        # equilibrium: |c - c_target| at every check [Pa]
    strain_tol: float = 0.01        # equilibrium: strain drift over the window / strain scale
    ke_tol: float = 1e-10           # equilibrium: backbone kinetic energy per disk [J]
    window: int = 20_000            # window at 1000 disks [steps] (dem.settle scales it)
    check_every: int = 1000         # steps between checks
    max_steps: int = 1_000_000      # cap of a run [steps]: undecided when reached
    strain_norm: float = 2500.0     # the strain scale: elastic strain of this stress [Pa]
    runaway_ratio: float = 1000.0   # failure: |de| / scale beyond this with c lost
    runaway_stress: float = 250.0   # ... and |c - c_target| above this all the window [Pa]
    fail_strain: float = 0.01       # failure: |de| since the switch beyond this [-]
    hold: str = "dead_load"         # the held G: "dead_load" (walls.dead_load) or "servo"
    wall_mass: float | None = None  # m_G of the walls under the dead load [kg]; None: the rule
    wall_period_steps: float = 200.0  # the rule: the walls' period on their contacts, in steps
    relax_max_steps: int = 1_000_000  # cap of a relaxation at fixed strain [steps]
    stairs: int = 8                 # the staircase's first step: (loaded peak - c at rest) / this
    max_holds: int = 40             # cap of the staircase's holds
    probes: bool = True             # the kinematic probe of the path at every equilibrium
    probe_d_eps1: float = 1e-5      # the probe's axial strain along the path [-]
    probe_rate: float | None = None  # the probe's axial strain rate [1/s]; None: the move lasts
                                     # one equilibrium window (``probe_rate_of``)

    def validate(self, n_disks=None) -> "BurstOptions":
        """ValueError naming the option and its range for a bad value; ``n_disks``: the
        sample's size, for the relaxation cap against the equilibrium window."""
        from .settle import window_steps
        checks = (("rate", 0 < self.rate <= 10, "0 < rate <= 10 [1/s]"),
                  ("path_strain", 0 < self.path_strain < 0.5, "0 < path_strain < 0.5"),
                  ("record_strain", 0 < self.record_strain < self.path_strain,
                   "0 < record_strain < path_strain"),
                  ("peak_drop", self.peak_drop > 0, "peak_drop > 0 [Pa]"),
                  ("peak_strain", 0 < self.peak_strain < 0.5, "0 < peak_strain < 0.5"),
                  ("below_rise", 0 < self.below_rise < 1, "0 < below_rise < 1"),
                  ("dc", self.dc >= 0, "dc >= 0 [Pa]"),
                  ("strain_norm", self.strain_norm > 0, "strain_norm > 0 [Pa]"),
                  ("wall_period_steps", self.wall_period_steps >= 20,
                   "wall_period_steps >= 20 (the leapfrog resolves the walls' period)"),
                  ("stairs", self.stairs >= 1, "stairs >= 1"),
                  ("max_holds", self.max_holds >= 2, "max_holds >= 2"),
                  ("probe_d_eps1", 0 < self.probe_d_eps1 <= 1e-3, "0 < probe_d_eps1 <= 1e-3"))
        for name, ok, rng in checks:
            val = getattr(self, name)
            if not ok or not math.isfinite(val):
                raise ValueError(f"{name}={val!r}; allowed range: {rng}")
        if self.probe_rate is not None and not (math.isfinite(self.probe_rate)
                                                and 0 < self.probe_rate <= self.rate):
            raise ValueError(f"probe_rate={self.probe_rate!r}; allowed range: 0 < probe_rate <= "
                             "rate (the path's) [1/s], or the rule (one equilibrium window)")
        if self.hold not in HOLDS:
            raise ValueError(f"hold={self.hold!r}; allowed: {', '.join(HOLDS)}")
        if self.wall_mass is not None and not (math.isfinite(self.wall_mass)
                                               and self.wall_mass > 0):
            raise ValueError(f"wall_mass={self.wall_mass!r}; allowed range: wall_mass > 0 [kg] "
                             "(finite), or the rule (wall_period_steps)")
        win = window_steps(n_disks or 1000, self.rule())
        if not self.relax_max_steps >= 2 * win:
            raise ValueError(f"relax_max_steps={self.relax_max_steps!r}; allowed range: "
                             f"relax_max_steps >= {2 * win} (two equilibrium windows at "
                             f"{n_disks or 1000} disks: a relaxation is decided over a window of "
                             "its c's drift, itself a window long)")
        self.rule().validate()
        return self

    def rule(self) -> SettleRule:
        """``dem.settle``'s rule of a run: its equilibrium tolerances, the runaway with the
        servo unable to hold c, the strain beyond ``fail_strain``; no failure by the elastic
        strain ratio alone (fail_ratio: a creep is measured against a Voigt estimate here, not
        against an elastic probe)."""
        return SettleRule(self.unbalanced_tol, self.stress_tol, self.strain_tol, self.ke_tol,
                          self.window, self.check_every, self.runaway_ratio, math.inf,
                          self.max_steps, self.runaway_stress, self.fail_strain)


def confirm_peak(c, eps1, c_peak, eps1_peak, opts: BurstOptions) -> str:
    """The peak rule at one record (c [Pa], eps1) of the path, the largest c so far being
    ``c_peak`` at ``eps1_peak``: "new" (c is the largest so far), "drop" or "strain" (the peak
    is confirmed: c has fallen from it by ``opts.peak_drop``, or the path has gone
    ``opts.peak_strain`` beyond it), "" (go on)."""
    if c > c_peak:
        return "new"
    if c_peak - c >= opts.peak_drop:
        return "drop"
    if eps1 - eps1_peak >= opts.peak_strain:
        return "strain"
    return ""


def scan_peak(c, eps1, opts: BurstOptions):
    """``confirm_peak`` along whole arrays (the rule ``proportional_path`` applies as it goes):
    (row of the peak, how it was confirmed ("" if not), row where the path stops)."""
    peak = 0
    for k in range(1, len(c)):
        how = confirm_peak(c[k], eps1[k], c[peak], eps1[peak], opts)
        if how == "new":
            peak = k
        elif how:
            return peak, how, k
    return peak, "", len(c) - 1


def below_row(c, peak, rise) -> int:
    """The ``below`` switch: the first row with c >= c[0] + rise (c[peak] - c[0])."""
    c = np.asarray(c, float)
    return int(np.flatnonzero(c[:peak + 1] >= c[0] + rise * (c[peak] - c[0]))[0])


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
REST_COLUMNS = ["ratio", "start_fraction", "state", "eps1", "c_loaded", "c_rest", "drop",
                "eta_rest", "outcome", "steps", "ke_end", "unbalanced_end", "k_path"]
STAIR_COLUMNS = ["ratio", "start_fraction", "hold", "role", "c_from", "c_target", "dc",
                 "outcome", "steps", "eps1_start", "eps1_end", "c_end", "ke_switch",
                 "ke_backbone_max", "w2_int_end", "eq1_bookkeeping", "from", "k_path_from",
                 "k_path", "ke_w2ext_max", "ke_end_over_bound"]
# rest.csv's probe columns, and probes.csv's (every kinematic probe of the path: ``path_probe``)
PROBE_COLUMNS = ["ratio", "start_fraction", "key", "c_state", "c_before", "c_after", "eps1_before",
                 "d_eps1", "k_path", "w2", "outcome", "steps", "wall_time", "rate"]


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
    from .settle import window_steps
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
    from .settle import window_steps
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
    burst (``shared/spec/burst.md``, "What the DEM's burst proves"): ``state`` relaxed at fixed
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


def k_noise(probes, d_eps1, repeats=()) -> tuple:
    """The noise of k_path [Pa] from the probes of one path, (the larger of the two below, the
    relaxations', the repeats'): (1) sqrt(2) times the RMS change of c that relaxing an
    equilibrium at fixed strain makes (c_before - c_state, the states held under the dead load:
    the relaxed states of the path are at rest at fixed strain already), over d_eps1: c_before
    and c_after each carry it; (2) the scatter of k_path on one macroscopic state, from
    ``repeats``, pairs of probes of the same state before and after it was held once more with no
    change of load (the baselines' ends against the switches' starts): the RMS of their
    differences over sqrt(2). The second is the larger where the packing's last hold changes its
    response (2000 disks: 6.5e7 against 2.6e7 Pa at the below state, where the relaxations give
    6.9e6 Pa). NaN where neither can be had."""
    dz = [p.c_before - p.c_state for p in probes if p.key.startswith("h")]
    relax_noise = (math.sqrt(2.0) * math.sqrt(float(np.mean(np.square(dz)))) / d_eps1
                   if dz else math.nan)
    dk = [a.k_path - b.k_path for a, b in repeats]
    repeat_noise = (math.sqrt(float(np.mean(np.square(dk))) / 2.0) if dk else math.nan)
    both = [x for x in (relax_noise, repeat_noise) if math.isfinite(x)]
    return (max(both) if both else math.nan), relax_noise, repeat_noise


CLEARLY = 2.0      # k_path is clearly positive above this many times its noise


def theory_verdict(eqs, fails, noise, dc) -> dict:
    """The theory's verdict on one path's staircase (``shared/spec/burst.md``): at a state at
    rest, W2 of the path (the sign of k_path) vanishes where a held G can no longer be kept.

    ``eqs``: the staircase's equilibria in order, [(key, c [Pa], eps1, k_path [Pa])], the relaxed
    start first; ``fails``: its failing holds, [(key of the equilibrium it started from, step
    [Pa])]; ``noise``: k_path's noise [Pa] (``k_noise``); ``dc``: the smallest step [Pa].

    k_path is *clearly positive* above ``CLEARLY`` times its noise. The crossing: the zero of
    k_path, interpolated linearly in c between the first equilibrium with k_path <= 0 after the
    last one where it is clearly positive, and the one before it (the band: where k_path = +-
    CLEARLY noise there). A positive k_path within the noise after the crossing does not move it
    (at 4000 disks one, +1.8e6 Pa against a noise of 4.1e6 Pa, lies between two of -1.6e7 and
    -5.6e8 Pa), nor do positive ones within the noise before it (they are the rise's last
    equilibria). The overshoot: how far past it, in c and in eps1, the dead load still held (the
    c peak at rest, the last equilibrium). The verdict:
    "passes" when no hold of +dc failed from an equilibrium where k_path is clearly positive
    and k_path is not clearly positive at the last equilibrium; "contradicted" when a hold of +dc
    failed from an equilibrium where k_path is clearly positive; "no verdict" without a failing
    hold of +dc or without k_path (probes off or undecided). A failing hold of a larger step
    from a clearly positive k_path is reported (``finite_step_failures``), not counted against
    the theory: it speaks of an infinitesimal dG (the dead load's finite step also overshoots
    its static displacement dynamically)."""
    nan = math.nan
    k = np.array([e[3] for e in eqs], float)
    c = np.array([e[1] for e in eqs], float)
    e1 = np.array([e[2] for e in eqs], float)
    out = {"k_path_first": float(k[0]) if len(k) else nan,
           "k_path_last": float(k[-1]) if len(k) else nan,
           "k_path_ratio": float(k[-1] / k[0]) if len(k) and k[0] != 0 else nan,
           "k_noise": noise, "c_cross": nan, "c_cross_band": [nan, nan], "eps1_cross": nan,
           "overshoot_c": nan, "overshoot_eps1": nan, "finite_step_failures": 0,
           "c_peak_rest": float(c[-1]) if len(c) else nan,
           "verdict": "no verdict", "why": ""}
    if not len(k) or not np.all(np.isfinite(k)) or not math.isfinite(noise):
        out["why"] = "no k_path at every equilibrium"
        return out
    pos = k > CLEARLY * noise
    kk = {e[0]: (kv, p) for e, kv, p in zip(eqs, k, pos)}
    dc_fails = [f for f in fails if f[1] <= dc * (1 + 1e-9)]
    against = [f for f in dc_fails if kk.get(f[0], (nan, False))[1]]
    out["finite_step_failures"] = sum(1 for f in fails if f[1] > dc * (1 + 1e-9)
                                      and kk.get(f[0], (nan, False))[1])
    # the crossing: the first k_path <= 0 after the last clearly positive one (if one follows)
    above = np.flatnonzero(pos)
    after = np.flatnonzero(k[above[-1]:] <= 0) + above[-1] if len(above) else []
    if len(above) and len(after):
        a = int(after[0]) - 1

        def zero(level):
            return float(np.interp(level, [k[a + 1], k[a]], [c[a + 1], c[a]])), \
                float(np.interp(level, [k[a + 1], k[a]], [e1[a + 1], e1[a]]))

        out["c_cross"], out["eps1_cross"] = zero(0.0)
        out["c_cross_band"] = sorted([zero(CLEARLY * noise)[0], zero(-CLEARLY * noise)[0]])
        out["overshoot_c"] = float(c[-1] - out["c_cross"])
        out["overshoot_eps1"] = float(e1[-1] - out["eps1_cross"])
    elif not len(above):
        out["why"] = "k_path not clearly positive already at the first equilibrium"
    if against:
        out["verdict"] = "contradicted"
        out["why"] = (f"a hold of +{dc:g} Pa failed from an equilibrium where k_path is clearly "
                      f"positive ({kk[against[0][0]][0]:.3g} Pa, noise {noise:.2g} Pa)")
    elif not dc_fails:
        out["why"] = "no hold of +dc failed"
    elif pos[-1]:
        out["verdict"] = "contradicted"
        out["why"] = f"k_path is clearly positive at the last equilibrium ({k[-1]:.3g} Pa)"
    else:
        out["verdict"] = "passes"
        out["why"] = (f"k_path {k[0]:.3g} Pa at the first equilibrium, {k[-1]:.3g} Pa at the "
                      f"last (noise {noise:.2g} Pa): the holds of +{dc:g} Pa failed where W2 of "
                      "the path is <= 0 within noise")
    return out


class StairResult(NamedTuple):
    """The rest search of one path (``staircase``)."""
    relaxed: dict             # "start" and "peak" (the loaded peak's or the end's) -> RelaxResult
    holds: list               # [(role, c_from, c_target, HoldResult)]: the staircase's
                              # ("stair"), the below run ("below"), then each switch's state
                              # held with no change of load ("baseline_below", "baseline_past");
                              # the past run is the last failing stair hold
    c_peak: float             # the largest c at rest held at equilibrium (nan: none)
    eps1_peak: float          # its axial strain
    eta_peak: float
    switches: dict            # "below"/"past" -> index into holds
    end: str                  # how the search ended: "past found", "no loaded peak", ...
    wall_time: float
    starts: list = []         # the journal key of the state each hold started from
    probes: dict = {}         # journal key of an equilibrium -> ProbeResult (path_probe)
    verdict: dict = {}        # theory_verdict's, with the probes' rule
    baselines: dict = {}      # "below"/"past" -> index into holds of its baseline run


def staircase(path: PathResult, ratio: float, opts: BurstOptions = BurstOptions(), threads=None,
              log=None, journal=None) -> StairResult:
    """The c peak at rest along the path, found from rest as the theory asks it: the path's start
    state relaxed at fixed strain (``relax``), then G held by steps (``hold``, from the last
    equilibrium each time, so every hold starts from rest): the first step is (c_peak_loaded -
    c_rest) / ``opts.stairs``; a step that settles moves the staircase up (its end state, at
    rest, is the next start); one that fails is halved, down to ``opts.dc``; the search ends with
    a failing hold of +dc from an equilibrium at c: the c peak at rest is that c, the ``past``
    run that failing hold. (Each step raises the held force G, the force conjugate to U1, by
    W t times the step from the last equilibrium's, so G rises along the staircase; c = s1 + R
    s2 follows G through the box's shape, c W t = G + R F2 (W/H - W0/H0), and a hold that creeps
    may end at a c below its start: the c peak at rest is the c of the equilibrium under the
    largest G.) ``below``: from the first equilibrium of the staircase whose c reaches
    c_rest + below_rise (c_peak_rest - c_rest), held at its c + dc. Each switch's start state is
    also held with no change of load (its ``baseline`` run: the noise of the anatomy's counts).
    The loaded peak's state is relaxed too: its c at rest and its drop from the loaded c are
    recorded. A path without a loaded peak gets one below run from its end, relaxed. With
    ``opts.probes``, every equilibrium (the relaxed states, the end of every hold that settled)
    is probed along the path (``path_probe``: k_path) and the theory's verdict is drawn
    (``theory_verdict``). ``journal``: a ``_Journal`` that records every relaxation, hold and
    probe as it finishes (and gives them back on a resume)."""
    t0 = time.time()
    log = log or (lambda m: None)
    journal = journal or _Journal(None)
    dc = opts.dc
    relaxed = {}
    for name, (row, st) in zip(("start", "peak"), path.grid):
        res = journal.relaxation(name)
        if res is None:
            res = relax(st, ratio, opts, threads)
            journal.add_relaxation(name, res, path.rows[row, 8])
            log(f"{name} state relaxed at fixed strain: c {res.c_loaded / 1e3:.2f} -> "
                f"{res.c_rest / 1e3:.2f} kPa, {res.outcome} after {res.steps} steps")
        relaxed[name] = res
    holds, starts = [], []
    eq = [("relaxed_start", relaxed["start"].c_rest, path.rows[path.grid[0][0], 1])]  # equilibria

    def held(role, key, c_from, target):
        k = len(holds)
        got = journal.hold(k)
        if got is None:
            got = hold(journal.state(key), ratio, target, opts, threads)
            for when in ("end", "onset", "onset_prev", "end_prev"):   # the next start, figures
                journal.keep(f"h{k}_{when}", getattr(got, f"{when}_state"))
            journal.add_hold(k, role, c_from, target, got, key)
            log(f"{role} hold {k}: c {c_from / 1e3:.3f} -> {target / 1e3:.3f} kPa: "
                f"{got.outcome} after {got.steps} steps")
        holds.append((role, c_from, target, got._replace(end_state=None, onset_state=None,
                                                         onset_prev_state=None,
                                                         end_prev_state=None)))
        starts.append(key)
        return got

    switches, baselines = {}, {}
    c_peak = e_peak = eta_peak = math.nan
    if path.peak is None:                           # no loaded peak: below from the path's end
        held("below", "relaxed_peak", relaxed["peak"].c_rest, relaxed["peak"].c_rest + dc)
        switches["below"] = 0
        end = "no loaded peak"
    else:
        c_s = relaxed["start"].c_rest
        key = "relaxed_start"
        step = max((path.rows[path.peak, 8] - c_s) / opts.stairs, dc)
        end = ""
        while len(holds) < opts.max_holds:
            h = held("stair", key, c_s, c_s + step)
            if h.outcome == "equilibrium":
                key = f"h{len(holds) - 1}_end"
                c_s = h.history[-1, 4]
                eq.append((key, c_s, h.history[-1, 2]))
                continue
            if h.outcome == "undecided":
                end = "a hold undecided at --max-steps"
                break
            if step <= dc:
                end = "past found"
                break
            step = max(0.5 * step, dc)
        else:
            end = f"no failure within {opts.max_holds} holds"
        c_peak, e_peak = eq[-1][1], eq[-1][2]
        if end == "past found":
            switches["past"] = len(holds) - 1
            thr = eq[0][1] + opts.below_rise * (c_peak - eq[0][1])
            kb, cb, _ = next(x for x in eq if x[1] >= thr) if len(eq) > 1 else eq[0]
            held("below", kb, cb, cb + dc)
            switches["below"] = len(holds) - 1
            hp = holds[switches["past"]][3].history
            eta_peak = (hp[0, 10] - hp[0, 11]) / (0.5 * (hp[0, 10] + hp[0, 11]))
    # each switch's start held with no change of load: the anatomy's noise
    for sw in SWITCHES:
        if sw in switches:
            i = switches[sw]
            held(f"baseline_{sw}", starts[i], holds[i][1], holds[i][1])
            baselines[sw] = len(holds) - 1
    log(f"rest search: {end}; c peak at rest {c_peak / 1e3:.3f} kPa, {len(holds)} holds")
    probes, verdict = {}, {}
    if opts.probes:
        keys = ([k for k, _, _ in eq] + ["relaxed_peak"]
                + [f"h{k}_end" for k, (ro, _, _, h) in enumerate(holds)
                   if ro != "stair" and h.outcome == "equilibrium"])
        for key in keys:
            pr = journal.probe(key)
            if pr is None:
                pr = path_probe(journal.state(key), ratio, opts, threads, key)
                journal.add_probe(pr)
                log(f"probe at {key}: c {pr.c_before / 1e3:.3f} kPa, k_path {pr.k_path:.3g} Pa "
                    f"(dc {pr.c_after - pr.c_before:+.1f} Pa over d eps1 {pr.d_eps1:.3g}), "
                    f"{pr.outcome}")
            probes[key] = pr
        repeats = [(probes[starts[i]], probes[f"h{i}_end"]) for i in baselines.values()
                   if starts[i] in probes and f"h{i}_end" in probes]
        noise, relax_noise, repeat_noise = k_noise(list(probes.values()), opts.probe_d_eps1,
                                                   repeats)
        eqk = [(k, c, e, probes[k].k_path if probes[k].outcome == "equilibrium" else math.nan)
               for k, c, e in eq]
        fails = [(starts[i], ct - cf) for i, (ro, cf, ct, h) in enumerate(holds)
                 if ro == "stair" and h.outcome == "failure"]
        verdict = theory_verdict(eqk, fails, noise, dc) if end == "past found" else \
            {**theory_verdict(eqk, [], noise, dc), "why": f"the rest search ended: {end}"}
        st0 = journal.state("relaxed_start")
        verdict.update(k_noise_relax=relax_noise, k_noise_repeat=repeat_noise,
                       probe_d_eps1=opts.probe_d_eps1,
                       probe_rate=probe_rate_of(len(st0.r), st0.params.dt, opts))
        log(f"theory: {verdict['verdict']} ({verdict['why']})")
    return StairResult({k: v._replace(state=None) for k, v in relaxed.items()}, holds, c_peak,
                       e_peak, eta_peak, switches, end, time.time() - t0, starts, probes,
                       verdict, baselines)


class _Journal:
    """A staircase's record (``staircase``): ``dir``/R{r}_f{f}.jsonl, one line per relaxation and
    hold as it finishes, and the states it starts holds from (``keep``, ``state``) as npz files
    beside it, so that a resumed staircase replays what it had and goes on from its last
    equilibrium. ``Journal(None)``: records nothing (a staircase in memory)."""

    def __init__(self, base, resume=False):
        self.base = base
        self.records = []
        self.mem = {}
        if base and resume and os.path.exists(base + ".jsonl"):
            with open(base + ".jsonl") as f:
                for line in f.read().split("\n"):
                    try:
                        self.records.append(json.loads(line))
                    except ValueError:
                        continue
        if base:
            from .io import atomic_write_bytes
            atomic_write_bytes(base + ".jsonl", "".join(json.dumps(r) + "\n"
                                                         for r in self.records).encode())

    def _add(self, rec):
        self.records.append(rec)
        if self.base:
            with open(self.base + ".jsonl", "a") as f:
                f.write(json.dumps(rec) + "\n")
                f.flush()
                os.fsync(f.fileno())

    def relaxation(self, name):
        for r in self.records:
            if r["kind"] == "relax" and r["name"] == name:
                return RelaxResult(self.state("relaxed_" + name), r["outcome"], r["steps"],
                                   r["c_loaded"], r["c_rest"], r["eta_rest"], r["ke_end"],
                                   r["unbalanced_end"], np.asarray(r["history"], float),
                                   r["wall_time"])
        return None

    def add_relaxation(self, name, res, c_path):
        self.keep("relaxed_" + name, res.state)
        self._add({"kind": "relax", "name": name, "outcome": res.outcome, "steps": res.steps,
                   "c_loaded": res.c_loaded, "c_rest": res.c_rest, "eta_rest": res.eta_rest,
                   "ke_end": res.ke_end, "unbalanced_end": res.unbalanced_end,
                   "history": res.history.tolist(), "wall_time": res.wall_time,
                   "c_path": c_path})

    def hold(self, k):
        for r in self.records:
            if r["kind"] == "hold" and r["k"] == k:
                return HoldResult(r["outcome"], r["steps"], np.asarray(r["history"], float),
                                  r["creep_rate"], r["wall_time"], r["hold"], r["ke_switch"],
                                  r["g_held"], r["wall_mass"], None, None, r["onset_step"])
        return None

    def probe(self, key):
        for r in self.records:
            if r["kind"] == "probe" and r["key"] == key:
                return ProbeResult(**{f: r[f] for f in ProbeResult._fields if f in r})
        return None

    def add_probe(self, p: ProbeResult):
        self._add({"kind": "probe", **p._asdict()})

    def add_hold(self, k, role, c_from, target, h, start):
        self._add({"kind": "hold", "k": k, "role": role, "c_from": c_from, "c_target": target,
                   "from": start,
                   "outcome": h.outcome, "steps": h.steps, "history": h.history.tolist(),
                   "creep_rate": h.creep_rate, "wall_time": h.wall_time, "hold": h.hold,
                   "ke_switch": h.ke_switch, "g_held": h.g_held, "wall_mass": h.wall_mass,
                   "onset_step": h.onset_step})

    def keep(self, key, state):
        if state is None:
            return
        self.mem[key] = state
        if self.base:
            from .io import save_state
            save_state(f"{self.base}_{key}.npz", state)

    def state(self, key):
        if key in self.mem:
            return self.mem[key]
        from .io import load_state
        return load_state(f"{self.base}_{key}.npz")[0]

    def has(self, key):
        return key in self.mem or bool(self.base) and os.path.exists(f"{self.base}_{key}.npz")

    def files(self):
        """The journal and its state files."""
        if not self.base:
            return []
        d, b = os.path.split(self.base)
        return [os.path.join(d, f) for f in os.listdir(d) if f.startswith(b + "_") or
                f == b + ".jsonl"]


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
    from .walls import dead_load, generalized_force
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
    # E_c at the switch: the backbone's (disks with two contacts or more), as ke_growth's
    return HoldResult(res.outcome, res.steps, np.asarray(hist, float), res.creep_rate,
                      time.time() - t0, opts.hold, hist[0][8], g_held, m_g, sim.state(),
                      onset[0][1] if onset else None, onset[0][0] if onset else -1,
                      onset[0][2] if onset else None, recent[0])


def ke_growth(keb) -> float:
    """Largest backbone kinetic energy over the one at the switch, where the sample is at rest
    (the ``ke_growth`` column): a ratio to the kinetic-energy floor of the start, which depends on
    how well the start had settled and on the sample's size, so it tells neither settling from
    bursting nor one size from another (a settling run read x2e5 at 2000 disks, x27 at 300):
    the growth measures are ``growth`` (the energy release against the work of the held step,
    and the kinetic energy at the end against the equilibrium bound)."""
    keb = np.asarray(keb, float)
    return float(keb.max() / keb[0]) if keb[0] > 0 else math.inf


def growth(history, n_disks, ke_tol) -> dict:
    """The growth of a held run's backbone kinetic energy measured against what the held step
    put in (``hmodel.burst_rule.energy_release``, the one measure of the three parts: E_c
    gained since the switch over W2_ext = dG dU1, its largest value ``ke_w2ext_max``, the time
    ``t_release`` [s] it first passes ``RELEASE``, ``released``) and against the equilibrium
    bound: ``ke_end_over_bound``, the backbone E_c at the end over ke_tol x disks. Neither depends
    on the kinetic-energy floor of the start. ``history``: a hold's (HISTORY_COLUMNS from
    "step")."""
    from hmodel.burst_rule import energy_release
    h = np.asarray(history, float)
    r = energy_release(h[:, 1], h[:, 8], h[:, H["w2_ext_held"]])
    return {"ke_w2ext_max": r["ratio_max"], "t_release": r["t_release"],
            "released": int(r["released"]), "ke_end_over_bound": float(h[-1, 8] / (ke_tol * n_disks))}


# ----------------------------------------------------------------------------------------------
# The command: every (R, f) path, then every switch, spread over processes; files and figures
# ----------------------------------------------------------------------------------------------
def load_starts(biaxial_dir, fractions, params_file=None):
    """[(f, State, meta)] of ``biaxial_dir/states/state_fF.FFF.npz`` for each start fraction,
    the drained peak eta (``summary.json``) and the states' parameters. ValueError (one line,
    naming the option) for a fraction not saved, states of other parameters than the biaxial
    test's, or a ``params_file`` that is not theirs."""
    from .domain import load_states
    from .params import DemParams, load_params
    out = []
    for f in fractions:
        (todo, eta_peak) = load_states(biaxial_dir, [f"f={f:g}"], option="--start-fractions")
        out.append((float(f), todo[0][1], todo[0][2]))
    with open(os.path.join(biaxial_dir, "summary.json")) as fh:    # read by load_states
        own = DemParams.from_dict(json.load(fh).get("params", {}))
    for f, st, _ in out:
        if st.params != own:
            raise ValueError(f"--biaxial {biaxial_dir}: state_f{f:.3f}.npz was made with other "
                             "parameters than the biaxial test's summary.json; allowed: the "
                             "states of one biaxial test")
    if params_file:
        given = load_params(params_file)
        if given != own:
            diff = [k for k, v in own.to_dict().items() if given.to_dict()[k] != v]
            raise ValueError(f"--params {params_file} conflicts with the parameters the states "
                             f"carry ({', '.join(diff)}); allowed: the states' own, or no --params")
    return out, eta_peak, own


def _log(msg):
    print(f"[burst] {msg}", file=sys.stderr, flush=True)


def _path_task(args):
    state, ratio, fraction, opts, threads, verbose = args
    last = [time.time()]

    def progress(steps, row, peak):
        if verbose and time.time() - last[0] > 10.0:
            last[0] = time.time()
            _log(f"R={ratio:g} f={fraction:g} path: step {steps} eps1={row[1]:.5f} "
                 f"c={row[8] / 1e3:.2f} kPa, largest {peak[8] / 1e3:.2f} kPa at eps1={peak[1]:.5f}")

    return proportional_path(state, ratio, opts, threads, progress)


def _stairs_task(args):
    path, ratio, fraction, opts, threads, verbose, base, resume = args
    log = (lambda m: _log(f"R={ratio:g} f={fraction:g} {m}")) if verbose else None
    return staircase(path, ratio, opts, threads, log, _Journal(base, resume))


def checkpoint_header(starts, ratios, opts) -> dict:
    """What a burst run is, for its checkpoint: the start states' fingerprints, the ratios and
    the options (``starts`` as ``load_starts`` gives them)."""
    from .probes import state_fingerprint
    return json.loads(json.dumps({"fingerprints": {f"{f:g}": state_fingerprint(st)
                                                   for f, st, _ in starts},
                                  "ratios": [float(r) for r in ratios],
                                  "options": opts._asdict()}))


def read_checkpoint(out_dir, header) -> list:
    """The finished paths of ``out_dir``/burst_runs.jsonl (none if there is no such file; a torn
    last line dropped). ValueError (``--resume``, one line) if it belongs to other start states,
    ratios or options."""
    path = os.path.join(out_dir, "burst_runs.jsonl")
    if not os.path.exists(path):
        return []
    recs = []
    with open(path) as f:
        for line in f.read().split("\n"):
            try:
                recs.append(json.loads(line))
            except ValueError:
                continue
    if not recs or recs[0] != header:
        raise ValueError(f"--resume: {path} belongs to other start states, ratios or options; "
                         "remove it or choose another output folder")
    return recs[1:]


def run_burst(biaxial_dir, out_dir, ratios, fractions, opts: BurstOptions = BurstOptions(),
              workers=None, threads=None, verbose=True, params_file=None, stage=None,
              resume=False, scheduler=None):
    """Every proportional path (one per ratio and start fraction), then the rest search of every
    path (``staircase``: its start relaxed at fixed strain, then G held by steps from rest until
    a hold of +dc fails; the below and past runs), each path's task an independent run spread
    over ``workers`` local processes or a dask cluster at ``scheduler`` (one thread each;
    ``threads`` in a single process). Every finished path goes to ``out_dir``/burst_runs.jsonl
    and every relaxation and hold of a staircase to its journal in ``out_dir``/rest/, so that
    ``resume`` continues from them (refusing a folder of other states or options). Writes
    ``out_dir``/burst.csv, history.csv, paths.csv, rest.csv, stairs.csv, summary.json,
    params.json, the states the switches started from (rest/) and the figures. Returns (burst
    rows as dicts, summary dict)."""
    from . import io
    from .io import atomic_write_bytes
    from .probes import _map
    ratios = [check_ratio(float(r)) for r in ratios]
    starts, eta_peak, params = load_starts(biaxial_dir, fractions, params_file)
    opts.validate(params.n)
    header = checkpoint_header(starts, ratios, opts)
    done = read_checkpoint(out_dir, header) if resume else []   # refused before any write
    t0 = time.time()
    os.makedirs(os.path.join(out_dir, "rest"), exist_ok=True)
    # the parameters the run used, in the shared file format (``--params DIR/params.json``)
    from .params import record_params
    record_params(out_dir, params, f"python -m dem burst; parameters: the start states' own "
                                   f"(--biaxial {biaxial_dir})")
    ck = os.path.join(out_dir, "burst_runs.jsonl")
    if not resume and os.path.exists(ck):
        os.replace(ck, ck[:-len(".jsonl")] + ".previous.jsonl")
    atomic_write_bytes(ck, "".join(json.dumps(r) + "\n" for r in [header] + done).encode())
    combos = [(r, f, st) for r in ratios for f, st, _ in starts]
    # a run in a pool of processes runs on one thread; alone in this process, on ``threads``
    # (None: dem.threads chooses)
    per_run = lambda tasks: (threads if threads is not None or (workers == 1 and not scheduler)
                             or len(tasks) == 1 else 1)
    log = _log if verbose else (lambda m: None)
    log(f"{len(combos)} proportional paths ({params.n} disks, rate {opts.rate:g}/s): R in "
        f"{ratios}, start fractions {list(fractions)}; then from rest (the start relaxed at "
        f"fixed strain) G held by steps ({'dead load' if opts.hold == 'dead_load' else 'servo'})"
        f" until a step of {opts.dc:g} Pa fails: the c peak at rest; below at "
        f"{opts.below_rise:g} of the rise at rest")
    paths, stairs = {}, {}
    for rec in done:
        key = (rec["ratio"], rec["start_fraction"])
        grid = [(row, io.load_state(os.path.join(out_dir, "rest", f"{_base(*key)}_path{i}.npz"))[0])
                for i, row in enumerate(rec["grid"])]
        paths[key] = PathResult(np.asarray(rec["rows"], float), rec["peak"],
                                rec["confirmed_by"], grid, rec["steps"], rec["wall_time"])
    if done:
        log(f"resumed from {ck}: {len(paths)} paths finished")
    if stage:
        stage.at("dem burst: the proportional paths")

    def got_path(key, res):
        r, f = key
        for i, (_, st) in enumerate(res.grid):
            io.save_state(os.path.join(out_dir, "rest", f"{_base(r, f)}_path{i}.npz"), st)
        with open(ck, "a") as fh:
            fh.write(json.dumps({"kind": "path", "ratio": r, "start_fraction": f,
                                 "rows": res.rows.tolist(), "peak": res.peak,
                                 "confirmed_by": res.confirmed_by,
                                 "grid": [row for row, _ in res.grid], "steps": res.steps,
                                 "wall_time": res.wall_time}) + "\n")
        paths[key] = res
        pk = (f"loaded c peak {res.rows[res.peak, 8] / 1e3:.2f} kPa at eta "
              f"{res.rows[res.peak, 7]:.4f} (confirmed by {res.confirmed_by})"
              if res.peak is not None else "the specimen unloaded"
              if res.confirmed_by == "unloaded" else "no c peak")
        log(f"R={r:g} f={f:g} path: {pk}, {res.steps} steps, {res.wall_time:.0f} s")

    todo = [(r, f, st) for r, f, st in combos if (r, f) not in paths]
    _map([((r, f), (st, r, f, opts, per_run(todo), verbose)) for r, f, st in todo],
         got_path, workers, scheduler, fn=_path_task)
    if stage:
        stage.at("dem burst: the rest search (from rest, G held by steps)")
    tasks = [((r, f), (paths[(r, f)], r, f, opts, None, verbose,
                       os.path.join(out_dir, "rest", _base(r, f)), resume))
             for r, f, _ in combos if paths[(r, f)].confirmed_by != "unloaded"]
    tasks = [(k, a[:4] + (per_run(tasks),) + a[5:]) for k, a in tasks]

    def got_stairs(key, res):
        stairs[key] = res
        log(f"R={key[0]:g} f={key[1]:g}: {res.end}, {len(res.holds)} holds, "
            f"{res.wall_time:.0f} s")

    _map(tasks, got_stairs, workers, scheduler, fn=_stairs_task)
    rows = []
    for r, f, st in combos:
        if (r, f) not in stairs:
            continue
        for sw, i in sorted(stairs[(r, f)].switches.items(), key=lambda x: SWITCHES.index(x[0])):
            rows.append(burst_row(r, f, sw, paths[(r, f)], stairs[(r, f)], i, opts, eta_peak,
                                  params.n))
    summary = {"biaxial": os.path.abspath(biaxial_dir), "n_disks": params.n,
               "drained_eta_peak": eta_peak, "ratios": ratios, "start_fractions": list(fractions),
               "options": opts._asdict(), "params": params.to_dict(), "dt": params.dt,
               "fingerprints": header["fingerprints"],
               "paths": [{"ratio": r, "start_fraction": f, "steps": paths[(r, f)].steps,
                          "wall_time": paths[(r, f)].wall_time,
                          "end": (paths[(r, f)].confirmed_by or "path_strain reached"),
                          "rest_search": stairs[(r, f)].end if (r, f) in stairs else None,
                          "holds": len(stairs[(r, f)].holds) if (r, f) in stairs else 0,
                          "rest_search_wall_time": stairs[(r, f)].wall_time
                          if (r, f) in stairs else None,
                          # the kinematic probes and the theory's verdict (``theory_verdict``)
                          "theory": stairs[(r, f)].verdict if (r, f) in stairs else {},
                          "k_path": [{"key": p.key, "c": p.c_before, "eps1": p.eps1_before,
                                      "k_path": p.k_path, "outcome": p.outcome}
                                     for p in stairs[(r, f)].probes.values()]
                          if (r, f) in stairs else []} for r, f, _ in combos],
               "runs": [{k: row[k] for k in ("ratio", "start_fraction", "switch", "outcome",
                                             "steps", "ke_w2ext_max", "t_release", "released",
                                             "ke_end_over_bound", "k_path_switch",
                                             "n_unstable_max", "unstable_noise_max",
                                             "n_unstable_excess")} for row in rows],
               "growth_rule": {"release": RELEASE, "measure": "(E_c - E_c(0)) / W2_ext of the "
                               "held step, backbone E_c (hmodel.burst_rule.energy_release)"},
               "wall_time": time.time() - t0}
    write_burst_files(out_dir, combos, paths, stairs, rows, summary)
    # the states the switches started from stay (rest/R.._f.._switch.npz); the rest served the
    # search and a resume
    from .anatomy import plot_anatomy, write_anatomy_vtk
    from .io import save_state
    panels = []
    for r, f, _ in combos:
        j = _Journal(os.path.join(out_dir, "rest", _base(r, f)), resume=True)
        keep = {}
        if (r, f) in stairs:
            res = stairs[(r, f)]
            keep = {sw: j.state(res.starts[i]) for sw, i in res.switches.items()}
            # the anatomy at the onset of a burst (if it came) and at the end of every switch's
            # run: VTU for ParaView, and the first path's figure, below beside past
            for sw in SWITCHES:
                if sw not in res.switches:
                    continue
                i = res.switches[sw]
                s0 = contact_state(Simulation(keep[sw]))
                for when in ("onset", "end"):
                    if j.has(f"h{i}_{when}"):
                        sim = Simulation(j.state(f"h{i}_{when}"))
                        sp = (contact_state(Simulation(j.state(f"h{i}_{when}_prev")))
                              if j.has(f"h{i}_{when}_prev") else None)
                        write_anatomy_vtk(os.path.join(out_dir, "anatomy"),
                                          f"{_base(r, f)}_{sw}_{when}", sim, s0, sp)
                        if (r, f) == (combos[0][0], combos[0][1]):
                            t = (sim.step - keep[sw].step) * sim.dt
                            row = next(x for x in rows if x["switch"] == sw and
                                       (x["ratio"], x["start_fraction"]) == (r, f))
                            panels.append((f"{sw}: {res.holds[i][3].outcome}, at the {when} "
                                           f"(t = {t:.3g} s)\nheld with no change of load: "
                                           f"<= {row['unstable_noise_max']:.0f} unstable",
                                           sim, s0, sp))
        for path in j.files() + [os.path.join(out_dir, "rest", f"{_base(r, f)}_path{i}.npz")
                                 for i in range(2)]:
            if os.path.exists(path):
                os.unlink(path)
        for sw, st in keep.items():
            save_state(os.path.join(out_dir, "rest", f"{_base(r, f)}_{sw}.npz"), st)
    if panels:
        plot_anatomy(os.path.join(out_dir, "fig_burst_anatomy.png"), panels)
    return rows, summary


def _base(ratio, fraction):
    return f"R{ratio:g}_f{fraction:g}"


def burst_row(ratio, fraction, switch, path: PathResult, res: StairResult, i, opts, eta_peak, n):
    """One row of burst.csv (BURST_COLUMNS) as a dict: the path (its loaded peak), the rest
    search (the c peak at rest, the switch's hold ``i``: its start at rest, its target)."""
    pr = path.rows
    role, c_from, c_target, run = res.holds[i]
    h = run.history
    nan = math.nan
    lpk = path.peak
    rs = res.relaxed["start"]
    eps_sw = h[0, 2]
    c_loaded = float(np.interp(eps_sw, pr[:, 1], pr[:, 8])) if eps_sw <= pr[-1, 1] else nan
    peak = res.end == "past found"
    eta_sw = (h[0, 10] - h[0, 11]) / (0.5 * (h[0, 10] + h[0, 11]))
    return {"ratio": ratio, "start_fraction": fraction, "eta_start": rs.eta_rest,
            "eta_peak_c": res.eta_peak if peak else nan,
            "fraction_peak_c": res.eta_peak / eta_peak if peak else nan,
            "eps1_peak_c": res.eps1_peak - pr[0, 1] if peak else nan,
            "c_start": rs.c_rest, "c_peak": res.c_peak if peak else nan,
            "peak_confirmed_by": path.confirmed_by, "switch": switch,
            "eta_switch": eta_sw, "eps1_switch": eps_sw, "c_switch": h[0, 4],
            "dc": c_target - c_from, "c_target": c_target, "outcome": run.outcome,
            "ke_growth": ke_growth(h[:, 8]), "ke_max": float(h[:, 7].max()),
            "ke_backbone_max": float(h[:, 8].max()), "w2_ext_end": h[-1, H["w2_ext"]],
            "w2_walls_end": h[-1, H["w2_walls"]], "w2_int_end": h[-1, H["w2_int"]],
            "t_end": h[-1, 1], "steps": run.steps,
            "de1_end": h[-1, 2] - h[0, 2], "de2_end": h[-1, 3] - h[0, 3],
            "creep_rate": run.creep_rate, "unbalanced_end": h[-1, 9],
            "path_steps": path.steps, "n_disks": n,
            "w2_ext_held_end": h[-1, H["w2_ext_held"]],
            "w2_int_secant_end": h[-1, H["w2_int_secant"]], "w_damp_end": h[-1, H["w_damp"]],
            "u0_end": h[-1, H["u0"]], "eq1_bookkeeping": float(np.max(h[:, H["eq1_bookkeeping"]])),
            "ke_switch": run.ke_switch, "c_rest": h[0, 4], "c_loaded": c_loaded,
            "hold": run.hold, "c_peak_loaded": pr[lpk, 8] if lpk is not None else nan,
            "eta_peak_loaded": pr[lpk, 7] if lpk is not None else nan,
            "wall_mass": run.wall_mass, "g_held": run.g_held,
            "holds": len(res.holds), "rest_search": res.end,
            **growth(h, n, opts.ke_tol),
            "k_path_switch": _k(res, res.starts[i]), "k_noise": res.verdict.get("k_noise", nan),
            "c_cross": res.verdict.get("c_cross", nan),
            "overshoot_c": res.verdict.get("overshoot_c", nan),
            "overshoot_eps1": res.verdict.get("overshoot_eps1", nan),
            "verdict": res.verdict.get("verdict", "no probes"),
            **_anatomy_figures(run, res.holds[res.baselines[switch]][3]
                               if switch in res.baselines else None)}


def _k(res: StairResult, key):
    """k_path of the state ``key`` [Pa] (NaN if not probed or its probe did not settle)."""
    p = res.probes.get(key)
    return p.k_path if p is not None and p.outcome == "equilibrium" else math.nan


def _anatomy_figures(run: HoldResult, base: HoldResult | None) -> dict:
    """The anatomy of a switch's run against its baseline run (``staircase``: the switch's
    start held with no change of load, the same window and threshold): the largest count of
    unstable contacts over the run (below -UNSTABLE_TAU x the energy scale, ``dem.anatomy``),
    the baseline's mean and largest, the excess of the first over the baseline's largest; the
    largest cluster of each; the raw counts (threshold 0) of both; at the burst's onset
    (``ONSET``) the time, the count, the largest cluster and the sliding share."""
    h = run.history
    nan = math.nan
    out = {"n_unstable_max": float(np.max(h[:, H["n_unstable"]])),
           "largest_cluster_max": float(np.max(h[:, H["largest_cluster"]])),
           "sliding_share_switch": float(h[0, H["sliding_share"]])}
    b = base.history if base is not None else None
    out["unstable_noise_mean"] = float(np.mean(b[1:, H["n_unstable"]])) if b is not None and len(b) > 1 else nan
    out["unstable_noise_max"] = float(np.max(b[1:, H["n_unstable"]])) if b is not None and len(b) > 1 else nan
    out["largest_cluster_noise_max"] = (float(np.max(b[1:, H["largest_cluster"]]))
                                        if b is not None and len(b) > 1 else nan)
    out["n_unstable_excess"] = out["n_unstable_max"] - out["unstable_noise_max"]
    out["n_unstable_raw_max"] = float(np.max(h[:, H["n_unstable_raw"]]))
    out["unstable_raw_noise_max"] = (float(np.max(b[1:, H["n_unstable_raw"]]))
                                     if b is not None and len(b) > 1 else nan)
    k = np.flatnonzero(h[:, 0] == run.onset_step) if run.onset_step >= 0 else []
    if len(k):
        r = h[k[0]]
        out.update(t_onset=r[1], n_unstable_onset=r[H["n_unstable"]],
                   largest_cluster_onset=r[H["largest_cluster"]],
                   sliding_share_onset=r[H["sliding_share"]])
    else:
        out.update(t_onset=nan, n_unstable_onset=nan, largest_cluster_onset=nan,
                   sliding_share_onset=nan)
    return out


def write_burst_files(out_dir, combos, paths, stairs, rows, summary):
    """burst.csv, history.csv (the below and past runs and their baselines), paths.csv, rest.csv
    (the relaxations), stairs.csv (every hold of every staircase), probes.csv (every kinematic
    probe), summary.json and the figures."""
    from . import io
    io.write_csv(os.path.join(out_dir, "burst.csv"), BURST_COLUMNS,
                 [[r[c] for c in BURST_COLUMNS] for r in rows])
    runs = {(r, f, sw): stairs[(r, f)].holds[i][3] for (r, f), res in stairs.items()
            for sw, i in res.switches.items()}
    bases = {(r, f, f"baseline_{sw}"): stairs[(r, f)].holds[i][3] for (r, f), res in stairs.items()
             for sw, i in res.baselines.items()}
    io.write_csv(os.path.join(out_dir, "history.csv"), HISTORY_COLUMNS,
                 [[r, f, sw] + list(h) for (r, f, sw), run in {**runs, **bases}.items()
                  for h in run.history])
    io.write_csv(os.path.join(out_dir, "paths.csv"), PATH_COLUMNS,
                 [[r, f] + list(x) for r, f, _ in combos for x in paths[(r, f)].rows])
    rest = []
    for (r, f), res in stairs.items():
        for name, x in res.relaxed.items():
            row = paths[(r, f)].grid[0 if name == "start" else 1][0]
            rest.append([r, f, name, paths[(r, f)].rows[row, 1], x.c_loaded, x.c_rest,
                         x.c_loaded - x.c_rest, x.eta_rest, x.outcome, x.steps, x.ke_end,
                         x.unbalanced_end, _k(res, "relaxed_" + name)])
    io.write_csv(os.path.join(out_dir, "rest.csv"), REST_COLUMNS, rest)
    n = summary["n_disks"]
    tol = summary["options"]["ke_tol"]
    stair_rows = []
    for (r, f), res in stairs.items():
        for k, (role, a, b, h) in enumerate(res.holds):
            g = growth(h.history, n, tol)
            stair_rows.append([r, f, k, role, a, b, b - a, h.outcome, h.steps, h.history[0, 2],
                               h.history[-1, 2], h.history[-1, 4], h.ke_switch,
                               float(h.history[:, 8].max()), h.history[-1, H["w2_int"]],
                               float(np.max(h.history[:, H["eq1_bookkeeping"]])), res.starts[k],
                               _k(res, res.starts[k]),
                               _k(res, f"h{k}_end") if h.outcome == "equilibrium" else math.nan,
                               g["ke_w2ext_max"], g["ke_end_over_bound"]])
    io.write_csv(os.path.join(out_dir, "stairs.csv"), STAIR_COLUMNS, stair_rows)
    io.write_csv(os.path.join(out_dir, "probes.csv"), PROBE_COLUMNS,
                 [[r, f] + [getattr(p, c) for c in PROBE_COLUMNS[2:]]
                  for (r, f), res in stairs.items() for p in res.probes.values()])
    io.atomic_write_bytes(os.path.join(out_dir, "summary.json"),
                          json.dumps(summary, indent=1, default=float).encode())
    plot_burst(out_dir, combos, paths, stairs, runs, summary)
    from .ledger import plot_ledger
    for r, f, _ in combos[:1]:          # Eq. 1's terms of the first path's holds
        panels = [(f"R = {r:g}, f = {f:g}, {sw}: {runs[(r, f, sw)].outcome} "
                   f"({summary['n_disks']} disks)", runs[(r, f, sw)].history, HISTORY_COLUMNS[3:])
                  for sw in SWITCHES if (r, f, sw) in runs]
        if panels:
            plot_ledger(os.path.join(out_dir, "fig_burst_ledger.png"), panels)


OUTCOME_COLOR = {"equilibrium": "C2", "failure": "C3", "undecided": "0.5"}


def plot_burst(out_dir, combos, paths, stairs, runs, summary):
    """fig_burst_c.png: c against eps1 along every path (loaded, under strain control), the
    loaded peak (open star), the path's start and loaded peak relaxed at fixed strain (open
    circles), the staircase of holds from rest (each hold's end: green at equilibrium, red when
    it failed) and its c peak at rest (filled star), the below and past runs from their
    switches; fig_burst_ke.png: the backbone kinetic energy against the time since the switch
    (log axes: from rest it spans decades); fig_burst_strain.png: the strains since the switch
    against time (log axis)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hmodel.io import save_figure
    n = summary["n_disks"]
    fig, ax = plt.subplots(figsize=(8, 5), constrained_layout=True)
    for j, (r, f, _) in enumerate(combos):
        p = paths[(r, f)]
        col = f"C{j % 10}" if j % 10 not in (2, 3) else f"C{j % 10 + 5}"
        ax.plot(p.rows[:, 1] * 100, p.rows[:, 8] / 1e3, "-", lw=0.8, color=col,
                label=f"path R = {r:g} from {f:g} of the drained peak (strain control)")
        if p.peak is not None:
            ax.plot(p.rows[p.peak, 1] * 100, p.rows[p.peak, 8] / 1e3, "*", ms=12, mfc="w",
                    mec=col, mew=1.0)
        res = stairs.get((r, f))
        if res is None:
            continue
        for (row, _), x in zip(p.grid, res.relaxed.values()):
            ax.plot([p.rows[row, 1] * 100] * 2, [x.c_loaded / 1e3, x.c_rest / 1e3], "-",
                    color="0.5", lw=0.8)
            ax.plot(p.rows[row, 1] * 100, x.c_rest / 1e3, "o", ms=6, mfc="w", mec=col)
        for role, _, target, h in res.holds:
            if role == "stair" and h.outcome == "equilibrium":    # where it came to rest
                ax.plot(h.history[-1, 2] * 100, h.history[-1, 4] / 1e3, "s", ms=4,
                        color=OUTCOME_COLOR[h.outcome])
            elif role == "stair":                                 # the c it could not hold
                ax.plot(h.history[0, 2] * 100, target / 1e3, "x", ms=5,
                        color=OUTCOME_COLOR[h.outcome])
        if res.end == "past found":
            ax.plot(res.eps1_peak * 100, res.c_peak / 1e3, "*", ms=13, color=col, mec="k",
                    mew=0.5)
        for sw, mk in zip(SWITCHES, "ov"):
            if (r, f, sw) not in runs:
                continue
            h = runs[(r, f, sw)].history
            oc = runs[(r, f, sw)].outcome
            ax.plot(h[:, 2] * 100, h[:, 4] / 1e3, "-", lw=1.2, color=OUTCOME_COLOR[oc], alpha=0.7)
            ax.plot(h[0, 2] * 100, h[0, 4] / 1e3, mk, ms=8, mfc=OUTCOME_COLOR[oc], mec="k")
    ax.plot([], [], "*", mfc="w", mec="0.3", ms=10, label="c peak of the loaded path")
    ax.plot([], [], "o", mfc="w", mec="0.3", label="relaxed at fixed strain (drop: grey)")
    ax.plot([], [], "s", color=OUTCOME_COLOR["equilibrium"], ms=4,
            label="staircase from rest: held (end of each hold)")
    ax.plot([], [], "x", color=OUTCOME_COLOR["failure"], ms=5,
            label="staircase: the c a hold failed to hold")
    ax.plot([], [], "*", color="0.3", ms=10, mec="k", label="c peak at rest (largest c held)")
    ax.plot([], [], "o", mfc="w", mec="k", label="below switch (from rest)")
    ax.plot([], [], "v", mfc="w", mec="k", label="past switch: the peak at rest + dc")
    for oc, col in OUTCOME_COLOR.items():
        ax.plot([], [], "-", color=col, lw=1.5, label=f"run after the switch: {oc}")
    ax.set_xlabel(r"axial strain $\varepsilon_1$ [%]")
    ax.set_ylabel(r"$c = \sigma_1 + R\,\sigma_2$ [kPa]")
    ax.set_title(f"DEM ({n} disks): the proportional strain paths and the c-controlled runs\n"
                 r"$d\varepsilon_2 = R\,d\varepsilon_1$, compression positive", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    save_figure(fig, os.path.join(out_dir, "fig_burst_c.png"), dpi=120)

    # the kinetic energy, and its release against the held step's work (``growth``)
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 4.8), constrained_layout=True)
    for (r, f, sw), run in runs.items():
        h = run.history
        oc = run.outcome
        lab = f"R = {r:g}, f = {f:g}, {sw}: {oc}"
        ls = "-" if sw == "below" else "--"
        t = np.maximum(h[:, 1], 0.5 * h[1, 1] if len(h) > 1 else 1e-6)
        ax.loglog(t, np.maximum(h[:, 8], 1e-16), ls, color=OUTCOME_COLOR[oc], label=lab)
        w = h[:, H["w2_ext_held"]]
        ratio = np.where(w > 0, (h[:, 8] - h[0, 8]) / np.where(w > 0, w, 1.0), np.nan)
        bx.semilogx(t, ratio, ls, color=OUTCOME_COLOR[oc], label=lab)
    ax.axhline(summary["options"]["ke_tol"] * n, color="k", ls=":", lw=0.8,
               label="equilibrium bound (ke_tol x disks)")
    bx.axhline(RELEASE, color="k", ls=":", lw=0.8,
               label=f"release: E_c gained = {RELEASE:g} W2_ext (the sample gave back >= W2_ext)")
    bx.axhline(1.0, color="0.6", ls="-", lw=0.6)
    ax.set_ylabel("backbone kinetic energy [J]")
    bx.set_ylabel(r"$(E_c - E_c(0))\,/\,W_2^{ext}$, $W_2^{ext} = dG\,dU_1$ [-]")
    bx.set_yscale("symlog", linthresh=1.0)
    ax.set_title(f"DEM ({n} disks): kinetic energy of the disks with two contacts or more",
                 fontsize=10)
    bx.set_title("the kinetic energy gained against the work the held step put in\n"
                 "(solid: below, dashed: past)", fontsize=10)
    for x in (ax, bx):
        x.set_xlabel("time since the switch [s]")
        x.grid(alpha=0.3, which="both")
        if runs:
            x.legend(fontsize=7)
    if not runs:
        ax.text(0.5, 0.5, "no switched run (no peak at rest found)", ha="center",
                transform=ax.transAxes)
    save_figure(fig, os.path.join(out_dir, "fig_burst_ke.png"), dpi=120)

    fig, ax = plt.subplots(figsize=(8, 4.8), constrained_layout=True)
    for (r, f, sw), run in runs.items():
        h = run.history
        oc = run.outcome
        ls = "-" if sw == "below" else "--"
        ax.semilogy(h[1:, 1], np.abs(h[1:, 2] - h[0, 2]) * 100, ls, color=OUTCOME_COLOR[oc],
                    label=f"R = {r:g}, f = {f:g}, {sw}: {oc}, axial")
        ax.semilogy(h[1:, 1], np.abs(h[1:, 3] - h[0, 3]) * 100, ":", color=OUTCOME_COLOR[oc],
                    label=f"R = {r:g}, f = {f:g}, {sw}: lateral")
    ax.set_xlabel("time since the switch [s]")
    ax.set_ylabel(r"strain since the switch $|\Delta\varepsilon|$ [%]")
    ax.set_title(f"DEM ({n} disks): axial strain (solid: below, dashed: past) and lateral "
                 "strain (dotted) since the switch", fontsize=10)
    ax.grid(alpha=0.3, which="both")
    if runs:
        ax.legend(fontsize=7)
    else:
        ax.text(0.5, 0.5, "no switched run (no peak at rest found)", ha="center",
                transform=ax.transAxes)
    save_figure(fig, os.path.join(out_dir, "fig_burst_strain.png"), dpi=120)
    plot_k_path(os.path.join(out_dir, "fig_burst_k.png"), combos, stairs, n)


def plot_k_path(path, combos, stairs, n):
    """fig_burst_k.png: the kinematic probes of every path (``path_probe``) against the c at
    rest of the state probed: k_path [Pa] with its noise band (+-CLEARLY k_noise), the staircase's
    equilibria (filled), the other equilibria probed (open: the relaxed loaded peak, the below
    run's end, the baselines' ends), the zero crossing and the c peak at rest (the largest c the
    dead load held), so that the overshoot reads off."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hmodel.io import save_figure
    fig, ax = plt.subplots(figsize=(8, 5), constrained_layout=True)
    drawn = False
    for j, (r, f, _) in enumerate(combos):
        res = stairs.get((r, f))
        if res is None or not res.probes:
            continue
        col = f"C{j % 10}" if j % 10 not in (2, 3) else f"C{j % 10 + 5}"
        v = res.verdict
        stair = ["relaxed_start"] + [f"h{k}_end" for k, (ro, _, _, h) in enumerate(res.holds)
                                     if ro == "stair" and h.outcome == "equilibrium"]
        pts = [(res.probes[k].c_before, res.probes[k].k_path) for k in stair if k in res.probes]
        if pts:
            c, k = np.array(pts).T
            ax.plot(c / 1e3, k / 1e6, "o-", color=col, ms=5,
                    label=f"R = {r:g}, f = {f:g}: the staircase's equilibria ({v.get('verdict')})")
        other = [p for key, p in res.probes.items() if key not in stair]
        if other:
            ax.plot([p.c_before / 1e3 for p in other], [p.k_path / 1e6 for p in other], "o",
                    mfc="w", mec=col, ms=6, label="other equilibria probed (loaded peak relaxed, "
                                                  "below's end, baselines' ends)")
        noise = v.get("k_noise", math.nan)
        if math.isfinite(noise):
            ax.axhspan(-CLEARLY * noise / 1e6, CLEARLY * noise / 1e6, color=col, alpha=0.12,
                       label=f"noise band: +-{CLEARLY:g} x k_noise ({noise / 1e6:.2g} MPa)")
        if math.isfinite(v.get("c_cross", math.nan)):
            ax.axvline(v["c_cross"] / 1e3, color=col, ls="--", lw=1,
                       label=f"k_path = 0: c = {v['c_cross'] / 1e3:.2f} kPa")
        if math.isfinite(res.c_peak):
            ax.axvline(res.c_peak / 1e3, color="C3", ls=":", lw=1.2,
                       label=f"the largest c held at rest: {res.c_peak / 1e3:.2f} kPa "
                             f"(+{res.holds[res.switches['past']][2] - res.c_peak:g} Pa failed)"
                       if "past" in res.switches else "the largest c held at rest")
        drawn = True
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_xlabel("c at rest of the state probed [kPa]")
    ax.set_ylabel(r"$k_{path} = dc / d\varepsilon_1$ at rest [MPa]")
    ax.set_title(f"DEM ({n} disks): the path's static stiffness at rest, W2 = dc d eps1 "
                 "(kinematic probes)", fontsize=10)
    ax.grid(alpha=0.3)
    if drawn:
        ax.legend(fontsize=7, loc="best")
    else:
        ax.text(0.5, 0.5, "no kinematic probe (--no-probes, or no equilibrium)", ha="center",
                transform=ax.transAxes)
    save_figure(fig, path, dpi=120)
