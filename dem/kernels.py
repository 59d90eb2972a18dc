"""Numba kernels: every per-particle / per-contact loop of the DEM lives here.

Kernels take only arrays and scalars.  Conventions (2D, thickness t):
  x (N,2) positions [m], v (N,2) velocities [m/s], w (N,) spins [rad/s],
  r (N,) radii [m], m (N,) masses [kg], inertia (N,) [kg m^2].
  Pair list: pi, pj (P,) int32 with pi < pj, sorted by (pi, pj); ft (P,) tangential
  force history [N] expressed in the contact frame (t = z x n), which in 2D *is*
  the history rotated with the contact.
  Force convention: fpx/fpy (P,) force exerted on pi by pj.  n = (x_j - x_i)/|.|.
  Walls: walls (4,) = [x_left, x_right, y_bottom, y_top] [m]; frictionless.

Determinism: forces are computed per contact in parallel (no reduction) and
gathered per particle in a fixed order (the incidence list), so results do not
depend on the number of threads.
"""
import math

import numpy as np
from numba import njit, prange


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
def carry_history(old_pi, old_pj, old_ft, new_pi, new_pj, n):
    """Tangential history of the new pair list, copied from the old one for pairs in both."""
    off = row_offsets(old_pi, n)
    ft = np.zeros(new_pi.shape[0])
    for k in prange(new_pi.shape[0]):
        i = new_pi[k]
        j = new_pj[k]
        for a in range(off[i], off[i + 1]):
            if old_pj[a] == j:
                ft[k] = old_ft[a]
                break
    return ft


@njit(cache=True)
def incidence(pi, pj, n):
    """Per-particle list of incident pairs: entry e = 2k + side (side 1: particle is pj[k]).

    Entries are in increasing k for each particle so the force gather has a fixed order.
    """
    off = np.zeros(n + 1, np.int64)
    for k in range(pi.shape[0]):
        off[pi[k] + 1] += 1
        off[pj[k] + 1] += 1
    for i in range(n):
        off[i + 1] += off[i]
    fill = off[:-1].copy()
    ent = np.empty(2 * pi.shape[0], np.int64)
    for k in range(pi.shape[0]):
        ent[fill[pi[k]]] = 2 * k
        fill[pi[k]] += 1
        ent[fill[pj[k]]] = 2 * k + 1
        fill[pj[k]] += 1
    return off, ent


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
@njit(cache=True, parallel=True)
def pair_forces(x, v, w, r, m, pi, pj, ft, fpx, fpy, kn, kt, mu, cap_on, beta, dt):
    """Linear spring contact law with incremental tangential spring and Coulomb cap.

    fn = kn * overlap (+ optional normal dashpot, beta = fraction of critical damping),
    no tension (fn >= 0); ft += kt * (relative tangential velocity) * dt, |ft| <= mu fn
    when cap_on (cap_on = 0 means sliding prevented: the 'elastic' probes).
    Writes the force on pi by pj into fpx, fpy and the new history into ft.
    """
    for k in prange(pi.shape[0]):
        i = pi[k]
        j = pj[k]
        dx = x[j, 0] - x[i, 0]
        dy = x[j, 1] - x[i, 1]
        d2 = dx * dx + dy * dy
        rs = r[i] + r[j]
        if d2 >= rs * rs:
            # contact open: history is lost (cohesionless)
            ft[k] = 0.0
            fpx[k] = 0.0
            fpy[k] = 0.0
            continue
        d = math.sqrt(d2)
        nx = dx / d
        ny = dy / d
        tx = -ny
        ty = nx
        dvx = v[j, 0] - v[i, 0]
        dvy = v[j, 1] - v[i, 1]
        fn = kn * (rs - d)
        if beta > 0.0:
            meff = m[i] * m[j] / (m[i] + m[j])
            fn -= 2.0 * beta * math.sqrt(kn * meff) * (dvx * nx + dvy * ny)
            if fn < 0.0:
                fn = 0.0
        vt = dvx * tx + dvy * ty - (w[i] * r[i] + w[j] * r[j])
        f_t = ft[k] + kt * vt * dt
        if cap_on:
            lim = mu * fn
            if f_t > lim:
                f_t = lim
            elif f_t < -lim:
                f_t = -lim
        ft[k] = f_t
        fpx[k] = -fn * nx + f_t * tx
        fpy[k] = -fn * ny + f_t * ty


@njit(cache=True)
def wall_forces(x, v, r, m, walls, cand_off, cand, fext, kn, beta, wF, wK):
    """Frictionless linear walls.  Resets fext of candidates, then adds wall forces.

    wF (4,) receives the compressive force on each wall [N], wK (4,) the sum of the
    contact stiffnesses of each wall [N/m] (used by the servo).
    """
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


@njit(cache=True, parallel=True)
def integrate(x, v, w, theta, r, m, inertia, inc_off, inc_ent, fpx, fpy, ft, fext, fnet,
              x_ref, disp2, damping, dt):
    """Gather contact forces per particle (fixed order), Cundall damping, leapfrog update.

    Cundall non-viscous damping per component: F <- F - lambda |F| sign(v).
    fnet (N,3) receives the undamped resultant (fx, fy, torque); disp2 (N,) the squared
    displacement since the last neighbour-list rebuild.
    """
    for p in prange(x.shape[0]):
        fx = fext[p, 0]
        fy = fext[p, 1]
        tq = 0.0
        for a in range(inc_off[p], inc_off[p + 1]):
            e = inc_ent[a]
            k = e >> 1
            # branchless: the side bit is random, a branch would mispredict half the time
            sg = 1.0 - 2.0 * (e & 1)
            fx += sg * fpx[k]
            fy += sg * fpy[k]
            tq += ft[k]
        tq *= r[p]
        fnet[p, 0] = fx
        fnet[p, 1] = fy
        fnet[p, 2] = tq
        if damping > 0.0:
            fx -= damping * abs(fx) * np.sign(v[p, 0])
            fy -= damping * abs(fy) * np.sign(v[p, 1])
            tq -= damping * abs(tq) * np.sign(w[p])
        v[p, 0] += fx / m[p] * dt
        v[p, 1] += fy / m[p] * dt
        w[p] += tq / inertia[p] * dt
        x[p, 0] += v[p, 0] * dt
        x[p, 1] += v[p, 1] * dt
        theta[p] += w[p] * dt
        ddx = x[p, 0] - x_ref[p, 0]
        ddy = x[p, 1] - x_ref[p, 1]
        disp2[p] = ddx * ddx + ddy * ddy


# --------------------------------------------------------------------------------------
# Wall control (YADE TriaxialStressController-like servo)
# --------------------------------------------------------------------------------------
@njit(cache=True)
def servo_walls(walls, wF, wK, mode, s_from, s_to, ramp_t, rate, len0, prev, thickness,
                gain, smoothing, vmax, dt):
    """Move the walls for one step.

    mode (2,): per axis (0 = x walls, 1 = y walls) 0 = stress control, 1 = strain rate.
    Stress target = s_from + (s_to - s_from) * ramp_t (compression positive) [Pa].
    Stress control: inward displacement gain * (F_target - F) / sum(k_contacts), clipped to
    vmax*dt and smoothed with the previous one (prev (4,) is updated).
    Strain control: each wall moves inward at rate * len0 / 2 [m/s] (rate > 0 compresses).
    """
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


# --------------------------------------------------------------------------------------
# One thread: contact law, gather and integration fused in two passes
# --------------------------------------------------------------------------------------
@njit(cache=True)
def forces_and_integrate_serial(x, v, w, theta, r, m, inertia, pi, pj, ft, fext, fnet,
                                x_ref, disp2, kn, kt, mu, cap_on, beta, damping, dt):
    """One time step of ``pair_forces`` + ``integrate`` on one thread, bit-identical to them.

    The pair loop scatters each contact force straight into fnet (N,3) instead of storing it
    per pair and gathering it through the incidence list: for every particle the additions
    come in increasing pair index, the order of the incidence list, and a - b equals
    a + (-1.0) b exactly, so the sums are the same to the bit.  It saves the per-pair force
    arrays and the random reads of the gather.  ``wall_forces`` must have filled fext.
    Returns the largest squared displacement since the last rebuild [m^2].
    """
    n = x.shape[0]
    for p in range(n):
        fnet[p, 0] = fext[p, 0]
        fnet[p, 1] = fext[p, 1]
        fnet[p, 2] = 0.0
    for k in range(pi.shape[0]):
        i = pi[k]
        j = pj[k]
        dx = x[j, 0] - x[i, 0]
        dy = x[j, 1] - x[i, 1]
        d2 = dx * dx + dy * dy
        rs = r[i] + r[j]
        if d2 >= rs * rs:
            # contact open: history is lost (cohesionless); a zero force adds nothing
            ft[k] = 0.0
            continue
        d = math.sqrt(d2)
        nx = dx / d
        ny = dy / d
        tx = -ny
        ty = nx
        dvx = v[j, 0] - v[i, 0]
        dvy = v[j, 1] - v[i, 1]
        fn = kn * (rs - d)
        if beta > 0.0:
            meff = m[i] * m[j] / (m[i] + m[j])
            fn -= 2.0 * beta * math.sqrt(kn * meff) * (dvx * nx + dvy * ny)
            if fn < 0.0:
                fn = 0.0
        vt = dvx * tx + dvy * ty - (w[i] * r[i] + w[j] * r[j])
        f_t = ft[k] + kt * vt * dt
        if cap_on:
            lim = mu * fn
            if f_t > lim:
                f_t = lim
            elif f_t < -lim:
                f_t = -lim
        ft[k] = f_t
        fx = -fn * nx + f_t * tx
        fy = -fn * ny + f_t * ty
        fnet[i, 0] += fx
        fnet[i, 1] += fy
        fnet[i, 2] += f_t
        fnet[j, 0] -= fx
        fnet[j, 1] -= fy
        fnet[j, 2] += f_t
    dmax = 0.0
    for p in range(n):
        fx = fnet[p, 0]
        fy = fnet[p, 1]
        tq = fnet[p, 2] * r[p]
        fnet[p, 2] = tq
        if damping > 0.0:
            fx -= damping * abs(fx) * np.sign(v[p, 0])
            fy -= damping * abs(fy) * np.sign(v[p, 1])
            tq -= damping * abs(tq) * np.sign(w[p])
        v[p, 0] += fx / m[p] * dt
        v[p, 1] += fy / m[p] * dt
        w[p] += tq / inertia[p] * dt
        x[p, 0] += v[p, 0] * dt
        x[p, 1] += v[p, 1] * dt
        theta[p] += w[p] * dt
        ddx = x[p, 0] - x_ref[p, 0]
        ddy = x[p, 1] - x_ref[p, 1]
        dd = ddx * ddx + ddy * ddy
        disp2[p] = dd
        if dd > dmax:
            dmax = dd
    return dmax


# --------------------------------------------------------------------------------------
# Driver: many steps in one call
# --------------------------------------------------------------------------------------
@njit(cache=True)
def advance(nsteps, x, v, w, theta, r, m, inertia, pi, pj, ft, fpx, fpy, inc_off, inc_ent,
            cand_off, cand, fext, fnet, x_ref, walls_ref, disp2, walls, prev, wF, wK,
            mode, s_from, s_to, ramp_start, ramp_len, rate, len0, step0,
            kn, kt, mu, cap_on, beta, damping, dt, thickness, gain, smoothing, vmax, half_skin,
            serial):
    """Run up to nsteps time steps; stop early when the neighbour list must be rebuilt.

    Returns the number of steps done.  step0 is the global step counter at entry (the
    stress ramp of the servo is a function of it, so a chunked run equals a single run).
    ``serial``: use the fused one-thread kernel (same results to the bit as the parallel
    kernels, which it would otherwise run on one thread with their scheduling overhead).
    """
    hs2 = half_skin * half_skin
    n = x.shape[0]
    done = 0
    dmax = 0.0
    for s in range(nsteps):
        if serial:
            wall_forces(x, v, r, m, walls, cand_off, cand, fext, kn, beta, wF, wK)
            dmax = forces_and_integrate_serial(x, v, w, theta, r, m, inertia, pi, pj, ft, fext,
                                               fnet, x_ref, disp2, kn, kt, mu, cap_on, beta,
                                               damping, dt)
        else:
            pair_forces(x, v, w, r, m, pi, pj, ft, fpx, fpy, kn, kt, mu, cap_on, beta, dt)
            wall_forces(x, v, r, m, walls, cand_off, cand, fext, kn, beta, wF, wK)
        gstep = step0 + s
        if ramp_len > 0:
            rt = (gstep - ramp_start + 1) / ramp_len
            rt = min(max(rt, 0.0), 1.0)
        else:
            rt = 1.0
        if not serial:
            integrate(x, v, w, theta, r, m, inertia, inc_off, inc_ent, fpx, fpy, ft, fext, fnet,
                      x_ref, disp2, damping, dt)
        servo_walls(walls, wF, wK, mode, s_from, s_to, rt, rate, len0, prev, thickness,
                    gain, smoothing, vmax, dt)
        done += 1
        rebuild = False
        for wi in range(4):
            if abs(walls[wi] - walls_ref[wi]) > half_skin:
                rebuild = True
        if serial:
            rebuild = rebuild or dmax > hs2
        elif not rebuild:
            for p in range(n):
                if disp2[p] > hs2:
                    rebuild = True
                    break
        if rebuild:
            break
    return done


# --------------------------------------------------------------------------------------
# Measurements at a given configuration (pure functions of the state)
# --------------------------------------------------------------------------------------
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
