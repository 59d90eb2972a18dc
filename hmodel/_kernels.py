"""Numba kernels of the H-microdirectional model (the only module with @njit).

Layout: every hexagon field is a C-contiguous array of shape (npts, n_dir), in the order of
``material.HEX_FIELDS`` (d1, d2, alpha, N1, T1, N2, l1, l2, cos_a, sin_a: the cos and sin of alpha
are carried in the state, so a closed hexagon costs no trigonometric call); strains and stresses
are (npts, 3) in the order (11, 22, 12) with tensor (not engineering) shear; tangents are
(npts, 3, 3) with T[p, a, b] = d sigma_a / d v_b, v = (de11, de22, de12), de12 = de21.

The hexagon solve follows the formulation of docs/hmodel.md (Eqs. 16-22 of Nicot, Hadda & Darve 2013 with the two
corrections the spec lists). For a fixed sliding/opening pattern every increment is affine in de,
so the derivative of the returned stress is assembled exactly, term by term (chain rule through
the 3x3 solve, the new angle, the new lengths and the volume).

One update kernel for every caller (``material.update`` / ``update_full``, the driver's Numba
paths, the probes, the FE's ``MaterialField``): per point, a branch-free fast pass the compiler
vectorizes over the orientations (``_fast_pass``: closed hexagons that stay closed, elastic or
sliding, small rotation, no extra contact) and a general loop for the rest (open, opening,
closing, extra contacts, large rotations) with the same operations in the same order, so the same
bits; ``extras=True`` (Lagrangian tangent, T3, micro sums) runs every hexagon through the general
loop. ``update_general`` skips the fast pass: the reference of the tests.
"""
import math

import numpy as np
from numba import literally, njit, prange


@njit(cache=True, inline="always")
def _closed_hexagon(p, i, d1, d2, alpha, N1, T1, N2, l1, l2, cos_a, sin_a, was_open, e11, e22, e12,
                    cos_t, sin_t, omega, kn, kt, mu, two_r, rkn, allow_sliding, with_sliding):
    """Hexagon i of point p updated as in the fast pass: closed at both ends of the step, no
    extra contact 1-4 or 2-6, |d_alpha| < 0.01, and elastic or (``with_sliding``) sliding
    (Coulomb). The operations of the general loop of ``_update_point`` for that case, in the same
    order (same bits), without a branch: with ``with_sliding`` the elastic trial and the sliding
    solve are both computed and selected. ``with_sliding`` is a literal at the call sites
    (``_fast_pass``), so the compiler drops the sliding solve from the elastic pass, where a
    hexagon whose trial violates Coulomb (when sliding is allowed) is left to the general loop.

    Returns the new (d1, d2, alpha, N1, T1, N2, l1, l2, cos alpha, sin alpha), ``other`` = 1.0
    where the hexagon is not in this case (0.0 otherwise), ``slide`` (1.0 where it slides), the
    three stress terms and the nine tangent terms (row-major) that the point sums (Love-Weber,
    Eq. 23)."""
    c = cos_t[i]
    s = sin_t[i]
    cc = c * c
    ss = s * s
    cs = c * s
    w = omega[i]
    en = cc * e11 + ss * e22 + 2.0 * cs * e12
    et = ss * e11 + cc * e22 - 2.0 * cs * e12
    L1 = l1[p, i]
    L2 = l2[p, i]
    dl1 = -L1 * en
    dl2 = -L2 * et
    g10 = -L1 * cc; g11 = -L1 * ss; g12 = -2.0 * L1 * cs
    g20 = -L2 * ss; g21 = -L2 * cc; g22 = 2.0 * L2 * cs
    D1 = d1[p, i]
    n1 = N1[p, i]
    t1 = T1[p, i]
    ca = cos_a[p, i]
    sa = sin_a[p, i]
    a00 = 2.0 * ca; a02 = -2.0 * D1 * sa
    a10 = 2.0 * sa; a12 = 2.0 * D1 * ca
    a22 = (n1 * sa - t1 * ca - kt * D1 * sa) * rkn
    c01 = a12 * ca - a10 * a22
    rdet = 1.0 / (a00 * a12 + c01 - a02 * a10)
    i00 = a12 * rdet; i01 = (-a02 - a22) * rdet
    i10 = c01 * rdet; i11 = (a00 * a22 - a02 * ca) * rdet
    i20 = -a10 * rdet; i21 = (ca + a00) * rdet
    dd1 = i00 * dl1 + i01 * dl2
    dd2 = i10 * dl1 + i11 * dl2
    da = i20 * dl1 + i21 * dl2
    nN1 = n1 - kn * dd1
    Ttr = t1 + kt * D1 * da
    trial_slides = allow_sliding & (abs(Ttr) >= mu * nN1)
    slide = with_sliding & trial_slides
    # Coulomb sliding (the general loop's branch): row 3 replaced, the system solved again
    xi = 1.0 if Ttr >= 0.0 else -1.0
    a20 = ca + xi * mu * sa
    sa22 = (n1 * sa - t1 * ca) * rkn
    b2 = sa * (xi * mu * n1 - t1) * rkn
    sc01 = a12 * a20 - a10 * sa22
    srdet = 1.0 / (a00 * a12 + sc01 - a02 * a10)
    j00 = a12 * srdet; j01 = (-a02 - sa22) * srdet
    j10 = sc01 * srdet; j11 = (a00 * sa22 - a02 * a20) * srdet; j12 = (a02 * a10 - a00 * a12) * srdet
    j20 = -a10 * srdet; j21 = (a20 + a00) * srdet
    sdd1 = j00 * dl1 + j01 * dl2 + j00 * b2
    sdd2 = j10 * dl1 + j11 * dl2 + j12 * b2
    sda = j20 * dl1 + j21 * dl2 + j20 * b2
    i00 = j00 if slide else i00
    i01 = j01 if slide else i01
    i10 = j10 if slide else i10
    i11 = j11 if slide else i11
    i20 = j20 if slide else i20
    i21 = j21 if slide else i21
    dd1 = sdd1 if slide else dd1
    dd2 = sdd2 if slide else dd2
    da = sda if slide else da
    nN1 = n1 - kn * dd1          # elastic: the same value again
    x10 = i00 * g10 + i01 * g20; x11 = i00 * g11 + i01 * g21; x12 = i00 * g12 + i01 * g22
    x20 = i10 * g10 + i11 * g20; x21 = i10 * g11 + i11 * g21; x22 = i10 * g12 + i11 * g22
    x30 = i20 * g10 + i21 * g20; x31 = i20 * g11 + i21 * g21; x32 = i20 * g12 + i21 * g22
    nN2 = N2[p, i] - kn * dd2
    dN1_0 = -kn * x10; dN1_1 = -kn * x11; dN1_2 = -kn * x12
    dN2_0 = -kn * x20; dN2_1 = -kn * x21; dN2_2 = -kn * x22
    nT1 = xi * mu * nN1 if slide else Ttr
    dT1_0 = xi * mu * dN1_0 if slide else kt * D1 * x30
    dT1_1 = xi * mu * dN1_1 if slide else kt * D1 * x31
    dT1_2 = xi * mu * dN1_2 if slide else kt * D1 * x32
    z = da * da
    sd = da + da * z * (-1.0 / 6.0 + z * (1.0 / 120.0 - z * (1.0 / 5040.0)))
    cd = 1.0 + z * (-0.5 + z * (1.0 / 24.0 + z * (-1.0 / 720.0 + z * (1.0 / 40320.0))))
    cna = ca * cd - sa * sd
    sna = sa * cd + ca * sd
    nl1 = L1 + dl1
    nl2 = L2 + dl2
    # the additions of the (zero) extra-contact terms stay: x + 0.0 is not x for x = -0.0
    zero = 0.0
    F2 = nN1 * sna - nT1 * cna
    dF2_0 = dN1_0 * sna + nN1 * cna * x30 - dT1_0 * cna + nT1 * sna * x30
    dF2_1 = dN1_1 * sna + nN1 * cna * x31 - dT1_1 * cna + nT1 * sna * x31
    dF2_2 = dN1_2 * sna + nN1 * cna * x32 - dT1_2 * cna + nT1 * sna * x32
    PP1 = 2.0 * nN2 + zero
    PP2 = 2.0 * F2 + 2.0 * zero
    wS1 = w * (PP1 * nl1)
    wS2 = w * (PP2 * nl2)
    dS1_0 = (2.0 * dN2_0 + zero) * nl1 + PP1 * g10
    dS1_1 = (2.0 * dN2_1 + zero) * nl1 + PP1 * g11
    dS1_2 = (2.0 * dN2_2 + zero) * nl1 + PP1 * g12
    dS2_0 = (2.0 * dF2_0 + 2.0 * zero) * nl2 + PP2 * g20
    dS2_1 = (2.0 * dF2_1 + 2.0 * zero) * nl2 + PP2 * g21
    dS2_2 = (2.0 * dF2_2 + 2.0 * zero) * nl2 + PP2 * g22
    # not this case: open at the start, Coulomb trial violated in the elastic pass, opening,
    # large rotation, an extra contact (NaN: general too)
    other = (was_open[p, i] | (trial_slides & (not with_sliding))
             | (nN1 < 0.0) | (nN2 < 0.0) | (not (abs(da) < 0.01))
             | (L1 < two_r) | (L2 < two_r) | (nl1 < two_r) | (nl2 < two_r))
    return (D1 + dd1, d2[p, i] + dd2, alpha[p, i] + da, nN1, nT1, nN2, nl1, nl2, cna, sna,
            1.0 if other else 0.0, 1.0 if slide else 0.0,
            wS1 * cc + wS2 * ss, wS1 * ss + wS2 * cc, (wS1 - wS2) * cs,
            w * (dS1_0 * cc + dS2_0 * ss), w * (dS1_1 * cc + dS2_1 * ss), w * (dS1_2 * cc + dS2_2 * ss),
            w * (dS1_0 * ss + dS2_0 * cc), w * (dS1_1 * ss + dS2_1 * cc), w * (dS1_2 * ss + dS2_2 * cc),
            w * (dS1_0 - dS2_0) * cs, w * (dS1_1 - dS2_1) * cs, w * (dS1_2 - dS2_2) * cs)


@njit(cache=True, error_model="numpy")
def _fast_pass(p, d1, d2, alpha, N1, T1, N2, l1, l2, cos_a, sin_a, was_open, e11, e22, e12,
               cos_t, sin_t, omega, kn, kt, mu, two_r, rkn, allow_sliding, with_sliding,
               o_d1, o_d2, o_alpha, o_N1, o_T1, o_N2, o_l1, o_l2, o_cos_a, o_sin_a, o_sliding, o_open,
               fast):
    """The fast pass of point ``p``: ``_closed_hexagon`` for every orientation, elastic only or
    (``with_sliding``) elastic and sliding. Stores the ten new hexagon fields and the sliding
    flags in the ``o_*`` arrays (open = False) and, in ``fast`` (14, n_dir), the flag ``other``
    (row 0), the stress terms (rows 1-3), the tangent terms (rows 4-12, row-major) and ``slide``
    (row 13).

    Written for the compiler's loop vectorizer (SIMD over orientations): no branch, and each loop
    stores at most eight arrays (beyond that its run-time overlap checks rule vectorization out;
    the per-hexagon update is cheap, so each loop repeats it and the compiler keeps what that loop
    stores). ``with_sliding`` is dispatched as a literal (``numba.literally``: one compiled
    variant per value, the callers pass True or False), so the compiler folds it and the elastic
    variant carries no Coulomb solve. error_model="numpy": 1/0 gives inf instead of a branch to a
    ZeroDivisionError, which would also rule vectorization out; such a hexagon gets a non-finite
    d_alpha, hence the flag, and the general loop redoes it (with Python's error model)."""
    literally(with_sliding)      # one compiled variant per value: the literal folds
    ndir = d1.shape[1]
    for i in range(ndir):
        h = _closed_hexagon(p, i, d1, d2, alpha, N1, T1, N2, l1, l2, cos_a, sin_a, was_open,
                            e11, e22, e12, cos_t, sin_t, omega, kn, kt, mu, two_r, rkn, allow_sliding,
                            with_sliding)
        o_d1[p, i] = h[0]; o_d2[p, i] = h[1]; o_alpha[p, i] = h[2]; o_N1[p, i] = h[3]
        o_T1[p, i] = h[4]; o_N2[p, i] = h[5]; o_l1[p, i] = h[6]; o_l2[p, i] = h[7]
    for i in range(ndir):
        h = _closed_hexagon(p, i, d1, d2, alpha, N1, T1, N2, l1, l2, cos_a, sin_a, was_open,
                            e11, e22, e12, cos_t, sin_t, omega, kn, kt, mu, two_r, rkn, allow_sliding,
                            with_sliding)
        o_cos_a[p, i] = h[8]; o_sin_a[p, i] = h[9]
        fast[0, i] = h[10]; fast[1, i] = h[12]; fast[2, i] = h[13]; fast[3, i] = h[14]
        fast[4, i] = h[15]; fast[5, i] = h[16]
    for i in range(ndir):
        h = _closed_hexagon(p, i, d1, d2, alpha, N1, T1, N2, l1, l2, cos_a, sin_a, was_open,
                            e11, e22, e12, cos_t, sin_t, omega, kn, kt, mu, two_r, rkn, allow_sliding,
                            with_sliding)
        fast[6, i] = h[17]; fast[7, i] = h[18]; fast[8, i] = h[19]; fast[9, i] = h[20]
        fast[10, i] = h[21]; fast[11, i] = h[22]; fast[12, i] = h[23]; fast[13, i] = h[11]
    for i in range(ndir):
        o_sliding[p, i] = fast[13, i] != 0.0
        o_open[p, i] = False


@njit(cache=True)
def _update_point(p, d1, d2, alpha, N1, T1, N2, l1, l2, cos_a, sin_a, was_open, eps, V0, de,
                 cos_t, sin_t, omega, kn, kt, mu, r_g, allow_sliding, extras, fast_ok,
                 o_d1, o_d2, o_alpha, o_N1, o_T1, o_N2, o_l1, o_l2, o_cos_a, o_sin_a, o_sliding, o_open,
                 o_sig, o_tan, o_tanL, o_dPi, o_T3, o_w2, o_w2n, o_w2t):
    """Update the n_dir hexagons of point ``p`` (one iteration of the point loop). The point
    loop lives in the two drivers below, so that the parallel one has a trivial body (Numba's
    parfor analysis fails intermittently on this body's control flow: "unexpected cycle in
    lookup()"). ``fast_ok=False`` sends every hexagon through the general loop (the reference
    the fast pass is tested against, ``update_general``)."""
    ndir = d1.shape[1]
    two_r = 2.0 * r_g
    rkn = 1.0 / kn             # multiply, not divide, in the hexagon loop
    e11 = de[p, 0]
    e22 = de[p, 1]
    e12 = de[p, 2]
    # accumulators: stress sums S, tangent dS/dv, Lagrangian dPi and its tangent, T3, micro w2
    s0 = 0.0; s1 = 0.0; s2 = 0.0
    t00 = 0.0; t01 = 0.0; t02 = 0.0; t10 = 0.0; t11 = 0.0; t12 = 0.0; t20 = 0.0; t21 = 0.0; t22 = 0.0
    L00 = 0.0; L01 = 0.0; L02 = 0.0; L10 = 0.0; L11 = 0.0; L12 = 0.0; L20 = 0.0; L21 = 0.0; L22 = 0.0
    P0 = 0.0; P1 = 0.0; P2 = 0.0
    q0 = 0.0; q1 = 0.0; q2 = 0.0
    w2 = 0.0; w2n = 0.0; w2t = 0.0
    # The fast pass first (``_fast_pass``: closed at both ends of the step, no extra contact,
    # small rotation, elastic or sliding: every hexagon of the isotropic state, and most closed
    # hexagons of a loaded one), vectorized: it stores the new hexagon fields and, in ``fast``, a
    # flag (row 0) for the hexagons that are not in it, the stress (rows 1-3) and tangent (rows
    # 4-12) terms of the others. The loop below redoes the flagged hexagons the general way and
    # sums the terms in the orientation order, as it would without the fast pass (the same
    # operations, so the same bits). Worth it when at least half the hexagons start closed (else
    # most of its work is discarded; either way the results are the same bits). The extras are
    # the general loop's only: with ``extras`` every hexagon goes through it (a fast pass that
    # also computed them, tried for issue 19, took the first compilation from 84 s to 265 s and
    # left the domain's time unchanged: docs/hmodel.md). The sliding variant of the pass (the
    # Coulomb solve computed for every hexagon) only where a closed hexagon starts at the
    # Coulomb limit, |T1| >= mu N1 (exactly the hexagons that slid in the step that made the
    # state: their T1 = +-mu N1); elsewhere the elastic variant, which leaves a hexagon that
    # starts to slide to the general loop. The same bits either way: only the time differs.
    n_closed = 0
    n_limit = 0
    if fast_ok and not extras:
        for i in range(ndir):
            if not was_open[p, i]:
                n_closed += 1
                if abs(T1[p, i]) >= mu * N1[p, i]:
                    n_limit += 1
    use_fast = 2 * n_closed >= ndir and not extras and fast_ok
    fast = np.empty((14, ndir))
    with_sliding = allow_sliding and n_limit > 0
    if use_fast and with_sliding:
        _fast_pass(p, d1, d2, alpha, N1, T1, N2, l1, l2, cos_a, sin_a, was_open, e11, e22, e12,
                   cos_t, sin_t, omega, kn, kt, mu, two_r, rkn, allow_sliding, True,
                   o_d1, o_d2, o_alpha, o_N1, o_T1, o_N2, o_l1, o_l2, o_cos_a, o_sin_a,
                   o_sliding, o_open, fast)
    elif use_fast:
        _fast_pass(p, d1, d2, alpha, N1, T1, N2, l1, l2, cos_a, sin_a, was_open, e11, e22, e12,
                   cos_t, sin_t, omega, kn, kt, mu, two_r, rkn, allow_sliding, False,
                   o_d1, o_d2, o_alpha, o_N1, o_T1, o_N2, o_l1, o_l2, o_cos_a, o_sin_a,
                   o_sliding, o_open, fast)
    for i in range(ndir):
        if use_fast and fast[0, i] == 0.0:
            # fast pass: the new fields are stored already
            s0 += fast[1, i]
            s1 += fast[2, i]
            s2 += fast[3, i]
            t00 += fast[4, i]; t01 += fast[5, i]; t02 += fast[6, i]
            t10 += fast[7, i]; t11 += fast[8, i]; t12 += fast[9, i]
            t20 += fast[10, i]; t21 += fast[11, i]; t22 += fast[12, i]
            continue
        # general case: any pattern
        c = cos_t[i]
        s = sin_t[i]
        cc = c * c
        ss = s * s
        cs = c * s
        w = omega[i]
        # kinematic localization (Eq. 16): dl1 = -l1 n.de.n, dl2 = -l2 t.de.t, shear included
        en = cc * e11 + ss * e22 + 2.0 * cs * e12
        et = ss * e11 + cc * e22 - 2.0 * cs * e12
        L1 = l1[p, i]
        L2 = l2[p, i]
        dl1 = -L1 * en
        dl2 = -L2 * et
        g10 = -L1 * cc; g11 = -L1 * ss; g12 = -2.0 * L1 * cs     # d(dl1)/dv
        g20 = -L2 * ss; g21 = -L2 * cc; g22 = 2.0 * L2 * cs      # d(dl2)/dv
        D1 = d1[p, i]
        D2 = d2[p, i]
        a = alpha[p, i]
        n1 = N1[p, i]
        t1 = T1[p, i]
        n2 = N2[p, i]
        closed_end = True
        if was_open[p, i]:
            # open hexagon: no force; it closes when (l1, l2) re-enters the set reachable with
            # d1, d2 <= 2 r_g, i.e. l2 <= 4 r_g and l1 <= 2 r_g + sqrt(16 r_g^2 - l2^2)
            nl1_ = L1 + dl1
            nl2_ = L2 + dl2
            closed_end = False
            if nl2_ < 2.0 * two_r and nl1_ > two_r:
                if nl1_ <= two_r + math.sqrt(4.0 * two_r * two_r - nl2_ * nl2_):
                    closed_end = True
            # stays open: no force, no stiffness, no second-order work; unless an extra
            # contact (1-4 or 2-6) touches, nothing but the lengths changes
            if (not closed_end and L1 >= two_r and L2 >= two_r and nl1_ >= two_r
                    and nl2_ >= two_r):
                o_d1[p, i] = two_r
                o_d2[p, i] = two_r
                o_alpha[p, i] = a
                o_N1[p, i] = 0.0
                o_T1[p, i] = 0.0
                o_N2[p, i] = 0.0
                o_l1[p, i] = nl1_
                o_l2[p, i] = nl2_
                o_cos_a[p, i] = cos_a[p, i]
                o_sin_a[p, i] = sin_a[p, i]
                o_sliding[p, i] = False
                o_open[p, i] = True
                continue
        # cos, sin of the start angle: carried in the state (no transcendental call per step)
        ca = cos_a[p, i]
        sa = sin_a[p, i]
        slide = False
        xi = 0.0
        # derivatives of (dd1, dd2, da) w.r.t. v; x = (dd1, dd2, da)
        if was_open[p, i]:
            if closed_end:
                # Close in equilibrium with zero tangential force: N2 = N1 cos(a), i.e.
                # f(a) = 2 r (1 - cos a) - l1 + 1.5 l2 cot(a) = 0, decreasing in a; f = 0 on the
                # boundary gives d1 = d2 = 2 r_g, so the forces start from zero (continuity).
                lo = math.asin(min(nl2_ / (2.0 * two_r), 1.0))
                hi = 0.5 * math.pi
                for _ in range(60):
                    mid = 0.5 * (lo + hi)
                    fm = two_r * (1.0 - math.cos(mid)) - nl1_ + 1.5 * nl2_ * math.cos(mid) / math.sin(mid)
                    if fm > 0.0:
                        lo = mid
                    else:
                        hi = mid
                an = 0.5 * (lo + hi)
                can_ = math.cos(an)
                san_ = math.sin(an)
                nd1 = nl2_ / (2.0 * san_)
                nd2 = nl1_ - nl2_ * can_ / san_
                da = an - a
                dd1 = nd1 - D1
                dd2 = nd2 - D2
                # implicit derivative of the closing angle, then of d1, d2
                fa = two_r * san_ - 1.5 * nl2_ / (san_ * san_)
                fl2 = 1.5 * can_ / san_
                x30 = (g10 - fl2 * g20) / fa; x31 = (g11 - fl2 * g21) / fa; x32 = (g12 - fl2 * g22) / fa
                k1 = nl2_ * can_ / (2.0 * san_ * san_)
                x10 = g20 / (2.0 * san_) - k1 * x30
                x11 = g21 / (2.0 * san_) - k1 * x31
                x12 = g22 / (2.0 * san_) - k1 * x32
                k2 = nl2_ / (san_ * san_)
                x20 = g10 - g20 * can_ / san_ + k2 * x30
                x21 = g11 - g21 * can_ / san_ + k2 * x31
                x22 = g12 - g22 * can_ / san_ + k2 * x32
                nN1 = kn * (two_r - nd1)
                nN2 = kn * (two_r - nd2)
                nT1 = 0.0
                dN1_0 = -kn * x10; dN1_1 = -kn * x11; dN1_2 = -kn * x12
                dN2_0 = -kn * x20; dN2_1 = -kn * x21; dN2_2 = -kn * x22
                dT1_0 = 0.0; dT1_1 = 0.0; dT1_2 = 0.0
            else:
                # stays open next to an extra contact (1-4 or 2-6): forces zero, lengths follow
                da = 0.0
                dd1 = two_r - D1
                dd2 = two_r - D2
                nd1 = two_r
                nd2 = two_r
                x30 = 0.0; x31 = 0.0; x32 = 0.0
        else:
            # 3x3 system A x = b for x = (dd1, dd2, da): rows 1-2 geometry (Eqs. 18-19
            # differentiated), row 3 equilibrium,
            #   A = [[2 ca, 1, -2 d1 sa], [2 sa, 0, 2 d1 ca], [a20, -1, a22]],  b = (dl1, dl2, b2),
            # inverted by cofactors with the constant entries folded in. The elastic trial has
            # a20 = ca and b2 = 0: only the first two columns of the inverse are needed (they are
            # also all the tangent needs, b2 does not depend on de).
            a00 = 2.0 * ca; a02 = -2.0 * D1 * sa
            a10 = 2.0 * sa; a12 = 2.0 * D1 * ca
            a22 = (n1 * sa - t1 * ca - kt * D1 * sa) * rkn
            c01 = a12 * ca - a10 * a22
            rdet = 1.0 / (a00 * a12 + c01 - a02 * a10)
            i00 = a12 * rdet; i01 = (-a02 - a22) * rdet
            i10 = c01 * rdet; i11 = (a00 * a22 - a02 * ca) * rdet
            i20 = -a10 * rdet; i21 = (ca + a00) * rdet
            dd1 = i00 * dl1 + i01 * dl2
            dd2 = i10 * dl1 + i11 * dl2
            da = i20 * dl1 + i21 * dl2
            nN1 = n1 - kn * dd1
            Ttr = t1 + kt * D1 * da
            if allow_sliding and abs(Ttr) >= mu * nN1:
                # Coulomb sliding: replace row 3 (spec: xi multiplies mu N1 only), solve again;
                # the third column of the inverse equals the first (i02 = i00, i22 = i20)
                slide = True
                xi = 1.0 if Ttr >= 0.0 else -1.0
                a20 = ca + xi * mu * sa
                a22 = (n1 * sa - t1 * ca) * rkn
                b2 = sa * (xi * mu * n1 - t1) * rkn
                c01 = a12 * a20 - a10 * a22
                rdet = 1.0 / (a00 * a12 + c01 - a02 * a10)
                i00 = a12 * rdet; i01 = (-a02 - a22) * rdet
                i10 = c01 * rdet; i11 = (a00 * a22 - a02 * a20) * rdet; i12 = (a02 * a10 - a00 * a12) * rdet
                i20 = -a10 * rdet; i21 = (a20 + a00) * rdet
                dd1 = i00 * dl1 + i01 * dl2 + i00 * b2
                dd2 = i10 * dl1 + i11 * dl2 + i12 * b2
                da = i20 * dl1 + i21 * dl2 + i20 * b2
                nN1 = n1 - kn * dd1
            x10 = i00 * g10 + i01 * g20; x11 = i00 * g11 + i01 * g21; x12 = i00 * g12 + i01 * g22
            x20 = i10 * g10 + i11 * g20; x21 = i10 * g11 + i11 * g21; x22 = i10 * g12 + i11 * g22
            x30 = i20 * g10 + i21 * g20; x31 = i20 * g11 + i21 * g21; x32 = i20 * g12 + i21 * g22
            nd1 = D1 + dd1
            nd2 = D2 + dd2
            nN2 = n2 - kn * dd2
            dN1_0 = -kn * x10; dN1_1 = -kn * x11; dN1_2 = -kn * x12
            dN2_0 = -kn * x20; dN2_1 = -kn * x21; dN2_2 = -kn * x22
            if slide:
                nT1 = xi * mu * nN1
                dT1_0 = xi * mu * dN1_0; dT1_1 = xi * mu * dN1_1; dT1_2 = xi * mu * dN1_2
            else:
                nT1 = t1 + kt * D1 * da
                dT1_0 = kt * D1 * x30; dT1_1 = kt * D1 * x31; dT1_2 = kt * D1 * x32
            if nN1 < 0.0 or nN2 < 0.0:
                closed_end = False
                slide = False
        if not closed_end:
            nN1 = 0.0; nN2 = 0.0; nT1 = 0.0
            dN1_0 = 0.0; dN1_1 = 0.0; dN1_2 = 0.0
            dN2_0 = 0.0; dN2_1 = 0.0; dN2_2 = 0.0
            dT1_0 = 0.0; dT1_1 = 0.0; dT1_2 = 0.0
        na = a + da
        if abs(da) < 0.01:
            # rotate (cos a, sin a) by the small d_alpha: Taylor series exact to round-off for
            # |da| < 0.01 (next terms < 3e-24), in Horner form with constant reciprocals (a
            # division costs several multiplications and the compiler may not replace it)
            z = da * da
            sd = da + da * z * (-1.0 / 6.0 + z * (1.0 / 120.0 - z * (1.0 / 5040.0)))
            cd = 1.0 + z * (-0.5 + z * (1.0 / 24.0 + z * (-1.0 / 720.0 + z * (1.0 / 40320.0))))
            cna = ca * cd - sa * sd
            sna = sa * cd + ca * sd
        else:
            cna = math.cos(na)
            sna = math.sin(na)
        nl1 = L1 + dl1
        nl2 = L2 + dl2
        # extra contacts 1-4 (one pair) and 2-6, 3-5 (two pairs), purely geometric
        f14_0 = kn * (two_r - L1) if L1 < two_r else 0.0
        f26_0 = kn * (two_r - L2) if L2 < two_r else 0.0
        if nl1 < two_r:
            f14 = kn * (two_r - nl1)
            df14_0 = -kn * g10; df14_1 = -kn * g11; df14_2 = -kn * g12
        else:
            f14 = 0.0
            df14_0 = 0.0; df14_1 = 0.0; df14_2 = 0.0
        if nl2 < two_r:
            f26 = kn * (two_r - nl2)
            df26_0 = -kn * g20; df26_1 = -kn * g21; df26_2 = -kn * g22
        else:
            f26 = 0.0
            df26_0 = 0.0; df26_1 = 0.0; df26_2 = 0.0
        # new hexagon stress moments S1 = P1 l1, S2 = P2 l2 (Eqs. 26-27)
        F2 = nN1 * sna - nT1 * cna
        dF2_0 = dN1_0 * sna + nN1 * cna * x30 - dT1_0 * cna + nT1 * sna * x30
        dF2_1 = dN1_1 * sna + nN1 * cna * x31 - dT1_1 * cna + nT1 * sna * x31
        dF2_2 = dN1_2 * sna + nN1 * cna * x32 - dT1_2 * cna + nT1 * sna * x32
        PP1 = 2.0 * nN2 + f14
        PP2 = 2.0 * F2 + 2.0 * f26
        S1 = PP1 * nl1
        S2 = PP2 * nl2
        dS1_0 = (2.0 * dN2_0 + df14_0) * nl1 + PP1 * g10
        dS1_1 = (2.0 * dN2_1 + df14_1) * nl1 + PP1 * g11
        dS1_2 = (2.0 * dN2_2 + df14_2) * nl1 + PP1 * g12
        dS2_0 = (2.0 * dF2_0 + 2.0 * df26_0) * nl2 + PP2 * g20
        dS2_1 = (2.0 * dF2_1 + 2.0 * df26_1) * nl2 + PP2 * g21
        dS2_2 = (2.0 * dF2_2 + 2.0 * df26_2) * nl2 + PP2 * g22
        # Love-Weber (Eq. 23) with n(x)n = (cc, ss, cs), t(x)t = (ss, cc, -cs)
        wS1 = w * S1
        wS2 = w * S2
        s0 += wS1 * cc + wS2 * ss
        s1 += wS1 * ss + wS2 * cc
        s2 += (wS1 - wS2) * cs
        t00 += w * (dS1_0 * cc + dS2_0 * ss); t01 += w * (dS1_1 * cc + dS2_1 * ss); t02 += w * (dS1_2 * cc + dS2_2 * ss)
        t10 += w * (dS1_0 * ss + dS2_0 * cc); t11 += w * (dS1_1 * ss + dS2_1 * cc); t12 += w * (dS1_2 * ss + dS2_2 * cc)
        t20 += w * (dS1_0 - dS2_0) * cs; t21 += w * (dS1_1 - dS2_1) * cs; t22 += w * (dS1_2 - dS2_2) * cs
        if extras:
            # Lagrangian increment T1 = dPi: forces change at the start geometry (Eq. 32).
            # A hexagon closed at both ends takes the law's increments directly: as differences
            # of the new and old forces (nN1 - n1) they would carry the old forces' rounding,
            # eps |N1|, a relative error ~ 1/|de| that breaks the micro = macro identity at small
            # increments (1e-10 at |de| = 1e-8); these satisfy the linearized equilibrium (row 3
            # of the 3x3 system) to the increments' own rounding.
            if not was_open[p, i] and closed_end:
                DN1 = -kn * dd1
                DN2 = -kn * dd2
                DT1 = (xi * mu * n1 - t1) + xi * mu * DN1 if slide else kt * D1 * da
            else:
                DN1 = nN1 - n1
                DT1 = nT1 - t1
                DN2 = nN2 - n2
            DF2 = DN1 * sa + n1 * ca * da - DT1 * ca + t1 * sa * da
            Df14 = -kn * dl1 if (L1 < two_r and nl1 < two_r) else f14 - f14_0
            Df26 = -kn * dl2 if (L2 < two_r and nl2 < two_r) else f26 - f26_0
            DP1 = 2.0 * DN2 + Df14
            DP2 = 2.0 * DF2 + 2.0 * Df26
            wA = w * DP1 * L1
            wB = w * DP2 * L2
            P0 += wA * cc + wB * ss
            P1 += wA * ss + wB * cc
            P2 += (wA - wB) * cs
            dDF2_0 = dN1_0 * sa + n1 * ca * x30 - dT1_0 * ca + t1 * sa * x30
            dDF2_1 = dN1_1 * sa + n1 * ca * x31 - dT1_1 * ca + t1 * sa * x31
            dDF2_2 = dN1_2 * sa + n1 * ca * x32 - dT1_2 * ca + t1 * sa * x32
            dA0 = w * (2.0 * dN2_0 + df14_0) * L1; dA1 = w * (2.0 * dN2_1 + df14_1) * L1; dA2 = w * (2.0 * dN2_2 + df14_2) * L1
            dB0 = w * (2.0 * dDF2_0 + 2.0 * df26_0) * L2; dB1 = w * (2.0 * dDF2_1 + 2.0 * df26_1) * L2
            dB2 = w * (2.0 * dDF2_2 + 2.0 * df26_2) * L2
            L00 += dA0 * cc + dB0 * ss; L01 += dA1 * cc + dB1 * ss; L02 += dA2 * cc + dB2 * ss
            L10 += dA0 * ss + dB0 * cc; L11 += dA1 * ss + dB1 * cc; L12 += dA2 * ss + dB2 * cc
            L20 += (dA0 - dB0) * cs; L21 += (dA1 - dB1) * cs; L22 += (dA2 - dB2) * cs
            # transport term T3: geometry changes at the start forces
            F2_0 = n1 * sa - t1 * ca
            wC = w * (2.0 * n2 + f14_0) * dl1
            wD = w * (2.0 * F2_0 + 2.0 * f26_0) * dl2
            q0 += wC * cc + wD * ss
            q1 += wC * ss + wD * cc
            q2 += (wC - wD) * cs
            # micro second-order work (Eq. 36, compression-positive lengths) and its contact split
            w2 += -w * (DP1 * dl1 + DP2 * dl2)
            # contacts 1-2, 1-6, 4-3, 4-5 in their own frame (n_c, t_c) at the start:
            # df = (-dN1 - T1 da) n_c + (dT1 - N1 da) t_c,  dl = dd1 n_c + d1 da t_c
            w2n += w * (4.0 * (-DN1 - t1 * da) * dd1 - 2.0 * DN2 * dd2 - Df14 * dl1 - 2.0 * Df26 * dl2)
            w2t += w * (4.0 * (DT1 - n1 * da) * D1 * da)
        o_d1[p, i] = nd1
        o_d2[p, i] = nd2
        o_alpha[p, i] = na
        o_N1[p, i] = nN1
        o_T1[p, i] = nT1
        o_N2[p, i] = nN2
        o_l1[p, i] = nl1
        o_l2[p, i] = nl2
        o_cos_a[p, i] = cna
        o_sin_a[p, i] = sna
        o_sliding[p, i] = slide
        o_open[p, i] = not closed_end
    # volumes: V = V0 det(I - eps) at the start, V' at the end of the step
    b11 = 1.0 - eps[p, 0]
    b22 = 1.0 - eps[p, 1]
    b12 = -eps[p, 2]
    V = V0[p] * (b11 * b22 - b12 * b12)
    a11 = b11 - e11
    a22 = b22 - e22
    a12 = b12 - e12
    detA = a11 * a22 - a12 * a12
    Vn = V0[p] * detA
    # d ln V'/dv, v = (e11, e22, e12)
    k0 = -a22 / detA
    k1 = -a11 / detA
    k2 = 2.0 * a12 / detA
    sg0 = s0 / Vn
    sg1 = s1 / Vn
    sg2 = s2 / Vn
    o_sig[p, 0] = sg0
    o_sig[p, 1] = sg1
    o_sig[p, 2] = sg2
    o_tan[p, 0, 0] = t00 / Vn - sg0 * k0; o_tan[p, 0, 1] = t01 / Vn - sg0 * k1; o_tan[p, 0, 2] = t02 / Vn - sg0 * k2
    o_tan[p, 1, 0] = t10 / Vn - sg1 * k0; o_tan[p, 1, 1] = t11 / Vn - sg1 * k1; o_tan[p, 1, 2] = t12 / Vn - sg1 * k2
    o_tan[p, 2, 0] = t20 / Vn - sg2 * k0; o_tan[p, 2, 1] = t21 / Vn - sg2 * k1; o_tan[p, 2, 2] = t22 / Vn - sg2 * k2
    if extras:
        o_tanL[p, 0, 0] = L00 / V; o_tanL[p, 0, 1] = L01 / V; o_tanL[p, 0, 2] = L02 / V
        o_tanL[p, 1, 0] = L10 / V; o_tanL[p, 1, 1] = L11 / V; o_tanL[p, 1, 2] = L12 / V
        o_tanL[p, 2, 0] = L20 / V; o_tanL[p, 2, 1] = L21 / V; o_tanL[p, 2, 2] = L22 / V
        o_dPi[p, 0] = P0 / V
        o_dPi[p, 1] = P1 / V
        o_dPi[p, 2] = P2 / V
        o_T3[p, 0] = q0 / V
        o_T3[p, 1] = q1 / V
        o_T3[p, 2] = q2 / V
        o_w2[p] = w2
        o_w2n[p] = w2n
        o_w2t[p] = w2t
    else:
        # not computed: NaN rather than a plausible-looking zero
        for a_ in range(3):
            o_dPi[p, a_] = np.nan
            o_T3[p, a_] = np.nan
            for b_ in range(3):
                o_tanL[p, a_, b_] = np.nan
        o_w2[p] = np.nan
        o_w2n[p] = np.nan
        o_w2t[p] = np.nan


@njit(cache=True)
def update_serial(d1, d2, alpha, N1, T1, N2, l1, l2, cos_a, sin_a, was_open, eps, V0, de,
                  cos_t, sin_t, omega, kn, kt, mu, r_g, allow_sliding, extras,
                  o_d1, o_d2, o_alpha, o_N1, o_T1, o_N2, o_l1, o_l2, o_cos_a, o_sin_a, o_sliding, o_open,
                  o_sig, o_tan, o_tanL, o_dPi, o_T3, o_w2, o_w2n, o_w2t):
    """The update of every point, one thread (arguments: see the module docstring)."""
    for p in range(d1.shape[0]):
        _update_point(p, d1, d2, alpha, N1, T1, N2, l1, l2, cos_a, sin_a, was_open, eps, V0, de,
                      cos_t, sin_t, omega, kn, kt, mu, r_g, allow_sliding, extras, True,
                      o_d1, o_d2, o_alpha, o_N1, o_T1, o_N2, o_l1, o_l2, o_cos_a, o_sin_a, o_sliding, o_open,
                      o_sig, o_tan, o_tanL, o_dPi, o_T3, o_w2, o_w2n, o_w2t)


@njit(cache=True, parallel=True)
def update_parallel(d1, d2, alpha, N1, T1, N2, l1, l2, cos_a, sin_a, was_open, eps, V0, de,
                    cos_t, sin_t, omega, kn, kt, mu, r_g, allow_sliding, extras,
                    o_d1, o_d2, o_alpha, o_N1, o_T1, o_N2, o_l1, o_l2, o_cos_a, o_sin_a, o_sliding, o_open,
                    o_sig, o_tan, o_tanL, o_dPi, o_T3, o_w2, o_w2n, o_w2t):
    """The same, points spread over threads (each point is independent: same results)."""
    for p in prange(d1.shape[0]):
        _update_point(p, d1, d2, alpha, N1, T1, N2, l1, l2, cos_a, sin_a, was_open, eps, V0, de,
                      cos_t, sin_t, omega, kn, kt, mu, r_g, allow_sliding, extras, True,
                      o_d1, o_d2, o_alpha, o_N1, o_T1, o_N2, o_l1, o_l2, o_cos_a, o_sin_a, o_sliding, o_open,
                      o_sig, o_tan, o_tanL, o_dPi, o_T3, o_w2, o_w2n, o_w2t)


@njit(cache=True)
def update_general(d1, d2, alpha, N1, T1, N2, l1, l2, cos_a, sin_a, was_open, eps, V0, de,
                   cos_t, sin_t, omega, kn, kt, mu, r_g, allow_sliding, extras,
                   o_d1, o_d2, o_alpha, o_N1, o_T1, o_N2, o_l1, o_l2, o_cos_a, o_sin_a, o_sliding, o_open,
                   o_sig, o_tan, o_tanL, o_dPi, o_T3, o_w2, o_w2n, o_w2t):
    """``update_serial`` with every hexagon through the general loop, no fast pass: the
    reference the fast pass is tested against (tests/hmodel/test_fast_pass.py); the same bits.
    Compiled on its first call only (not by ``compile_kernels``)."""
    for p in range(d1.shape[0]):
        _update_point(p, d1, d2, alpha, N1, T1, N2, l1, l2, cos_a, sin_a, was_open, eps, V0, de,
                      cos_t, sin_t, omega, kn, kt, mu, r_g, allow_sliding, extras, False,
                      o_d1, o_d2, o_alpha, o_N1, o_T1, o_N2, o_l1, o_l2, o_cos_a, o_sin_a, o_sliding, o_open,
                      o_sig, o_tan, o_tanL, o_dPi, o_T3, o_w2, o_w2n, o_w2t)


def allocate_outputs(npts, ndir):
    """Output arrays of the update kernel, in its argument order."""
    f = lambda: np.empty((npts, ndir))
    return (f(), f(), f(), f(), f(), f(), f(), f(), f(), f(),
            np.empty((npts, ndir), dtype=np.bool_), np.empty((npts, ndir), dtype=np.bool_),
            np.empty((npts, 3)), np.empty((npts, 3, 3)), np.empty((npts, 3, 3)),
            np.empty((npts, 3)), np.empty((npts, 3)),
            np.empty(npts), np.empty(npts), np.empty(npts))


@njit(cache=True, inline="always")
def _to_strain(ep, Ainv, de):
    """de (1, 3) = A^-1 e' of the controlled variables e' (1, 3) (a general mixed control)."""
    for i in range(3):
        acc = 0.0
        for j in range(3):
            acc += Ainv[i, j] * ep[0, j]
        de[0, i] = acc


@njit(cache=True, inline="always")
def _to_controlled(de, A, ep):
    """ep (3,) = A de of a strain increment de (3,): its controlled variables."""
    for i in range(3):
        acc = 0.0
        for j in range(3):
            acc += A[i, j] * de[j]
        ep[i] = acc


@njit(cache=True, inline="always")
def _conjugate(sig, Ainv, general, sv):
    """sv (3,) = the stresses conjugate to the controlled variables: A^-T sigma (sigma = sig[0]),
    or sigma itself without ``general``."""
    for i in range(3):
        if general:
            acc = 0.0
            for j in range(3):
                acc += Ainv[j, i] * sig[0, j]
            sv[i] = acc
        else:
            sv[i] = sig[0, i]


@njit(cache=True, inline="always")
def _jacobian(tan, Ainv, general, free, nfree, J):
    """J (nfree, nfree): d s'_a / d e'_b on the free entries: A^-T (d sigma / d de) A^-1, or the
    tangent's own block without ``general``."""
    for a in range(nfree):
        for b in range(nfree):
            if general:
                acc = 0.0
                for i in range(3):
                    for j in range(3):
                        acc += Ainv[i, free[a]] * tan[0, i, j] * Ainv[j, free[b]]
                J[a, b] = acc
            else:
                J[a, b] = tan[0, free[a], free[b]]


@njit(cache=True)
def mixed_step_single(d1, d2, alpha, N1, T1, N2, l1, l2, cos_a, sin_a, was_open, eps, V0,
                      cos_t, sin_t, omega, kn, kt, mu, r_g, allow_sliding, extras,
                      strain_controlled, de_start, target, tol, max_iter,
                      o_d1, o_d2, o_alpha, o_N1, o_T1, o_N2, o_l1, o_l2, o_cos_a, o_sin_a, o_sliding, o_open,
                      o_sig, o_tan, o_tanL, o_dPi, o_T3, o_w2, o_w2n, o_w2t, general, Ainv):
    """Newton with backtracking on the stress-controlled components of one point (npts = 1).

    strain_controlled : (3,) bool; de_start : (3,) start increment (strain-controlled entries are
    the prescribed ones); target : (3,) stress [Pa] of the stress-controlled entries.
    ``general``: the controlled variables are e' = A de and their conjugates s' = A^-T sigma
    (``driver.MixedControl.control_matrix``), with ``Ainv`` = A^-1 (3, 3): then ``de_start`` and
    ``target`` are in those variables and Newton runs on the free entries of e' with the
    Jacobian A^-T (d sigma / d de) A^-1; without it (A = I, ``Ainv`` unused) none of these
    products is formed (the operations of the plain mixed control, the same bits).
    Outputs (the ``o_*`` buffers) hold the accepted update. Returns (iterations, residual,
    d_eps (1, 3), the strain increment itself whatever the variables); iterations = -1 when
    Newton did not converge in ``max_iter``, -2 when the tangent on the stress-controlled
    components is singular (e.g. every hexagon open, or a tie along which nothing resists).
    """
    nfree = 0
    free = np.empty(3, dtype=np.int64)
    for k in range(3):
        if not strain_controlled[k]:
            free[nfree] = k
            nfree += 1
    ep = de_start.copy().reshape(1, 3)       # the controlled variables (A = I: de itself)
    de = ep.copy()
    if general:
        _to_strain(ep, Ainv, de)
    sv = np.empty(3)                          # the conjugate stresses s' of the free entries
    ndir = d1.shape[1]
    # trial buffers for the backtracking line search
    b_d1 = np.empty((1, ndir)); b_d2 = np.empty((1, ndir)); b_al = np.empty((1, ndir))
    b_N1 = np.empty((1, ndir)); b_T1 = np.empty((1, ndir)); b_N2 = np.empty((1, ndir))
    b_l1 = np.empty((1, ndir)); b_l2 = np.empty((1, ndir))
    b_ca = np.empty((1, ndir)); b_sa = np.empty((1, ndir))
    b_sl = np.empty((1, ndir), dtype=np.bool_); b_op = np.empty((1, ndir), dtype=np.bool_)
    b_sig = np.empty((1, 3)); b_tan = np.empty((1, 3, 3)); b_tanL = np.empty((1, 3, 3))
    b_dPi = np.empty((1, 3)); b_T3 = np.empty((1, 3))
    b_w2 = np.empty(1); b_w2n = np.empty(1); b_w2t = np.empty(1)
    update_serial(d1, d2, alpha, N1, T1, N2, l1, l2, cos_a, sin_a, was_open, eps, V0, de,
                  cos_t, sin_t, omega, kn, kt, mu, r_g, allow_sliding, extras,
                  o_d1, o_d2, o_alpha, o_N1, o_T1, o_N2, o_l1, o_l2, o_cos_a, o_sin_a, o_sliding, o_open,
                  o_sig, o_tan, o_tanL, o_dPi, o_T3, o_w2, o_w2n, o_w2t)
    _conjugate(o_sig, Ainv, general, sv)
    rn = 0.0
    for k in range(nfree):
        rn = max(rn, abs(sv[free[k]] - target[free[k]]))
    if nfree == 0:
        return 1, 0.0, de
    J = np.empty((nfree, nfree))
    r = np.empty(nfree)
    trial_ep = ep.copy()
    trial = de.copy()
    for it in range(1, max_iter + 1):
        if rn <= tol:
            return it, rn, de
        for a in range(nfree):
            r[a] = sv[free[a]] - target[free[a]]
        _jacobian(o_tan, Ainv, general, free, nfree, J)
        jmax = np.max(np.abs(J))
        if not (jmax > 0.0) or abs(np.linalg.det(J)) <= 1e-13 * jmax ** nfree:
            return -2, rn, de        # no stiffness on the stress-controlled components
        step = np.linalg.solve(J, r)
        lam = 1.0
        trial_ep[:, :] = ep
        while True:
            for a in range(nfree):
                trial_ep[0, free[a]] = ep[0, free[a]] - lam * step[a]
            if general:
                _to_strain(trial_ep, Ainv, trial)
            else:
                trial[:, :] = trial_ep
            update_serial(d1, d2, alpha, N1, T1, N2, l1, l2, cos_a, sin_a, was_open, eps, V0, trial,
                          cos_t, sin_t, omega, kn, kt, mu, r_g, allow_sliding, extras,
                          b_d1, b_d2, b_al, b_N1, b_T1, b_N2, b_l1, b_l2, b_ca, b_sa, b_sl, b_op,
                          b_sig, b_tan, b_tanL, b_dPi, b_T3, b_w2, b_w2n, b_w2t)
            _conjugate(b_sig, Ainv, general, sv)
            rt = 0.0
            for a in range(nfree):
                rt = max(rt, abs(sv[free[a]] - target[free[a]]))
            # the stress is continuous but only piecewise smooth (sliding switches): backtrack
            if rt < (1.0 - 1e-4 * lam) * rn or lam < 1e-8:
                break
            lam *= 0.5
        ep[:, :] = trial_ep
        de[:, :] = trial
        rn = rt
        o_d1[:, :] = b_d1; o_d2[:, :] = b_d2; o_alpha[:, :] = b_al
        o_N1[:, :] = b_N1; o_T1[:, :] = b_T1; o_N2[:, :] = b_N2
        o_l1[:, :] = b_l1; o_l2[:, :] = b_l2; o_cos_a[:, :] = b_ca; o_sin_a[:, :] = b_sa
        o_sliding[:, :] = b_sl; o_open[:, :] = b_op
        o_sig[:, :] = b_sig; o_tan[:, :, :] = b_tan; o_tanL[:, :, :] = b_tanL
        o_dPi[:, :] = b_dPi; o_T3[:, :] = b_T3; o_w2[:] = b_w2; o_w2n[:] = b_w2n; o_w2t[:] = b_w2t
    if rn <= tol:
        return max_iter, rn, de
    return -1, rn, de


@njit(cache=True)
def path_single(d1, d2, alpha, N1, T1, N2, l1, l2, cos_a, sin_a, was_open, eps, V0,
                cos_t, sin_t, omega, kn, kt, mu, r_g,
                strain_controlled, d_eps, sig_start, d_sigma, k_start, n_steps, guess, tol, max_iter,
                h_de, h_sig, h_it, h_nsl, h_nop, last_sliding, general, A, Ainv):
    """``n_steps`` mixed-control steps of one point, in place on the state arrays (copies owned
    by the caller). Step k (1-based, from ``k_start`` + 1) targets sig_start + k d_sigma on the
    stress-controlled entries. Histories h_* get one row per step: strain increment (3,),
    stress (3,), Newton iterations, sliding and open counts. Returns the number of steps done
    (fewer than ``n_steps`` when a step failed), the last residual and the failure code of
    ``mixed_step_single`` (0 if none). ``general``: d_eps, sig_start and d_sigma are in the
    controlled variables e' = A de, s' = A^-T sigma (A (3, 3), Ainv its inverse; see
    ``mixed_step_single``); ``guess`` and the histories are strain and stress themselves."""
    ndir = d1.shape[1]
    out_h = [np.empty((1, ndir)) for _ in range(10)]
    o_sl = np.empty((1, ndir), dtype=np.bool_)
    o_op = np.empty((1, ndir), dtype=np.bool_)
    o_sig = np.empty((1, 3)); o_tan = np.empty((1, 3, 3)); o_tanL = np.empty((1, 3, 3))
    o_dPi = np.empty((1, 3)); o_T3 = np.empty((1, 3))
    o_w2 = np.empty(1); o_w2n = np.empty(1); o_w2t = np.empty(1)
    target = np.empty(3)
    de0 = guess.copy()
    if general:
        _to_controlled(guess, A, de0)
    rn = 0.0
    for k in range(n_steps):
        for c in range(3):
            target[c] = sig_start[c] + (k_start + k + 1) * d_sigma[c]
            if strain_controlled[c]:
                de0[c] = d_eps[c]
        it, rn, de = mixed_step_single(d1, d2, alpha, N1, T1, N2, l1, l2, cos_a, sin_a, was_open, eps, V0,
                                       cos_t, sin_t, omega, kn, kt, mu, r_g, True, False,
                                       strain_controlled, de0, target, tol, max_iter,
                                       out_h[0], out_h[1], out_h[2], out_h[3], out_h[4], out_h[5],
                                       out_h[6], out_h[7], out_h[8], out_h[9], o_sl, o_op,
                                       o_sig, o_tan, o_tanL, o_dPi, o_T3, o_w2, o_w2n, o_w2t,
                                       general, Ainv)
        if it < 0:
            return k, rn, it
        d1[:, :] = out_h[0]; d2[:, :] = out_h[1]; alpha[:, :] = out_h[2]
        N1[:, :] = out_h[3]; T1[:, :] = out_h[4]; N2[:, :] = out_h[5]
        l1[:, :] = out_h[6]; l2[:, :] = out_h[7]; cos_a[:, :] = out_h[8]; sin_a[:, :] = out_h[9]
        was_open[:, :] = o_op
        last_sliding[:, :] = o_sl
        for c in range(3):
            eps[0, c] += de[0, c]
            de0[c] = de[0, c]
            h_de[k, c] = de[0, c]
            h_sig[k, c] = o_sig[0, c]
        if general:
            _to_controlled(de[0], A, de0)      # the next step's guess, in e'

        h_it[k] = it
        ns = 0
        no = 0
        for i in range(ndir):
            if o_sl[0, i]:
                ns += 1
            if o_op[0, i]:
                no += 1
        h_nsl[k] = ns
        h_nop[k] = no
    return n_steps, rn, 0


@njit(cache=True)
def row_fractions(flags):
    """(npts,) fraction of the True flags of each row of (npts, n_dir) bools: the integer count
    / n_dir, the value (and bits) of flags.mean(axis=-1), without numpy's conversion of the
    flags to numbers."""
    npts, n = flags.shape
    out = np.empty(npts)
    for p in range(npts):
        c = 0
        for i in range(n):
            c += flags[p, i]
        out[p] = c / n
    return out


@njit(cache=True)
def n_differ(a, b):
    """Number of entries where two bool arrays of the same shape differ."""
    x = a.ravel()
    y = b.ravel()
    c = 0
    for i in range(x.size):
        c += x[i] != y[i]
    return c
