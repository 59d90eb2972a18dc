"""Failure made to happen in the DEM: the proportional strain path, its conjugate stress held
past its peak, and the burst of kinetic energy (paper Eq. 1; ``docs/burst.md``, ``docs/dem.md``).

From a state of the drained biaxial path (``dem biaxial --save-fractions``), the walls impose the
proportional strain path d eps2 = R d eps1 (R < 0: lateral extension) at the axial strain rate of
the biaxial test (``walls.strain_rate``, both axes strain controlled; engineering strains on the
biaxial test's reference lengths) while the stress conjugate to it, c = s1 + R s2 (wall stresses,
compression positive), is recorded: along the path W2 = d eps1 dc, so W2 = 0 where c peaks.
Then the control switches to c (``walls.tied``: the y walls move to hold c, the x walls follow
them so that d eps2 = R d eps1 still holds at every step; ``kernels._servo_tied``), held at
c_switch + dc, and ``dem.settle`` decides the run with the stress error |c - c_target|.

* **The peak** (``proportional_path``): the largest c recorded, confirmed once the path has gone
  ``peak_strain`` (0.5 %) of axial strain beyond it without a larger one, or c has fallen from it
  by ``peak_drop`` (150 kPa): the DEM's c is noisy, with stick-slip falls of up to 62 kPa that
  it recovers within a few tenths of a percent (the measurements behind the amounts are in
  ``docs/dem.md``). A path that unloads (its mean wall stress below ``UNLOADED`` of its start:
  the walls have left the grains, as along R = -2.5) ends without a peak and without runs.
* **The switches**: ``below`` at the first state of the path with c >= c_start + ``below_rise``
  (c_peak - c_start), ``past`` at the peak state; both held at their own c + dc. A path whose c
  does not peak within ``path_strain`` gets one ``below`` run, switched at its end.
  ``below_rise`` is 0.5 here, not the 0.95 of ``docs/burst.md``: under strain control at
  0.01/s the DEM's c stands above what the sample holds under c control (rate overstress and
  stick-slip: 2000 disks, R = -2 from 0.90, path peak 75.9 kPa; holds at 0.95 and 0.75 of the
  rise fail, c never above 74.4 and 73.1 kPa; the hold at 0.5, 70.8 kPa, settles).
* **The runs** (``hold``) end by ``dem.settle``'s rule: equilibrium over a window (unbalanced
  force, |c - c_target| <= stress_tol, strain drift, backbone kinetic energy); failure when the
  strain since the switch passes ``fail_strain`` or runs away (``runaway_ratio`` times the
  elastic strain of ``strain_norm``) with the servo unable to hold c and the kinetic energy not
  decaying; undecided at the cap.

Every check records (history.csv): total and backbone kinetic energy [J], unbalanced ratio,
strains, wall stresses, c, c_target, |c - c_target|, ``w2_ext_held`` = dG dU1 (dG = W_s t dc,
U1 = H0 eps1 the platens' shortening: what the held step puts in if G were held exactly), the
walls' own secant second-order work sum_w dF_w dU_w, ``w2_int_secant``, the paper's contact sum
sum_c df . dl over the grain and wall contacts since the switch (Eq. 15 form, secant; by Eq. 14
it is the walls' less sum_p dF_p . dx_p), and the energy ledger from the switch (``dem.ledger``):
the walls' work, the contact work and its split into stored and dissipated energy, the Cundall
damping's work, and Eq. 1 in second-order form, E_c - E_c(0) = W2_ext - W2_int + W_damp + U0,
closed to round-off (``w2_ext``, ``w2_int``, ``u0``, ``eq1_residual``).
"""
from __future__ import annotations

import json
import math
import os
import sys
import time
from typing import NamedTuple

import numpy as np

from hmodel.burst import check_ratio

from . import kernels
from .ledger import COLUMNS as LEDGER_COLUMNS, EXTRA_COLUMNS as LEDGER_EXTRA_COLUMNS, Ledger
from .settle import RULE_COLUMNS, SettleRule, settle, voigt_strain
from .simulation import Simulation, State
from .threads import ThreadChooser
from .walls import strain_rate, tied

SWITCHES = ("below", "past")
HOLDS = ("dead_load", "servo")
REST_MARGIN = 5e-4     # strain beyond the loaded c peak where the rest peak is looked for
UNLOADED = 0.05        # a path whose mean wall stress falls below this of its start has unloaded

# a path's records, then its energy ledger from the path's start (first order: the second-order
# terms of a path are not the experiment's)
PATH_LEDGER_COLUMNS = ["ke", "w_ext", "w_int", "w_damp", "e_elastic", "d_slip", "d_roll",
                       "balance_residual", "split_residual"]
PATH_COLUMNS = ["ratio", "start_fraction", "step", "eps1", "eps2", "s1", "s2", "p", "q", "eta",
                "c", "unbalanced"] + PATH_LEDGER_COLUMNS
# the ledger's columns (dem.ledger) but its "ke", which is the "ke" column already there
HOLD_LEDGER_COLUMNS = [c for c in LEDGER_COLUMNS + LEDGER_EXTRA_COLUMNS if c != "ke"]
HISTORY_COLUMNS = ["ratio", "start_fraction", "switch", "step", "t", "eps1", "eps2", "c",
                   "c_target", "stress_error", "ke", "ke_backbone", "unbalanced", "s1", "s2",
                   "strain_ratio", "w2_ext_held", "w2_walls", "w2_int_secant"] + HOLD_LEDGER_COLUMNS
BURST_COLUMNS = ["ratio", "start_fraction", "eta_start", "eta_peak_c", "fraction_peak_c",
                 "eps1_peak_c", "c_start", "c_peak", "peak_confirmed_by", "switch",
                 "eta_switch", "eps1_switch", "c_switch", "dc", "c_target", "outcome",
                 "ke_growth", "ke_max", "ke_backbone_max", "w2_ext_end", "w2_walls_end",
                 "w2_int_end", "t_end", "steps", "de1_end", "de2_end", "creep_rate",
                 "unbalanced_end", "path_steps", "n_disks", "w2_ext_held_end",
                 "w2_int_secant_end", "w_damp_end", "u0_end", "eq1_residual", "ke_switch",
                 "c_rest", "c_loaded", "hold", "c_peak_loaded", "eta_peak_loaded", "wall_mass",
                 "g_held", "relaxations", "relax_outcome"]


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
    rest_every: int = 10            # the path keeps a state every this many records (rest grid)
    rest_coarse: int = 8            # states relaxed in the first round of the rest search

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
                  ("rest_every", self.rest_every >= 1, "rest_every >= 1"),
                  ("rest_coarse", self.rest_coarse >= 3, "rest_coarse >= 3"))
        for name, ok, rng in checks:
            val = getattr(self, name)
            if not ok or not math.isfinite(val):
                raise ValueError(f"{name}={val!r}; allowed range: {rng}")
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
    grid: list                # [(row, State)]: the start and every opts.rest_every-th record
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
    Keeps the states of the rest search's grid: the start and every ``opts.rest_every``-th
    record, up to the path's end (the loaded peak + ``peak_strain``)."""
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
    peak, how = 0, ""
    while True:
        sim.run(every)
        rows.append(_record(sim, ratio))
        k = len(rows) - 1
        e1, c, p = rows[k][1], rows[k][8], rows[k][5]
        if k % opts.rest_every == 0:
            grid.append((k, sim.state()))
        how = confirm_peak(c, e1, rows[peak][8], rows[peak][1], opts)
        if how == "new":
            peak, how = k, ""
        if not how and p < UNLOADED * p_start:
            how = "unloaded"
        if progress:
            progress(sim.step - state.step, rows[k], rows[peak])
        if how or e1 - e_start >= opts.path_strain:
            break
    rows = np.asarray(rows, float)
    if how == "unloaded":
        return PathResult(rows, None, how, [], sim.step - state.step, time.time() - t0)
    if how:          # the rest search looks up to the loaded peak + REST_MARGIN of strain
        lim = rows[peak, 1] + REST_MARGIN
        grid = [(k, st) for k, st in grid if rows[k, 1] <= lim] or grid[:1]
    else:            # no peak: one below run from the path's end
        grid = [grid[0], (len(rows) - 1, sim.state())]
    return PathResult(rows, peak if how else None, how, grid, sim.step - state.step,
                      time.time() - t0)


# ----------------------------------------------------------------------------------------------
# From rest: a state relaxed at fixed strain, and the c peak at rest along the path
# ----------------------------------------------------------------------------------------------
REST_COLUMNS = ["ratio", "start_fraction", "grid", "row", "eps1", "c_loaded", "c_rest",
                "eta_rest", "outcome", "steps", "ke_end", "unbalanced_end"]


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


class RestSearch:
    """The c peak at rest along a path (``PathResult.grid``), found by relaxing grid states:
    the start, ``opts.rest_coarse`` states evenly spread from it to the loaded peak +
    REST_MARGIN of strain (the rest peak does not lie beyond the loaded one by more than the
    overstress's strain: measured in docs/dem.md), then halving the grid interval around the
    largest relaxed c until the neighbours are relaxed; the ``below`` switch is the first grid
    state whose relaxed c reaches c_rest(start) + below_rise (c_rest_peak - c_rest(start)),
    found by halving between the relaxed states that bracket it. ``todo()`` says which grid
    states to relax next (each round's in one pool), ``add()`` takes their results; ``done``
    once both switches are known. A path without a loaded peak gets one ``below`` run from its
    last grid state."""

    def __init__(self, path: PathResult, opts: BurstOptions):
        self.path = path
        self.opts = opts
        self.relaxed = {}                         # grid index -> RelaxResult
        self.end = len(path.grid) - 1             # the path keeps the grid it needs
        if path.peak is None:
            self._round = [0, self.end]
        else:
            n = min(self.opts.rest_coarse, self.end + 1)
            self._round = sorted(set(int(round(v)) for v in np.linspace(0, self.end, n)))
        self.peak = None          # grid index of the rest peak
        self.below = None         # grid index of the below switch
        self.confirmed = path.peak is not None

    def c(self, i):
        return self.relaxed[i].c_rest

    def todo(self):
        return [i for i in self._round if i not in self.relaxed]

    def add(self, results: dict):
        self.relaxed.update(results)
        if self.todo():
            return
        self._round = self._next()

    @property
    def done(self):
        return not self._round

    def _next(self):
        """The next round's grid indices ([] when the search is over)."""
        done = sorted(self.relaxed)
        if self.path.peak is None:                 # no loaded peak: below at the path's end
            self.below = self.end
            return []
        if self.peak is None:
            best = max(done, key=self.c)
            lo = max([i for i in done if i < best], default=None)
            hi = min([i for i in done if i > best], default=None)
            need = [(a + b) // 2 for a, b in ((lo, best), (best, hi))
                    if a is not None and b is not None and b - a > 1]
            if need:
                return need
            self.peak = best
        if self.peak == 0:                         # c at rest falls from the start: no below
            return []
        thr = self.c(0) + self.opts.below_rise * (self.c(self.peak) - self.c(0))
        first = min(i for i in done if i <= self.peak and self.c(i) >= thr)
        prev = max(i for i in done if i < first)
        if first - prev > 1:
            return [(prev + first) // 2]
        self.below = first
        return []

    def switches(self):
        """{"below"/"past": grid index} of the switches found."""
        out = {}
        if self.below is not None:
            out["below"] = self.below
        if self.peak is not None and self.confirmed:
            out["past"] = self.peak
        return out


H = {c: k for k, c in enumerate(HISTORY_COLUMNS[3:])}    # a hold's history columns (from "step")


class HoldResult(NamedTuple):
    outcome: str
    steps: int
    history: np.ndarray       # (checks, len(HISTORY_COLUMNS) - 3): HISTORY_COLUMNS from "step"
    creep_rate: float         # [1/s] over the last window
    wall_time: float          # [s]
    hold: str = "servo"       # "dead_load" or "servo"
    ke_switch: float = math.nan   # E_c at the switch [J] (the disks')
    g_held: float = math.nan  # the held generalized force [N] (dead load)
    wall_mass: float = math.nan   # the walls' generalized mass m_G [kg] (dead load)


class ContactTable(NamedTuple):
    """The contacts of a configuration: sorted keys (K,), grain contacts i (N + 4) + j and wall
    contacts p (N + 4) + N + wall, with the force (K, 2) on the first disk [N]; and the
    positions (N, 2) and walls (4,) [m] that give every branch."""
    keys: np.ndarray
    force: np.ndarray
    x: np.ndarray
    walls: np.ndarray


def contact_table(sim) -> ContactTable:
    """The contacts of ``sim`` now (copies)."""
    snap = sim.snapshot()
    n = sim.n
    fw = np.zeros((len(snap.ww), 2))
    fw[np.arange(len(snap.ww)), snap.ww // 2] = np.where(snap.ww % 2 == 0, 1.0, -1.0) * snap.wf
    keys = np.concatenate([snap.ci * (n + 4) + snap.cj, snap.wp * (n + 4) + n + snap.ww])
    force = np.concatenate([np.column_stack([snap.fx, snap.fy]), fw])
    order = np.argsort(keys, kind="stable")
    return ContactTable(keys[order], force[order], sim.x.copy(), sim.walls.copy())


def _branches(keys, x, walls):
    """Branch (K, 2) of each key [m]: x_j - x_i, or from the disk to its wall along the wall's
    axis."""
    n = len(x)
    i, j = keys // (n + 4), keys % (n + 4)
    out = np.zeros((len(keys), 2))
    g = j < n
    out[g] = x[j[g]] - x[i[g]]
    w = ~g
    wl = j[w] - n
    out[np.flatnonzero(w), wl // 2] = walls[wl] - x[i[w], wl // 2]
    return out


def contact_work(t0: ContactTable, t1: ContactTable) -> float:
    """sum_c df . dl [J] between two configurations (paper Eq. 15, secant) over the grain and
    wall contacts at either end; a contact missing at one end has f = 0 there, its branch is
    the one the disks' positions give. By Eq. 14 it equals the walls' secant second-order work
    less sum_p dF_p . dx_p (the unbalanced forces')."""
    keys = np.union1d(t0.keys, t1.keys)
    f0 = np.zeros((len(keys), 2))
    f1 = np.zeros((len(keys), 2))
    f0[np.searchsorted(keys, t0.keys)] = t0.force
    f1[np.searchsorted(keys, t1.keys)] = t1.force
    dl = _branches(keys, t1.x, t1.walls) - _branches(keys, t0.x, t0.walls)
    return float(np.sum((f1 - f0) * dl))


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
    c0 = contact_table(sim)
    g0, walls0 = np.bincount(snap0.ww, weights=snap0.wf, minlength=4), sim.walls.copy()
    step0, eps1_0 = sim.step, sim.strain()[1]
    t = sim.params.thickness
    d_g = sim.size[0] * t * (c_target - c_switch)     # dG [N]
    h0 = sim.ref_len[1]
    ke_switch = sim.kinetic_energy()
    g_held = m_g = math.nan
    if opts.hold == "dead_load":
        g_held = generalized_force(g0, ratio, sim.ref_len) + d_g
        m_g = opts.wall_mass or wall_mass_rule(sim, ratio, opts.wall_period_steps)
        sim.set_control(dead_load(ratio, g_held, m_g, sim.ref_len))
        kx = ratio * sim.ref_len[0] / sim.ref_len[1]

        def error(sx, sy):
            w, h = sim.size
            return abs((sy * w + kx * sx * h) * t - g_held) / (w * t)
    else:
        sim.set_control(tied(ratio, c_target, c_target, sim.step, 0, sim.ref_len))

        def error(sx, sy):
            return abs(sy + ratio * sx - c_target)
    Ledger(sim)
    hist = []
    led = [len(RULE_COLUMNS) + k for k, c in enumerate(LEDGER_COLUMNS + LEDGER_EXTRA_COLUMNS)
           if c != "ke"]      # settle's row: the rule's columns, then the ledger's

    def check(steps, row):
        step, ke, keb, ub, e1, e2, s1_, s2_, err, ratio_ = row[:len(RULE_COLUMNS)]
        hist.append([step - step0, (step - step0) * sim.dt, e1, e2, s1_ + ratio * s2_, c_target,
                     err, ke, keb, ub, s1_, s2_, ratio_, d_g * h0 * (e1 - eps1_0),
                     wall_work(sim, g0, walls0), contact_work(c0, contact_table(sim))]
                    + [row[k] for k in led])
        if progress:
            progress(steps, hist[-1])

    res = settle(sim, None, opts.rule(), strain_scale=voigt_strain(sim, opts.strain_norm),
                 progress=check, stress_error=error)
    return HoldResult(res.outcome, res.steps, np.asarray(hist, float), res.creep_rate,
                      time.time() - t0, opts.hold, ke_switch, g_held, m_g)


def ke_growth(keb) -> float:
    """Largest backbone kinetic energy over the one at the switch (the first check: the sample
    still moves at the path's rate there), the ``ke_growth`` column."""
    keb = np.asarray(keb, float)
    return float(keb.max() / keb[0]) if keb[0] > 0 else math.inf


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


def _relax_task(args):
    state, ratio, fraction, i, opts, threads, verbose = args
    last = [time.time()]

    def progress(steps, row):
        if verbose and time.time() - last[0] > 10.0:
            last[0] = time.time()
            _log(f"R={ratio:g} f={fraction:g} relaxing grid state {i}: step {steps} "
                 f"unbalanced={row[3]:.2e} c drift={row[8]:.0f} Pa backbone KE={row[2]:.2e} J")

    return relax(state, ratio, opts, threads, progress)


def _hold_task(args):
    state, ratio, fraction, switch, c_target, opts, threads, verbose = args
    last = [time.time()]

    def progress(steps, h):
        if verbose and time.time() - last[0] > 10.0:
            last[0] = time.time()
            _log(f"R={ratio:g} f={fraction:g} {switch}: step {steps} eps1={h[2]:.5f} "
                 f"stress error={h[6]:.0f} Pa backbone KE={h[8]:.2e} J")

    return hold(state, ratio, c_target, opts, threads, progress)


def checkpoint_header(starts, ratios, opts) -> dict:
    """What a burst run is, for its checkpoint: the start states' fingerprints, the ratios and
    the options (``starts`` as ``load_starts`` gives them)."""
    from .probes import state_fingerprint
    return json.loads(json.dumps({"fingerprints": {f"{f:g}": state_fingerprint(st)
                                                   for f, st, _ in starts},
                                  "ratios": [float(r) for r in ratios],
                                  "options": opts._asdict()}))


def read_checkpoint(out_dir, header) -> list:
    """The finished runs of ``out_dir``/burst_runs.jsonl (none if there is no such file; a torn
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


class _Checkpoint:
    """``out_dir``/burst_runs.jsonl: a header (the start states' fingerprints, the ratios, the
    options), then one line per finished run (a path, a relaxation, a hold), each written and
    flushed as it finishes; the states a later run needs beside it in ``out_dir``/rest/. With
    ``resume`` the finished runs are read back (a torn last line dropped) and a header of other
    states or options is refused with ValueError; without it an earlier file is set aside."""

    def __init__(self, out_dir, header, resume):
        from .io import atomic_write_bytes
        self.dir = os.path.join(out_dir, "rest")
        self.path = os.path.join(out_dir, "burst_runs.jsonl")
        self.records = read_checkpoint(out_dir, header) if resume else []
        if not resume and os.path.exists(self.path):
            os.replace(self.path, self.path[:-len(".jsonl")] + ".previous.jsonl")
        atomic_write_bytes(self.path, ("\n".join(json.dumps(r) for r in [header] + self.records)
                                       + "\n").encode())
        os.makedirs(self.dir, exist_ok=True)
        self.sink = open(self.path, "a")

    def add(self, rec):
        self.sink.write(json.dumps(rec) + "\n")
        self.sink.flush()
        os.fsync(self.sink.fileno())

    def state_path(self, ratio, fraction, kind, i):
        return os.path.join(self.dir, f"R{ratio:g}_f{fraction:g}_{kind}{i:04d}.npz")

    def close(self):
        self.sink.close()


def run_burst(biaxial_dir, out_dir, ratios, fractions, opts: BurstOptions = BurstOptions(),
              workers=None, threads=None, verbose=True, params_file=None, stage=None,
              resume=False, scheduler=None):
    """Every proportional path (one per ratio and start fraction), then the rest search of
    every path (``RestSearch``: rounds of relaxations at fixed strain), then the holds of every
    switch from its relaxed state, each an independent run spread over ``workers`` local
    processes or a dask cluster at ``scheduler`` (one thread each; ``threads`` in a single
    process). Every finished run goes to ``out_dir``/burst_runs.jsonl (``resume`` continues
    from it, refusing one of other states or options). Writes ``out_dir``/burst.csv,
    history.csv, paths.csv, rest.csv, summary.json, params.json, the relaxed switch states
    (rest/) and the figures. Returns (burst rows as dicts, summary dict)."""
    from . import io
    from .probes import _map
    ratios = [check_ratio(float(r)) for r in ratios]
    starts, eta_peak, params = load_starts(biaxial_dir, fractions, params_file)
    opts.validate(params.n)
    header = checkpoint_header(starts, ratios, opts)
    if resume:
        read_checkpoint(out_dir, header)      # refused before anything is written
    t0 = time.time()
    os.makedirs(out_dir, exist_ok=True)
    # the parameters the run used, in the shared file format (``--params DIR/params.json``)
    from .params import record_params
    record_params(out_dir, params, f"python -m dem burst; parameters: the start states' own "
                                   f"(--biaxial {biaxial_dir})")
    combos = [(r, f, st) for r in ratios for f, st, _ in starts]
    ck = _Checkpoint(out_dir, header, resume)
    # a run in a pool of processes runs on one thread; alone in this process, on ``threads``
    # (None: dem.threads chooses)
    per_run = lambda tasks: (threads if threads is not None or (workers == 1 and not scheduler)
                             or len(tasks) == 1 else 1)
    log = _log if verbose else (lambda m: None)
    log(f"{len(combos)} proportional paths ({params.n} disks, rate {opts.rate:g}/s): R in "
        f"{ratios}, start fractions {list(fractions)}; the c peak at rest (states relaxed at "
        f"fixed strain); below at {opts.below_rise:g} of the rise at rest; held at c_rest + "
        f"{opts.dc:g} Pa by a {'dead load' if opts.hold == 'dead_load' else 'servo'}")
    paths, searches, runs = {}, {}, {}
    avail = {}                                # (r, f, grid index) -> RelaxResult (no state)
    for rec in ck.records:                    # what a resumed run has already
        key = (rec["ratio"], rec["start_fraction"])
        if rec["kind"] == "path":
            grid = [(row, None) for row in rec["grid"]]
            paths[key] = PathResult(np.asarray(rec["rows"], float), rec["peak"],
                                    rec["confirmed_by"], grid, rec["steps"], rec["wall_time"])
        elif rec["kind"] == "relax":
            avail[key + (rec["grid"],)] = RelaxResult(
                None, rec["outcome"], rec["steps"], rec["c_loaded"], rec["c_rest"],
                rec["eta_rest"], rec["ke_end"], rec["unbalanced_end"],
                np.asarray(rec["history"], float), rec["wall_time"])
        elif rec["kind"] == "hold":
            runs[key + (rec["switch"],)] = HoldResult(
                rec["outcome"], rec["steps"], np.asarray(rec["history"], float),
                rec["creep_rate"], rec["wall_time"], rec["hold"], rec["ke_switch"],
                rec["g_held"], rec["wall_mass"])
    if ck.records:
        log(f"resumed from {ck.path}: {len(paths)} paths, {len(avail)} relaxations, "
            f"{len(runs)} holds finished")
    try:
        if stage:
            stage.at("dem burst: the proportional paths")

        def got_path(key, res):
            r, f = key
            for i, (_, st) in enumerate(res.grid):
                io.save_state(ck.state_path(r, f, "grid", i), st)
            ck.add({"kind": "path", "ratio": r, "start_fraction": f, "rows": res.rows.tolist(),
                    "peak": res.peak, "confirmed_by": res.confirmed_by,
                    "grid": [row for row, _ in res.grid], "steps": res.steps,
                    "wall_time": res.wall_time})
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
            stage.at("dem burst: the rest search (relaxations at fixed strain)")
        grid_state = lambda r, f, i: (paths[(r, f)].grid[i][1] if paths[(r, f)].grid[i][1]
                                      is not None else
                                      io.load_state(ck.state_path(r, f, "grid", i))[0])
        for r, f, _ in combos:
            if paths[(r, f)].confirmed_by != "unloaded":
                searches[(r, f)] = RestSearch(paths[(r, f)], opts)

        def got_relax(key, res):
            r, f, i = key
            io.save_state(ck.state_path(r, f, "relaxed", i), res.state)
            ck.add({"kind": "relax", "ratio": r, "start_fraction": f, "grid": i,
                    "row": paths[(r, f)].grid[i][0], "outcome": res.outcome, "steps": res.steps,
                    "c_loaded": res.c_loaded, "c_rest": res.c_rest, "eta_rest": res.eta_rest,
                    "ke_end": res.ke_end, "unbalanced_end": res.unbalanced_end,
                    "history": res.history.tolist(), "wall_time": res.wall_time})
            avail[key] = res._replace(state=None)
            log(f"R={r:g} f={f:g} grid state {i} (eps1 "
                f"{paths[(r, f)].rows[paths[(r, f)].grid[i][0], 1]:.5f}) relaxed: c "
                f"{res.c_loaded / 1e3:.2f} -> {res.c_rest / 1e3:.2f} kPa, {res.outcome} after "
                f"{res.steps} steps")

        while True:                     # rounds of relaxations, every path's in one pool
            for key, srch in searches.items():
                got = {i: avail[key + (i,)] for i in srch.todo() if key + (i,) in avail}
                while got:
                    srch.add(got)
                    got = {i: avail[key + (i,)] for i in srch.todo() if key + (i,) in avail}
            tasks = [((r, f, i), (grid_state(r, f, i), r, f, i, opts))
                     for (r, f), srch in searches.items() for i in srch.todo()]
            if not tasks:
                break
            _map([(k, a + (per_run(tasks), verbose)) for k, a in tasks], got_relax, workers,
                 scheduler, fn=_relax_task)
        for (r, f), srch in searches.items():
            sw = srch.switches()
            txt = ", ".join(f"{k} at grid state {i} (c at rest {srch.c(i) / 1e3:.2f} kPa)"
                            for k, i in sw.items())
            log(f"R={r:g} f={f:g} rest search: {len(srch.relaxed)} relaxations; {txt or 'none'}")

        if stage:
            stage.at("dem burst: the held runs from rest")
        holds = []
        for (r, f), srch in searches.items():
            for sw, i in srch.switches().items():
                if (r, f, sw) in runs:
                    continue
                st, _ = io.load_state(ck.state_path(r, f, "relaxed", i))
                holds.append(((r, f, sw), (st, r, f, sw, srch.c(i) + opts.dc, opts, None,
                                           verbose)))
        holds = [(k, a[:6] + (per_run(holds),) + a[7:]) for k, a in holds]

        def got_run(key, res):
            r, f, sw = key
            ck.add({"kind": "hold", "ratio": r, "start_fraction": f, "switch": sw,
                    "outcome": res.outcome, "steps": res.steps, "history": res.history.tolist(),
                    "creep_rate": res.creep_rate, "wall_time": res.wall_time, "hold": res.hold,
                    "ke_switch": res.ke_switch, "g_held": res.g_held,
                    "wall_mass": res.wall_mass})
            runs[key] = res
            log(f"R={r:g} f={f:g} {sw}: {res.outcome} after {res.steps} steps "
                f"({res.wall_time:.0f} s)")

        _map(holds, got_run, workers, scheduler, fn=_hold_task)
    finally:
        ck.close()
    rows = []
    for r, f, st in combos:
        if (r, f) not in searches:
            continue
        for sw, i in searches[(r, f)].switches().items():
            rows.append(burst_row(r, f, sw, paths[(r, f)], searches[(r, f)], i,
                                  runs[(r, f, sw)], opts, eta_peak, params.n))
    summary = {"biaxial": os.path.abspath(biaxial_dir), "n_disks": params.n,
               "drained_eta_peak": eta_peak, "ratios": ratios, "start_fractions": list(fractions),
               "options": opts._asdict(), "params": params.to_dict(), "dt": params.dt,
               "fingerprints": header["fingerprints"],
               "paths": [{"ratio": r, "start_fraction": f, "steps": paths[(r, f)].steps,
                          "wall_time": paths[(r, f)].wall_time,
                          "end": (paths[(r, f)].confirmed_by or "path_strain reached"),
                          "relaxations": len(searches[(r, f)].relaxed) if (r, f) in searches
                          else 0} for r, f, _ in combos],
               "runs": [{k: row[k] for k in ("ratio", "start_fraction", "switch", "outcome",
                                             "steps")} | {"wall_time": runs[(row["ratio"],
                        row["start_fraction"], row["switch"])].wall_time} for row in rows],
               "wall_time": time.time() - t0}
    write_burst_files(out_dir, combos, paths, searches, runs, rows, summary)
    for r, f, _ in combos:            # the grid's states served the search: only the switches'
        keep = set(searches[(r, f)].switches().values()) if (r, f) in searches else set()
        for i in range(len(paths[(r, f)].grid)):
            for kind in ("grid", "relaxed"):
                path = ck.state_path(r, f, kind, i)
                if os.path.exists(path) and not (kind == "relaxed" and i in keep):
                    os.unlink(path)
    return rows, summary


def burst_row(ratio, fraction, switch, path: PathResult, search: RestSearch, i, run: HoldResult,
              opts, eta_peak, n):
    """One row of burst.csv (BURST_COLUMNS) as a dict: the path (its loaded peak), the rest
    search (the peak at rest, the relaxed switch state, grid index ``i``), the hold."""
    pr = path.rows
    grid_row = lambda j: path.grid[j][0]
    h = run.history
    pk = search.peak if search.confirmed else None
    rx = search.relaxed
    nan = math.nan
    lpk = path.peak
    return {"ratio": ratio, "start_fraction": fraction, "eta_start": rx[0].eta_rest,
            "eta_peak_c": rx[pk].eta_rest if pk is not None else nan,
            "fraction_peak_c": rx[pk].eta_rest / eta_peak if pk is not None else nan,
            "eps1_peak_c": pr[grid_row(pk), 1] - pr[0, 1] if pk is not None else nan,
            "c_start": rx[0].c_rest, "c_peak": rx[pk].c_rest if pk is not None else nan,
            "peak_confirmed_by": path.confirmed_by, "switch": switch,
            "eta_switch": rx[i].eta_rest, "eps1_switch": pr[grid_row(i), 1],
            "c_switch": rx[i].c_rest, "dc": opts.dc, "c_target": rx[i].c_rest + opts.dc,
            "outcome": run.outcome,
            "ke_growth": ke_growth(h[:, 8]), "ke_max": float(h[:, 7].max()),
            "ke_backbone_max": float(h[:, 8].max()), "w2_ext_end": h[-1, H["w2_ext"]],
            "w2_walls_end": h[-1, H["w2_walls"]], "w2_int_end": h[-1, H["w2_int"]],
            "t_end": h[-1, 1], "steps": run.steps,
            "de1_end": h[-1, 2] - h[0, 2], "de2_end": h[-1, 3] - h[0, 3],
            "creep_rate": run.creep_rate, "unbalanced_end": h[-1, 9],
            "path_steps": path.steps, "n_disks": n,
            "w2_ext_held_end": h[-1, H["w2_ext_held"]],
            "w2_int_secant_end": h[-1, H["w2_int_secant"]], "w_damp_end": h[-1, H["w_damp"]],
            "u0_end": h[-1, H["u0"]], "eq1_residual": float(np.max(h[:, H["eq1_residual"]])),
            "ke_switch": run.ke_switch, "c_rest": rx[i].c_rest, "c_loaded": rx[i].c_loaded,
            "hold": run.hold, "c_peak_loaded": pr[lpk, 8] if lpk is not None else nan,
            "eta_peak_loaded": pr[lpk, 7] if lpk is not None else nan,
            "wall_mass": run.wall_mass, "g_held": run.g_held,
            "relaxations": len(rx), "relax_outcome": rx[i].outcome}


def write_burst_files(out_dir, combos, paths, searches, runs, rows, summary):
    """burst.csv, history.csv, paths.csv, rest.csv, summary.json and the figures."""
    from . import io
    io.write_csv(os.path.join(out_dir, "burst.csv"), BURST_COLUMNS,
                 [[r[c] for c in BURST_COLUMNS] for r in rows])
    io.write_csv(os.path.join(out_dir, "rest.csv"), REST_COLUMNS,
                 [[r, f, i, paths[(r, f)].grid[i][0], paths[(r, f)].rows[paths[(r, f)].grid[i][0], 1],
                   x.c_loaded, x.c_rest, x.eta_rest, x.outcome, x.steps, x.ke_end,
                   x.unbalanced_end] for (r, f), srch in searches.items()
                  for i, x in sorted(srch.relaxed.items())])
    io.write_csv(os.path.join(out_dir, "history.csv"), HISTORY_COLUMNS,
                 [[r, f, sw] + list(h) for (r, f, sw), run in runs.items() for h in run.history])
    io.write_csv(os.path.join(out_dir, "paths.csv"), PATH_COLUMNS,
                 [[r, f] + list(x) for r, f, _ in combos for x in paths[(r, f)].rows])
    io.atomic_write_bytes(os.path.join(out_dir, "summary.json"),
                          json.dumps(summary, indent=1, default=float).encode())
    plot_burst(out_dir, combos, paths, searches, runs, summary)
    from .ledger import plot_ledger
    for r, f, _ in combos[:1]:          # Eq. 1's terms of the first path's holds
        panels = [(f"R = {r:g}, f = {f:g}, {sw}: {runs[(r, f, sw)].outcome} "
                   f"({summary['n_disks']} disks)", runs[(r, f, sw)].history, HISTORY_COLUMNS[3:])
                  for sw in SWITCHES if (r, f, sw) in runs]
        if panels:
            plot_ledger(os.path.join(out_dir, "fig_burst_ledger.png"), panels)


OUTCOME_COLOR = {"equilibrium": "C2", "failure": "C3", "undecided": "0.5"}


def plot_burst(out_dir, combos, paths, searches, runs, summary):
    """fig_burst_c.png: c against eps1 along every path (loaded), the c its relaxed states keep
    at rest (dots), the loaded peak (open star) and the peak at rest (filled star), the switches
    (at rest) and each held run's (eps1, c) from its switch; fig_burst_ke.png: the backbone
    kinetic energy against the time since the switch (log axes: from rest it spans decades);
    fig_burst_strain.png: the strains since the switch against time (log axis)."""
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
                label=f"path R = {r:g} from {f:g} of the drained peak")
        if p.peak is not None:
            ax.plot(p.rows[p.peak, 1] * 100, p.rows[p.peak, 8] / 1e3, "*", ms=12, mfc="w",
                    mec=col, mew=1.0)
        srch = searches.get((r, f))
        if srch is None:
            continue
        rel = sorted(srch.relaxed)
        e_rel = [p.rows[p.grid[i][0], 1] * 100 for i in rel]
        ax.plot(e_rel, [srch.c(i) / 1e3 for i in rel], ".:", color=col, ms=5, lw=0.8)
        if srch.peak is not None and srch.confirmed:
            ax.plot(p.rows[p.grid[srch.peak][0], 1] * 100, srch.c(srch.peak) / 1e3, "*", ms=13,
                    color=col, mec="k", mew=0.5)
        for sw, mk in zip(SWITCHES, "ov"):
            if (r, f, sw) not in runs:
                continue
            h = runs[(r, f, sw)].history
            oc = runs[(r, f, sw)].outcome
            ax.plot(h[:, 2] * 100, h[:, 4] / 1e3, "-", lw=1.2, color=OUTCOME_COLOR[oc], alpha=0.7)
            i = srch.switches()[sw]
            ax.plot(p.rows[p.grid[i][0], 1] * 100, srch.c(i) / 1e3, mk, ms=8,
                    mfc=OUTCOME_COLOR[oc], mec="k")
    ax.plot([], [], "*", mfc="w", mec="0.3", ms=10, label="c peak of the loaded path")
    ax.plot([], [], ".:", color="0.3", label="c at rest (states relaxed at fixed strain)")
    ax.plot([], [], "*", color="0.3", ms=10, mec="k", label="c peak at rest")
    ax.plot([], [], "o", mfc="w", mec="k", label="below switch (at rest)")
    ax.plot([], [], "v", mfc="w", mec="k", label="past switch (the peak at rest)")
    for oc, col in OUTCOME_COLOR.items():
        ax.plot([], [], "-", color=col, lw=1.5, label=f"run after the switch: {oc}")
    ax.set_xlabel(r"axial strain $\varepsilon_1$ [%]")
    ax.set_ylabel(r"$c = \sigma_1 + R\,\sigma_2$ [kPa]")
    ax.set_title(f"DEM ({n} disks): the proportional strain paths and the c-controlled runs\n"
                 r"$d\varepsilon_2 = R\,d\varepsilon_1$, compression positive", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    save_figure(fig, os.path.join(out_dir, "fig_burst_c.png"), dpi=120)

    for name, ylabel, title in (
            ("fig_burst_ke.png", "backbone kinetic energy [J]",
             "kinetic energy of the disks with two contacts or more after the switch"),
            ("fig_burst_strain.png", r"strain since the switch $|\Delta\varepsilon|$ [%]",
             r"axial (solid) and lateral (dotted) strain since the switch")):
        fig, ax = plt.subplots(figsize=(8, 4.8), constrained_layout=True)
        for (r, f, sw), run in runs.items():
            h = run.history
            oc = run.outcome
            lab = f"R = {r:g}, f = {f:g}, {sw}: {oc}"
            ls = "-" if sw == "below" else "--"
            if name == "fig_burst_ke.png":
                ax.loglog(np.maximum(h[:, 1], 0.5 * h[1, 1] if len(h) > 1 else 1e-6),
                          np.maximum(h[:, 8], 1e-16), ls, color=OUTCOME_COLOR[oc], label=lab)
            else:
                ax.semilogy(h[1:, 1], np.abs(h[1:, 2] - h[0, 2]) * 100, ls,
                            color=OUTCOME_COLOR[oc], label=lab)
                ax.semilogy(h[1:, 1], np.abs(h[1:, 3] - h[0, 3]) * 100, ":",
                            color=OUTCOME_COLOR[oc])
        if name == "fig_burst_ke.png":
            ax.axhline(summary["options"]["ke_tol"] * n, color="k", ls=":", lw=0.8,
                       label="equilibrium bound (ke_tol x disks)")
        ax.set_xlabel("time since the switch [s]")
        ax.set_ylabel(ylabel)
        ax.set_title(f"DEM ({n} disks): {title}", fontsize=10)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
        save_figure(fig, os.path.join(out_dir, name), dpi=120)
