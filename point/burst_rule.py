"""How a run held at a generalized force ends: equilibrium, failure or undecided, by rule.

Shared by the material point (``hmodel.burst``) and the dynamic FE specimen (``fem.dynamics``);
the DEM decides its runs with its own rule (``dem.settle``), the same ideas on noisier data.

Paper Eq. 1: delta^2 E_c = W2_ext - W2_int. From an equilibrium state the loading switches to
the generalized force G conjugate to the controlled kinematic variable U1 (the platen
displacement along the tied strain path, ``docs/burst.md``), held at G_switch + dG. Then

    E_c(t) = W2_ext(t) - W2_int(t) - D(t),  W2_ext = dG (U1(t) - U1(0)) >= 0,

with D >= 0 the work of the stated damping. A specimen whose internal second-order work stays
non-negative along the motion (W2_int >= 0: Hill's stability) can never hold more kinetic
energy than dG has put in (E_c <= W2_ext): it oscillates about a nearby equilibrium and, with
the damping, settles. Where W2_int < 0 (past the peak of G along the path) the specimen itself
releases energy: E_c exceeds W2_ext by any factor and keeps growing: the burst.

The rule, checked at every recorded step (t = 0 at the switch; ``window`` a stated time, a few
lowest periods of the specimen; ``rule`` a ``BurstRule``):

* **failure**: the axial strain since the switch is beyond ``runaway_strain`` (the displacement
  runs away), or, over a whole window since the switch, the kinetic energy is more than
  ``ke_over_w2ext`` times W2_ext (so at least 1 - 1/ke_over_w2ext of it came from the specimen:
  W2_int < 0 by Eq. 1) and it grew by ``growth`` or more over the last window.
* **equilibrium**: a whole window since the switch, the kinetic energy never exceeded
  ``ke_bound`` times the largest W2_ext (Eq. 1 with W2_int >= 0 gives 1), its largest value over
  the last window is below ``ke_decay`` times its largest value since the switch (it decays with
  the damping), and the axial strain moved over the last window by less than ``drift`` times its
  largest excursion since the switch (the displacement converges). A run held at exactly its
  equilibrium (dG = 0 from rest: E_c = 0 throughout) is an equilibrium.
* **undecided**: neither by ``max_time`` (the cap); reported, never counted as either.
* **not_converged**: set by the integrator, not by ``decide``: a time step converged at no
  substep (the caller says what failed, its ``failure_reason``). The numerics stopped, not the
  specimen: never counted as a burst (nor as an equilibrium), whatever E_c did before.

**The energy release** (``energy_release``; the one growth measure of the three parts, the DEM
included): the kinetic energy gained since the switch against the work the held step has put
in, r(t) = (E_c(t) - E_c(0)) / W2_ext(t). By Eq. 1, E_c(t) - E_c(0) = W2_ext - W2_int - D with
D >= 0, so r(t) > 1 proves W2_int < 0 (the specimen gave energy back) and r(t) >= ``RELEASE``
proves -W2_int >= (``RELEASE`` - 1) W2_ext. Neither the kinetic energy at the switch (the
floor: it is subtracted) nor the time step (both are energies of the motion, not of a step)
enters it, and, unlike a growth over E_c one step after the switch, it does not depend on how
small that first E_c is. From rest r -> 1 as t -> 0 (all the work is kinetic at first); a
stable specimen then stays below 1 (W2_int >= 0), a bursting one passes ``RELEASE`` at a time
t_release that converges with the time step and does not depend on where the run is stopped
after it.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

__all__ = ["BurstRule", "decide", "OUTCOMES", "ke_growth", "RELEASE", "energy_release",
           "release_ratio", "release_columns", "EnergyCheck", "check_columns"]

# the outcomes of a held run: the three of ``decide`` and the cap, and the integrator's own
OUTCOMES = ("equilibrium", "failure", "undecided", "not_converged")
# the energy release that tells a burst: E_c - E_c(0) >= RELEASE x W2_ext, i.e. the specimen gave
# back at least as much as the held step put in (-W2_int >= W2_ext; ``energy_release``)
RELEASE = 2.0


class BurstRule(NamedTuple):
    """Thresholds of ``decide`` (dimensionless unless stated).

    ke_over_w2ext : failure: E_c > this x W2_ext (Eq. 1: at least 90 % of E_c from W2_int < 0).
    growth : failure: and E_c grew by this factor or more over the last window.
    runaway_strain : failure: |eps1(t) - eps1(0)| beyond this [-] whatever the energies.
    ke_bound : equilibrium: max E_c <= this x max W2_ext (1 by Eq. 1 when W2_int >= 0; the
        margin covers the second-order work of a sliding switch inside one step).
    ke_decay : equilibrium: max E_c over the last window <= this x max E_c since the switch.
    drift : equilibrium: range of eps1 over the last window <= this x max |eps1 - eps1(0)|.
    window_periods : the window, in lowest (elastic) periods T1 of the specimen at the switch.
    max_periods : the cap, in periods T1: undecided when reached.
    """

    ke_over_w2ext: float = 10.0
    growth: float = 10.0
    runaway_strain: float = 0.02
    ke_bound: float = 1.5
    ke_decay: float = 1e-3
    drift: float = 1e-3
    window_periods: float = 4.0
    max_periods: float = 400.0

    def validate(self, prefix: str = "") -> "BurstRule":
        checks = (("ke_over_w2ext", self.ke_over_w2ext > 1, "ke_over_w2ext > 1"),
                  ("growth", self.growth > 1, "growth > 1"),
                  ("runaway_strain", 0 < self.runaway_strain < 1, "0 < runaway_strain < 1"),
                  ("ke_bound", self.ke_bound >= 1, "ke_bound >= 1"),
                  ("ke_decay", 0 < self.ke_decay < 1, "0 < ke_decay < 1"),
                  ("drift", 0 < self.drift < 1, "0 < drift < 1"),
                  ("window_periods", self.window_periods > 0, "window_periods > 0"),
                  ("max_periods", self.max_periods > self.window_periods,
                   "max_periods > window_periods"))
        for name, ok, allowed in checks:
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and ok):
                raise ValueError(f"{prefix}{name} = {v!r} is out of range: allowed {allowed}")
        return self


def ke_growth(ke) -> float:
    """Largest kinetic energy over the one just after the switch (row 1; row 0 is the switch,
    at rest): the ``ke_growth`` column of burst.csv, kept for the cross-check. Not the growth
    measure: from rest E_c after one step is ~ dG^2 dt^2 / (2 m), so this ratio grows as
    1 / dt^2 and with where the run is stopped (``energy_release`` is the measure). inf when E_c
    was 0 just after the switch and grew, nan when it stayed 0."""
    ke = np.asarray(ke, float)
    if ke.size < 2:
        return math.nan
    top = float(np.max(ke[1:]))
    if ke[1] > 0:
        return top / float(ke[1])
    return math.inf if top > 0 else math.nan


def release_ratio(ke, w2_ext) -> np.ndarray:
    """r(t) = (E_c(t) - E_c(0)) / W2_ext(t) (module doc), (n,) [-], nan where W2_ext <= 0
    (nothing put in yet). ke, w2_ext : (n,) [J or J/m], row 0 the switch."""
    ke = np.asarray(ke, float)
    w2 = np.asarray(w2_ext, float)
    ok = w2 > 0
    r = np.full(w2.shape, math.nan)
    r[ok] = (ke[ok] - ke[0]) / w2[ok]
    return r


def energy_release(t, ke, w2_ext, multiple: float = RELEASE) -> dict:
    """The energy release of a held run (module doc): ``ratio_max``, the largest
    r = (E_c - E_c(0)) / W2_ext over the rows with W2_ext > 0 (nan without any), ``t_release``
    [s], the first time r >= ``multiple`` (nan if never), ``released`` (whether it came).

    t : (n,) time since the switch [s]; ke : (n,) kinetic energy [J] (t[0]: the switch);
    w2_ext : (n,) dG (U1 - U1(0)) [J]; multiple : > 1.
    """
    if not (math.isfinite(multiple) and multiple > 1):
        raise ValueError(f"multiple = {multiple!r} is out of range: allowed multiple > 1")
    t = np.asarray(t, float)
    ke = np.asarray(ke, float)
    w2 = np.asarray(w2_ext, float)
    if not (t.shape == ke.shape == w2.shape and t.ndim == 1 and t.size >= 1):
        raise ValueError("t, ke, w2_ext: allowed one-dimensional arrays of one length >= 1")
    r = release_ratio(ke, w2)
    ok = np.isfinite(r)
    hit = np.flatnonzero(ok & (r >= multiple))
    return {"ratio_max": float(np.max(r[ok])) if ok.any() else math.nan,
            "t_release": float(t[hit[0]]) if hit.size else math.nan,
            "released": bool(hit.size)}


def release_columns(t, ke, w2_ext, t1: float) -> dict:
    """The burst.csv columns of the energy release of a run (``energy_release`` at ``RELEASE``):
    ``ke_w2ext_max`` (the largest (E_c - E_c(0)) / W2_ext), ``t_release`` [s], ``t_release_t1``
    (t_release / ``t1``, the lowest elastic period at the switch [s]), ``released``; arrays as
    ``energy_release``'s."""
    r = energy_release(t, ke, w2_ext)
    return {"ke_w2ext_max": r["ratio_max"], "t_release": r["t_release"],
            "t_release_t1": r["t_release"] / float(t1), "released": r["released"]}


def decide(t, ke, w2_ext, eps1, window: float, rule: BurstRule = BurstRule()) -> str | None:
    """The outcome at the last recorded row, or None (go on); the caller applies the cap.

    t : (n,) time since the switch [s] (t[0] = 0); ke : (n,) kinetic energy [J]; w2_ext : (n,)
    second-order external work dG (U1 - U1(0)) [J]; eps1 : (n,) axial strain [-] (any origin);
    window : the window [s] (``rule.window_periods`` x T1).
    """
    t = np.asarray(t, float)
    ke = np.asarray(ke, float)
    w2 = np.asarray(w2_ext, float)
    e = np.asarray(eps1, float) - float(eps1[0])
    excursion = float(np.max(np.abs(e)))
    if excursion > rule.runaway_strain:
        return "failure"
    if t[-1] < window:
        return None                                  # not a whole window yet
    k0 = int(np.searchsorted(t, t[-1] - window, side="right")) - 1   # the row a window back
    last = slice(k0, None)
    w2_now = max(float(w2[-1]), 0.0)
    if ke[-1] > rule.ke_over_w2ext * w2_now and ke[-1] >= rule.growth * ke[k0] and ke[-1] > 0:
        return "failure"
    ke_max = float(np.max(ke))
    if (ke_max <= rule.ke_bound * max(float(np.max(w2)), 0.0)
            and float(np.max(ke[last])) <= rule.ke_decay * ke_max
            and float(np.ptp(e[last])) <= rule.drift * excursion):
        return "equilibrium"
    return None


class EnergyCheck:
    """Eq. 1 of a held run from what the time integrator does not use (docs/burst.md, "The
    energy checks"): the balance that Newmark cannot satisfy by itself.

    Newmark's own balance, E_c(n+1) - E_c(n) = dz . (F(n) + F(n+1)) / 2 with E_c = v.M v / 2 and
    F = f_ext - f_int - C v the integrator's reduced forces, is an identity of the scheme
    (average acceleration) for any symmetric M and any f_int: its residual is the work of the
    Newton residual over the step and nothing else (``newton_work`` in the histories). Here every
    term comes from elsewhere, step by step (each substep of a cut step its own):

    * ``ke_mid`` [J or J/m]: the kinetic energy at the step's midpoint of the velocity field of
      the trajectory itself, (u(n+1) - u(n)) / dt (not the integrator's velocity update),
      integrated with the density over the specimen (not with the integrator's mass matrix);
    * ``dw2_int``: the internal second-order work of the step from the material's own stresses
      and strain increments, sum over the points of ((s(n) + s(n+1)) / 2 - s(0)) : de dV (not the
      nodal internal forces);
    * ``dw2_ext``: dG dU1 of the step; the damping's work by the midpoint rule, 2 ``alpha``
      ke_mid dt (mass-proportional damping C = alpha M: power alpha v.M v).

    ``step`` returns ke_mid minus the mean of Phi = W2_ext - W2_int - D at the step's two ends
    [J or J/m]: both are second-order-accurate values of the continuous balance
    E_c = W2_ext - W2_int - D (Eq. 1 from rest, D >= 0 the damping's work) at t(n + 1/2), so the
    check closes to O(dt^2) on a healthy run. For Newmark with the right mass and forces the
    difference is exactly -dv.M dv / 8 (dv the step's velocity change): for a linear oscillator
    under a step load dG its largest is (omega dt)^2 / 16 of the run's scale (m (omega^2 U_s
    dt)^2 / 8 against W2_ext's largest, 2 dG U_s = 2 m omega^2 U_s^2). A wrong mass, an internal
    force inconsistent with the stresses or a wrong damping leave a difference that does not
    shrink with dt. ``check_columns`` reduces a history to the relative figures of burst.csv.

    ``scale``: the largest of ke_mid, |W2_ext|, |W2_int|, D so far (second-order energies: the
    first-order work of the prestress would hide any residual).
    """

    def __init__(self, alpha: float):
        if not (math.isfinite(alpha) and alpha >= 0):
            raise ValueError(f"alpha = {alpha!r} is out of range: allowed alpha >= 0 [1/s]")
        self.alpha = float(alpha)
        self.w2_ext = self.w2_int = self.damping = self.scale = 0.0

    @property
    def phi(self) -> float:
        """W2_ext - W2_int - D so far: the kinetic energy Eq. 1 predicts [J or J/m]."""
        return self.w2_ext - self.w2_int - self.damping

    def step(self, dt: float, ke_mid: float, dw2_ext: float, dw2_int: float) -> float:
        """Add a (sub)step of length ``dt`` [s]; returns its residual
        ke_mid - (Phi(n) + Phi(n+1)) / 2 [J or J/m] (signed: -dv.M dv / 8 <= 0 for Newmark)."""
        before = self.phi
        self.w2_ext += float(dw2_ext)
        self.w2_int += float(dw2_int)
        self.damping += 2.0 * self.alpha * float(ke_mid) * float(dt)
        self.scale = max(self.scale, float(ke_mid), abs(self.w2_ext), abs(self.w2_int),
                         self.damping)
        return float(ke_mid) - 0.5 * (before + self.phi)


def check_columns(history) -> dict:
    """The burst.csv figures of a run's energy checks from its history (columns ke_mid,
    w2_ext, w2_int_stress, damping_mid, energy_check [J or J/m], w2_int): ``energy_check``, the
    largest |residual| of ``EnergyCheck.step`` over the run's scale (the largest of ke_mid,
    |W2_ext|, |W2_int from the stresses|, D over the run); ``work_check``, the largest
    |W2_int from the stresses - W2_int of the integrator's forces| over the same scale."""
    h = history
    scale = max(float(np.max(h["ke_mid"])), float(np.max(np.abs(h["w2_ext"]))),
                float(np.max(np.abs(h["w2_int_stress"]))), float(np.max(h["damping_mid"])))
    if not scale > 0:
        return {"energy_check": 0.0, "work_check": 0.0}
    return {"energy_check": float(np.max(np.abs(h["energy_check"]))) / scale,
            "work_check": float(np.max(np.abs(np.asarray(h["w2_int_stress"])
                                              - np.asarray(h["w2_int"])))) / scale}
