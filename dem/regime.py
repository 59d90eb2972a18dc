"""The granular regime of a DEM run: checked before it, watched during it.

**Before a run: the stiffness number.**  A contact of two disks of thickness t carries, at the
confining stress sigma2, a normal force of about sigma2 D t (D the mean diameter: the stress times
the share of a wall or a section that one contact holds), so its overlap is about sigma2 D t / kn,
and relative to the diameter

    delta / D ~ 1 / kappa,   kappa = kn / (sigma2 t) = (kn/D) (D/t) / sigma2,

kappa the *stiffness number* of Roux & Chevoir (2005) and Agnolin & Roux (2007), written for
disks of thickness t (kn/t is a contact's stiffness per unit thickness, in Pa, as sigma2 is).  The
contact law (springs between grains that touch at a point) describes rigid grains only where
kappa is large: those authors call kappa >~ 1e4 the rigid limit (the packing's geometry no longer
depends on it), and common 2D practice runs 1e3-1e4.  The paper's set is at kappa = 2720 (kn/D =
32 GPa, D = 17 mm, t = 1 m, sigma2 = 200 kPa: the mean overlap 3.7e-4 D).  Measured on 300 disks
compacted to 200 kPa (seed 1): the mean overlap is 1.16 / kappa of D and the largest 13 / kappa
of the smallest diameter, and the porosity of the packing drifts from the rigid limit's as kappa
falls:

    kappa             2720    272    100    27     2.7     0.85
    porosity          0.173   0.162  0.147  0.094  -0.40   -1.80
    disks outside     0       0      0      0      1       36

A set is refused below ``KAPPA_MIN`` = 100 (``check_regime``: one line naming kn/D, the stiffness
number and what to change): there the mean overlap passes 1 % of the diameter, the largest reach
13 % of the smallest one and the porosity is off by 0.03 from the rigid grains'.  Not 1e4: the
paper's own set and the calibration's search range (kn/D from 2 GPa: kappa 170) lie below it and
are sound, if not rigid.  ``allow_soft`` runs a refused set anyway; the summary records it
(``regime``).  The ratio kn / (D sigma2) (1.6e5 for the paper's set) leaves out D / t and is not
the overlap's.

**During a run: the watch** (``watch_run`` after every chunk of ``Simulation.run``,
``watch_contacts`` at every ``Simulation.snapshot``: reads only, so a trajectory is the same with
or without it).  A state that no granular packing can be stops the run with ``UnsoundState``, a
named outcome (``OUTCOMES``), one line, the state kept for inspection (``dem`` then exits 1):

* ``non_finite_state``: a position, velocity or spin that is NaN or infinite;
* ``disk_outside_walls``: a disk's centre beyond a wall (it went through it);
* ``walls_crossed``: the box turned inside out (the servo or the strain control unstable);
* ``porosity_out_of_range``: the porosity 1 - sum(pi r^2) / (W H) outside (0, 1): the disks'
  area larger than the box's;
* ``overlap_beyond_bound``: a contact overlapping by more than ``OVERLAP_MAX`` (one half) of the
  smaller diameter of its two disks (a wall contact: of the disk's diameter), i.e. one centre on
  or inside the other disk: two grains no longer touching at a point.  At kappa >= 100 the
  largest overlap measured is 13 % of the smallest diameter at sigma2 (a few times that at the
  peak of a biaxial test), so an accepted set stays far below it.
"""
from __future__ import annotations

import math

import numpy as np

KAPPA_MIN = 100.0      # stiffness number kn / (sigma2 t) below which a set is refused
OVERLAP_MAX = 0.5      # the largest overlap a run accepts, over the smaller diameter of the pair
OUTCOMES = ("non_finite_state", "disk_outside_walls", "walls_crossed", "porosity_out_of_range",
            "overlap_beyond_bound")
KEPT = "unsound_state.npz"     # the file an unsound state is kept in (in the command's --out)


def stiffness_number(params, sigma2: float) -> float:
    """kappa = kn / (sigma2 t) [-] of ``params`` (DemParams) at the confining stress ``sigma2``
    [Pa] (module doc)."""
    return params.kn / (sigma2 * params.thickness)


def regime(params, sigma2: float, allow_soft: bool = False) -> dict:
    """What a summary records of the regime: the stiffness number, the expected mean overlap over
    the mean diameter (1 / kappa), the bound, whether the set is inside it and whether it was run
    anyway (``allow_soft``)."""
    k = stiffness_number(params, sigma2)
    return {"stiffness_number": k, "expected_overlap": 1.0 / k, "sigma2": float(sigma2),
            "kappa_min": KAPPA_MIN, "inside": bool(k >= KAPPA_MIN),
            "allow_soft": bool(allow_soft)}


class SoftContactError(ValueError):
    """A parameter set outside the granular regime (``check_regime``): bad input, refused before
    anything runs."""


def check_regime(params, sigma2: float, allow_soft: bool = False, where: str = "",
                 sigma_option: str = "--sigma2",
                 anyway: str = "--allow-soft runs it anyway") -> dict:
    """``regime(params, sigma2)``, or SoftContactError of one line (naming kn/D, the stiffness
    number and what to change) where kappa < KAPPA_MIN and not ``allow_soft``. ``where``: what
    the parameters are, as the message starts ("--kn-over-d 1e+07", "the state's parameters
    (--state S)"); ``sigma_option``: the option of the confining stress, if any; ``anyway``:
    how the command runs such a set all the same, as the message ends."""
    got = regime(params, sigma2, allow_soft)
    if got["inside"] or allow_soft:
        return got
    k = got["stiffness_number"]
    need = KAPPA_MIN * sigma2 * params.thickness / params.d_mean
    head = where or f"--kn-over-d {params.kn_over_d:g}"
    sig = f" or a smaller {sigma_option}" if sigma_option else ""
    raise SoftContactError(
        f"{head}: the stiffness number kn/(sigma2 t) = {k:.3g} (kn/D {params.kn_over_d:.3g} Pa, "
        f"D {params.d_mean:g} m, t {params.thickness:g} m, sigma2 {sigma2 / 1e3:g} kPa) puts a "
        f"contact's overlap at {100.0 / k:.3g} % of the diameter, outside the granular regime; "
        f"allowed: a stiffness number >= {KAPPA_MIN:g} (overlap <= {100.0 / KAPPA_MIN:g} %), "
        f"here kn/D >= {need:.3g} Pa{sig}; {anyway}")


def softest(space, base):
    """The softest set of a calibration's search ``space`` (``dem.calibrate.Space``) around the
    start set ``base``: kn/D, r_min and r_max at the lower ends of their ranges where varied (the
    stiffness number falls with each), and where it comes from, for ``check_regime``'s line."""
    ends = {f: lo for f, lo in zip(space.names, space.lo) if f in ("kn_over_d", "r_min", "r_max")}
    r_min = ends.get("r_min", base.r_min)
    soft = base.replace(**{**ends, "r_max": max(ends.get("r_max", base.r_max), r_min)})
    varied = ", ".join(f"{f} from {v:g}" for f, v in ends.items())
    return soft, (f"the softest set of the search (--bounds: {varied})" if varied else
                  f"--kn-over-d {base.kn_over_d:g}")


def check_biaxial_regime(biaxial_dir, allow_soft=False, option="--biaxial") -> dict:
    """``check_regime`` of the parameters of a ``dem biaxial`` folder (its summary.json) at its
    confining stress: what ``dem domain`` and ``dem burst`` start from."""
    import json
    import os
    from .params import DemParams
    with open(os.path.join(biaxial_dir, "summary.json")) as f:
        s = json.load(f)
    return check_regime(DemParams.from_dict(s["params"]), float(s["confining"]), allow_soft,
                        f"{option} {biaxial_dir} (its parameters)", "")


class UnsoundState(Exception):
    """A run stopped on a state no granular packing can be (module doc): ``outcome`` (one of
    ``OUTCOMES``), ``step``, ``state`` (the ``State`` at that point, for inspection;
    ``dem.io.save_unsound`` writes it). One line: ``str(e)``. Not a ValueError: a run's failure,
    not bad input."""

    def __init__(self, outcome: str, message: str, step: int = -1, state=None):
        super().__init__(f"unsound state ({outcome}) at step {step}: {message}")
        self.outcome, self.message, self.step, self.state = outcome, message, step, state

    def __reduce__(self):       # across processes (probe workers, dask) with its state
        return (type(self), (self.outcome, self.message, self.step, self.state))


def _unsound(sim, outcome, message):
    return UnsoundState(outcome, message, sim.step, sim.state())


def watch_run(sim) -> None:
    """The cheap checks after a chunk of steps (``Simulation.run``): positions, velocities and
    spins finite, the walls not crossed, every centre within the walls, the porosity within
    (0, 1) (the disks' area ``sim.solid``, kept since the last rebuild, over the box's). Raises
    ``UnsoundState``; reads only. About 40 us at 12,000 disks (a column's min is 20 times faster
    than the (N, 2) array's min along its first axis)."""
    x, walls = sim.x, sim.walls
    xs, ys = x[:, 0], x[:, 1]
    # a NaN fails every comparison, so finite positions inside the box pass this test alone
    inside = (xs.min() >= walls[0] and xs.max() <= walls[1] and ys.min() >= walls[2]
              and ys.max() <= walls[3])
    box = (walls[1] - walls[0]) * (walls[3] - walls[2])
    if inside and 0.0 < sim.solid < box and math.isfinite(float(np.sum(sim.v))
                                                          + float(np.sum(sim.w))):
        return
    names = [n for a, n in ((x, "position"), (sim.v, "velocity"), (sim.w, "spin"),
                            (walls, "wall position")) if not np.all(np.isfinite(a))]
    if names:
        raise _unsound(sim, "non_finite_state", f"a disk's or wall's {' and '.join(names)} is "
                       "not finite (NaN or inf)")
    if walls[1] <= walls[0] or walls[3] <= walls[2]:
        raise _unsound(sim, "walls_crossed", f"walls crossed (x {walls[0]:.6g}, {walls[1]:.6g}; "
                       f"y {walls[2]:.6g}, {walls[3]:.6g} m): the servo or the strain control is "
                       "unstable")
    if not inside:
        out = np.flatnonzero((xs < walls[0]) | (xs > walls[1]) | (ys < walls[2]) | (ys > walls[3]))
        i = int(out[0])
        raise _unsound(sim, "disk_outside_walls",
                       f"{len(out)} disk centre(s) outside the walls, the first disk {i} at "
                       f"({x[i, 0]:.6g}, {x[i, 1]:.6g}) m, walls x {walls[0]:.6g} to "
                       f"{walls[1]:.6g}, y {walls[2]:.6g} to {walls[3]:.6g} m: it went through "
                       "a wall (the contacts too soft for the stress, or the time step too large)")
    if not 0.0 < sim.solid < box:
        raise _unsound(sim, "porosity_out_of_range",
                       f"porosity {1.0 - sim.solid / box:.4g}, outside (0, 1): the disks' area "
                       "exceeds the box's (overlaps of the order of the diameter: the contacts "
                       "too soft for the stress)")
    # finite velocities whose sum overflowed: nothing unsound


def watch_contacts(sim, snap) -> None:
    """The overlaps of a contact snapshot (``Simulation.snapshot``) against ``OVERLAP_MAX`` of
    the smaller diameter of each pair (of the disk's for a wall contact). Raises
    ``UnsoundState``; reads only."""
    kn = sim.params.kn
    r = sim.r
    worst, which = 0.0, None
    if len(snap.fn):
        rel = snap.fn / (kn * 2.0 * np.minimum(r[snap.ci], r[snap.cj]))
        k = int(np.argmax(rel))
        worst, which = float(rel[k]), f"disks {int(snap.ci[k])} and {int(snap.cj[k])}"
    if len(snap.wf):
        rel = snap.wf / (kn * 2.0 * r[snap.wp])
        k = int(np.argmax(rel))
        if rel[k] > worst:
            worst, which = float(rel[k]), f"disk {int(snap.wp[k])} and wall {int(snap.ww[k])}"
    if worst > OVERLAP_MAX:
        raise _unsound(sim, "overlap_beyond_bound",
                       f"the contact of {which} overlaps by {worst:.3g} of the smaller diameter, "
                       f"beyond {OVERLAP_MAX:g} (one centre inside the other disk: the contacts "
                       f"too soft for the stress, stiffness number "
                       f"{stiffness_number(sim.params, max(_stress(sim, snap), 1e-300)):.3g})")


def _stress(sim, snap) -> float:
    """The smaller wall stress [Pa] of ``snap`` (for the message)."""
    from .walls import wall_stress
    wF = np.bincount(snap.ww, weights=snap.wf, minlength=4)
    return float(min(wall_stress(wF, sim.walls, sim.params.thickness)))
