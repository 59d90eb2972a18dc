"""The walls: their forces on the disks (``wall_forces``) and their control for one step
(``servo_walls``: the stress servo, strain rate, the tied servo ``_servo_tied`` and the dead
load ``_dead_load``), with the generalized force of the tied walls, G = F1 + k F2
(``generalized_force``: the one definition, also called from Python by ``dem.walls`` and
``dem.burst``)."""
import math

from numba import njit

from .common import FAST


@njit(**FAST)
def wall_forces(x, v, r, m, walls, cand_off, cand, fext, kn, beta, wF, wK, fw):
    """Frictionless linear walls.  Resets fext of candidates, then adds wall forces.

    wF (4,) receives the compressive force on each wall [N], wK (4,) the sum of the
    contact stiffnesses of each wall [N/m] (used by the servo).  fw (2, C) or (2, 0): with
    C = the candidate entries, receives for the energy ledger the compressive force of each
    entry [N] (0 where it does not touch) and its dashpot part (the force less kn overlap).
    """
    ledger = fw.shape[1] > 0
    for a in range(cand_off[4]):
        p = cand[a]
        fext[p, 0] = 0.0
        fext[p, 1] = 0.0
    for wi in range(4):
        wF[wi] = 0.0
        wK[wi] = 0.0
        axis = wi // 2
        sgn = 1.0 if wi % 2 == 0 else -1.0  # direction of the force on the particle
        for a in range(cand_off[wi], cand_off[wi + 1]):
            p = cand[a]
            gap = sgn * (x[p, axis] - walls[wi])
            ov = r[p] - gap
            if ov > 0.0:
                f = kn * ov
                if beta > 0.0:
                    f -= 2.0 * beta * math.sqrt(kn * m[p]) * sgn * v[p, axis]
                    if f < 0.0:
                        f = 0.0
                fext[p, axis] += sgn * f
                wF[wi] += f
                wK[wi] += kn
                if ledger:
                    fw[0, a] = f
                    fw[1, a] = f - kn * ov
            elif ledger:
                fw[0, a] = 0.0
                fw[1, a] = 0.0


# --------------------------------------------------------------------------------------
# Wall control (YADE TriaxialStressController-like servo)
# --------------------------------------------------------------------------------------
@njit(**FAST)
def servo_walls(walls, wF, wK, prev, servo, ramp_t, dt):
    """Move the walls (4,) for one step under the control ``servo`` (a ``Servo``, as a tuple).

    servo.mode (2,): per axis (0 = x walls, 1 = y walls) 0 = stress control, 1 = strain rate,
    or both 2 = tied (``_servo_tied``; ``ratio`` = R, used by it only), or both 3 = tied under
    a dead load (``_dead_load``: the held generalized force ``g_held`` [N], the walls'
    generalized mass ``wall_mass`` [kg]; unused by the other modes).
    Stress target = s_from + (s_to - s_from) * ramp_t (compression positive) [Pa].
    Stress control: inward displacement gain * (F_target - F) / sum(k_contacts), clipped to
    vmax*dt and smoothed with the previous one (prev (4,) is updated).
    Strain control: each wall moves inward at rate * len0 / 2 [m/s] (rate > 0 compresses).
    """
    (mode, s_from, s_to, _, _, rate, len0, ratio, wall_mass, g_held, thickness, gain,
     smoothing, vmax) = servo
    if mode[1] == 2:
        _servo_tied(walls, wF, wK, s_from[1] + (s_to[1] - s_from[1]) * ramp_t, len0, prev,
                    thickness, gain, smoothing, vmax, dt, ratio)
        return
    if mode[1] == 3:
        _dead_load(walls, wF, g_held, wall_mass, len0, prev, dt, ratio)
        return
    for axis in range(2):
        other = 1 - axis
        area = (walls[2 * other + 1] - walls[2 * other]) * thickness
        for side in range(2):
            wi = 2 * axis + side
            if mode[axis] == 0:
                target = (s_from[axis] + (s_to[axis] - s_from[axis]) * ramp_t) * area
                if wK[wi] > 0.0:
                    d = gain * (target - wF[wi]) / wK[wi]
                else:
                    d = vmax * dt
                lim = vmax * dt
                if d > lim:
                    d = lim
                elif d < -lim:
                    d = -lim
                d = smoothing * d + (1.0 - smoothing) * prev[wi]
            else:
                d = 0.5 * rate[axis] * len0[axis] * dt
            prev[wi] = d
            if side == 0:
                walls[wi] += d
            else:
                walls[wi] -= d


@njit(**FAST)
def _servo_tied(walls, wF, wK, c_target, len0, prev, thickness, gain, smoothing, vmax, dt,
                ratio):
    """One step of the tied control: the proportional strain path d eps2 = R d eps1 (R =
    ``ratio`` < 0) with its conjugate stress c = s1 + R s2 held at ``c_target`` [Pa].

    The tie: each y wall moves inward by d, each x wall by k d with k = R W0 / H0 (len0 =
    (W0, H0), the reference lengths of the engineering strains), so dU2 = k dU1 and
    d eps2 = 2 k d / W0 = R (2 d / H0) = R d eps1 at every step (and G below is conjugate to
    U1 exactly: F1 dU1 + F2 dU2 = (F1 + k F2) dU1).
    The servo acts on the generalized force G = F1 + R (W/H) F2 = W t c (F1, F2: the mean
    compressive forces on the two y walls and on the two x walls; W, H the current box): d is
    gain (G_target - G) / K_G, G_target = W t c_target, clipped to vmax dt and smoothed with
    the previous d, as the stress servo does.  K_G = dG/dd with the disks held still: each
    wall's force rises by its contact stiffness times its inward move, so dF1 = k1 d and
    dF2 = k2 k d (k1, k2 the mean contact stiffness of the y walls and of the x walls), and
    K_G = k1 + R (W/H) k k2 = k1 + R^2 (W/H) (W0/H0) k2 (= k1 + R^2 (W/H)^2 k2 at the
    reference shape); the geometric change of R W/H with d is of order F/W, negligible beside
    the contact stiffnesses.  Like the stress servo's, this stiffness is that of the walls'
    contacts alone, an upper bound of the specimen's, so the servo never overshoots."""
    w = walls[1] - walls[0]
    h = walls[3] - walls[2]
    a = ratio * w / h
    g = generalized_force(0.5 * (wF[2] + wF[3]), 0.5 * (wF[0] + wF[1]), a)
    err = c_target * w * thickness - g
    k = ratio * len0[0] / len0[1]
    kg = 0.5 * (wK[2] + wK[3]) + a * k * 0.5 * (wK[0] + wK[1])
    lim = vmax * dt
    if kg > 0.0:
        d = gain * err / kg
    else:
        d = lim if err > 0.0 else -lim     # no wall contact: move towards the target
    if d > lim:
        d = lim
    elif d < -lim:
        d = -lim
    d = smoothing * d + (1.0 - smoothing) * prev[2]
    _move_tied(walls, prev, d, k)


@njit(**FAST)
def _dead_load(walls, wF, g_held, m_g, len0, prev, dt, ratio):
    """One step of the tied walls under a dead load (``walls.dead_load``): the platens'
    shortening U1 (each y wall inward by U1 / 2, each x wall by k U1 / 2, k = R W0 / H0) with
    generalized mass m_g [kg] under the held generalized force g_held [N] against the sample's
    G = F1 + k F2 (the walls' forces of this step), by the disks' leapfrog:
    U1'(n+1/2) = U1'(n-1/2) + dt (g_held - G) / m_g, U1(n+1) = U1(n) + dt U1'(n+1/2).  ``prev``
    holds the walls' moves of the last step, so the y walls' prev[2] = U1'(n-1/2) dt / 2: the
    velocity needs no other memory, and a state saved under this control continues it."""
    k = ratio * len0[0] / len0[1]
    g = generalized_force(0.5 * (wF[2] + wF[3]), 0.5 * (wF[0] + wF[1]), k)
    d = prev[2] + 0.5 * dt * dt * (g_held - g) / m_g
    _move_tied(walls, prev, d, k)


@njit(**FAST)
def _move_tied(walls, prev, d, k):
    """The tied walls' move of a step: each y wall inward by d [m], each x wall by k d (the tie,
    k = R W0 / H0); ``prev`` records the moves (the servo's and the dead load's memory)."""
    dx = k * d
    prev[0] = dx
    prev[1] = dx
    prev[2] = d
    prev[3] = d
    walls[0] += dx
    walls[1] -= dx
    walls[2] += d
    walls[3] -= d


@njit(**FAST)
def generalized_force(f1, f2, k):
    """G = F1 + k F2 [N]: the generalized force of the tied walls, F1 and F2 the mean compressive
    forces on the two y walls and on the two x walls [N].  With k = R W0 / H0 (the tie, each x
    wall moving k times as far as each y wall) G is conjugate to the platens' shortening U1,
    F1 dU1 + F2 dU2 = G dU1 exactly (``_dead_load``, ``dem.walls.generalized_force``, the dead
    load's stress error in ``dem.burst``); with k = R W / H it is W t c, c = s1 + R s2 the
    stress the tied servo holds (``_servo_tied``).  The one place the sum is written: the
    kernels and the Python side get the same bits from it (x 0.5 of a sum, as the callers
    give F1 and F2, is exact, so k 0.5 (a + b) and k (0.5 (a + b)) are the same number)."""
    return f1 + k * f2
