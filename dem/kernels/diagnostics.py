"""Measurements at a given configuration (pure functions of the state): the contacts' elastic
energy, the contact snapshot, the per-particle stress, the net forces."""
import math

import numpy as np
from numba import njit


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
