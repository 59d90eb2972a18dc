"""Many steps in one call (``advance``: wall forces, the step of the disks, the walls' control,
until the neighbour list must be rebuilt) with the energy ledger's scalar slots (``L_*``) and its
walls' share (``_ledger_walls``)."""
import math

import numpy as np
from numba import njit

from .common import FAST
from .step import (CHUNK, SCRATCH_ROWS, _block_step, block_partition, blocks_step, cross_forces,
                   cross_pairs)
from .walls import servo_walls, wall_forces


# The energy ledger's scalar slots (``advance``'s ``lsc``; ``dem.ledger`` reads them)
L_W_EXT = 0         # sum over steps and walls of F_w dU_w [J]: the walls' work on the sample
L_W_INT_WALL = 1    # sum over the wall contacts of f (dU_w - dx_p . inward) [J]
L_D_DASH_WALL = 2   # the wall contacts' dashpot dissipation [J]
L_DU = 3            # 3..6: the inward centred displacement of each wall since the start [m]
L_FW0 = 7           # 7..10: the wall forces F_w(0) of the first step [N]
L_STARTED = 11      # 1 once F_w(0) and the disks' F_p(0) are taken
L_STEPS = 12        # steps counted
L_SIZE = 13


@njit(**FAST)
def advance(nsteps, disks, pairs, ws, servo, law, step0, half_skin, nblocks, books):
    """Run up to nsteps time steps; stop early when the neighbour list must be rebuilt.

    Returns the number of steps done.  ``disks``, ``pairs``, ``ws``, ``servo``, ``law``: the
    disks' arrays, the pair list, the walls, their control and the contact law, each a tuple
    in the order of its record (``Disks``, ``PairList``, ``WallState``, ``Servo``, ``Law``;
    arrays read and written in place).  Plain tuples (``tuple(record)``, or built in that
    order as ``Simulation.run`` does): Numba types a named tuple at every call in Python
    (measured +9 us a call; a 300-disk step is 7 us), a plain one in C; the records also
    work, at that cost.
    step0 is the global step counter at entry (the stress ramp of the servo is a function of
    it, so a chunked run equals a single run).  ``half_skin``: half the skin of the pair list
    [m] (a disk or a wall that moved further asks for a rebuild).  ``nblocks``: blocks of
    disks run concurrently (one per thread; results do not depend on it, see
    ``_block_step``).  One block is the plain serial loop.  Rolling resistance: law.kr =
    rolling_stiffness * kt [N/m], law.mur = current rolling friction (0 = off).
    ``servo.ratio``: R of the tied controls (modes 2, 3, ``servo_walls``), ``wall_mass`` the
    walls' generalized mass and ``g_held`` the held generalized force [N] under a dead load
    (mode 3); unused by the other modes.

    The energy ledger (``dem.ledger``), ``books`` = (lsc, led, F0), off when ``lsc`` is empty:
    ``lsc`` (L_SIZE,) its scalar sums (the L_* slots), ``led`` (6, N) the per-disk sums of
    ``_block_step``, ``F0`` (N, 3) receives at the ledger's first step the net force and torque
    of every disk (F_p(0) of Eq. 14's unbalanced term).  The walls' centred displacement is
    dU_w(n) = (d(n-1/2) + d(n+1/2)) / 2 with d the servo's inward move of a step (``prev``
    before and after it); each wall contact's work uses its force of the step and the disk's
    centred displacement.  The ledger only reads the trajectory: the same bits with it as
    without it.
    """
    x, v, w, theta, r, m, inertia, fext, fnet, x_ref, disp2 = disks
    pi, pj, ft, mr, cand_off, cand = pairs
    walls, walls_ref, prev, wF, wK = ws
    mode, _, _, ramp_start, ramp_len, _, _, _, _, g_held, _, _, _, _ = servo
    kn, kt, mu, cap_on, beta, kr, mur, damping, dt = law
    lsc, led, F0 = books
    hs2 = half_skin * half_skin
    n = x.shape[0]
    bounds, kbounds = block_partition(pi, n, nblocks)
    cross_k, ci_off, cj_off, cj_idx = cross_pairs(pj, bounds, kbounds)
    cf = np.empty((cross_k.shape[0], 7))
    con = np.empty(cross_k.shape[0], np.bool_)
    dmax = np.zeros(nblocks)
    # each block's pair scratch (_block_step); zeros: without the dashpot its reduced-mass row
    # is never written, and the law then reads it without using it
    sc = np.zeros((nblocks, SCRATCH_ROWS * CHUNK))
    ledger = lsc.shape[0] > 0
    nc = cand_off[4] if ledger else 0
    fw = np.zeros((2, nc))                # each wall entry's force and dashpot part
    vc = np.zeros(nc)                     # its disk's velocity along the wall's axis, v(n-1/2)
    pb = np.zeros(4)                      # the walls' inward move of the last step, d(n-1/2)
    done = 0
    for s in range(nsteps):
        wall_forces(x, v, r, m, walls, cand_off, cand, fext, kn, beta, wF, wK, fw)
        if ledger:
            for wi in range(4):
                pb[wi] = prev[wi]
                for a in range(cand_off[wi], cand_off[wi + 1]):
                    vc[a] = v[cand[a], wi // 2]
        if nblocks == 1:
            dmax[0] = _block_step(0, bounds, kbounds, cross_k, ci_off, cj_off, cj_idx, cf, con,
                                  x, v, w, theta, r, m, inertia, pi, pj, ft, mr, fext, fnet,
                                  x_ref, disp2, kn, kt, mu, cap_on, beta, kr, mur, damping, dt, sc,
                                  led)
        else:
            cross_forces(cross_k, x, v, w, r, m, pi, pj, ft, mr, kn, kt, mu, cap_on, beta, kr,
                         mur, dt, cf, con)
            blocks_step(bounds, kbounds, cross_k, ci_off, cj_off, cj_idx, cf, con,
                        x, v, w, theta, r, m, inertia, pi, pj, ft, mr, fext, fnet, x_ref, disp2,
                        kn, kt, mu, cap_on, beta, kr, mur, damping, dt, dmax, sc, led)
        gstep = step0 + s
        if ramp_len > 0:
            rt = (gstep - ramp_start + 1) / ramp_len
            rt = min(max(rt, 0.0), 1.0)
        else:
            rt = 1.0
        servo_walls(walls, wF, wK, prev, servo, rt, dt)
        if ledger:
            _ledger_walls(lsc, wF, pb, prev, fw, vc, cand_off, cand, v, dt,
                          g_held if mode[1] == 3 else math.nan)
            if lsc[L_STARTED] == 0.0:
                for p in range(n):
                    F0[p, 0] = fnet[p, 0]
                    F0[p, 1] = fnet[p, 1]
                    F0[p, 2] = fnet[p, 2]
                for wi in range(4):
                    lsc[L_FW0 + wi] = wF[wi]
                lsc[L_STARTED] = 1.0
            lsc[L_STEPS] += 1.0
        done += 1
        rebuild = np.max(dmax) > hs2
        for wi in range(4):
            if abs(walls[wi] - walls_ref[wi]) > half_skin:
                rebuild = True
        if rebuild:
            break
    return done


@njit(**FAST)
def _ledger_walls(lsc, wF, pb, prev, fw, vc, cand_off, cand, v, dt, g_dead):
    """The walls' share of one step of the ledger (``advance``): the external work, and each
    wall contact's work f (dU_w - sgn dx_p) (the compression of the contact, sgn = +1 on the
    left and bottom walls, -1 on the others) with dx_p = dt (v(n-1/2) + v(n+1/2)) / 2 along the
    wall's axis; the dashpot part of its force times the half step's compression.  The external
    work is the walls' on the sample, F_w dU_w, or under a dead load (``g_dead`` its force,
    NaN otherwise) the dead load's, G_held dU1 with dU1 = dU_bottom + dU_top: the walls are then
    part of the system, their kinetic energy with the disks' (``dem.ledger``)."""
    if not math.isnan(g_dead):
        lsc[L_W_EXT] += g_dead * 0.5 * (pb[2] + prev[2] + pb[3] + prev[3])
    for wi in range(4):
        du = 0.5 * (pb[wi] + prev[wi])
        if math.isnan(g_dead):
            lsc[L_W_EXT] += wF[wi] * du
        lsc[L_DU + wi] += du
        axis = wi // 2
        sgn = 1.0 if wi % 2 == 0 else -1.0
        for a in range(cand_off[wi], cand_off[wi + 1]):
            f = fw[0, a]
            if f != 0.0:
                dxp = 0.5 * dt * (vc[a] + v[cand[a], axis])
                lsc[L_W_INT_WALL] += f * (du - sgn * dxp)
                if fw[1, a] != 0.0:
                    lsc[L_D_DASH_WALL] += fw[1, a] * (pb[wi] - sgn * vc[a] * dt)
