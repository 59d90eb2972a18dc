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

from .ledger import COLUMNS as LEDGER_COLUMNS, EXTRA_COLUMNS as LEDGER_EXTRA_COLUMNS, Ledger
from .settle import RULE_COLUMNS, SettleRule, settle, voigt_strain
from .simulation import Simulation, State
from .threads import ThreadChooser
from .walls import strain_rate, tied

SWITCHES = ("below", "past")
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
                 "w2_int_secant_end", "w_damp_end", "u0_end", "eq1_residual"]


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

    def validate(self) -> "BurstOptions":
        checks = (("rate", 0 < self.rate <= 10, "0 < rate <= 10 [1/s]"),
                  ("path_strain", 0 < self.path_strain < 0.5, "0 < path_strain < 0.5"),
                  ("record_strain", 0 < self.record_strain < self.path_strain,
                   "0 < record_strain < path_strain"),
                  ("peak_drop", self.peak_drop > 0, "peak_drop > 0 [Pa]"),
                  ("peak_strain", 0 < self.peak_strain < 0.5, "0 < peak_strain < 0.5"),
                  ("below_rise", 0 <= self.below_rise < 1, "0 <= below_rise < 1"),
                  ("dc", self.dc >= 0, "dc >= 0 [Pa]"),
                  ("strain_norm", self.strain_norm > 0, "strain_norm > 0 [Pa]"))
        for name, ok, rng in checks:
            val = getattr(self, name)
            if not ok or not math.isfinite(val):
                raise ValueError(f"{name}={val!r}; allowed range: {rng}")
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
    peak: int | None          # row of the c peak (None: no peak within the path)
    confirmed_by: str         # "drop", "strain", "" (no peak) or "unloaded"
    switches: dict            # {"below"/"past": (row, State)}
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
    axes strain controlled), recorded every ``opts.record_strain``, until the c peak is
    confirmed, the path has gone ``opts.path_strain`` or it has unloaded (see the module doc).
    Keeps in memory the states of the switches: every record that raised the largest c so
    far, dropped once below the ``below`` threshold of the largest (the first state at or
    above a threshold is always one of them)."""
    t0 = time.time()
    sim = Simulation(state)
    if threads is not None:
        sim.threads = ThreadChooser(sim.n, threads)
    sim.set_control(strain_rate(ratio * opts.rate, opts.rate, sim.ref_len))
    Ledger(sim)
    every = max(1, int(round(opts.record_strain / (opts.rate * sim.dt))))
    rows = [_record(sim, ratio)]
    e_start, c_start, p_start = rows[0][1], rows[0][8], rows[0][5]
    kept = [(0, sim.state())]         # (row, State) that raised the largest c
    peak, how = 0, ""
    while True:
        sim.run(every)
        rows.append(_record(sim, ratio))
        k = len(rows) - 1
        e1, c, p = rows[k][1], rows[k][8], rows[k][5]
        how = confirm_peak(c, e1, rows[peak][8], rows[peak][1], opts)
        if how == "new":
            peak, how = k, ""
            low = c_start + opts.below_rise * (c - c_start)
            kept = [(j, s) for j, s in kept if rows[j][8] >= low] + [(k, sim.state())]
        if not how and p < UNLOADED * p_start:
            how = "unloaded"
        if progress:
            progress(sim.step - state.step, rows[k], rows[peak])
        if how or e1 - e_start >= opts.path_strain:
            break
    rows = np.asarray(rows, float)
    if how == "unloaded":
        return PathResult(rows, None, how, {}, sim.step - state.step, time.time() - t0)
    if how:                         # a confirmed peak
        states = dict(kept)
        kb = below_row(rows[:, 8], peak, opts.below_rise)
        switches = {"below": (kb, states[kb]), "past": (peak, states[peak])}
    else:                           # no peak within the path: below at its end
        peak = None
        switches = {"below": (len(rows) - 1, sim.state())}
    return PathResult(rows, peak, how, switches, sim.step - state.step, time.time() - t0)


H = {c: k for k, c in enumerate(HISTORY_COLUMNS[3:])}    # a hold's history columns (from "step")


class HoldResult(NamedTuple):
    outcome: str
    steps: int
    history: np.ndarray       # (checks, len(HISTORY_COLUMNS) - 3): HISTORY_COLUMNS from "step"
    creep_rate: float         # [1/s] over the last window
    wall_time: float          # [s]


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


def hold(state: State, ratio: float, c_target: float, opts: BurstOptions = BurstOptions(),
         threads=None, progress=None) -> HoldResult:
    """The tied run from ``state``: d eps2 = R d eps1 kept, c held at ``c_target`` [Pa]
    (``walls.tied``), decided by ``dem.settle`` with the stress error |c - c_target| (see the
    module doc). ``progress(steps, history row)``: after each check."""
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
    d_g = sim.size[0] * sim.params.thickness * (c_target - c_switch)     # dG [N]
    h0 = sim.ref_len[1]
    sim.set_control(tied(ratio, c_target, c_target, sim.step, 0, sim.ref_len))
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
                 progress=check, stress_error=lambda sx, sy: abs(sy + ratio * sx - c_target))
    return HoldResult(res.outcome, res.steps, np.asarray(hist, float), res.creep_rate,
                      time.time() - t0)


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


def _hold_task(args):
    state, ratio, fraction, switch, c_target, opts, threads, verbose = args
    last = [time.time()]

    def progress(steps, h):
        if verbose and time.time() - last[0] > 10.0:
            last[0] = time.time()
            _log(f"R={ratio:g} f={fraction:g} {switch}: step {steps} eps1={h[2]:.5f} "
                 f"|c - c_target|={h[6]:.0f} Pa backbone KE={h[8]:.2e} J")

    return hold(state, ratio, c_target, opts, threads, progress)


def run_burst(biaxial_dir, out_dir, ratios, fractions, opts: BurstOptions = BurstOptions(),
              workers=None, threads=None, verbose=True, params_file=None, stage=None):
    """Every proportional path (one per ratio and start fraction), then every switch of every
    path, each an independent run spread over ``workers`` local processes (one thread each;
    ``threads`` in a single process); writes ``out_dir``/burst.csv, history.csv, paths.csv,
    summary.json, params.json and the figures. Returns (burst rows as dicts, summary dict)."""
    from .probes import _map, state_fingerprint
    opts.validate()
    ratios = [check_ratio(float(r)) for r in ratios]
    starts, eta_peak, params = load_starts(biaxial_dir, fractions, params_file)
    t0 = time.time()
    os.makedirs(out_dir, exist_ok=True)
    # the parameters the run used, in the shared file format (``--params DIR/params.json``)
    from .params import record_params
    record_params(out_dir, params, f"python -m dem burst; parameters: the start states' own "
                                   f"(--biaxial {biaxial_dir})")
    combos = [(r, f, st) for r in ratios for f, st, _ in starts]
    # a run in a pool of processes runs on one thread; alone in this process, on ``threads``
    # (None: dem.threads chooses)
    per_run = lambda tasks: threads if threads is not None or workers == 1 or len(tasks) == 1 else 1
    log = _log if verbose else (lambda m: None)
    log(f"{len(combos)} proportional paths ({params.n} disks, rate {opts.rate:g}/s): R in "
        f"{ratios}, start fractions {list(fractions)}; peak confirmed {opts.peak_strain:g} of "
        f"strain beyond it or {opts.peak_drop:g} Pa below; below at {opts.below_rise:g} of the "
        f"rise; c held at its switch value + {opts.dc:g} Pa")
    if stage:
        stage.at("dem burst: the proportional paths")
    paths = {}

    def got_path(key, res):
        paths[key] = res
        r, f = key
        pk = (f"c peak {res.rows[res.peak, 8] / 1e3:.2f} kPa at eta {res.rows[res.peak, 7]:.4f} "
              f"(confirmed by {res.confirmed_by})" if res.peak is not None else
              "the specimen unloaded" if res.confirmed_by == "unloaded" else "no c peak")
        log(f"R={r:g} f={f:g} path: {pk}, {res.steps} steps, {res.wall_time:.0f} s")

    _map([((r, f), (st, r, f, opts, per_run(combos), verbose)) for r, f, st in combos],
         got_path, workers, None, fn=_path_task)
    todo = [(r, f, sw) for r, f, _ in combos for sw in SWITCHES if sw in paths[(r, f)].switches]
    holds = []
    for r, f, sw in todo:
        row, st = paths[(r, f)].switches[sw]
        holds.append(((r, f, sw), (st, r, f, sw, paths[(r, f)].rows[row, 8] + opts.dc, opts,
                                   per_run(todo), verbose)))
    if stage:
        stage.at("dem burst: the switched runs")
    runs = {}

    def got_run(key, res):
        runs[key] = res
        log(f"R={key[0]:g} f={key[1]:g} {key[2]}: {res.outcome} after {res.steps} steps "
            f"({res.wall_time:.0f} s)")

    _map(holds, got_run, workers, None, fn=_hold_task)
    rows = []
    for r, f, st in combos:
        p = paths[(r, f)]
        for sw in SWITCHES:
            if (r, f, sw) in runs:
                rows.append(burst_row(r, f, sw, p, runs[(r, f, sw)], opts, eta_peak, params.n))
    summary = {"biaxial": os.path.abspath(biaxial_dir), "n_disks": params.n,
               "drained_eta_peak": eta_peak, "ratios": ratios, "start_fractions": list(fractions),
               "options": opts._asdict(), "params": params.to_dict(), "dt": params.dt,
               "fingerprints": {f"{f:g}": state_fingerprint(st) for f, st, _ in starts},
               "paths": [{"ratio": r, "start_fraction": f, "steps": paths[(r, f)].steps,
                          "wall_time": paths[(r, f)].wall_time,
                          "end": (paths[(r, f)].confirmed_by or "path_strain reached")}
                         for r, f, _ in combos],
               "runs": [{k: row[k] for k in ("ratio", "start_fraction", "switch", "outcome",
                                             "steps")} | {"wall_time": runs[(row["ratio"],
                        row["start_fraction"], row["switch"])].wall_time} for row in rows],
               "wall_time": time.time() - t0}
    write_burst_files(out_dir, combos, paths, runs, rows, summary)
    return rows, summary


def burst_row(ratio, fraction, switch, path: PathResult, run: HoldResult, opts, eta_peak, n):
    """One row of burst.csv (BURST_COLUMNS) as a dict."""
    pr = path.rows
    k_sw = path.switches[switch][0]
    h = run.history
    pk = path.peak
    nan = math.nan
    return {"ratio": ratio, "start_fraction": fraction, "eta_start": pr[0, 7],
            "eta_peak_c": pr[pk, 7] if pk is not None else nan,
            "fraction_peak_c": pr[pk, 7] / eta_peak if pk is not None else nan,
            "eps1_peak_c": pr[pk, 1] - pr[0, 1] if pk is not None else nan,
            "c_start": pr[0, 8], "c_peak": pr[pk, 8] if pk is not None else nan,
            "peak_confirmed_by": path.confirmed_by, "switch": switch,
            "eta_switch": pr[k_sw, 7], "eps1_switch": pr[k_sw, 1], "c_switch": pr[k_sw, 8],
            "dc": opts.dc, "c_target": pr[k_sw, 8] + opts.dc, "outcome": run.outcome,
            "ke_growth": ke_growth(h[:, 8]), "ke_max": float(h[:, 7].max()),
            "ke_backbone_max": float(h[:, 8].max()), "w2_ext_end": h[-1, H["w2_ext"]],
            "w2_walls_end": h[-1, H["w2_walls"]], "w2_int_end": h[-1, H["w2_int"]],
            "t_end": h[-1, 1], "w2_ext_held_end": h[-1, H["w2_ext_held"]],
            "w2_int_secant_end": h[-1, H["w2_int_secant"]], "w_damp_end": h[-1, H["w_damp"]],
            "u0_end": h[-1, H["u0"]], "eq1_residual": float(np.max(h[:, H["eq1_residual"]])),
            "steps": run.steps,
            "de1_end": h[-1, 2] - h[0, 2], "de2_end": h[-1, 3] - h[0, 3],
            "creep_rate": run.creep_rate, "unbalanced_end": h[-1, 9],
            "path_steps": path.steps, "n_disks": n}


def write_burst_files(out_dir, combos, paths, runs, rows, summary):
    """burst.csv, history.csv, paths.csv, summary.json and the three figures."""
    from . import io
    io.write_csv(os.path.join(out_dir, "burst.csv"), BURST_COLUMNS,
                 [[r[c] for c in BURST_COLUMNS] for r in rows])
    io.write_csv(os.path.join(out_dir, "history.csv"), HISTORY_COLUMNS,
                 [[r, f, sw] + list(h) for (r, f, sw), run in runs.items() for h in run.history])
    io.write_csv(os.path.join(out_dir, "paths.csv"), PATH_COLUMNS,
                 [[r, f] + list(x) for r, f, _ in combos for x in paths[(r, f)].rows])
    io.atomic_write_bytes(os.path.join(out_dir, "summary.json"),
                          json.dumps(summary, indent=1, default=float).encode())
    plot_burst(out_dir, combos, paths, runs, summary)


OUTCOME_COLOR = {"equilibrium": "C2", "failure": "C3", "undecided": "0.5"}


def plot_burst(out_dir, combos, paths, runs, summary):
    """fig_burst_c.png: c against eps1 along every path, its peak and the switches marked, each
    switched run's (eps1, c) drawn from its switch; fig_burst_ke.png: the backbone kinetic
    energy against the time since the switch (log axis); fig_burst_strain.png: the strains
    since the switch against time (log axis)."""
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
            ax.plot(p.rows[p.peak, 1] * 100, p.rows[p.peak, 8] / 1e3, "*", ms=12, color=col,
                    mec="k", mew=0.5)
        for sw, mk in zip(SWITCHES, "ov"):
            if (r, f, sw) not in runs:
                continue
            h = runs[(r, f, sw)].history
            oc = runs[(r, f, sw)].outcome
            ax.plot(h[:, 2] * 100, h[:, 4] / 1e3, "-", lw=1.2, color=OUTCOME_COLOR[oc], alpha=0.7)
            k = p.switches[sw][0]
            ax.plot(p.rows[k, 1] * 100, p.rows[k, 8] / 1e3, mk, ms=8, mfc=OUTCOME_COLOR[oc],
                    mec="k")
    ax.plot([], [], "*", color="0.3", ms=10, label="c peak (largest c)")
    ax.plot([], [], "o", mfc="w", mec="k", label="below switch")
    ax.plot([], [], "v", mfc="w", mec="k", label="past switch (at the peak)")
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
                ax.semilogy(h[:, 1], np.maximum(h[:, 8], 1e-16), ls, color=OUTCOME_COLOR[oc],
                            label=lab)
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
