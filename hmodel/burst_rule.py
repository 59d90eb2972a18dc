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

__all__ = ["BurstRule", "decide", "OUTCOMES", "ke_growth", "RELEASE", "energy_release"]

OUTCOMES = ("equilibrium", "failure", "undecided")
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
    at rest): the ``ke_growth`` column of burst.csv. inf when E_c was 0 just after the switch
    and grew, nan when it stayed 0."""
    ke = np.asarray(ke, float)
    if ke.size < 2:
        return math.nan
    top = float(np.max(ke[1:]))
    if ke[1] > 0:
        return top / float(ke[1])
    return math.inf if top > 0 else math.nan


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
    ok = w2 > 0
    r = np.full(t.shape, math.nan)
    r[ok] = (ke[ok] - ke[0]) / w2[ok]
    hit = np.flatnonzero(ok & (r >= multiple))
    return {"ratio_max": float(np.max(r[ok])) if ok.any() else math.nan,
            "t_release": float(t[hit[0]]) if hit.size else math.nan,
            "released": bool(hit.size)}


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
