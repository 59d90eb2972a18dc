"""How a stress-controlled run ends: equilibrium, failure or undecided, by rule.

Paper Eq. 1: d2Ec = W2_ext - W2_int.  Under stress control the loading is prescribed; where
the sample's second-order work vanishes in the loading direction the increment cannot be
balanced and the kinetic energy bursts: the sample runs away (a *failure*, a result).  A
probe can also creep and settle late (an *equilibrium* reached slowly), and the two look
alike for a while.  ``settle`` runs the sample under its current control, checks it every
``check_every`` steps, records the history of every check and stops on the first of:

* **equilibrium**: over the whole trailing window of ``window`` steps (see
  ``window_steps``: it grows with the sample's size) the unbalanced-force ratio stayed
  below ``unbalanced_tol``, the wall stresses stayed within ``stress_tol`` of their
  targets and the wall strains moved by less than ``strain_tol`` times the strain scale
  (the probe's own strain increment |de|, or, for a relaxation, the elastic strain of a
  probe: ``voigt_strain``), and the kinetic energy of the backbone (disks with two contacts
  or more; rattlers fly undamped because Cundall damping scales with the force) is below
  ``ke_tol`` per disk.  A once-checked test can pass at the slow start of a collapse (two
  probes at A did, with the wrong sign of W2); a window cannot, because the collapse moves
  the strains during it.
* **failure**: the strain increment is beyond ``runaway_ratio`` times the elastic probe's, the
  servo has not held the wall stresses within ``runaway_stress`` (250 Pa, ten times the
  equilibrium tolerance, and kept when that is tightened) at any check of the last window (the
  sample deforms faster than the walls can follow: the burst) and the backbone's kinetic energy
  has not fallen to less than half over that window (a decaying creep, as after a
  strain-controlled loading, is not a runaway), or the strain increment is beyond
  ``fail_ratio`` times the elastic strain, more than any settled probe was measured to reach.
* **undecided**: neither by ``max_steps``; its creep rate (strain rate over the last window,
  1/s) is reported.

The thresholds come from probe histories measured for this rule (docs/dem.md, "How a probe ends"; 1000 and
2000 disks): settled probes reach at most ~220 times the elastic strain and hold the stresses
to < 1 Pa after ~50,000 steps; runaways pass 400 times with stress errors of kPa.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from common.options import vocabulary_range

from .anatomy import ANATOMY_COLUMNS
from .ledger import COLUMNS as LEDGER_COLUMNS, EXTRA_COLUMNS as LEDGER_EXTRA_COLUMNS
from .simulation import kinetic_energy

# a check's row: the rule's columns, then the energy ledger's (dem.ledger; NaN when the run has
# no ledger attached), then the anatomy of its contacts since the start (dem.anatomy; NaN when
# settle is not given the contacts at the start)
RULE_COLUMNS = ["step", "kinetic_energy", "kinetic_energy_backbone", "unbalanced",
                "eps1", "eps2", "s1", "s2", "stress_error", "strain_ratio"]
HISTORY_COLUMNS = RULE_COLUMNS + LEDGER_COLUMNS + LEDGER_EXTRA_COLUMNS + ANATOMY_COLUMNS
OUTCOMES = ("equilibrium", "failure", "undecided")


class SettleRule(NamedTuple):
    """Tolerances of ``settle`` (SI; strains compression positive, axis 1 = y)."""
    unbalanced_tol: float = 1e-4    # unbalanced-force ratio, at every check of the window
    stress_tol: float = 25.0        # |wall stress - target| [Pa], at every check of the window
    strain_tol: float = 0.01        # strain drift over the window / strain scale
    ke_tol: float = 1e-10           # backbone kinetic energy per disk [J]
    window: int = 20_000            # window [steps] at 1000 disks (window_steps scales it)
    check_every: int = 1000         # steps between checks
    runaway_ratio: float = 100.0    # |de| / |de_elastic| beyond which a sustained stress
    fail_ratio: float = 1000.0      # error is a failure; beyond fail_ratio alone it is one
    max_steps: int = 400_000        # cap [steps]: undecided when reached
    runaway_stress: float = 250.0   # the sustained stress error of a runaway [Pa]
    fail_strain: float = math.inf   # failure: |de| beyond this, whatever the scale [-]

    def validate(self, prefix=""):
        max_steps = vocabulary_range("SettleRule", "max_steps")
        checks = (("unbalanced_tol", 0 < self.unbalanced_tol < 1, "0 < unbalanced_tol < 1"),
                  ("stress_tol", self.stress_tol > 0, "stress_tol > 0 [Pa]"),
                  ("strain_tol", 0 < self.strain_tol < 1, "0 < strain_tol < 1"),
                  ("ke_tol", self.ke_tol > 0, "ke_tol > 0 [J per disk]"),
                  ("window", self.window >= self.check_every, "window >= check_every [steps]"),
                  ("check_every", self.check_every > 0, "check_every > 0 [steps]"),
                  ("runaway_ratio", self.runaway_ratio > 1, "runaway_ratio > 1"),
                  ("fail_ratio", self.fail_ratio > self.runaway_ratio,
                   "fail_ratio > runaway_ratio"),
                  # the range of the vocabulary's --max-steps (written once, there)
                  ("max_steps", max_steps.contains(self.max_steps), max_steps.text("max_steps")),
                  ("runaway_stress", self.runaway_stress > 0, "runaway_stress > 0 [Pa]"),
                  ("fail_strain", self.fail_strain > 0, "fail_strain > 0"))
        for name, ok, rng in checks:
            val = getattr(self, name)
            # inf: no failure by that test (a relaxation's strain ratio, a burst's)
            bad = isinstance(val, float) and (math.isnan(val) or (
                math.isinf(val) and name not in ("fail_strain", "fail_ratio")))
            if not ok or bad:
                raise ValueError(f"{prefix}{name}={val!r}; allowed range: {rng}")
        return self


def window_steps(n_disks: int, rule: SettleRule) -> int:
    """The window for a sample of ``n_disks``: ``rule.window`` at 1000 disks, scaled with the
    sample's width (sqrt of n: the time a disturbance takes to cross it), a whole number of
    checks."""
    w = rule.window * math.sqrt(max(n_disks, 1) / 1000.0)
    return int(math.ceil(w / rule.check_every)) * rule.check_every


class Settled(NamedTuple):
    outcome: str                # one of OUTCOMES
    steps: int                  # steps run by settle
    unbalanced: float           # at the last check
    ke_peak_backbone: float     # largest backbone kinetic energy seen [J]
    strain_ratio: float         # |de| / elastic scale at the end
    creep_rate: float           # |d eps| / dt over the last window [1/s]
    history: np.ndarray         # (checks, len(HISTORY_COLUMNS)): the rule's, then the ledger's


def backbone_kinetic_energy(sim, snap):
    """Kinetic energy [J] of the disks with two contacts or more (walls included)."""
    cnt = (np.bincount(snap.ci, minlength=sim.n) + np.bincount(snap.cj, minlength=sim.n)
           + np.bincount(snap.wp, minlength=sim.n))
    b = cnt >= 2
    return kinetic_energy(sim.m[b], sim.inertia[b], sim.v[b], sim.w[b])


def voigt_strain(sim, norm: float) -> float:
    """Elastic strain [-] of a stress increment of ``norm`` [Pa] under the Voigt (uniform
    strain) estimate of the contact stiffness, E = (3/8) sum_c kn |l_c|^2 / V (3/8 = mean of
    n1^4 over directions): a lower bound of the real elastic strain, so a drift tolerance
    built on it is on the strict side."""
    snap = sim.snapshot()
    l2 = np.sum((sim.x[snap.cj] - sim.x[snap.ci]) ** 2, axis=1)
    e = 0.375 * sim.params.kn * float(np.sum(l2)) / sim.volume
    return norm / e if e > 0 else math.inf


def settle(sim, target_xy, rule: SettleRule, eps0=None, de_elastic=None, strain_scale=None,
           progress=None, stress_error=None, contacts0=None) -> Settled:
    """Run ``sim`` (its control already set) until equilibrium, failure or ``rule.max_steps``
    (see the module docstring).  ``target_xy``: wall-stress targets (s_xx, s_yy) [Pa];
    ``eps0``: wall strains (eps1, eps2) at the start of the probe (default: now);
    ``de_elastic``: |de| of the elastic probe in the same direction (failure rules);
    ``strain_scale``: the strain scale of the drift test when |de| is not one (relaxation)
    and of the strain ratio when ``de_elastic`` is not given.  ``progress(steps, row)``:
    called after each check.  ``stress_error(s_xx, s_yy)``: the stress error [Pa] of a control
    that holds something else than the two wall stresses (``dem.burst``: |c - c_target|; then
    ``target_xy`` is not used); default max |(s_xx, s_yy) - target_xy|.  ``contacts0``: the
    contacts at the start (``dem.anatomy.contact_state``), for the anatomy columns of every
    check: what changed since the start, and the unstable contacts of the last
    ``dem.anatomy.UNSTABLE_WINDOW`` checks (since the start for the first ones), d f . d l below
    -``UNSTABLE_TAU`` times the start's ``energy_scale``."""
    from collections import deque

    from .anatomy import UNSTABLE_TAU, UNSTABLE_WINDOW, energy_scale
    # before a check appends its state, window[0] is the state UNSTABLE_WINDOW checks back (the
    # start for the first ones): the increment of ``dem.burst.hold``'s onset and end states too
    window = deque([contacts0], maxlen=UNSTABLE_WINDOW) if contacts0 is not None else None
    tau = UNSTABLE_TAU * energy_scale(contacts0, sim.params.kn) if contacts0 is not None else 0.0
    target = None if stress_error else np.asarray(target_xy, float)
    e = lambda: sim.strain()[::-1]                      # (eps1, eps2) = (y, x)
    eps0 = e() if eps0 is None else np.asarray(eps0, float)
    w_checks = window_steps(sim.n, rule) // rule.check_every
    el = de_elastic if de_elastic else strain_scale
    hist = []
    steps = 0
    while True:
        snap = sim.snapshot()
        sx, sy = sim.wall_stress(snap)
        ub = sim.unbalanced(snap)
        de = e() - eps0
        err = (float(stress_error(sx, sy)) if stress_error else
               float(np.max(np.abs(np.array([sx, sy]) - target))))
        ratio = float(np.linalg.norm(de) / el) if el else math.nan
        hist.append([sim.step, sim.kinetic_energy(), backbone_kinetic_energy(sim, snap), ub,
                     de[0] + eps0[0], de[1] + eps0[1], sy, sx, err, ratio] + ledger_row(sim)
                    + anatomy_row(sim, contacts0, window, tau))
        if progress:
            progress(steps, hist[-1])
        outcome = _decide(np.asarray(hist[-(w_checks + 1):]), de, ratio, rule, sim.n,
                          w_checks, strain_scale)
        if outcome is None and steps >= rule.max_steps:
            outcome = "undecided"
        if outcome is not None:
            h = np.asarray(hist, float)
            k = max(0, len(h) - 1 - w_checks)
            dt_win = (h[-1, 0] - h[k, 0]) * sim.dt
            creep = (float(np.linalg.norm(h[-1, 4:6] - h[k, 4:6]) / dt_win) if dt_win > 0
                     else math.nan)
            return Settled(outcome, steps, ub, float(h[:, 2].max()), ratio, creep, h)
        k = min(rule.check_every, rule.max_steps - steps)
        sim.run(k)
        steps += k


def ledger_row(sim) -> list:
    """The energy ledger's columns (``LEDGER_COLUMNS + LEDGER_EXTRA_COLUMNS``) of ``sim`` now, or
    NaN where no ledger is attached."""
    if sim.ledger is None:
        return [math.nan] * (len(LEDGER_COLUMNS) + len(LEDGER_EXTRA_COLUMNS))
    return sim.ledger.read().row()


def anatomy_row(sim, contacts0, window=None, tau=0.0) -> list:
    """The anatomy columns (``ANATOMY_COLUMNS``) of ``sim`` now against the contacts at the start
    ``contacts0`` (NaN without them) and, for the unstable contacts, against the oldest of
    ``window`` (a deque of contact states of the last checks, the present one appended here;
    None: since the start); ``tau`` [J]: the threshold of an unstable contact."""
    if contacts0 is None:
        return [math.nan] * len(ANATOMY_COLUMNS)
    from .anatomy import anatomy, contact_state
    s = contact_state(sim)
    prev = None
    if window is not None:
        prev = window[0]
        window.append(s)
    a = anatomy(contacts0, s, sim.n, prev, tau)
    return [a[c] for c in ANATOMY_COLUMNS]


def _decide(win, de, ratio, rule, n, w_checks, strain_scale):
    """Outcome at the last row of ``win`` (the trailing window of checks), or None."""
    if ratio > rule.fail_ratio or float(np.linalg.norm(de)) > rule.fail_strain:
        return "failure"
    if len(win) < w_checks + 1:
        return None                                     # not a whole window yet
    keb = win[:, 2]
    if (ratio > rule.runaway_ratio and np.all(win[:, 8] > rule.runaway_stress)
            and keb[-1] >= 0.5 * keb[0]):
        # ... and the motion is not dying out: the creep that follows a strain-controlled
        # loading also keeps the servo off target for a while, with decaying kinetic energy
        return "failure"
    scale = max(float(np.linalg.norm(de)), strain_scale or 0.0)
    drift = float(np.max(np.linalg.norm(win[:, 4:6] - win[-1, 4:6], axis=1)))
    if (np.all(win[:, 3] <= rule.unbalanced_tol) and np.all(win[:, 8] <= rule.stress_tol)
            and drift <= rule.strain_tol * scale and win[-1, 2] <= rule.ke_tol * n):
        return "equilibrium"
    return None
