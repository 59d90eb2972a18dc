"""The local bifurcation indicators, at every quadrature point, from its tangent D (2, 2, 2, 2,
npts) in the orthonormal Mandel basis (e11, e22, sqrt(2) e12), where eps : D : eps = x . D_M x:
- det D_M, det of its symmetric part, its smallest eigenvalue lam_min(D_s) (exact);
- min over unit strain directions x of the normalized second-order work x.D x / (|D x| |x|)
  (Fibonacci sampling of the unit sphere of Mandel strain directions, then a pattern search of
  shrinking rings around the best direction); its sign agrees with lam_min(D_s) up to sampling;
- Rice's indicator min over unit n of det(A(n)), A_jk = n_i D_ijkl n_l (acoustic tensor), sampled
  over n at angles in [0, pi).

The kernels run on 1 or all Numba threads, whichever is faster here and now
(``common.threads.ThreadChooser``).
"""
from __future__ import annotations

import time

import numba
import numpy as np

from common.threads import ThreadChooser

__all__ = ["mandel", "fibonacci_sphere", "local_indicators"]


_R2 = np.sqrt(2.0)
_MIDX = ((0, 0), (1, 1), (0, 1))
_MW = (1.0, 1.0, _R2)


def mandel(D: np.ndarray) -> np.ndarray:
    """(2, 2, 2, 2, *batch) tangent with minor symmetries -> (3, 3, *batch) Mandel matrix."""
    M = np.empty((3, 3) + D.shape[4:])
    for a, (i, j) in enumerate(_MIDX):
        for b, (k, l) in enumerate(_MIDX):
            M[a, b] = _MW[a] * _MW[b] * D[i, j, k, l]
    return M


def fibonacci_sphere(n: int) -> np.ndarray:
    """(n, 3) quasi-uniform unit vectors on the upper half sphere (z >= 0): x and -x give the same
    normalized second-order work, so the half sphere covers every direction."""
    i = np.arange(n) + 0.5
    z = i / n                                   # uniform in (0, 1): equal-area on the half sphere
    r = np.sqrt(1.0 - z ** 2)
    phi = np.pi * (1.0 + 5.0 ** 0.5) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


@numba.njit(cache=True, parallel=True)
def _w2_min_kernel(M, X, spacing):
    """Per point: min over the sampled unit directions X (N, 3) of x.Mx / (|Mx| |x|), then a
    pattern search (rings of 12 directions at radii h/3, 2h/3, h around the best, h /= 3, 4
    rounds). The sampled pass ranks the directions by the monotone transform v |v| = x.Mx |x.Mx| /
    |Mx|^2 (no square root, a loop the compiler vectorizes); the pattern search evaluates v itself
    (the operations of ``_w2_one``) on the 36 directions of a round in one vectorizable loop, then
    takes the first of them below the best so far (what comparing them one by one, in the same
    order, keeps: the same bits, 5.2 -> 3.9 ms a 3200-point step on one thread); the 12 cos/sin of
    the ring are computed once."""
    P = M.shape[0]
    N = X.shape[0]
    Xx = np.ascontiguousarray(X[:, 0])
    Xy = np.ascontiguousarray(X[:, 1])
    Xz = np.ascontiguousarray(X[:, 2])
    out = np.empty(P)
    ring = 2.0 * np.pi * np.arange(12) / 12.0
    cr, sr = np.cos(ring), np.sin(ring)
    R = 36                                  # 3 radii x 12 angles, radius-major
    rc = np.empty(R)
    rs = np.empty(R)
    ri = np.empty(R)
    for r in range(1, 4):
        for k in range(12):
            rc[(r - 1) * 12 + k] = cr[k]
            rs[(r - 1) * 12 + k] = sr[k]
            ri[(r - 1) * 12 + k] = r
    for p in numba.prange(P):
        m = M[p]
        m00, m01, m02 = m[0, 0], m[0, 1], m[0, 2]
        m10, m11, m12 = m[1, 0], m[1, 1], m[1, 2]
        m20, m21, m22 = m[2, 0], m[2, 1], m[2, 2]
        vals = np.empty(N)
        for n in range(N):
            x, y, z = Xx[n], Xy[n], Xz[n]
            d0 = m00 * x + m01 * y + m02 * z
            d1 = m10 * x + m11 * y + m12 * z
            d2 = m20 * x + m21 * y + m22 * z
            num = x * d0 + y * d1 + z * d2
            vals[n] = num * abs(num) / max(d0 * d0 + d1 * d1 + d2 * d2, 1e-300)   # M x = 0: 0
        nb = 0
        for n in range(1, N):
            if vals[n] < vals[nb]:
                nb = n
        bx, by, bz = Xx[nb], Xy[nb], Xz[nb]
        best = _w2_one(m, bx, by, bz)
        h = spacing
        xs = np.empty(R)
        ys = np.empty(R)
        zs = np.empty(R)
        vs = np.empty(R)
        for _ in range(4):
            # tangent frame at the best direction
            if abs(bz) < 0.9:
                t1x, t1y, t1z = -by, bx, 0.0           # best x e_z
            else:
                t1x, t1y, t1z = 0.0, bz, -by           # best x e_x
            nt = np.sqrt(t1x * t1x + t1y * t1y + t1z * t1z)
            t1x, t1y, t1z = t1x / nt, t1y / nt, t1z / nt
            t2x = by * t1z - bz * t1y
            t2y = bz * t1x - bx * t1z
            t2z = bx * t1y - by * t1x
            cx, cy, cz = bx, by, bz
            for j in range(R):                         # _w2_one at the 36 directions
                rad = h * ri[j] / 3.0
                ca, sa = rc[j], rs[j]
                x = cx + rad * (ca * t1x + sa * t2x)
                y = cy + rad * (ca * t1y + sa * t2y)
                z = cz + rad * (ca * t1z + sa * t2z)
                d0 = m00 * x + m01 * y + m02 * z
                d1 = m10 * x + m11 * y + m12 * z
                d2 = m20 * x + m21 * y + m22 * z
                den = np.sqrt((d0 * d0 + d1 * d1 + d2 * d2) * (x * x + y * y + z * z))
                num = x * d0 + y * d1 + z * d2
                vs[j] = num / den if den != 0.0 else 0.0
                xs[j], ys[j], zs[j] = x, y, z
            jb = -1
            for j in range(R):
                if vs[j] < best:
                    best, jb = vs[j], j
            if jb >= 0:
                x, y, z = xs[jb], ys[jb], zs[jb]
                nn = np.sqrt(x * x + y * y + z * z)
                bx, by, bz = x / nn, y / nn, z / nn
            h /= 3.0
        out[p] = best
    return out


@numba.njit(cache=True, inline="always")
def _w2_one(m, x, y, z):
    d0 = m[0, 0] * x + m[0, 1] * y + m[0, 2] * z
    d1 = m[1, 0] * x + m[1, 1] * y + m[1, 2] * z
    d2 = m[2, 0] * x + m[2, 1] * y + m[2, 2] * z
    den = np.sqrt((d0 * d0 + d1 * d1 + d2 * d2) * (x * x + y * y + z * z))
    if den == 0.0:
        return 0.0
    return (x * d0 + y * d1 + z * d2) / den


@numba.njit(cache=True, parallel=True)
def _rice_kernel(Dq, c, s):
    """min over the angles (cos c, sin s) of det A(n), A_jk = n_i D_ijkl n_l, per point; Dq is
    (P, 16) in C order of (i, j, k, l). Returns (min values, index of the minimizing angle: the
    first one). The products n_i n_l are formed once per angle, det A at every angle of a point
    in one vectorizable loop, then the first minimum (the same bits as one angle at a time)."""
    P = Dq.shape[0]
    A = c.shape[0]
    vals = np.empty(P)
    idx = np.empty(P, dtype=np.int64)
    q00, q01, q10, q11 = c * c, c * s, s * c, s * s      # n0 n0, n0 n1, n1 n0, n1 n1
    for p in numba.prange(P):
        d = Dq[p]
        v = np.empty(A)
        for a in range(A):
            # A_jk = n0 n0 D_0jk0 + n0 n1 D_0jk1 + n1 n0 D_1jk0 + n1 n1 D_1jk1, d[8 i + 4 j + 2 k + l]
            a00 = q00[a] * d[0] + q01[a] * d[1] + q10[a] * d[8] + q11[a] * d[9]
            a01 = q00[a] * d[2] + q01[a] * d[3] + q10[a] * d[10] + q11[a] * d[11]
            a10 = q00[a] * d[4] + q01[a] * d[5] + q10[a] * d[12] + q11[a] * d[13]
            a11 = q00[a] * d[6] + q01[a] * d[7] + q10[a] * d[14] + q11[a] * d[15]
            v[a] = a00 * a11 - a01 * a10
        best = 1e300
        kb = 0
        for a in range(A):
            if v[a] < best:
                best, kb = v[a], a
        vals[p] = best
        idx[p] = kb
    return vals, idx


def local_indicators(D: np.ndarray, n_sphere: int = 600, n_angles: int = 180,
                     one_thread: bool = False) -> dict:
    """Local indicators of tangents D (2, 2, 2, 2, npts) [Pa]; every output has shape (npts,).
    The kernels run on the faster of 1 and all Numba threads (measured as they go), or on one
    with ``one_thread`` (another process has the other core: a biaxial run's global check).

    det_D [Pa^3], det_Ds [Pa^3], lam_min_Ds [Pa], w2_min [-] (min normalized W2 over strain
    directions), rice_min [Pa^2] (min over n of det of the acoustic tensor), rice_angle [deg]
    (the angle of the minimizing n from the x axis).
    """
    npts = D.shape[-1]
    M = np.moveaxis(mandel(D), -1, 0)                    # (P, 3, 3)
    Ms = 0.5 * (M + np.swapaxes(M, 1, 2))
    out = {"det_D": np.linalg.det(M), "det_Ds": np.linalg.det(Ms),
           "lam_min_Ds": np.linalg.eigvalsh(Ms)[:, 0]}
    X = fibonacci_sphere(n_sphere)                       # (N, 3)
    spacing = np.sqrt(2.0 * np.pi / n_sphere)            # typical angular gap [rad]
    th = np.linspace(0.0, np.pi, n_angles, endpoint=False)
    Dq = np.ascontiguousarray(np.moveaxis(D, -1, 0)).reshape(npts, 16)     # (P, ijkl)
    Mc = np.ascontiguousarray(M)
    n_max = numba.get_num_threads()
    n = 1 if one_thread else _LOCAL_THREADS.pick(n_max)
    t0 = time.perf_counter()
    numba.set_num_threads(n)
    try:
        out["w2_min"] = _w2_min_kernel(Mc, X, spacing)
        out["rice_min"], k = _rice_kernel(Dq, np.cos(th), np.sin(th))
    finally:
        numba.set_num_threads(n_max)
    _LOCAL_THREADS.record(n, (time.perf_counter() - t0) / max(npts, 1))
    out["rice_angle"] = np.degrees(th[k])
    return out


# the local kernels' thread count: the faster of 1 and all Numba threads by the running mean of
# the wall time per point of every call, the slower re-tried every 16 calls (the load of a shared
# machine moves). On 2 cores with one kept busy by another process, two threads wait for each
# other (measured 5-22 ms a 3200-point step against 8.2 ms on one thread; 5.0 ms when idle). The
# points are independent: the same bits for any count.
_LOCAL_THREADS = ThreadChooser(retry=16)
