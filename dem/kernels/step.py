"""One time step of the disks, in blocks of disks: the partition into blocks (``block_partition``),
the pairs between blocks and their forces (``cross_pairs``, ``cross_forces``), the step of a
block (``_block_step``: contact forces summed in pair order, Cundall damping, leapfrog, the
ledger's per-disk sums) and of every block on the threads (``blocks_step``)."""
import numpy as np
from numba import njit, prange

from .common import FAST, U
from .contact import _contact_law, _rolling_moment
from .neighbours import row_offsets

CHUNK = 256     # pairs per chunk of _block_step's three passes (7 rows x 256 x 8 B = 14 kB)
# The rows of a block's scratch, flat: row k at k * CHUNK, a constant the compiler folds into
# the addresses (as a 2-D array's rows, their runtime stride cost registers the pair loops
# lacked: spilled base pointers reloaded at every pair).  The contact law's results overwrite
# the rows it consumed: fx in _DX, fy in _DY, f_t in _RS, and for the ledger d_slip in _DVX,
# d_dash in _DVY.
_DX, _DY, _RS, _DVX, _DVY, _WR, _MEFF = (k * CHUNK for k in range(7))
SCRATCH_ROWS = 7


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
    cost 15 % of its speed inside it).  sc (nblocks, SCRATCH_ROWS * CHUNK): the block's
    scratch rows of the chunked contact law (``advance`` allocates it).

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
    xf = x.reshape(-1)
    vf = v.reshape(-1)
    c = ci_off[b]
    for k0 in range(kbounds[b], kbounds[b + 1], CHUNK):
        nk = min(CHUNK, kbounds[b + 1] - k0)
        for q in range(nk):
            k = U(k0 + q)
            i = U(pi[k])
            j = U(pj[k])
            i2 = i + i
            j2 = j + j
            S[_DX + q] = xf[j2] - xf[i2]
            S[_DY + q] = xf[j2 + U(1)] - xf[i2 + U(1)]
            S[_RS + q] = r[i] + r[j]
            S[_DVX + q] = vf[j2] - vf[i2]
            S[_DVY + q] = vf[j2 + U(1)] - vf[i2 + U(1)]
            S[_WR + q] = w[i] * r[i] + w[j] * r[j]
        if beta > 0.0:      # its own loop: a branch inside the gather slows it
            for q in range(nk):
                k = U(k0 + q)
                i = U(pi[k])
                j = U(pj[k])
                S[_MEFF + q] = m[i] * m[j] / (m[i] + m[j])
        if ledger and beta > 0.0:   # the same law, its dissipations kept in rows it consumed
            for q in range(nk):
                _, fx, fy, f_t, d_slip, d_dash = _contact_law(
                    S[_DX + q], S[_DY + q], S[_RS + q], S[_DVX + q], S[_DVY + q], S[_WR + q],
                    ft[U(k0 + q)], S[_MEFF + q], kn, kt, mu, cap_on, beta, dt)
                S[_DX + q] = fx
                S[_DY + q] = fy
                S[_RS + q] = f_t
                S[_DVX + q] = d_slip
                S[_DVY + q] = d_dash
        elif ledger:
            for q in range(nk):
                _, fx, fy, f_t, d_slip, _ = _contact_law(
                    S[_DX + q], S[_DY + q], S[_RS + q], S[_DVX + q], S[_DVY + q], S[_WR + q],
                    ft[U(k0 + q)], S[_MEFF + q], kn, kt, mu, cap_on, beta, dt)
                S[_DX + q] = fx
                S[_DY + q] = fy
                S[_RS + q] = f_t
                S[_DVX + q] = d_slip
        else:
            for q in range(nk):
                _, fx, fy, f_t, _, _ = _contact_law(
                    S[_DX + q], S[_DY + q], S[_RS + q], S[_DVX + q], S[_DVY + q], S[_WR + q],
                    ft[U(k0 + q)], S[_MEFF + q], kn, kt, mu, cap_on, beta, dt)
                S[_DX + q] = fx
                S[_DY + q] = fy
                S[_RS + q] = f_t
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
            fx = S[_DX + q]
            fy = S[_DY + q]
            f_t = S[_RS + q]
            ft[k] = f_t
            fnet[i, 0] += fx
            fnet[i, 1] += fy
            fnet[i, 2] += f_t
            fnet[j, 0] -= fx
            fnet[j, 1] -= fy
            fnet[j, 2] += f_t
            if ledger:
                # most contacts do not slide: a well-predicted branch spares the sum's store
                if S[_DVX + q] != 0.0:
                    l_slip[i] += S[_DVX + q]
                if beta > 0.0:
                    l_dash[i] += S[_DVY + q]
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
