"""Bifurcation indicators: global (condensed stiffness) and local (tangent at each point).

Global, on the condensed tangent stiffness K (free dofs) and K_s = (K + K^T)/2, for both platen
controls: displacement prescribed (K_d = K[free, free]) and force prescribed (K_f = T^T K T, the
top u_y tied into one extra dof, so K_f = [[K_d, b], [c^T, a]] is K_d bordered by the platen dof).
``GlobalCheck`` (what the biaxial run calls, step after step), in a banded dof order (LAPACK's
banded LU and a banded L D L^T kernel; SuperLU's fill-reducing orders above a half-bandwidth of
``GlobalCheck.MAX_BAND``):
- one LU of K_d with partial pivoting (unit-diagonal L): sign det K_d = prod sign(U_ii) times
  the parity of the row (and, for SuperLU, column) permutations; and with the same LU,
  det K_f = det K_d * z_f, z_f = a - c^T K_d^{-1} b (Schur complement of the platen dof);
- one L D L^T of sym(K_d) without pivoting: n_neg(K_s,d) = negative pivots (Sylvester), and
  n_neg(K_s,f) = n_neg(K_s,d) + [z_s < 0] (Haynsworth inertia additivity, z_s the Schur
  complement of the platen dof in K_s,f);
- smallest eigenvalue of K_s (each control): ARPACK shift-invert ``eigsh`` with k = 1 at a shift
  s proven to lie below the spectrum (inertia of K_s - s I is zero: then the eigenvalue nearest s
  is the smallest), reusing that factorization (the bordered K_s,f - s I is solved through the
  factorization of K_s,d - s I and its scalar Schur complement), from a seeded random start vector,
  then certified by the inertia of K_s - (lam - margin) I (no eigenvalue below the one found);
  the eigenvector is returned (the mode of lowest second-order work);
- the near-null vector of K (right singular vector of the smallest singular value, by
  shift-invert Lanczos on (K^T K)^{-1} with the same LU), on request (at det K sign changes).
``global_indicators_direct`` is the earlier route (two LUs, two LDL^T, ARPACK with k = n_neg + 1),
kept as the test oracle.

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

import time

import numba
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .problem import PatternGather

__all__ = ["permutation_parity", "det_sign", "symmetric_inertia", "lam_min_sym", "GlobalCheck",
           "GlobalCheckProcess",
           "global_indicators", "global_indicators_direct", "global_w2", "mandel",
           "local_indicators", "fibonacci_sphere"]


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


def global_indicators_direct(K, problem) -> dict:
    """The earlier route (the oracle of the tests): indicators of the full stiffness K (ndofs,
    ndofs) condensed two ways, each matrix factorized on its own (2 LUs, 2 LDL^T, eigsh with
    k = n_neg + 1 and its certificates). Same keys and meaning as ``GlobalCheck``.

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


_CONTROLS = ("", "_f")      # column suffixes: platen displacement prescribed, platen force prescribed


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


class _ShiftedLDLT:
    """K_s,d - t I factorized (``_SparseSym`` or ``_BandSym``), and the force-controlled
    K_s,f - t I = [[K_s,d - t I, b_s], [b_s^T, a - t]] through the scalar Schur complement of its
    platen dof, z(t) = a - t - b_s^T y, y = (K_s,d - t I)^{-1} b_s. Inertia: n_neg[""]
    (K_s,d - t I) and n_neg["_f"] = n_neg[""] + [z < 0] (Haynsworth), -1 where there is no
    certificate."""

    def __init__(self, sym, b_s: np.ndarray, a: float, t: float):
        self.t = float(t)
        self._solve, nd = sym.factor(self.t)
        self.n_neg = {"": nd, "_f": -1}
        self.b_s = b_s
        self.z = np.nan
        if self._solve is not None:
            self.y = self._solve(b_s)
            self.z = float(a - t - b_s @ self.y)
            if nd >= 0 and np.isfinite(self.z) and self.z != 0.0:
                self.n_neg["_f"] = nd + int(self.z < 0)

    def usable(self, suffix: str) -> bool:
        return self._solve is not None and (suffix == "" or (np.isfinite(self.z) and self.z != 0.0))

    def solve(self, suffix: str, r: np.ndarray) -> np.ndarray:
        """(K_s - t I)^{-1} r for the control ``suffix``; r (n,) or (n + 1,)."""
        if suffix == "":
            return self._solve(r)
        x0 = self._solve(r[:-1])
        xi = (r[-1] - self.b_s @ x0) / self.z
        return np.append(x0 - xi * self.y, xi)


class GlobalCheck:
    """The global indicators of ``problem`` (a Biaxial) step after step: ``check(K)`` -> (row,
    modes). One LU of K_d, one LDL^T of K_s,d per step, plus the shifted LDL^T of the eigenvalue
    search (see the module docstring); the previous step's lam_min only places the next shift (the
    results do not depend on it beyond the eigen-solver tolerance), the start vectors are seeded
    random vectors, the same at every step.

    row: det_k_sign[_f] (+1, -1, 0 if exactly singular), log10_abs_det_k[_f], lam_min_ks[_f] [Pa]
    (nan if the eigen-solver failed), n_neg_ks[_f] (-1 when no inertia certificate).
    modes: full dof vectors (ndofs,), unit Euclidean norm, prescribed dofs zero, or None:
    ``mode_ks[_f]`` the eigenvector of lam_min(K_s) where lam_min <= 0, ``mode_detk[_f]`` the
    near-null vector of K (right singular vector of its smallest singular value) where the sign
    of det K differs from the previous call's.
    """

    def __init__(self, problem, seed: int = 0, tol: float = 1e-10):
        self.free = np.asarray(problem.free)
        self.ndofs = int(problem.ndofs)
        self.T = problem.T_platen
        self.e_top = np.zeros(self.ndofs)
        self.e_top[problem.top_y] = 1.0
        self.seed = int(seed)
        self.tol = float(tol)
        self.prev_lam = {c: None for c in _CONTROLS}
        self.prev_sign = {c: None for c in _CONTROLS}
        self.xy = None              # dof coordinates (ndofs, 2), for a banded dof order
        mesh, basis = getattr(problem, "mesh", None), getattr(problem, "basis", None)
        if mesh is not None and basis is not None:
            nd = np.asarray(basis.nodal_dofs)
            self.xy = np.zeros((self.ndofs, 2))
            for c in range(nd.shape[0]):
                self.xy[nd[c]] = mesh.p[:2].T
        self._pattern = None
        self._band = None
        self._v0s = {}
        free = self.free
        self._kd = PatternGather(lambda M: M[free][:, free].tocsc())
        self._partner = None        # position in Kd.data of the transposed entry (symmetric pattern)

    def _v0(self, n: int, k: int = 0) -> np.ndarray:
        """The seeded start vector (n,) of attempt k (a copy of the one drawn at the first
        call: the same numbers at every step, drawn once)."""
        key = (n, k)
        v = self._v0s.get(key)
        if v is None:
            v = self._v0s[key] = np.random.default_rng((self.seed, n, k)).standard_normal(n)
        return v.copy()

    def _full(self, suffix: str, v: np.ndarray) -> np.ndarray:
        """A vector of the condensed unknowns -> the full dof vector (ndofs,), unit norm."""
        if suffix == "":
            u = np.zeros(self.ndofs)
            u[self.free] = v
        else:
            u = self.T @ v
        return u / np.linalg.norm(u)

    def __call__(self, K, want_modes: bool = True) -> tuple[dict, dict]:
        with one_blas_thread():
            return self._check(K, want_modes)

    def submit(self, K, want_modes: bool = True) -> None:
        """Start the check of K; ``result()`` gives it (here it runs in ``result``; the same
        protocol as ``GlobalCheckProcess``, which runs it in another process meanwhile)."""
        self._job = (K, want_modes)

    def result(self) -> tuple[dict, dict]:
        K, want_modes = self._job
        self._job = None
        return self(K, want_modes)

    def close(self) -> None:
        pass

    def _check(self, K, want_modes):
        K = sp.csr_matrix(K)
        free = self.free
        self._ensure_pattern(K)
        Kd = self._kd(K)                    # K[free][:, free].tocsc(), gathered
        n = Kd.shape[0]
        kt = K @ self.e_top
        b, c = kt[free], (K.T @ self.e_top)[free]
        a = float(self.e_top @ kt)
        row, modes = {}, {}
        # -- det K_d from one LU, det K_f from the Schur complement of the platen dof
        lu, sd, logd = self._lu_factor(K, Kd)
        zf = np.nan
        if lu is not None and sd != 0:
            y = lu.solve(b)
            zf = float(a - c @ y)
        if np.isfinite(zf):
            sf = sd * int(np.sign(zf))
            logf = logd + np.log10(abs(zf)) if zf != 0 else -np.inf
        else:                       # K_d singular: K_f on its own
            sf, logf = det_sign((self.T.T @ K @ self.T).tocsc())
        for suf, sgn, lg in (("", sd, logd), ("_f", sf, logf)):
            row["det_k_sign" + suf] = int(sgn)
            row["log10_abs_det_k" + suf] = float(lg)
        # -- K_s: inertia at 0 for both controls, then lam_min of each
        Sd = self._sym_part(Kd)
        b_s = 0.5 * (b + c)
        scale = float(np.mean(np.abs(Sd.diagonal()))) or 1.0
        if n <= 8:      # ARPACK needs k < n; tiny problems (one element) are solved densely
            lams = self._dense(Sd, b_s, a)
            F0 = _ShiftedLDLT(_SparseSym(Sd), b_s, a, 0.0)
        else:
            sym = self._sym_factorizer(K, Sd)
            cache = [_ShiftedLDLT(sym, b_s, a, 0.0)]
            F0 = cache[0]
            t_max = {suf: self._shift_bound(suf, F0, scale) for suf in _CONTROLS}
            if F0.n_neg[""] != 0:         # both need a shift below 0: one shift for both
                t_max[""] = t_max["_f"] = min(t_max.values())
            lams = {suf: self._lam_min(suf, cache, Sd, sym, b_s, a, scale, t_max[suf])
                    for suf in _CONTROLS}
        for suf in _CONTROLS:
            lam, vec = lams[suf]
            row["lam_min_ks" + suf] = lam
            row["n_neg_ks" + suf] = F0.n_neg[suf]
            self.prev_lam[suf] = lam if np.isfinite(lam) else None
            if want_modes:
                modes["mode_ks" + suf] = (self._full(suf, vec) if vec is not None and lam <= 0
                                          else None)
        # -- near-null vectors of K where det K changed sign since the previous call
        for suf in _CONTROLS:
            sgn = row["det_k_sign" + suf]
            changed = self.prev_sign[suf] is not None and sgn != self.prev_sign[suf]
            self.prev_sign[suf] = sgn
            if want_modes:
                modes["mode_detk" + suf] = (self._null_vector(suf, lu, b, c, zf)
                                            if changed and lu is not None else None)
        return row, modes

    # -- factorizations of sym(K_d) - t I ----------------------------------------------------
    MAX_BAND = 400        # half-bandwidth above which SuperLU's fill-reducing order is used

    def _sym_factorizer(self, K, Sd):
        """sym(K_d) ready to factorize at any shift: banded (``_BandSym``) in the dof order of
        smallest half-bandwidth among reverse Cuthill-McKee and the dofs sorted along the
        specimen's long then short axis, if that is at most MAX_BAND; else ``_SparseSym``. The
        band is gathered from K.data through indices computed once per sparsity pattern."""
        if self._band is None:
            return _SparseSym(Sd)
        sel, idx, wts, n, w, perm = self._band[:6]
        band = np.bincount(idx, weights=wts * K.data[sel], minlength=n * (w + 1))
        return _BandSym(band.reshape(n, w + 1), perm)

    def _ensure_pattern(self, K):
        """The banded order and the transposed-entry map of K's sparsity pattern (found once)."""
        pat = self._pattern
        if pat is None or not (np.array_equal(pat[0], K.indptr) and np.array_equal(pat[1], K.indices)):
            self._setup_band(K)
            self._setup_partner(self._kd(K))

    def _setup_partner(self, Kd):
        """For a canonical Kd (csc: columns, rows sorted in each) with a symmetric pattern, the
        position in Kd.data of the entry (j, i) of each entry (i, j); None otherwise."""
        self._partner = None
        n = Kd.shape[0]
        col = np.repeat(np.arange(n, dtype=np.int64), np.diff(Kd.indptr))
        row = Kd.indices.astype(np.int64)
        key = col * n + row
        if key.size == 0 or not np.all(np.diff(key) > 0):
            return
        tkey = row * n + col
        pos = np.minimum(np.searchsorted(key, tkey), key.size - 1)
        if np.array_equal(key[pos], tkey):
            self._partner = pos

    def _sym_part(self, Kd):
        """(0.5 * (Kd + Kd.T)).tocsc(), the same arrays: with a symmetric pattern each entry is
        (a_ij + a_ji) * 0.5 on Kd's pattern, unless some a_ij + a_ji is zero (scipy's sum drops
        those entries: then the expression itself)."""
        pos = self._partner
        if pos is not None and pos.size == Kd.nnz:
            s = Kd.data + Kd.data[pos]
            if not np.any(s == 0):
                return sp.csc_matrix((s * 0.5, Kd.indices.copy(), Kd.indptr.copy()), shape=Kd.shape)
        return (0.5 * (Kd + Kd.T)).tocsc()

    def _lu_factor(self, K, Kd):
        """(LU with .shape and .solve(r, trans) or None if singular, sign det K_d, log10 |det
        K_d|): LAPACK's banded LU with partial pivoting (dgbtrf) in the banded dof order, else
        SuperLU (``splu``, sign from U's diagonal and both permutations)."""
        self._ensure_pattern(K)
        if self._band is None:
            try:
                lu = spla.splu(Kd)
            except RuntimeError:        # "Factor is exactly singular"
                return None, 0, -np.inf
            sd, logd = _lu_det(lu)
            return (lu if sd != 0 else None), sd, logd
        sel, _, _, n, w, perm, gidx = self._band
        ab = np.zeros((3 * w + 1) * n)
        ab[gidx] = K.data[sel]
        lu = _BandLU(ab.reshape(3 * w + 1, n), w, perm)
        return (lu if lu.sign != 0 else None), lu.sign, lu.log10_abs

    def _setup_band(self, K):
        from scipy.sparse.csgraph import reverse_cuthill_mckee
        self._pattern = (K.indptr.copy(), K.indices.copy())
        n = self.free.size
        pos = np.full(self.ndofs, -1)
        pos[self.free] = np.arange(n)
        rows = np.repeat(np.arange(self.ndofs), np.diff(K.indptr))
        sel = (pos[rows] >= 0) & (pos[K.indices] >= 0)
        i, j = pos[rows[sel]], pos[K.indices[sel]]
        P = sp.coo_matrix((np.ones(i.size), (i, j)), shape=(n, n)).tocsr()
        orders = [np.asarray(reverse_cuthill_mckee((P + P.T).tocsr(), symmetric_mode=True))]
        if self.xy is not None:
            xy = self.xy[self.free]
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
        if w > self.MAX_BAND:
            self._band = None
            return
        ii, jj = inv[i], inv[j]
        idx = np.maximum(ii, jj) * (w + 1) + np.abs(ii - jj)
        wts = np.where(ii == jj, 1.0, 0.5)            # (K_ij + K_ji) / 2 off the diagonal
        gidx = (2 * w + ii - jj) * n + jj             # LAPACK general band, kl = ku = w
        self._band = (sel, idx, wts, n, w, perm, gidx)

    # -- smallest eigenvalue of K_s ----------------------------------------------------------
    def _dense(self, Sd, b_s, a):
        S = Sd.toarray()
        Sf = np.block([[S, b_s[:, None]], [b_s[None, :], np.array([[a]])]])
        out = {}
        for suf, M in (("", S), ("_f", Sf)):
            w, V = np.linalg.eigh(M)
            out[suf] = (float(w[0]), V[:, 0])
        return out

    def _proven(self, suffix, cache, sym, b_s, a, scale, t_max):
        """A factorization at a shift t <= t_max with n_neg(K_s - t I) = 0 (from the cache or new;
        the shift moves down x4 until the inertia is zero); None if no certificate is possible."""
        ok = [F for F in cache if F.n_neg[suffix] == 0 and F.t <= t_max]
        if ok:
            return max(ok, key=lambda F: F.t)
        t, step = t_max, max(abs(t_max), 1e-6 * scale)
        for _ in range(40):
            F = _ShiftedLDLT(sym, b_s, a, t)
            cache.append(F)
            if F.n_neg[suffix] == 0:
                return F
            if F.n_neg[suffix] < 0:
                return None
            step *= 4.0
            t = t_max - step
        return None

    def _shift_bound(self, suffix, F0, scale):
        """Where to look for a shift below the spectrum: 0 if K_s is positive definite (the
        inertia at 0 is zero), else below the previous step's lam_min by 5 % + 1e-6 scale."""
        if F0.n_neg[suffix] == 0:
            return 0.0
        h = self.prev_lam[suffix]
        h = 0.0 if h is None else min(h, 0.0)
        return h - 0.05 * abs(h) - 1e-6 * scale

    def _lam_min(self, suffix, cache, Sd, sym, b_s, a, scale, t_max):
        """(lam_min, eigenvector) of K_s of the control ``suffix``: eigsh k = 1 at a proven shift
        t <= t_max, certified by a zero inertia at a shift in [lam - 2 margin, lam), margin =
        1e-8 scale + 1e-6 |lam| (scale = mean |diag K_s,d|; a new certificate is factorized at
        lam - margin); (nan, None) if the eigen-solver fails; without a proven shift (no inertia
        certificate at any shift) the direct route ``lam_min_sym``, without the eigenvector."""
        n = Sd.shape[0] + (suffix == "_f")
        F = self._proven(suffix, cache, sym, b_s, a, scale, t_max)
        if F is None or not F.usable(suffix):      # no inertia certificate: the direct route
            S = Sd if suffix == "" else sp.bmat([[Sd, b_s[:, None]], [b_s[None, :], a]])
            return lam_min_sym(S)[0], None
        if suffix == "":
            matvec = Sd.__matmul__
        else:
            def matvec(x):
                return np.append(Sd @ x[:-1] + b_s * x[-1], b_s @ x[:-1] + a * x[-1])
        A = spla.LinearOperator((n, n), matvec=matvec, dtype=float)
        k = 1
        for attempt in range(20):
            OPinv = spla.LinearOperator((n, n), matvec=lambda r, F=F: F.solve(suffix, r), dtype=float)
            try:
                w, V = spla.eigsh(A, k=k, sigma=F.t, which="LM", OPinv=OPinv, tol=self.tol,
                                  v0=self._v0(n, attempt), ncv=min(n, max(2 * k + 1, 10)))
            except (spla.ArpackNoConvergence, RuntimeError):
                return np.nan, None
            i = int(np.argmin(w))
            lam, vec = float(w[i]), V[:, i]
            margin = 1e-8 * scale + 1e-6 * abs(lam)
            if lam - margin <= F.t:          # the proven shift itself certifies it
                return lam, vec
            done = [C for C in cache if lam - 2 * margin <= C.t < lam and C.n_neg[suffix] == 0]
            if done:
                return lam, vec
            C = _ShiftedLDLT(sym, b_s, a, lam - margin)
            cache.append(C)
            below = C.n_neg[suffix]
            if below <= 0:                   # certified (0), or no certificate possible (-1)
                return lam, vec
            k = min(below + 1, n - 2)        # missed: the `below` eigenvalues under lam - margin
        return np.nan, None

    # -- near-null vector of K ----------------------------------------------------------------
    def _null_vector(self, suffix, lu, b, c, zf):
        """Right singular vector of the smallest singular value of K_d or K_f (unit norm, full
        dofs): the largest eigenvector of (K^T K)^{-1} by Lanczos, two LU solves per product."""
        if suffix == "":
            n = lu.shape[0]

            def op(x):
                return lu.solve(lu.solve(x, trans="T"))
        else:
            if not (np.isfinite(zf) and zf != 0):
                return None
            n = lu.shape[0] + 1
            y, yt = lu.solve(b), lu.solve(c, trans="T")

            def solve(r):
                x0 = lu.solve(r[:-1])
                xi = (r[-1] - c @ x0) / zf
                return np.append(x0 - xi * y, xi)

            def solve_t(r):
                x0 = lu.solve(r[:-1], trans="T")
                xi = (r[-1] - b @ x0) / zf
                return np.append(x0 - xi * yt, xi)

            def op(x):
                return solve(solve_t(x))
        if n <= 8:
            M = np.linalg.inv(np.asarray([op(e) for e in np.eye(n)]).T)     # K^T K, dense
            return self._full(suffix, np.linalg.eigh(0.5 * (M + M.T))[1][:, 0])
        A = spla.LinearOperator((n, n), matvec=op, dtype=float)
        try:
            _, V = spla.eigsh(A, k=1, which="LA", v0=self._v0(n, 99), tol=1e-8)
        except (spla.ArpackNoConvergence, RuntimeError):
            return None
        return self._full(suffix, V[:, 0])


class GlobalCheckProcess:
    """``GlobalCheck`` of ``problem`` in a child process, for a run on more than one core: the
    run ``submit``s the stiffness of a converged step and does its local indicators and the
    previous step's output while the child checks it, then takes the ``result``. The child
    checks the steps one after another in their order with one GlobalCheck, so every row and
    mode is the same to the bit as in process.

    The child is forked at the first ``submit``: it shares the problem, the compiled kernels
    and that stiffness's sparsity pattern, and K.data goes through a shared buffer (the
    pattern is the same at every step of a run: only a one-byte message goes through the
    pipe; a new pattern goes whole). It runs no parallel kernel, so it needs none of the
    parent's threads. ``start`` returns None where fork is not available. The child ignores
    SIGINT and SIGTERM (Ctrl-C reaches the whole process group: the parent decides) and ends
    when the parent closes the pipe, or dies (the kernel closes it then)."""

    def __init__(self, problem, seed: int):
        self._problem, self._seed = problem, seed
        self._conn = self._proc = None
        self._pattern = self._buf = None

    @classmethod
    def start(cls, problem, seed: int = 0):
        import multiprocessing
        if "fork" not in multiprocessing.get_all_start_methods():
            return None
        return cls(problem, seed)

    def _fork(self, K):
        import mmap
        import multiprocessing
        import sys
        import warnings
        ctx = multiprocessing.get_context("fork")
        self._pattern = (K.indptr.copy(), K.indices.copy(), K.shape)
        self._buf = np.frombuffer(mmap.mmap(-1, max(K.data.nbytes, 8)), dtype=float)[:K.nnz]
        sys.stdout.flush()      # else the child would write the parent's buffered lines again
        sys.stderr.flush()
        parent, child = ctx.Pipe()
        proc = ctx.Process(target=_check_server,
                           args=(child, parent, self._problem, self._seed, self._pattern,
                                 self._buf), daemon=True, name="fem-global-check")
        with warnings.catch_warnings():
            # Python >= 3.12 warns about fork in a process with threads (Numba's pool): the
            # child runs only single-threaded code and takes no lock those threads hold
            warnings.simplefilter("ignore", DeprecationWarning)
            proc.start()
        child.close()
        self._conn, self._proc = parent, proc

    def submit(self, K, want_modes: bool = True) -> None:
        """Start the check of K (the previous one must have been taken by ``result``)."""
        K = sp.csr_matrix(K)
        if self._proc is None:
            self._fork(K)
        indptr, indices, shape = self._pattern
        if K.shape == shape and np.array_equal(K.indptr, indptr) \
                and np.array_equal(K.indices, indices):
            self._buf[:] = K.data
            self._conn.send_bytes(b"M" if want_modes else b"m")
        else:
            self._conn.send((K.indptr, K.indices, K.data, K.shape, want_modes))

    def result(self) -> tuple[dict, dict]:
        try:
            kind, value = self._conn.recv()
        except EOFError:
            raise RuntimeError(f"the global check's process ended (exit code "
                               f"{self._proc.exitcode})") from None
        if kind == "error":
            raise value
        return value

    def close(self) -> None:
        if self._proc is None:
            return
        try:
            self._conn.close()
        finally:
            self._proc.join(timeout=5)
            if self._proc.is_alive():
                self._proc.kill()
                self._proc.join()
            self._proc = None


def _check_server(conn, parent_end, problem, seed, pattern, buf):
    """The child of GlobalCheckProcess: one GlobalCheck, a step at a time, until the parent
    closes the pipe. A one-byte message: K has ``pattern`` and its data in ``buf`` (shared)."""
    import pickle
    import signal
    parent_end.close()      # the fork copied it: held open here, it would hide the parent's EOF
    for sig in (signal.SIGINT, signal.SIGTERM):     # the parent's to handle; it closes the pipe
        signal.signal(sig, signal.SIG_IGN)
    check = GlobalCheck(problem, seed=seed)
    indptr, indices, shape = pattern
    while True:
        try:
            msg = conn.recv_bytes()
        except (EOFError, OSError):
            return
        if len(msg) == 1:
            K = sp.csr_matrix((buf.copy(), indices, indptr), shape=shape)
            want_modes = msg == b"M"
        else:
            indptr_k, indices_k, data, shape_k, want_modes = pickle.loads(msg)
            K = sp.csr_matrix((data, indices_k, indptr_k), shape=shape_k)
        try:
            out = ("ok", check(K, want_modes))
        except Exception as e:          # to the parent, which raises it
            out = ("error", e)
        try:
            try:
                conn.send(out)
            except (pickle.PicklingError, TypeError, AttributeError):    # an unpicklable error
                conn.send(("error", RuntimeError(f"in the global check's process: {out[1]!r}")))
        except (BrokenPipeError, OSError):    # the parent stopped waiting (its run ended)
            return


def global_indicators(K, problem) -> dict:
    """The indicators of one stiffness K (ndofs, ndofs) of ``problem``, without the step history
    (see ``GlobalCheck``): det_k_sign[_f], log10_abs_det_k[_f], lam_min_ks[_f], n_neg_ks[_f]."""
    return GlobalCheck(problem)(K, want_modes=False)[0]


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


class _ThreadChoice:
    """Which of 1 and n_max Numba threads runs the local kernels faster here and now: the wall
    time per point of every call (running mean), the slower count re-tried every ``retry`` calls
    (the load of a shared machine moves). On 2 cores with one kept busy by another process, two
    threads wait for each other (measured 5-22 ms a 3200-point step against 8.2 ms on one
    thread; 5.0 ms when idle). The points are independent: the same bits for any count."""

    def __init__(self, retry: int = 16):
        self.retry = retry
        self.t = {}
        self.calls = 0
        self.warm = False          # the first call loads the compiled kernels: not timed

    def pick(self, n_max: int) -> int:
        if n_max <= 1:
            return 1
        for n in (1, n_max):
            if n not in self.t:
                return n
        self.calls += 1
        best, other = sorted((1, n_max), key=self.t.get)
        return other if self.calls % self.retry == 0 else best

    def record(self, n: int, seconds_per_point: float) -> None:
        if not self.warm:
            self.warm = True
            return
        old = self.t.get(n)
        self.t[n] = seconds_per_point if old is None else 0.5 * (old + seconds_per_point)


_LOCAL_THREADS = _ThreadChoice()
