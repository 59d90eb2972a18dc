"""Boundary control of the four rigid frictionless walls.

A `Control` says, per axis (0 = x walls = lateral = axis 2, 1 = y walls = axial = axis 1),
whether the walls are stress controlled (servo, YADE TriaxialStressController-like) or
strain-rate controlled, or, both axes together, tied (``tied``: the proportional strain path
d eps2 = R d eps1 with the stress conjugate to it, c = s1 + R s2, held by the servo), or tied
under a dead load (``dead_load``: the walls one dynamic degree of freedom under a constant
generalized force, no servo).  Stresses are compression positive [Pa], strain rates compression
positive [1/s], the held force of the dead load [N] in its own field (``g_held``).  The servo
itself is `kernels.servo_walls`.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .kernels import generalized_force as _g

STRESS, STRAIN, TIED, DEAD = 0, 1, 2, 3


class Control(NamedTuple):
    mode: tuple = (STRESS, STRESS)        # per axis (x, y)
    s_from: tuple = (0.0, 0.0)            # stress at ramp start [Pa] (STRESS; c for TIED)
    s_to: tuple = (0.0, 0.0)              # stress at ramp end [Pa] (STRESS; c for TIED)
    ramp_start: int = 0                   # global step where the ramp starts
    ramp_len: int = 0                     # ramp length in steps (0 = step change)
    rate: tuple = (0.0, 0.0)              # strain rate per axis [1/s], compression > 0
    len0: tuple = (1.0, 1.0)              # reference lengths (W0, H0) for the strain rate [m]
    ratio: float = 0.0                    # R of the tie d eps2 = R d eps1 (TIED, DEAD)
    wall_mass: float = 0.0                # m_G of the tied walls under a dead load [kg] (DEAD)
    g_held: float = 0.0                   # the held generalized force G_held [N] (DEAD)

    def arrays(self):
        return (np.asarray(self.mode, np.int64), np.asarray(self.s_from, float),
                np.asarray(self.s_to, float), int(self.ramp_start), int(self.ramp_len),
                np.asarray(self.rate, float), np.asarray(self.len0, float), float(self.ratio),
                float(self.wall_mass), float(self.g_held))


def isotropic(stress, ramp_from=None, step=0, ramp_len=0) -> Control:
    """Both axes stress controlled at `stress` [Pa]."""
    s0 = (stress, stress) if ramp_from is None else tuple(ramp_from)
    return Control((STRESS, STRESS), s0, (stress, stress), step, ramp_len)


def stress_path(s_from, s_to, step, ramp_len) -> Control:
    """Both axes stress controlled, linear ramp from s_from to s_to (sx, sy) [Pa]."""
    return Control((STRESS, STRESS), tuple(s_from), tuple(s_to), step, ramp_len)


def biaxial(lateral_stress, axial_rate, len0) -> Control:
    """Drained biaxial: y walls at axial strain rate, x walls hold lateral stress."""
    return Control((STRESS, STRAIN), (lateral_stress, 0.0), (lateral_stress, 0.0), 0, 0,
                   (0.0, axial_rate), tuple(len0))


def strain_rate(rate_x, rate_y, len0) -> Control:
    """Both axes strain-rate controlled."""
    return Control((STRAIN, STRAIN), (0.0, 0.0), (0.0, 0.0), 0, 0, (rate_x, rate_y),
                   tuple(len0))


def tied(ratio, c_from, c_to, step, ramp_len, len0) -> Control:
    """The proportional strain path d eps2 = R d eps1 (``ratio`` = R < 0) under the control of
    its conjugate stress c = s1 + R s2 [Pa], ramped from ``c_from`` to ``c_to`` over ``ramp_len``
    steps from global step ``step`` (0: a step change): the y walls move to hold c, the x walls
    follow them, dU2 = R (W0/H0) dU1 with (W0, H0) = ``len0`` the reference lengths of the
    strains, so that the engineering strains keep d eps2 = R d eps1 at every step
    (``kernels.servo_walls``).  The targets of c are stored as the y axis's stress targets."""
    if not (math.isfinite(ratio) and ratio < 0):
        raise ValueError(f"ratio={ratio!r}; allowed range: ratio < 0 (finite)")
    return Control((TIED, TIED), (0.0, float(c_from)), (0.0, float(c_to)), int(step),
                   int(ramp_len), (0.0, 0.0), tuple(len0), float(ratio))


def dead_load(ratio, g_held, wall_mass, len0) -> Control:
    """The proportional strain path d eps2 = R d eps1 (``ratio`` = R < 0) under a dead load: the
    walls, tied (each y wall moves inward by U1 / 2, each x wall by k U1 / 2, k = R W0 / H0 with
    (W0, H0) = ``len0``), are one degree of freedom, the platens' shortening U1, with the
    generalized mass ``wall_mass`` m_G [kg] (their kinetic energy is 1/2 m_G U1'^2), driven by
    the constant generalized force ``g_held`` [N] against the sample's, G = F1 + k F2 (F1, F2 the
    mean compressive forces on the y and on the x walls: F1 dU1 + F2 dU2 = G dU1 exactly):
    m_G U1'' = G_held - G, integrated by the disks' leapfrog (``kernels._dead_load``).  No
    servo, no speed limit, no damping on the walls.  The held force has its own field,
    ``Control.g_held`` [N] (the stress targets stay 0)."""
    if not (math.isfinite(ratio) and ratio < 0):
        raise ValueError(f"ratio={ratio!r}; allowed range: ratio < 0 (finite)")
    if not (math.isfinite(wall_mass) and wall_mass > 0):
        raise ValueError(f"wall_mass={wall_mass!r}; allowed range: wall_mass > 0 [kg] (finite)")
    return Control((DEAD, DEAD), (0.0, 0.0), (0.0, 0.0), 0, 0, (0.0, 0.0), tuple(len0),
                   float(ratio), float(wall_mass), float(g_held))


def generalized_force(wF, ratio, len0):
    """G = F1 + k F2 [N] of the walls' forces ``wF`` (4,) [N] (k = R W0 / H0): the generalized
    force conjugate to the platens' shortening U1 under the tie (``dead_load``), by the kernels'
    own ``generalized_force`` (the same bits as the dead load's step)."""
    k = ratio * len0[0] / len0[1]
    return _g(0.5 * (wF[2] + wF[3]), 0.5 * (wF[0] + wF[1]), k)


def wall_stress(wF, walls, thickness):
    """(s_xx, s_yy) [Pa] compression positive, from the wall forces wF (4,) [N]."""
    w = walls[1] - walls[0]
    h = walls[3] - walls[2]
    return np.array([0.5 * (wF[0] + wF[1]) / (h * thickness),
                     0.5 * (wF[2] + wF[3]) / (w * thickness)])
