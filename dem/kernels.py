"""Numba kernels: every per-particle / per-contact loop of the DEM lives here.

Kernels take only arrays and scalars.  Conventions (2D, thickness t):
  x (N,2) positions [m], v (N,2) velocities [m/s], w (N,) spins [rad/s],
  r (N,) radii [m], m (N,) masses [kg], inertia (N,) [kg m^2].
  Pair list: pi, pj (P,) int32 with pi < pj, sorted by (pi, pj); ft (P,) tangential
  force history [N] expressed in the contact frame (t = z x n), which in 2D *is*
  the history rotated with the contact; mr (P,) rolling-moment history [N m] (moment on
  pi; zero without rolling resistance).
  Force convention: force exerted on pi by pj.  n = (x_j - x_i)/|.|.
  Walls: walls (4,) = [x_left, x_right, y_bottom, y_top] [m]; frictionless.

Determinism: the disks are split into contiguous blocks, one per thread; every disk sums
its contact forces in increasing pair index whatever the split (``_block_step``), so
results do not depend on the number of threads, to the bit.

Speed (issue 11; ``bench/bench_dem.py``), with the arithmetic of every force unchanged to the
bit: indices into the per-disk arrays are unsigned in the step loops (numba then skips its
negative-index test: +23 % on one thread), the contact law is branch-free (+7 %), and the step
kernels use ``error_model="numpy"`` (no zero-division test; a contact at zero distance is
impossible with positive radii: +4 %); a block's pairs go through an L1 scratch in chunks
(gather, vectorized contact law, sums in pair order) and the leapfrog runs on flat views, both
vectorized (1.2-1.3x; ``_block_step``, tested against a plain one-loop step to the bit).
"""
import math

import numpy as np
from numba import njit, prange

U = np.uint64   # unsigned index: numba skips the negative-index wraparound test for it
FAST = dict(cache=True, error_model="numpy")   # the step kernels' compile options
CHUNK = 256     # pairs per chunk of _block_step's three passes (8 rows x 256 x 8 B = 16 kB)



# --------------------------------------------------------------------------------------
# Neighbour search (cell list -> pair list)
# --------------------------------------------------------------------------------------
@njit(cache=True)
def cell_sort(x, lo_x, lo_y, cell, ncx, ncy):
    """Counting sort of particles into square cells of side `cell` [m].

    Returns (cell_start (ncx*ncy+1,), cell_part (N,)) ; particles keep index order
    inside a cell so the pair list is reproducible.
    """
    n = x.shape[0]
    cid = np.empty(n, np.int64)
    counts = np.zeros(ncx * ncy + 1, np.int64)
    for p in range(n):
        cx = int((x[p, 0] - lo_x) / cell)
        cy = int((x[p, 1] - lo_y) / cell)
        cx = min(max(cx, 0), ncx - 1)
        cy = min(max(cy, 0), ncy - 1)
        cid[p] = cy * ncx + cx
        counts[cid[p] + 1] += 1
    for c in range(ncx * ncy):
        counts[c + 1] += counts[c]
    fill = counts[:-1].copy()
    part = np.empty(n, np.int64)
    for p in range(n):
        part[fill[cid[p]]] = p
        fill[cid[p]] += 1
    return counts, part, cid


@njit(cache=True)
def _neighbours_of(i, x, r, skin, start, part, cid, ncx, ncy, pi, pj, k, fill):
    """Scan the 3x3 cells around particle i for partners j > i within the skin. With
    ``fill`` the pairs are written from index k on; returns k plus the number found."""
    c = cid[i]
    cx = c % ncx
    cy = c // ncx
    for oy in range(-1, 2):
        yy = cy + oy
        if yy < 0 or yy >= ncy:
            continue
        for ox in range(-1, 2):
            xx = cx + ox
            if xx < 0 or xx >= ncx:
                continue
            cc = yy * ncx + xx
            for s in range(start[cc], start[cc + 1]):
                j = part[s]
                if j <= i:
                    continue
                dx = x[j, 0] - x[i, 0]
                dy = x[j, 1] - x[i, 1]
                rc = r[i] + r[j] + skin
                if dx * dx + dy * dy < rc * rc:
                    if fill:
                        pi[k] = i
                        pj[k] = j
                    k += 1
    return k


@njit(cache=True, parallel=True)
def build_pairs(x, r, skin, lo_x, lo_y, cell, ncx, ncy):
    """Pairs (i<j) whose gap is below `skin`: |x_i - x_j| < r_i + r_j + skin.

    Cell side must be >= 2 r_max + skin.  Returns pi, pj (int32), sorted by (i, j).
    Two passes over the same scan: count per particle, then fill at the prefix offsets.
    """
    n = x.shape[0]
    start, part, cid = cell_sort(x, lo_x, lo_y, cell, ncx, ncy)
    cnt = np.zeros(n + 1, np.int64)
    dummy = np.empty(0, np.int32)
    for i in prange(n):
        cnt[i + 1] = _neighbours_of(i, x, r, skin, start, part, cid, ncx, ncy, dummy, dummy, 0, False)
    for i in range(n):
        cnt[i + 1] += cnt[i]
    npairs = cnt[n]
    pi = np.empty(npairs, np.int32)
    pj = np.empty(npairs, np.int32)
    for i in prange(n):
        _neighbours_of(i, x, r, skin, start, part, cid, ncx, ncy, pi, pj, cnt[i], True)
        # insertion sort of this particle's segment by j (segments are short)
        for a in range(cnt[i] + 1, cnt[i + 1]):
            v = pj[a]
            b = a - 1
            while b >= cnt[i] and pj[b] > v:
                pj[b + 1] = pj[b]
                b -= 1
            pj[b + 1] = v
    return pi, pj


@njit(cache=True)
def row_offsets(pi, n):
    """CSR offsets (n+1,) of a pair list sorted by pi."""
    off = np.zeros(n + 1, np.int64)
    for k in range(pi.shape[0]):
        off[pi[k] + 1] += 1
    for i in range(n):
        off[i + 1] += off[i]
    return off


@njit(cache=True, parallel=True)
def carry_history(old_pi, old_pj, old_ft, old_mr, new_pi, new_pj, n):
    """Tangential and rolling histories (ft, mr) of the new pair list, copied from the old one
    for pairs in both (zero for new pairs)."""
    off = row_offsets(old_pi, n)
    ft = np.zeros(new_pi.shape[0])
    mr = np.zeros(new_pi.shape[0])
    for k in prange(new_pi.shape[0]):
        i = new_pi[k]
        j = new_pj[k]
        for a in range(off[i], off[i + 1]):
            if old_pj[a] == j:
                ft[k] = old_ft[a]
                mr[k] = old_mr[a]
                break
    return ft, mr


@njit(cache=True)
def wall_candidates(x, r, walls, skin):
    """Particles closer than r + skin to each wall.  Returns (off (5,), idx)."""
    n = x.shape[0]
    cnt = np.zeros(5, np.int64)
    tmp = np.empty((4, n), np.int64)
    for p in range(n):
        if x[p, 0] - walls[0] < r[p] + skin:
            tmp[0, cnt[1]] = p
            cnt[1] += 1
        if walls[1] - x[p, 0] < r[p] + skin:
            tmp[1, cnt[2]] = p
            cnt[2] += 1
        if x[p, 1] - walls[2] < r[p] + skin:
            tmp[2, cnt[3]] = p
            cnt[3] += 1
        if walls[3] - x[p, 1] < r[p] + skin:
            tmp[3, cnt[4]] = p
            cnt[4] += 1
    off = np.zeros(5, np.int64)
    for w in range(4):
        off[w + 1] = off[w] + cnt[w + 1]
    idx = np.empty(off[4], np.int64)
    for w in range(4):
        for a in range(cnt[w + 1]):
            idx[off[w] + a] = tmp[w, a]
    return off, idx


# --------------------------------------------------------------------------------------
# Contact law
# --------------------------------------------------------------------------------------
@njit(**FAST)
def _contact_law(dx, dy, rs, dvx, dvy, wr, ft_old, meff, kn, kt, mu, cap_on, beta, dt):
    """Linear spring contact law with incremental tangential spring and Coulomb cap, for one
    pair of disks i, j.  Scalars only: an array passed to a function called in a hot loop
    costs reference counting at every call (it halved the speed of the pair loop), scalars
    let the compiler inline it for free.  Branch-free: the forces of a pair that does not
    touch are computed and then zeroed (a quarter of the pairs of a dense sample are only
    within the skin, and a mispredicted branch cost more than the arithmetic).

    dx, dy = x_j - x_i [m]; rs = r_i + r_j [m]; dvx, dvy = v_j - v_i [m/s];
    wr = w_i r_i + w_j r_j [m/s]; ft_old: tangential history [N]; meff: reduced mass [kg]
    (used only with the normal dashpot).  fn = kn * overlap (+ dashpot, beta = fraction of
    critical damping), no tension (fn >= 0); ft += kt * (relative tangential velocity) * dt,
    |ft| <= mu fn when cap_on (cap_on = 0 means sliding prevented: the 'elastic' probes).
    Returns (touching, fx, fy, f_t, d_slip, d_dash): the force [N] on i by j and its
    tangential component, the new history (0 when the disks do not touch: cohesionless, the
    history is lost), and for the energy ledger (``dem.ledger``; unused values cost nothing,
    the compiler drops them) the energy [J] the step dissipates by sliding, (ft_old + f_t) / 2
    (f_trial - f_t) / kt (the step's mean force times the slip the cap takes out of its
    tangential displacement vt dt), and in the normal dashpot, its force times the step's
    normal approach -(v_n dt) (the half-step displacement the law integrates).
    """
    touch, nx, ny, fn = _normal_force(dx, dy, rs, dvx, dvy, meff, kn, beta)
    tx = -ny
    ty = nx
    vt = dvx * tx + dvy * ty - wr
    f_trial = ft_old + kt * vt * dt
    f_t = f_trial
    if cap_on:
        lim = mu * fn
        f_t = min(max(f_t, -lim), lim)
    fx = -fn * nx + f_t * tx
    fy = -fn * ny + f_t * ty
    # the force over the plastic increment is the step's mean (trapezoid): with f_t alone the
    # split of the contact work into stored and dissipated energy would be off by O(dt)
    # wherever mu fn varies during sliding (dem.ledger); 1/kt: hoisted out of the pair loop
    d_slip = 0.5 * (ft_old + f_t) * (f_trial - f_t) * (1.0 / kt)
    d_dash = 0.0
    if beta > 0.0:
        d_dash = (fn - kn * (rs - math.sqrt(dx * dx + dy * dy))) * -(dvx * nx + dvy * ny) * dt
    return (touch, fx if touch else 0.0, fy if touch else 0.0, f_t if touch else 0.0,
            d_slip if touch else 0.0, d_dash if touch else 0.0)


@njit(**FAST)
def _normal_force(dx, dy, rs, dvx, dvy, meff, kn, beta):
    """(touching, nx, ny, fn) of a pair: the unit normal from i to j and the normal force
    [N] (meaningless when not touching: the caller zeroes what it uses)."""
    d2 = dx * dx + dy * dy
    touch = d2 < rs * rs
    d = math.sqrt(d2)
    nx = dx / d
    ny = dy / d
    fn = kn * (rs - d)
    if beta > 0.0:
        fn -= 2.0 * beta * math.sqrt(kn * meff) * (dvx * nx + dvy * ny)
        fn = max(fn, 0.0)
    return touch, nx, ny, fn


@njit(**FAST)
def _rolling_moment(dx, dy, rs, dvx, dvy, meff, kn, beta, dw, mr_old, ri, rj, kr, mur,
                    cap_on, dt):
    """Elastic-plastic rolling resistance (Iwashita & Oda 1998; Ai et al. 2011 type C without
    the viscous part): the rolling moment on i [N m] after a step of relative rotation
    dw * dt, dw = w_i - w_j [rad/s]; stiffness k_r = kr R*^2 (kr = rolling_stiffness * kt
    [N/m]), capped at mu_r R* fn when cap_on, R* = r_i r_j / (r_i + r_j); 0 when the disks do
    not touch.  Disk j receives the opposite moment.  The normal force is the contact law's
    (``_normal_force``, same arguments).  Returns (M, d_roll): the moment and, for the energy
    ledger, the energy [J] the step dissipates by rolling plasticity, (M_old + M) / 2
    (M_trial - M) / k_r (0 below the cap; the step's mean moment, as ``_contact_law``'s
    sliding; unused values cost nothing)."""
    touch, _, _, fn = _normal_force(dx, dy, rs, dvx, dvy, meff, kn, beta)
    rstar = ri * rj / (ri + rj)
    m_trial = mr_old - kr * rstar * rstar * dw * dt
    m = m_trial
    if cap_on:
        lim = mur * rstar * fn
        m = min(max(m, -lim), lim)
    d_roll = 0.5 * (mr_old + m) * (m_trial - m) / (kr * rstar * rstar)
    return (m if touch else 0.0), (d_roll if touch else 0.0)


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
def servo_walls(walls, wF, wK, mode, s_from, s_to, ramp_t, rate, len0, prev, thickness,
                gain, smoothing, vmax, dt, ratio, wall_mass):
    """Move the walls for one step.

    mode (2,): per axis (0 = x walls, 1 = y walls) 0 = stress control, 1 = strain rate, or
    both 2 = tied (``_servo_tied``; ``ratio`` = R, used by it only), or both 3 = tied under a
    dead load (``_dead_load``: the held force s_to[1] [N], the walls' generalized mass
    ``wall_mass`` [kg]).
    Stress target = s_from + (s_to - s_from) * ramp_t (compression positive) [Pa].
    Stress control: inward displacement gain * (F_target - F) / sum(k_contacts), clipped to
    vmax*dt and smoothed with the previous one (prev (4,) is updated).
    Strain control: each wall moves inward at rate * len0 / 2 [m/s] (rate > 0 compresses).
    """
    if mode[1] == 2:
        _servo_tied(walls, wF, wK, s_from[1] + (s_to[1] - s_from[1]) * ramp_t, len0, prev,
                    thickness, gain, smoothing, vmax, dt, ratio)
        return
    if mode[1] == 3:
        _dead_load(walls, wF, s_to[1], wall_mass, len0, prev, dt, ratio)
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
    g = 0.5 * (wF[2] + wF[3]) + a * 0.5 * (wF[0] + wF[1])
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
def _dead_load(walls, wF, g_held, m_g, len0, prev, dt, ratio):
    """One step of the tied walls under a dead load (``walls.dead_load``): the platens'
    shortening U1 (each y wall inward by U1 / 2, each x wall by k U1 / 2, k = R W0 / H0) with
    generalized mass m_g [kg] under the held generalized force g_held [N] against the sample's
    G = F1 + k F2 (the walls' forces of this step), by the disks' leapfrog:
    U1'(n+1/2) = U1'(n-1/2) + dt (g_held - G) / m_g, U1(n+1) = U1(n) + dt U1'(n+1/2).  ``prev``
    holds the walls' moves of the last step, so the y walls' prev[2] = U1'(n-1/2) dt / 2: the
    velocity needs no other memory, and a state saved under this control continues it."""
    k = ratio * len0[0] / len0[1]
    g = 0.5 * (wF[2] + wF[3]) + k * 0.5 * (wF[0] + wF[1])
    d = prev[2] + 0.5 * dt * dt * (g_held - g) / m_g
    dx = k * d
    prev[0] = dx
    prev[1] = dx
    prev[2] = d
    prev[3] = d
    walls[0] += dx
    walls[1] -= dx
    walls[2] += d
    walls[3] -= d


# --------------------------------------------------------------------------------------
# Contact forces, their sum per disk and the integration, in blocks of disks
# --------------------------------------------------------------------------------------
@njit(cache=True)
def block_partition(pi, n, nblocks):
    """Split the disks into ``nblocks`` contiguous index ranges of about equal work (one unit
    per disk and per pair it heads).  Returns bounds (nblocks+1,) of disk indices and
    kbounds (nblocks+1,) of pair indices: block b owns disks [bounds[b], bounds[b+1]) and
    the pairs [kbounds[b], kbounds[b+1]) whose first disk it owns (pairs sorted by pi)."""
    off = row_offsets(pi, n)
    total = n + pi.shape[0]
    bounds = np.empty(nblocks + 1, np.int64)
    bounds[0] = 0
    p = 0
    for b in range(1, nblocks):
        target = (total * b) // nblocks
        while p < n and p + off[p] < target:
            p += 1
        bounds[b] = p
    bounds[nblocks] = n
    kbounds = np.empty(nblocks + 1, np.int64)
    for b in range(nblocks + 1):
        kbounds[b] = off[bounds[b]]
    return bounds, kbounds


@njit(cache=True)
def cross_pairs(pj, bounds, kbounds):
    """Pairs whose second disk lies in a later block than their first.  Returns cross_k
    (C,) their pair indices in increasing order, ci_off (nblocks+1,) the range of cross_k
    headed by each block, and cj_off (nblocks+1,), cj_idx (C,) the cross entries grouped by
    the block of their second disk, in increasing pair index inside each group."""
    nb = bounds.shape[0] - 1
    ci_off = np.zeros(nb + 1, np.int64)
    cj_cnt = np.zeros(nb + 1, np.int64)
    for b in range(nb):
        for k in range(kbounds[b], kbounds[b + 1]):
            if pj[k] >= bounds[b + 1]:
                ci_off[b + 1] += 1
                bj = b + 1
                while pj[k] >= bounds[bj + 1]:
                    bj += 1
                cj_cnt[bj + 1] += 1
    for b in range(nb):
        ci_off[b + 1] += ci_off[b]
        cj_cnt[b + 1] += cj_cnt[b]
    ncross = ci_off[nb]
    cross_k = np.empty(ncross, np.int64)
    cj_idx = np.empty(ncross, np.int64)
    fill = cj_cnt[:-1].copy()
    c = 0
    for b in range(nb):
        for k in range(kbounds[b], kbounds[b + 1]):
            if pj[k] >= bounds[b + 1]:
                cross_k[c] = k
                bj = b + 1
                while pj[k] >= bounds[bj + 1]:
                    bj += 1
                cj_idx[fill[bj]] = c
                fill[bj] += 1
                c += 1
    return cross_k, ci_off, cj_cnt, cj_idx


@njit(cache=True, parallel=True, error_model="numpy")
def cross_forces(cross_k, x, v, w, r, m, pi, pj, ft, mr, kn, kt, mu, cap_on, beta, kr, mur,
                 dt, cf, con):
    """Contact law of the cross pairs (between blocks), before the blocks run: cf (C,7)
    receives (fx, fy, f_t, rolling moment on i, and the step's dissipation by sliding, in the
    dashpot and by rolling plasticity [J] for the energy ledger), con (C,) whether the disks
    touch."""
    for c in prange(cross_k.shape[0]):
        k = cross_k[c]
        i = pi[k]
        j = pj[k]
        meff = m[i] * m[j] / (m[i] + m[j]) if beta > 0.0 else 0.0
        touch, fx, fy, f_t, d_slip, d_dash = _contact_law(
            x[j, 0] - x[i, 0], x[j, 1] - x[i, 1], r[i] + r[j], v[j, 0] - v[i, 0],
            v[j, 1] - v[i, 1], w[i] * r[i] + w[j] * r[j], ft[k], meff, kn, kt, mu, cap_on,
            beta, dt)
        ft[k] = f_t
        con[c] = touch
        cf[c, 0] = fx
        cf[c, 1] = fy
        cf[c, 2] = f_t
        cf[c, 3] = 0.0
        cf[c, 4] = d_slip
        cf[c, 5] = d_dash
        cf[c, 6] = 0.0
        if mur > 0.0:
            mk, d_roll = _rolling_moment(x[j, 0] - x[i, 0], x[j, 1] - x[i, 1], r[i] + r[j],
                                         v[j, 0] - v[i, 0], v[j, 1] - v[i, 1], meff, kn, beta,
                                         w[i] - w[j], mr[k], r[i], r[j], kr, mur, cap_on, dt)
            mr[k] = mk
            cf[c, 3] = mk
            cf[c, 6] = d_roll


@njit(**FAST)
def _block_step(b, bounds, kbounds, cross_k, ci_off, cj_off, cj_idx, cf, con,
                x, v, w, theta, r, m, inertia, pi, pj, ft, mr, fext, fnet, x_ref, disp2,
                kn, kt, mu, cap_on, beta, kr, mur, damping, dt, sc, led):
    """One time step of the disks of block b: contact forces summed into fnet (N,4) =
    (fx, fy, sum of tangential forces -> torque, rolling moments), Cundall damping, leapfrog.
    Returns the largest squared displacement since the last rebuild in the block [m^2].

    Each contact force is added straight into the net force of its two disks, in increasing
    pair index for every disk, starting from the wall force fext; a - b equals a + (-1) b
    exactly, so the sums do not depend on how the disks are split into blocks: results are
    the same to the bit for any number of blocks (threads).  The contributions of the cross
    pairs of earlier blocks come first (their pair indices are lower than any pair this block
    heads); those of the cross pairs this block heads come in their place.  A block writes
    only its own disks and reads others' positions only through cross pairs, computed
    before, so blocks run concurrently.  Rolling resistance (mur > 0) is a second pass over
    the same pairs, summing the moments into column 3 in the same order; without it neither
    that pass nor that column is touched, and the force loop carries no rolling code (it
    cost 15 % of its speed inside it).  sc (nblocks, 8, chunk): the block's scratch rows of
    the chunked contact law (``advance`` allocates it).

    led (6, N) or (6, 0): the energy ledger's per-disk sums (``dem.ledger``), off when empty
    (then the loops are the ones without it, the same code as before the ledger existed).
    Row 0 += the work of the grain contacts' forces and of their tangential forces' torque on
    the disk, F_c . dx + r sum(f_t) dtheta, with the centred displacement dx = (x(n+1) -
    x(n-1)) / 2 = dt (v(n-1/2) + v(n+1/2)) / 2 (the leapfrog's own: 1/2 m (v(n+1/2)^2 -
    v(n-1/2)^2) = (F + D) . dx exactly); row 5 += the rolling moments' work, M dtheta; row 1
    += the Cundall damping force's, D . dx; rows 2, 3, 4 += the step's dissipation by
    sliding, rolling plasticity and in the normal dashpot of the pairs the disk heads
    (``_contact_law``).  A disk's sums are its own whatever the split into blocks, so they too
    are the same for any number of threads.
    """
    rolling = mur > 0.0
    ledger = led.shape[1] > 0
    l_slip = led[2]
    l_dash = led[4]
    p0 = bounds[b]
    p1 = bounds[b + 1]
    for pp in range(p0, p1):
        p = U(pp)
        fnet[p, 0] = fext[p, 0]
        fnet[p, 1] = fext[p, 1]
        fnet[p, 2] = 0.0
        if rolling:
            fnet[p, 3] = 0.0
    for e in range(cj_off[b], cj_off[b + 1]):
        c = cj_idx[e]
        if con[c]:
            j = pj[cross_k[c]]
            fnet[j, 0] -= cf[c, 0]
            fnet[j, 1] -= cf[c, 1]
            fnet[j, 2] += cf[c, 2]
            if rolling:
                fnet[j, 3] -= cf[c, 3]
    # The pairs the block heads, in chunks of CHUNK pairs through the rows of sc[b] (in L1):
    # pass 0 gathers each pair's relative kinematics into contiguous rows, pass 1 runs the
    # contact law on them (no indirect access: the compiler vectorizes it, divisions and
    # square roots included), pass 2 adds the forces to the disks in increasing pair index.
    # The operations of every force are the same as in one loop, so are their bits.
    S = sc[b]
    ch = sc.shape[2]
    c = ci_off[b]
    for k0 in range(kbounds[b], kbounds[b + 1], ch):
        nk = min(ch, kbounds[b + 1] - k0)
        for q in range(nk):
            k = U(k0 + q)
            i = U(pi[k])
            j = U(pj[k])
            S[0, q] = x[j, 0] - x[i, 0]
            S[1, q] = x[j, 1] - x[i, 1]
            S[2, q] = r[i] + r[j]
            S[3, q] = v[j, 0] - v[i, 0]
            S[4, q] = v[j, 1] - v[i, 1]
            S[5, q] = w[i] * r[i] + w[j] * r[j]
            S[6, q] = ft[k]
            S[7, q] = m[i] * m[j] / (m[i] + m[j]) if beta > 0.0 else 0.0
        if ledger and beta > 0.0:   # the same law, its dissipations kept in rows it consumed
            for q in range(nk):
                _, fx, fy, f_t, d_slip, d_dash = _contact_law(
                    S[0, q], S[1, q], S[2, q], S[3, q], S[4, q], S[5, q], S[6, q], S[7, q],
                    kn, kt, mu, cap_on, beta, dt)
                S[0, q] = fx
                S[1, q] = fy
                S[2, q] = f_t
                S[3, q] = d_slip
                S[4, q] = d_dash
        elif ledger:
            for q in range(nk):
                _, fx, fy, f_t, d_slip, _ = _contact_law(
                    S[0, q], S[1, q], S[2, q], S[3, q], S[4, q], S[5, q], S[6, q], S[7, q],
                    kn, kt, mu, cap_on, beta, dt)
                S[0, q] = fx
                S[1, q] = fy
                S[2, q] = f_t
                S[3, q] = d_slip
        else:
            for q in range(nk):
                _, fx, fy, f_t, _, _ = _contact_law(S[0, q], S[1, q], S[2, q], S[3, q],
                                                    S[4, q], S[5, q], S[6, q], S[7, q], kn, kt,
                                                    mu, cap_on, beta, dt)
                S[0, q] = fx
                S[1, q] = fy
                S[2, q] = f_t
        for q in range(nk):
            k = U(k0 + q)
            i = U(pi[k])
            j = U(pj[k])
            if pj[k] >= p1:
                # cross pair: force computed before (cross_forces, which also updated its
                # history); this block adds the share of its disk i
                if con[c]:
                    fnet[i, 0] += cf[c, 0]
                    fnet[i, 1] += cf[c, 1]
                    fnet[i, 2] += cf[c, 2]
                    if ledger:
                        l_slip[i] += cf[c, 4]
                        l_dash[i] += cf[c, 5]
                c += 1
                continue
            fx = S[0, q]
            fy = S[1, q]
            f_t = S[2, q]
            ft[k] = f_t
            fnet[i, 0] += fx
            fnet[i, 1] += fy
            fnet[i, 2] += f_t
            fnet[j, 0] -= fx
            fnet[j, 1] -= fy
            fnet[j, 2] += f_t
            if ledger:
                # most contacts do not slide: a well-predicted branch spares the sum's store
                if S[3, q] != 0.0:
                    l_slip[i] += S[3, q]
                if beta > 0.0:
                    l_dash[i] += S[4, q]
    if rolling:
        c = ci_off[b]
        for kk in range(kbounds[b], kbounds[b + 1]):
            k = U(kk)
            i = U(pi[k])
            j = U(pj[k])
            if pj[k] >= p1:
                if con[c]:
                    fnet[i, 3] += cf[c, 3]
                    if ledger:
                        led[3, i] += cf[c, 6]
                c += 1
                continue
            meff = m[i] * m[j] / (m[i] + m[j]) if beta > 0.0 else 0.0
            mk, d_roll = _rolling_moment(x[j, 0] - x[i, 0], x[j, 1] - x[i, 1], r[i] + r[j],
                                         v[j, 0] - v[i, 0], v[j, 1] - v[i, 1], meff, kn, beta,
                                         w[i] - w[j], mr[k], r[i], r[j], kr, mur, cap_on, dt)
            mr[k] = mk
            fnet[i, 3] += mk
            fnet[j, 3] -= mk
            if ledger:
                led[3, i] += d_roll
    # The leapfrog on flat views with the new v, w, x kept in locals: written so, the loop
    # vectorizes (measured 7.1 -> 4.7 ns a disk; the same operations, the same bits)
    ff = fnet.reshape(-1)
    vf = v.reshape(-1)
    xf = x.reshape(-1)
    xr = x_ref.reshape(-1)
    if ledger:
        _leapfrog_ledger(p0, p1, ff, fext.reshape(-1), vf, xf, xr, w, theta, r, m, inertia,
                         disp2, rolling, damping, dt, led[0], led[1], led[5])
    else:
        for pp in range(p0, p1):
            _leapfrog_disk(U(pp), ff, vf, xf, xr, w, theta, r, m, inertia, disp2, rolling,
                           damping, dt)
    dmax = 0.0
    for pp in range(p0, p1):
        dd = disp2[U(pp)]
        if dd > dmax:
            dmax = dd
    return dmax


@njit(**FAST)
def _leapfrog_ledger(p0, p1, ff, fe, vf, xf, xr, w, theta, r, m, inertia, disp2, rolling,
                     damping, dt, w_contact, w_damp, w_roll):
    """The leapfrog of ``_block_step`` (``_leapfrog_disk``: the same operations, so the same
    bits) with the ledger's per-disk works (rows 0, 1 and 5 of ``led``, see there): the centred
    displacement dt (v(n-1/2) + v(n+1/2)) / 2 of each disk times the force of its grain contacts
    (the net force less the wall's, fe = fext flat) with their tangential forces' torque, times
    the damping force, and (``rolling``) times the rolling moments.  Two loops, with and without
    rolling resistance: a branch on it inside the loop kept the compiler from vectorizing it
    (measured: the ledger's cost 1.25 -> 1.05 of a step at 12,000 disks)."""
    if rolling:
        for pp in range(p0, p1):
            p = U(pp)
            ht = _ledger_disk(p, ff, fe, vf, xf, xr, w, theta, r, m, inertia, disp2, True,
                              damping, dt, w_contact, w_damp)
            w_roll[p] += ff[U(4) * p + U(3)] * ht
    else:
        for pp in range(p0, p1):
            _ledger_disk(U(pp), ff, fe, vf, xf, xr, w, theta, r, m, inertia, disp2, False,
                         damping, dt, w_contact, w_damp)


@njit(**FAST)
def _ledger_disk(p, ff, fe, vf, xf, xr, w, theta, r, m, inertia, disp2, rolling, damping, dt,
                 w_contact, w_damp):
    """``_leapfrog_disk`` of disk p and its works (``_leapfrog_ledger``); returns its centred
    rotation dt (w(n-1/2) + w(n+1/2)) / 2."""
    fx, fy, tt, gx, gy, gt, vx, vy, wm, v0, v1, wp = _leapfrog_disk(
        p, ff, vf, xf, xr, w, theta, r, m, inertia, disp2, rolling, damping, dt)
    h = 0.5 * dt
    hx = h * (vx + v0)
    hy = h * (vy + v1)
    ht = h * (wm + wp)
    p2 = p + p
    w_contact[p] += (fx - fe[p2]) * hx + (fy - fe[p2 + U(1)]) * hy + tt * ht
    w_damp[p] -= gx * hx + gy * hy + gt * ht
    return ht


@njit(**FAST)
def _leapfrog_disk(p, ff, vf, xf, xr, w, theta, r, m, inertia, disp2, rolling, damping, dt):
    """The leapfrog of disk p (flat views of fnet, v, x and x_ref; ``_block_step``): its torque,
    Cundall's non-viscous damping per component (F <- F - lambda |F| sign(v)), the new
    velocities and positions, its squared displacement since the last rebuild.  Returns the
    step's terms the ledger needs (``_leapfrog_ledger``; unused values cost nothing): the force,
    the tangential forces' torque, the damping force, the velocities before and after."""
    p2 = p + p
    p4 = p2 + p2
    fx = ff[p4]
    fy = ff[p4 + U(1)]
    tt = ff[p4 + U(2)] * r[p]
    tq = tt
    if rolling:
        tq += ff[p4 + U(3)]
    ff[p4 + U(2)] = tq
    vx = vf[p2]
    vy = vf[p2 + U(1)]
    wm = w[p]
    gx = 0.0
    gy = 0.0
    gt = 0.0
    if damping > 0.0:
        gx = damping * abs(fx) * np.sign(vx)
        gy = damping * abs(fy) * np.sign(vy)
        gt = damping * abs(tq) * np.sign(wm)
    v0 = vx + (fx - gx) / m[p] * dt
    v1 = vy + (fy - gy) / m[p] * dt
    wp = wm + (tq - gt) / inertia[p] * dt
    vf[p2] = v0
    vf[p2 + U(1)] = v1
    w[p] = wp
    x0 = xf[p2] + v0 * dt
    x1 = xf[p2 + U(1)] + v1 * dt
    xf[p2] = x0
    xf[p2 + U(1)] = x1
    theta[p] += wp * dt
    ddx = x0 - xr[p2]
    ddy = x1 - xr[p2 + U(1)]
    disp2[p] = ddx * ddx + ddy * ddy
    return fx, fy, tt, gx, gy, gt, vx, vy, wm, v0, v1, wp


@njit(cache=True, parallel=True, error_model="numpy")
def blocks_step(bounds, kbounds, cross_k, ci_off, cj_off, cj_idx, cf, con,
                x, v, w, theta, r, m, inertia, pi, pj, ft, mr, fext, fnet, x_ref, disp2,
                kn, kt, mu, cap_on, beta, kr, mur, damping, dt, dmax, sc, led):
    """``_block_step`` of every block, blocks spread over threads; dmax (nblocks,)."""
    for b in prange(bounds.shape[0] - 1):
        dmax[b] = _block_step(b, bounds, kbounds, cross_k, ci_off, cj_off, cj_idx, cf, con,
                              x, v, w, theta, r, m, inertia, pi, pj, ft, mr, fext, fnet, x_ref,
                              disp2, kn, kt, mu, cap_on, beta, kr, mur, damping, dt, sc, led)


# --------------------------------------------------------------------------------------
# Driver: many steps in one call
# --------------------------------------------------------------------------------------
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
def advance(nsteps, x, v, w, theta, r, m, inertia, pi, pj, ft, mr, cand_off, cand, fext, fnet,
            x_ref, walls_ref, disp2, walls, prev, wF, wK,
            mode, s_from, s_to, ramp_start, ramp_len, rate, len0, step0,
            kn, kt, mu, cap_on, beta, kr, mur, damping, dt, thickness, gain, smoothing, vmax,
            half_skin, nblocks, ratio, wall_mass, lsc, led, F0):
    """Run up to nsteps time steps; stop early when the neighbour list must be rebuilt.

    Returns the number of steps done.  step0 is the global step counter at entry (the
    stress ramp of the servo is a function of it, so a chunked run equals a single run).
    ``nblocks``: blocks of disks run concurrently (one per thread; results do not depend on
    it, see ``_block_step``).  One block is the plain serial loop.  Rolling resistance:
    kr = rolling_stiffness * kt [N/m], mur = current rolling friction (0 = off); fnet (N,4).
    ``ratio``: R of the tied controls (modes 2, 3, ``servo_walls``), ``wall_mass`` the walls'
    generalized mass under a dead load (mode 3); unused by the other modes.

    The energy ledger (``dem.ledger``), off when ``lsc`` is empty: ``lsc`` (L_SIZE,) its scalar
    sums (the L_* slots), ``led`` (6, N) the per-disk sums of ``_block_step``, ``F0`` (N, 3)
    receives at the ledger's first step the net force and torque of every disk (F_p(0) of
    Eq. 14's unbalanced term).  The walls' centred displacement is dU_w(n) = (d(n-1/2) +
    d(n+1/2)) / 2 with d the servo's inward move of a step (``prev`` before and after it);
    each wall contact's work uses its force of the step and the disk's centred displacement.
    The ledger only reads the trajectory: the same bits with it as without it.
    """
    hs2 = half_skin * half_skin
    n = x.shape[0]
    bounds, kbounds = block_partition(pi, n, nblocks)
    cross_k, ci_off, cj_off, cj_idx = cross_pairs(pj, bounds, kbounds)
    cf = np.empty((cross_k.shape[0], 7))
    con = np.empty(cross_k.shape[0], np.bool_)
    dmax = np.zeros(nblocks)
    sc = np.empty((nblocks, 8, CHUNK))    # pair scratch of each block (_block_step)
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
        servo_walls(walls, wF, wK, mode, s_from, s_to, rt, rate, len0, prev, thickness,
                    gain, smoothing, vmax, dt, ratio, wall_mass)
        if ledger:
            _ledger_walls(lsc, wF, pb, prev, fw, vc, cand_off, cand, v, dt,
                          s_to[1] if mode[1] == 3 else math.nan)
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


# --------------------------------------------------------------------------------------
# Measurements at a given configuration (pure functions of the state)
# --------------------------------------------------------------------------------------
@njit(cache=True)
def elastic_energy(x, v, w, r, walls, prev, pi, pj, ft, mr, kn, kt, kr, rolling, dt):
    """Elastic energy [J] stored in the contacts at the midpoint of the last step, the
    configuration the leapfrog's half-step kinetic energy goes with (``dem.ledger``): positions
    x - dt v / 2 (= (x(n) + x(n+1)) / 2), walls back by half their last move ``prev``, the
    tangential force and the rolling moment half a step on, f_t + kt v_t dt / 2 and
    M - k_r (w_i - w_j) dt / 2 (v_t as the next step's law takes it).  Returns (normal
    kn ov^2 / 2, tangential f_t^2 / 2 kt, rolling M^2 / 2 k_r R*^2 (``rolling`` only), walls
    kn ov^2 / 2) over the contacts that overlap at the midpoint.  With on-step energies the
    balance of the contact work would be off by f dx / 2, O(dt); at the midpoint it closes to
    O(dt^2) (the leapfrog's sum f(n) (d(n+1) - d(n-1)) / 2 of a linear spring is
    k d(N) d(N+1) / 2, and the midpoint's k ((d(N) + d(N+1)) / 2)^2 / 2 differs by
    k (d(N+1) - d(N))^2 / 8)."""
    en = 0.0
    et = 0.0
    er = 0.0
    ew = 0.0
    h = 0.5 * dt
    for k in range(pi.shape[0]):
        i = pi[k]
        j = pj[k]
        dx = (x[j, 0] - h * v[j, 0]) - (x[i, 0] - h * v[i, 0])
        dy = (x[j, 1] - h * v[j, 1]) - (x[i, 1] - h * v[i, 1])
        rs = r[i] + r[j]
        d2 = dx * dx + dy * dy
        if d2 >= rs * rs:
            continue
        ov = rs - math.sqrt(d2)
        en += 0.5 * kn * ov * ov
        ex = x[j, 0] - x[i, 0]
        ey = x[j, 1] - x[i, 1]
        e = math.sqrt(ex * ex + ey * ey)
        vt = (-(v[j, 0] - v[i, 0]) * ey + (v[j, 1] - v[i, 1]) * ex) / e - (w[i] * r[i] + w[j] * r[j])
        f_t = ft[k] + kt * vt * h
        et += 0.5 * f_t * f_t / kt
        if rolling:
            rstar = r[i] * r[j] / (r[i] + r[j])
            krr = kr * rstar * rstar
            mm = mr[k] - krr * (w[i] - w[j]) * h
            er += 0.5 * mm * mm / krr
    for wi in range(4):
        axis = wi // 2
        sgn = 1.0 if wi % 2 == 0 else -1.0
        wm = walls[wi] - sgn * 0.5 * prev[wi]
        for p in range(x.shape[0]):
            ov = r[p] - sgn * ((x[p, axis] - h * v[p, axis]) - wm)
            if ov > 0.0:
                ew += 0.5 * kn * ov * ov
    return en, et, er, ew


@njit(cache=True)
def contact_snapshot(x, r, pi, pj, ft, walls, kn):
    """Contacts at the current positions with the stored tangential history.

    Returns (ci, cj, fx, fy, fn) over pairs in contact (force on ci by cj, elastic part
    only) and (wp, wwall, wf) for wall contacts (particle, wall index, compressive force).
    """
    npair = pi.shape[0]
    keep = np.zeros(npair, np.bool_)
    nc = 0
    for k in range(npair):
        i = pi[k]
        j = pj[k]
        dx = x[j, 0] - x[i, 0]
        dy = x[j, 1] - x[i, 1]
        rs = r[i] + r[j]
        if dx * dx + dy * dy < rs * rs:
            keep[k] = True
            nc += 1
    ci = np.empty(nc, np.int64)
    cj = np.empty(nc, np.int64)
    fx = np.empty(nc)
    fy = np.empty(nc)
    fn = np.empty(nc)
    a = 0
    for k in range(npair):
        if keep[k]:
            i = pi[k]
            j = pj[k]
            dx = x[j, 0] - x[i, 0]
            dy = x[j, 1] - x[i, 1]
            d = math.sqrt(dx * dx + dy * dy)
            nx = dx / d
            ny = dy / d
            f_n = kn * (r[i] + r[j] - d)
            ci[a] = i
            cj[a] = j
            fx[a] = -f_n * nx - ft[k] * ny
            fy[a] = -f_n * ny + ft[k] * nx
            fn[a] = f_n
            a += 1
    n = x.shape[0]
    nw = 0
    for p in range(n):
        for wi in range(4):
            axis = wi // 2
            sgn = 1.0 if wi % 2 == 0 else -1.0
            if r[p] - sgn * (x[p, axis] - walls[wi]) > 0.0:
                nw += 1
    wp = np.empty(nw, np.int64)
    ww = np.empty(nw, np.int64)
    wf = np.empty(nw)
    a = 0
    for p in range(n):
        for wi in range(4):
            axis = wi // 2
            sgn = 1.0 if wi % 2 == 0 else -1.0
            ov = r[p] - sgn * (x[p, axis] - walls[wi])
            if ov > 0.0:
                wp[a] = p
                ww[a] = wi
                wf[a] = kn * ov
                a += 1
    return ci, cj, fx, fy, fn, wp, ww, wf


@njit(cache=True)
def particle_stress(x, r, ci, cj, fx, fy, wp, ww, wf):
    """Per-particle sum of f (x) (x_contact - x_p) [N m] (N,2,2), tension positive.

    Contact point for disks: on the line of centres at distance r_p from p.
    Summed over particles and divided by the volume this is the Love-Weber stress.
    """
    n = x.shape[0]
    s = np.zeros((n, 2, 2))
    for a in range(ci.shape[0]):
        i = ci[a]
        j = cj[a]
        dx = x[j, 0] - x[i, 0]
        dy = x[j, 1] - x[i, 1]
        d = math.sqrt(dx * dx + dy * dy)
        nx = dx / d
        ny = dy / d
        # on i: force (fx, fy) at r_i n ; on j: force -(fx, fy) at -r_j n
        s[i, 0, 0] += fx[a] * r[i] * nx
        s[i, 0, 1] += fx[a] * r[i] * ny
        s[i, 1, 0] += fy[a] * r[i] * nx
        s[i, 1, 1] += fy[a] * r[i] * ny
        s[j, 0, 0] += fx[a] * r[j] * nx
        s[j, 0, 1] += fx[a] * r[j] * ny
        s[j, 1, 0] += fy[a] * r[j] * nx
        s[j, 1, 1] += fy[a] * r[j] * ny
    for a in range(wp.shape[0]):
        p = wp[a]
        wi = ww[a]
        axis = wi // 2
        sgn = 1.0 if wi % 2 == 0 else -1.0
        # force sgn*f along axis applied at the contact point -sgn*r along axis
        s[p, axis, axis] += -(sgn * wf[a]) * sgn * r[p]
    return s


@njit(cache=True)
def net_forces(n, x, ci, cj, fx, fy, wp, ww, wf):
    """Resultant force (N,2) on each particle from a contact snapshot [N]."""
    f = np.zeros((n, 2))
    for a in range(ci.shape[0]):
        f[ci[a], 0] += fx[a]
        f[ci[a], 1] += fy[a]
        f[cj[a], 0] -= fx[a]
        f[cj[a], 1] -= fy[a]
    for a in range(wp.shape[0]):
        wi = ww[a]
        sgn = 1.0 if wi % 2 == 0 else -1.0
        f[wp[a], wi // 2] += sgn * wf[a]
    return f
