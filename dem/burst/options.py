"""The burst's options (``dem.burst``): ``BurstOptions``, the path, the switches and the rule of
the runs, each value checked once where the record is defined (``BurstOptions.validate``: its ranges,
those of the options other commands share (--rate, --path-strain, --dc) read from the
vocabulary, ``common.options.VOCABULARY``, before the states load; ``BurstOptions.check_size``:
the rule of the sample's size, once it is known, before the states load too; ``run_burst``
calls both, as the command line does); and the rule of the loaded peak along the path
(``confirm_peak``, ``scan_peak``) and of the below switch (``below_row``)."""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from common.options import vocabulary_range

from ..settle import SettleRule

SWITCHES = ("below", "past")
HOLDS = ("dead_load", "servo")
RECORD = "BurstOptions"


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
        """ValueError naming the option and its range for a bad value (the table below: the
        vocabulary's ranges for --rate, --path-strain and --dc, this record's own for the rest;
        and ``dem.settle``'s rule); ``n_disks``: the sample's size, for the rule that depends on
        it too (``check_size``; None: that rule is left to a later ``check_size``, once the size
        is known)."""
        from ..settle import window_steps
        self.rule().validate()            # the equilibrium's (window, check_every: used below)
        # the range of a field whose option other commands share (--rate, --path-strain, --dc) is
        # the vocabulary's term's, read from it (_shared); the others are written here, once
        # (and the equilibrium's and max_steps' in dem.settle's SettleRule.validate)
        checks = (self._shared("rate"),
                  self._shared("path_strain"),
                  ("record_strain", 0 < self.record_strain < self.path_strain,
                   "0 < record_strain < path_strain"),
                  ("peak_drop", self.peak_drop > 0, "peak_drop > 0 [Pa]"),
                  ("peak_strain", 0 < self.peak_strain < 0.5, "0 < peak_strain < 0.5"),
                  ("below_rise", 0 < self.below_rise < 1, "0 < below_rise < 1"),
                  self._shared("dc"),
                  ("strain_norm", self.strain_norm > 0, "strain_norm > 0 [Pa]"),
                  ("wall_period_steps", self.wall_period_steps >= 20,
                   "wall_period_steps >= 20 (the leapfrog resolves the walls' period)"),
                  ("stairs", self.stairs >= 1, "stairs >= 1"),
                  ("max_holds", self.max_holds >= 2, "max_holds >= 2"),
                  ("probe_d_eps1", 0 < self.probe_d_eps1 <= 1e-3, "0 < probe_d_eps1 <= 1e-3"),
                  # two equilibrium windows of any sample: its window is a whole number of
                  # checks, one at least (the sample's own two: check_size)
                  ("relax_max_steps", self.relax_max_steps >= 2 * self.check_every,
                   "relax_max_steps >= two equilibrium windows of the sample, each window x "
                   "sqrt(n_disks / 1000) in whole checks of check_every steps "
                   f"({2 * self.check_every} at least, {2 * window_steps(1000, self.rule())} at "
                   "1000 disks)"))
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
        if n_disks is not None:
            self.check_size(n_disks)
        return self

    def _shared(self, name):
        """(name, allowed, range's text), a row of ``validate``'s table, of a field whose option
        other commands share: its range is the vocabulary's term's, read at each call
        (``common.options.vocabulary_range``; KeyError if no term lists the field)."""
        r = vocabulary_range(RECORD, name)
        return name, r.contains(getattr(self, name)), r.text(name, unit=True)

    def check_size(self, n_disks) -> "BurstOptions":
        """The rule of the sample's size, once it is known (``validate`` checks the rest):
        ValueError naming the option if a relaxation's cap is less than two equilibrium windows
        of ``n_disks`` disks (``dem.settle.window_steps``)."""
        from ..settle import window_steps
        win = window_steps(n_disks, self.rule())
        if not self.relax_max_steps >= 2 * win:
            raise ValueError(f"relax_max_steps={self.relax_max_steps!r}; allowed range: "
                             f"relax_max_steps >= {2 * win} (two equilibrium windows at "
                             f"{n_disks} disks: a relaxation is decided over a window of its "
                             "c's drift, itself a window long)")
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
