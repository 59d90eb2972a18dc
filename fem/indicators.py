"""Bifurcation indicators: global (condensed stiffness) and local (tangent at each point).

Global, on the condensed tangent stiffness K (free dofs) and K_s = (K + K^T)/2:
- sign of det K from a sparse LU, P_r K P_c = L U (SuperLU, unit-diagonal L):
  sign det K = prod sign(U_ii) * parity(perm_r) * parity(perm_c);
- inertia of K_s (number of negative eigenvalues) from a symmetric-mode LU without row pivoting
  (P^T K_s P = L D L^T, Sylvester's law of inertia), checked to have kept the symmetric permutation;
- smallest eigenvalue of K_s: ARPACK shift-invert (eigsh) near zero, certified by the inertia
  of K_s - (lam - margin) I (no eigenvalue below the one found), so it is the smallest
  eigenvalue, not merely the one nearest zero.

Local, at every quadrature point, from the tangent D (2, 2, 2, 2, npts) in the orthonormal Mandel
basis (e11, e22, sqrt(2) e12), where eps : D : eps = x . D_M x:
- det D_M, det of its symmetric part, its smallest eigenvalue lam_min(D_s) (exact);
- min over unit strain directions x of the normalized second-order work x.D x / (|D x| |x|)
  (Fibonacci sampling of the unit sphere of Mandel strain directions, then a pattern search of
  shrinking rings around the best direction); its sign agrees with lam_min(D_s) up to sampling;
- Rice's indicator min over unit n of det(A(n)), A_jk = n_i D_ijkl n_l (acoustic tensor), sampled
  over n at angles in [0, pi).
"""
from __future__ import annotations

import numba
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

__all__ = ["permutation_parity", "det_sign", "symmetric_inertia", "lam_min_sym",
           "global_indicators", "mandel", "local_indicators", "fibonacci_sphere"]


def permutation_parity(perm: np.ndarray) -> int:
    """+1 for an even permutation (array of images of 0..n-1), -1 for an odd one."""
    perm = np.asarray(perm)
    n = perm.size
    seen = np.zeros(n, dtype=bool)
    cycles = 0
    for i in range(n):
        if not seen[i]:
            cycles += 1
            j = i
            while not seen[j]:
                seen[j] = True
                j = perm[j]
    return 1 if (n - cycles) % 2 == 0 else -1


def det_sign(A) -> tuple[int, float]:
    """(sign of det A, log10 |det A|) of a sparse square matrix; (0, -inf) if exactly singular."""
    try:
        lu = spla.splu(sp.csc_matrix(A))
    except RuntimeError:          # "Factor is exactly singular"
        return 0, -np.inf
    d = lu.U.diagonal()
    if np.any(d == 0):
        return 0, -np.inf
    s = int(np.prod(np.sign(d))) * permutation_parity(lu.perm_r) * permutation_parity(lu.perm_c)
    return s, float(np.sum(np.log10(np.abs(d))))


def symmetric_inertia(S) -> int:
    """Number of negative eigenvalues of a sparse symmetric matrix, or -1 if the symmetric-mode
    LU had to pivot off the diagonal (then the diagonal of U is not an inertia certificate)."""
    try:
        lu = spla.splu(sp.csc_matrix(S), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                       options=dict(SymmetricMode=True))
    except RuntimeError:
        return -1
    if not np.array_equal(lu.perm_r, lu.perm_c):
        return -1
    d = lu.U.diagonal()
    if np.any(d == 0) or not np.all(np.isfinite(d)):
        return -1
    return int(np.count_nonzero(d < 0))


def lam_min_sym(S, rel_shift: float = 1e-7) -> tuple[float, int]:
    """(smallest eigenvalue, number of negative eigenvalues or -1) of a sparse symmetric S.

    If S has no negative pivot (positive semi-definite), the shift sigma = -rel_shift * mean|diag S|
    lies below the spectrum and shift-invert at sigma finds the smallest eigenvalue. Otherwise the
    n_neg + 1 eigenvalues nearest a small negative shift are computed and their minimum lam is
    certified by the inertia of S - (lam - margin) I (no eigenvalue below it); if the certificate
    fails the shift moves below lam and the search repeats.
    """
    S = sp.csc_matrix(S)
    n = S.shape[0]
    n_neg = symmetric_inertia(S)
    scale = float(np.mean(np.abs(S.diagonal()))) or 1.0
    if n <= 8:   # ARPACK needs k < n; tiny problems (one element) are solved densely
        return float(np.linalg.eigvalsh(S.toarray())[0]), n_neg
    eye = sp.identity(n, format="csc")
    sigma = -rel_shift * scale
    k = 1 if n_neg == 0 else min(max(n_neg, 1) + 1, n - 2)
    for _ in range(20):
        try:
            w = spla.eigsh(S, k=k, sigma=sigma, which="LM", return_eigenvectors=False, tol=1e-10)
        except (spla.ArpackNoConvergence, RuntimeError):
            return float("nan"), n_neg
        lam = float(np.min(w))
        if n_neg == 0:
            return lam, n_neg
        margin = 1e-8 * scale + 1e-6 * abs(lam)
        below = symmetric_inertia(S - (lam - margin) * eye)
        if below == 0:
            return lam, n_neg
        if below < 0:                # no certificate possible: best estimate
            return lam, n_neg
        sigma = 4.0 * min(sigma, lam, -abs(lam)) - margin   # an eigenvalue lies below: look lower
    return float("nan"), n_neg


def global_indicators(K, problem) -> dict:
    """Indicators of the full stiffness K (ndofs, ndofs) condensed two ways.

    Displacement-controlled platen (the applied BCs, suffix none): free = problem.free.
    Force-controlled platen (suffix ``_f``): the top u_y tied into one extra free dof, K_f = T^T K T;
    det K_f changes sign at the limit point of the load (the peak of the platen force).
    """
    K = sp.csr_matrix(K)
    out = {}
    Kd = K[problem.free][:, problem.free]
    T = problem.T_platen
    Kf = (T.T @ K @ T).tocsr()
    for suffix, A in (("", Kd), ("_f", Kf)):
        s, logdet = det_sign(A)
        lam, n_neg = lam_min_sym(0.5 * (A + A.T))
        out["det_k_sign" + suffix] = s
        out["log10_abs_det_k" + suffix] = logdet
        out["lam_min_ks" + suffix] = lam
        out["n_neg_ks" + suffix] = n_neg
    return out


def global_w2(du: np.ndarray, df_int: np.ndarray, df_ext: np.ndarray) -> dict:
    """Second-order work of a converged increment: du . dF_int and dF_ext . du [J/m] and their
    normalized forms (divided by |du| |dF|, in [-1, 1])."""
    out = {}
    nu = np.linalg.norm(du)
    for name, df in (("w2_global", df_int), ("w2_ext", df_ext)):
        w = float(du @ df)
        nf = np.linalg.norm(df)
        out[name + "_raw"] = w
        out[name] = w / (nu * nf) if nu > 0 and nf > 0 else 0.0
    return out


# -- local ------------------------------------------------------------------------------------
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
    """Per point: min over the sampled directions X (N, 3) of x.Mx / (|Mx| |x|), then a pattern
    search (rings of 12 directions at radii h/3, 2h/3, h around the best, h /= 3, 4 rounds)."""
    P = M.shape[0]
    N = X.shape[0]
    out = np.empty(P)
    for p in numba.prange(P):
        m = M[p]
        best = 1e300
        bx = 0.0
        by = 0.0
        bz = 1.0
        for n in range(N):
            v = _w2_one(m, X[n, 0], X[n, 1], X[n, 2])
            if v < best:
                best, bx, by, bz = v, X[n, 0], X[n, 1], X[n, 2]
        h = spacing
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
            for r in range(1, 4):
                rad = h * r / 3.0
                for k in range(12):
                    a = 2.0 * np.pi * k / 12.0
                    ca, sa = np.cos(a), np.sin(a)
                    x = cx + rad * (ca * t1x + sa * t2x)
                    y = cy + rad * (ca * t1y + sa * t2y)
                    z = cz + rad * (ca * t1z + sa * t2z)
                    v = _w2_one(m, x, y, z)
                    if v < best:
                        nn = np.sqrt(x * x + y * y + z * z)
                        best, bx, by, bz = v, x / nn, y / nn, z / nn
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
    (P, 16) in C order of (i, j, k, l). Returns (min values, index of the minimizing angle)."""
    P = Dq.shape[0]
    vals = np.empty(P)
    idx = np.empty(P, dtype=np.int64)
    for p in numba.prange(P):
        d = Dq[p]
        best = 1e300
        kb = 0
        for a in range(c.shape[0]):
            n0, n1 = c[a], s[a]
            A = np.zeros((2, 2))
            for j in range(2):
                for k in range(2):
                    A[j, k] = (n0 * n0 * d[0 * 8 + j * 4 + k * 2 + 0] + n0 * n1 * d[0 * 8 + j * 4 + k * 2 + 1]
                               + n1 * n0 * d[1 * 8 + j * 4 + k * 2 + 0] + n1 * n1 * d[1 * 8 + j * 4 + k * 2 + 1])
            v = A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
            if v < best:
                best, kb = v, a
        vals[p] = best
        idx[p] = kb
    return vals, idx


def local_indicators(D: np.ndarray, n_sphere: int = 600, n_angles: int = 180) -> dict:
    """Local indicators of tangents D (2, 2, 2, 2, npts) [Pa]; every output has shape (npts,).

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
    w2 = _w2_min_kernel(np.ascontiguousarray(M), X, spacing)
    out["w2_min"] = w2
    th = np.linspace(0.0, np.pi, n_angles, endpoint=False)
    Dq = np.ascontiguousarray(np.moveaxis(D, -1, 0)).reshape(npts, 16)     # (P, ijkl)
    out["rice_min"], k = _rice_kernel(Dq, np.cos(th), np.sin(th))
    out["rice_angle"] = np.degrees(th[k])
    return out
