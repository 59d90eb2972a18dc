"""The linear algebra of the global check (``global_check``): sparse direct (SuperLU) and banded
factorizations, the signs, inertias and smallest eigenvalues read from them, and the number of
OpenBLAS threads while they run.

- ``det_sign``, ``permutation_parity``: sign and log10 |det| of a sparse matrix from its LU
  (SuperLU: unit-diagonal L, the parity of the row and column permutations);
- ``symmetric_inertia``, ``lam_min_sym``: the number of negative eigenvalues of a sparse
  symmetric matrix from the pivots of its L D L^T (Sylvester), its smallest eigenvalue (ARPACK
  shift-invert, certified by an inertia);
- banded storage: ``band_layout`` finds, once per sparsity pattern, a dof order of small
  half-bandwidth (reverse Cuthill-McKee or the dofs sorted along the specimen's axes) and the
  indices that gather a stiffness's entries into band storage; ``band_lu`` (LAPACK's dgbtrf /
  dgbtrs, partial pivoting) and ``band_sym`` (the Numba L D L^T without pivoting of
  ``_band_ldlt``, at any shift) factorize it; ``_SparseSym`` is SuperLU's symmetric mode behind
  the same ``factor(t)`` (above ``GlobalCheck.MAX_BAND``);
- ``transposed_positions``, ``sym_part``: (K + K^T) / 2 on K's own pattern, without scipy's sum;
- ``one_blas_thread``: OpenBLAS on one thread inside a ``with`` block.
"""
from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

__all__ = ["one_blas_thread", "permutation_parity", "det_sign", "symmetric_inertia",
           "lam_min_sym", "BandLayout", "band_layout", "band_lu", "band_sym",
           "transposed_positions", "sym_part"]


_BLAS = None


def _openblas_handles() -> list:
    """(get_num_threads, set_num_threads) ctypes pairs of every OpenBLAS mapped into this process
    (numpy's and scipy's bundled ``scipy_openblas``, or a system ``libopenblas``), read from
    /proc/self/maps; [] where there is none or no such file (then nothing is changed)."""
    global _BLAS
    if _BLAS is None:
        import ctypes
        _BLAS = []
        try:
            with open("/proc/self/maps") as f:
                paths = sorted({ln.split()[-1] for ln in f if "openblas" in ln.lower() and "/" in ln})
        except OSError:
            paths = []
        for path in paths:
            try:
                lib = ctypes.CDLL(path)
            except OSError:
                continue
            for pre in ("scipy_openblas", "openblas"):
                for suf in ("", "64_"):
                    get = getattr(lib, f"{pre}_get_num_threads{suf}", None)
                    put = getattr(lib, f"{pre}_set_num_threads{suf}", None)
                    if get is not None and put is not None:
                        _BLAS.append((get, put))
                        break
                else:
                    continue
                break
    return _BLAS


class one_blas_thread:
    """Context manager: OpenBLAS on one thread inside, the previous counts restored after. The
    global check's dense kernels (SuperLU's supernodes, ARPACK's orthogonalization on ~10^3 dofs)
    are too small for threads, and on a shared 2-core machine OpenBLAS threads fight for the
    cores (measured: the indicators of a 20 x 40 step 76 -> 33 ms with one core busy elsewhere)."""

    def __enter__(self):
        self._old = [(put, get()) for get, put in _openblas_handles()]
        for put, _ in self._old:
            put(1)
        return self

    def __exit__(self, *exc):
        for put, n in self._old:
            put(n)
        return False


def permutation_parity(perm: np.ndarray) -> int:
    """+1 for an even permutation (array of images of 0..n-1), -1 for an odd one."""
    return int(_parity(np.ascontiguousarray(perm, dtype=np.int64)))


@numba.njit(cache=True, boundscheck=True)
def _parity(perm):
    n = perm.size
    seen = np.zeros(n, dtype=np.bool_)
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
    return _lu_det(lu)


def _lu_det(lu) -> tuple[int, float]:
    """(sign, log10 |det|) of the matrix factorized by a SuperLU object (unit-diagonal L)."""
    d = lu.U.diagonal()
    if np.any(d == 0):
        return 0, -np.inf
    s = int(np.prod(np.sign(d))) * permutation_parity(lu.perm_r) * permutation_parity(lu.perm_c)
    return s, float(np.sum(np.log10(np.abs(d))))


def _sym_ldlt(S):
    """Symmetric-mode SuperLU of a sparse symmetric csc matrix S, P^T S P = L D L^T (no pivoting
    off the diagonal). Returns (lu or None, n_neg): n_neg is the number of negative pivots = of
    negative eigenvalues (Sylvester) when the symmetric permutation was kept and no pivot is zero,
    else -1 (no inertia certificate; lu is still a valid LU for solves unless it is None)."""
    try:
        lu = spla.splu(S, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                       options=dict(SymmetricMode=True))
    except RuntimeError:
        return None, -1
    d = lu.U.diagonal()
    if np.any(d == 0) or not np.all(np.isfinite(d)):
        return None, -1
    if not np.array_equal(lu.perm_r, lu.perm_c):
        return lu, -1
    return lu, int(np.count_nonzero(d < 0))


def symmetric_inertia(S) -> int:
    """Number of negative eigenvalues of a sparse symmetric matrix, or -1 if the symmetric-mode
    LU had to pivot off the diagonal (then the diagonal of U is not an inertia certificate)."""
    return _sym_ldlt(sp.csc_matrix(S))[1]


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


@numba.njit(cache=True)
def _band_ldlt(A, shift):
    """L D L^T of S - shift I without pivoting, S symmetric in lower band storage A (n, w + 1),
    A[i, k] = S[i, i - k]. Returns (F, n_neg): F[i, 0] = D_i, F[i, k] = L[i, i - k]; n_neg the
    number of negative pivots (= of negative eigenvalues, Sylvester), -1 on a zero or non-finite
    pivot (no certificate, F unusable). Column j of L is copied into a contiguous vector before
    its rank-one update (step j never writes column j: the same operations in the same order as
    reading it in place, the same bits, without the strided reads; 2.6 x faster measured on
    3280 dofs, half-bandwidth 45)."""
    n = A.shape[0]
    w = A.shape[1] - 1
    F = A.copy()
    for i in range(n):
        F[i, 0] -= shift
    neg = 0
    v = np.empty(max(w, 1))
    for j in range(n):
        dj = F[j, 0]
        if dj == 0.0 or not np.isfinite(dj):
            return F, -1
        if dj < 0.0:
            neg += 1
        imax = min(n, j + w + 1)
        for i in range(j + 1, imax):
            F[i, i - j] /= dj
        for k in range(j + 1, imax):
            v[k - j - 1] = F[k, k - j]
        for i in range(j + 1, imax):
            c = F[i, i - j] * dj
            if c != 0.0:
                for k in range(j + 1, i + 1):
                    F[i, i - k] -= c * v[k - j - 1]
    return F, neg


@numba.njit(cache=True)
def _band_solve(F, b):
    """x = (L D L^T)^{-1} b for the factors F of ``_band_ldlt``."""
    n = F.shape[0]
    w = F.shape[1] - 1
    x = b.copy()
    for i in range(n):                      # L y = b
        s = x[i]
        for k in range(1, min(w, i) + 1):
            s -= F[i, k] * x[i - k]
        x[i] = s
    for i in range(n):                      # D z = y
        x[i] /= F[i, 0]
    for i in range(n - 1, -1, -1):          # L^T x = z
        s = x[i]
        for k in range(1, min(w, n - 1 - i) + 1):
            s -= F[i + k, k] * x[i + k]
        x[i] = s
    return x


class _SparseSym:
    """sym(K_d) (csc) factorized at a shift by SuperLU's symmetric mode (``_sym_ldlt``)."""

    def __init__(self, Sd):
        self.S = Sd

    def factor(self, t: float):
        """(solve or None, n_neg or -1) of S - t I."""
        A = self.S if t == 0.0 else (self.S - t * sp.identity(self.S.shape[0], format="csc")).tocsc()
        lu, n_neg = _sym_ldlt(A)
        return (None if lu is None else lu.solve), n_neg


class _BandSym:
    """sym(K_d) in lower band storage (n, w + 1) in the dof order ``perm`` (new -> old),
    factorized at a shift by ``_band_ldlt``: the same L D L^T without pivoting as SuperLU's
    symmetric mode, in a banded order instead of a fill-reducing one (measured on 1679 dofs,
    half-bandwidth 45: 0.6-1.4 ms a factorization instead of 4.1 ms)."""

    def __init__(self, band: np.ndarray, perm: np.ndarray):
        self.band, self.perm = band, perm

    def factor(self, t: float):
        F, n_neg = _band_ldlt(self.band, float(t))
        if n_neg < 0:
            return None, -1
        perm = self.perm

        def solve(r):
            x = np.empty_like(r)
            x[perm] = _band_solve(F, np.ascontiguousarray(r[perm]))
            return x
        return solve, n_neg


class _BandLU:
    """LU with partial pivoting of K_d in LAPACK general band storage ab (3 w + 1, n) (kl = ku =
    w, A[i, j] at ab[2 w + i - j, j]) in the dof order ``perm`` (new -> old), by dgbtrf: sign
    det = prod sign(U_ii) x (-1)^(row interchanges), 0 if exactly singular; solves by dgbtrs."""

    def __init__(self, ab: np.ndarray, w: int, perm: np.ndarray):
        from scipy.linalg import lapack
        self._trs = lapack.dgbtrs
        self.w, self.perm = w, perm
        n = ab.shape[1]
        self.shape = (n, n)
        self.lu, self.piv, info = lapack.dgbtrf(ab, w, w)
        d = self.lu[2 * w]
        if info != 0 or np.any(d == 0) or not np.all(np.isfinite(d)):
            self.sign, self.log10_abs = 0, -np.inf
            return
        swaps = int(np.count_nonzero(self.piv != np.arange(n)))
        self.sign = int(np.prod(np.sign(d))) * (-1 if swaps % 2 else 1)
        self.log10_abs = float(np.sum(np.log10(np.abs(d))))

    def solve(self, r: np.ndarray, trans: str = "N") -> np.ndarray:
        x, info = self._trs(self.lu, self.w, self.w, r[self.perm], self.piv,
                            trans=0 if trans == "N" else 1)
        out = np.empty_like(x)
        out[self.perm] = x
        return out


class BandLayout(NamedTuple):
    """Where the entries of a stiffness K (csr, one sparsity pattern) go in band storage of
    K[free, free] (n dofs, half-bandwidth w) in the dof order ``perm`` (new -> old): ``sel`` selects the
    entries of K.data in free rows and columns; ``idx`` and ``wts`` gather them into the lower
    band (n, w + 1) of the symmetric part ((K_ij + K_ji) / 2 off the diagonal); ``gidx`` into
    LAPACK's general band (3 w + 1, n), kl = ku = w."""
    sel: np.ndarray
    idx: np.ndarray
    wts: np.ndarray
    n: int
    w: int
    perm: np.ndarray
    gidx: np.ndarray


def band_layout(K, free: np.ndarray, ndofs: int, xy: np.ndarray | None,
                max_band: int) -> BandLayout | None:
    """The ``BandLayout`` of K[free, free] in the dof order of smallest half-bandwidth among
    reverse Cuthill-McKee and, with the dof coordinates ``xy`` (ndofs, 2), the dofs sorted along
    the specimen's long then short axis; None if that half-bandwidth is above ``max_band``."""
    from scipy.sparse.csgraph import reverse_cuthill_mckee
    n = free.size
    pos = np.full(ndofs, -1)
    pos[free] = np.arange(n)
    rows = np.repeat(np.arange(ndofs), np.diff(K.indptr))
    sel = (pos[rows] >= 0) & (pos[K.indices] >= 0)
    i, j = pos[rows[sel]], pos[K.indices[sel]]
    P = sp.coo_matrix((np.ones(i.size), (i, j)), shape=(n, n)).tocsr()
    orders = [np.asarray(reverse_cuthill_mckee((P + P.T).tocsr(), symmetric_mode=True))]
    if xy is not None:
        xy = xy[free]
        major = int(np.argmax(np.ptp(xy, axis=0)))
        orders.append(np.lexsort((np.arange(n), xy[:, 1 - major], xy[:, major])))
    best = None
    for perm in orders:
        inv = np.empty(n, dtype=np.int64)
        inv[perm] = np.arange(n)
        w = int(np.max(np.abs(inv[i] - inv[j]), initial=0))
        if best is None or w < best[0]:
            best = (w, perm, inv)
    w, perm, inv = best
    if w > max_band:
        return None
    ii, jj = inv[i], inv[j]
    idx = np.maximum(ii, jj) * (w + 1) + np.abs(ii - jj)
    wts = np.where(ii == jj, 1.0, 0.5)            # (K_ij + K_ji) / 2 off the diagonal
    gidx = (2 * w + ii - jj) * n + jj             # LAPACK general band, kl = ku = w
    return BandLayout(sel, idx, wts, n, w, perm, gidx)


def band_sym(lay: BandLayout, K) -> _BandSym:
    """sym(K[free, free]) in lower band storage, gathered from K.data, ready to factorize at any
    shift."""
    band = np.bincount(lay.idx, weights=lay.wts * K.data[lay.sel], minlength=lay.n * (lay.w + 1))
    return _BandSym(band.reshape(lay.n, lay.w + 1), lay.perm)


def band_lu(lay: BandLayout, K) -> _BandLU:
    """The LU with partial pivoting of K[free, free] in general band storage, gathered from
    K.data."""
    n, w = lay.n, lay.w
    ab = np.zeros((3 * w + 1) * n)
    ab[lay.gidx] = K.data[lay.sel]
    return _BandLU(ab.reshape(3 * w + 1, n), w, lay.perm)


def transposed_positions(Kd):
    """For a canonical Kd (csc: columns, rows sorted in each) with a symmetric pattern, the
    position in Kd.data of the entry (j, i) of each entry (i, j); None otherwise."""
    n = Kd.shape[0]
    col = np.repeat(np.arange(n, dtype=np.int64), np.diff(Kd.indptr))
    row = Kd.indices.astype(np.int64)
    key = col * n + row
    if key.size == 0 or not np.all(np.diff(key) > 0):
        return None
    tkey = row * n + col
    pos = np.minimum(np.searchsorted(key, tkey), key.size - 1)
    return pos if np.array_equal(key[pos], tkey) else None


def sym_part(Kd, pos):
    """(0.5 * (Kd + Kd.T)).tocsc(), the same arrays: with a symmetric pattern (``pos`` the
    ``transposed_positions`` of Kd) each entry is (a_ij + a_ji) * 0.5 on Kd's pattern, unless
    some a_ij + a_ji is zero (scipy's sum drops those entries: then the expression itself)."""
    if pos is not None and pos.size == Kd.nnz:
        s = Kd.data + Kd.data[pos]
        if not np.any(s == 0):
            return sp.csc_matrix((s * 0.5, Kd.indices.copy(), Kd.indptr.copy()), shape=Kd.shape)
    return (0.5 * (Kd + Kd.T)).tocsc()
