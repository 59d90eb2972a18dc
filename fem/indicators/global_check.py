"""The global bifurcation indicators of the specimen.

On the condensed tangent stiffness K (free dofs) and K_s = (K + K^T)/2, for both platen
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
kept as the test oracle. ``global_w2``: the second-order work of a converged increment.

The factorizations are ``linalg``'s; the check in a process of its own is ``process``'s.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..problem import PatternGather
from .linalg import (_SparseSym, band_layout, band_lu, band_sym, det_sign, lam_min_sym,
                     one_blas_thread, sym_part, transposed_positions, _lu_det)

__all__ = ["GlobalCheck", "global_indicators", "global_indicators_direct", "global_w2"]


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
        """sym(K_d) ready to factorize at any shift: banded (``linalg.band_sym``) in the dof
        order of ``linalg.band_layout`` if its half-bandwidth is at most MAX_BAND; else
        ``_SparseSym``. The band is gathered from K.data through indices computed once per
        sparsity pattern."""
        if self._band is None:
            return _SparseSym(Sd)
        return band_sym(self._band, K)

    def _ensure_pattern(self, K):
        """The banded order and the transposed-entry map of K's sparsity pattern (found once)."""
        pat = self._pattern
        if pat is None or not (np.array_equal(pat[0], K.indptr) and np.array_equal(pat[1], K.indices)):
            self._pattern = (K.indptr.copy(), K.indices.copy())
            self._band = band_layout(K, self.free, self.ndofs, self.xy, self.MAX_BAND)
            self._partner = transposed_positions(self._kd(K))

    def _sym_part(self, Kd):
        """(0.5 * (Kd + Kd.T)).tocsc(), the same arrays (``linalg.sym_part``)."""
        return sym_part(Kd, self._partner)

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
        lu = band_lu(self._band, K)
        return (lu if lu.sign != 0 else None), lu.sign, lu.log10_abs

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
