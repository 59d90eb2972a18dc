"""Newton iterations with the consistent tangent, load steps with cut-back, commit on convergence.

One load step takes the platen from delta_n to delta_n + h. The unknowns are the free nodal
displacements; the residual is r = f_int(u) - f_lat on the free dofs. Each iterate calls the
material with the TOTAL strain increment of the step from the committed state (the H-model decides
its sliding pattern from that increment), so iterates never pollute the history; the state is
committed only once |r| <= rtol * F_ref, F_ref = sigma2 * height (the lateral load per unit
thickness). With a fixed sliding pattern the update is smooth (linear contact laws, geometric and
volume terms quadratic), so Newton with the exact tangent converges quadratically; an iteration
in which the pattern switches shows a non-quadratic ratio and ``pattern_changes`` > 0 in the log.
"""
from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .problem import Biaxial, PatternGather

__all__ = ["NewtonError", "StepResult", "FreeSolver", "newton_step", "LoadStepper", "StaticLoss",
           "StaticVerdict", "static_scan"]


class NewtonError(RuntimeError):
    """A load step whose Newton iterations did not converge (carries the residual history)."""

    def __init__(self, msg, residuals=()):
        super().__init__(msg)
        self.residuals = list(residuals)


@dataclass
class StepResult:
    """A converged load step.

    u : (ndofs,) displacement [m]; f_int : (ndofs,) internal force [N/m]; trial : the converged
    material Trial (stress, tangent, new states); residuals : normalized residual norm of every
    iterate (first = predictor); pattern_changes : flags switched between successive iterates;
    times : seconds spent in the constitutive update, assembly and linear solves.
    """

    u: np.ndarray
    f_int: np.ndarray
    trial: object
    residuals: list
    pattern_changes: list
    times: dict = field(default_factory=dict)

    @property
    def iterations(self) -> int:
        return len(self.residuals) - 1


class FreeSolver:
    """du = K[free][:, free]^{-1} b for the Newton iterations, step after step: SuperLU's LU
    (``splu`` of K[free][:, free].tocsc(), COLAMD column order), with the matrix gathered from
    K.data (``PatternGather``) and the column order found once per sparsity pattern. The first
    matrix of a pattern is factorized so; its final column order perm_c (COLAMD, then SuperLU's
    postorder of the elimination tree: both from the pattern alone) is kept, and the next
    matrices are gathered with their columns in that order and factorized with
    permc_spec="NATURAL". SuperLU then sees the same columns in the same order (its postorder of
    an already postordered tree is the identity; checked: perm_c must come back as 0..n-1, else
    the plain route), so the same pivots and the same bits, without COLAMD at every iteration
    (5.7 -> 4.4 ms a factorization on the 20 x 40 benchmark's 1679 free dofs)."""

    def __init__(self, free: np.ndarray):
        self.free = np.asarray(free)
        free = self.free
        self._plain = PatternGather(lambda K: K[free][:, free].tocsc())
        self._ordered = None        # (pattern (indptr, indices), PatternGather, inverse order)

    def solve(self, K, b: np.ndarray) -> np.ndarray:
        """K[free][:, free]^{-1} b, b (n_free,) or (n_free, k) (k right-hand sides, one LU)."""
        with warnings.catch_warnings():
            warnings.simplefilter("error", spla.MatrixRankWarning)
            try:
                o = self._ordered
                if o is not None and np.array_equal(o[0][0], K.indptr) \
                        and np.array_equal(o[0][1], K.indices):
                    lu = spla.splu(o[1](K), permc_spec="NATURAL")
                    if np.array_equal(lu.perm_c, np.arange(b.shape[0])):
                        x = np.empty_like(b)
                        x[o[2]] = lu.solve(b)
                        return x
                lu = spla.splu(self._plain(K))
                inv = np.argsort(lu.perm_c)
                plain = self._plain
                self._ordered = ((K.indptr.copy(), K.indices.copy()),
                                 PatternGather(lambda M: plain(M)[:, inv].tocsc()), inv)
                return lu.solve(b)
            except (RuntimeError, spla.MatrixRankWarning) as e:
                raise NewtonError(f"singular tangent stiffness ({e})") from None


def newton_step(prob: Biaxial, u_old: np.ndarray, u_guess: np.ndarray, rtol: float = 1e-10,
                max_iter: int = 25, solver: FreeSolver | None = None) -> StepResult:
    """Equilibrium of the step from the committed displacement ``u_old`` (ndofs,) with the
    prescribed dofs of ``u_guess`` (ndofs,) already set to their end-of-step values; ``solver``
    the linear solver kept from step to step (None: a new one).

    Raises NewtonError when not converged in ``max_iter`` iterations or on a non-finite or
    singular system. Nothing is committed here.
    """
    mat = prob.material
    eps_old = prob.strain(u_old)
    f_ref = prob.sigma2 * prob.height
    free = prob.free
    u = u_guess.copy()
    res, changes = [], []
    times = {"update": 0.0, "assembly": 0.0, "solve": 0.0}
    prev = None
    if solver is None:
        solver = FreeSolver(free)
    for k in range(max_iter + 1):
        t0 = time.perf_counter()
        try:
            trial = mat.trial(prob.strain(u) - eps_old)
        except ValueError as e:      # e.g. non-finite strain increment
            raise NewtonError(f"material update failed: {e}", res) from None
        t1 = time.perf_counter()
        f = prob.internal_force(trial.sigma)
        r = (f - prob.f_lat)[free]
        rn = float(np.linalg.norm(r)) / f_ref
        times["update"] += t1 - t0
        times["assembly"] += time.perf_counter() - t1
        res.append(rn)
        changes.append(0 if prev is None else mat.pattern_changes(prev, trial))
        prev = trial
        if not np.isfinite(rn):
            raise NewtonError("non-finite residual", res)
        if rn <= rtol:
            return StepResult(u, f, trial, res, changes, times)
        if k == max_iter:
            break
        t2 = time.perf_counter()
        K = prob.stiffness(trial.D)
        t3 = time.perf_counter()
        du = solver.solve(K, -r)            # K[free][:, free]^{-1} (-r)
        times["assembly"] += t3 - t2
        times["solve"] += time.perf_counter() - t3
        u[free] += du
    raise NewtonError(f"Newton did not converge in {max_iter} iterations (residual "
                      f"{res[-1]:.3e} > rtol = {rtol:.1e} x sigma2 x height)", res)


class StaticVerdict(NamedTuple):
    """What ``static_scan`` found beyond the last converged state (lengths [m], SI).

    outcome : 'exists' (``result``: a converged state further on), 'uncontrollable' (the platen
        displacement turns at ``delta_max`` < the step's end, det K_ff changing sign: no static
        state beyond under it), 'discontinuous' (it turns there while det K_ff keeps its sign: a
        kink or jump of the response) or 'unresolved' (the path could not be followed further,
        nothing proven).
    delta_start, delta_target, delta_max : the platen displacement of the last converged state,
        of the failed step's end, and the largest one the scan reached [m].
    det_sign, lam_min, w2 : of the free dofs' stiffness K_ff (the controlled block; lam_min and
        w2 of its symmetric part: the smallest eigenvalue [Pa] and the normalized second-order
        work of its eigenvector, v.K v / (|v| |K v|)), before and after the turning point or at
        the last two points of the scan.
    points : converged points of the scan; result : (StepResult, platen displacement) of the
        state accepted when it exists, else None.
    """

    outcome: str
    delta_start: float
    delta_target: float
    delta_max: float
    det_sign: tuple
    lam_min: tuple
    w2: tuple
    points: int
    result: object = None

    def line(self, height: float) -> str:
        """In words, strains as delta / height."""
        e = lambda d: f"{100 * d / height:.4f} %"      # noqa: E731
        if self.outcome == "unresolved":
            return (f"the equilibrium path could not be followed past eps1 = {e(self.delta_max)} "
                    f"(the step to {e(self.delta_target)} asked) and det K_ff kept its sign "
                    f"({self.det_sign[0]:+d}, {self.det_sign[1]:+d}; lam_min {self.lam_min[0]:.4g}, "
                    f"{self.lam_min[1]:.4g} Pa): no limit point (W2 > 0 for this control), no "
                    "static state found either")
        if self.outcome == "uncontrollable":
            return (f"uncontrollable at eps1 = {e(self.delta_max)}: along the equilibrium path the "
                    f"platen displacement turns back at eps1 = {e(self.delta_max)}, short of the "
                    f"{e(self.delta_target)} asked (snap-back); det K_ff goes from "
                    f"{self.det_sign[0]:+d} to {self.det_sign[1]:+d}, lam_min of its symmetric part "
                    f"from {self.lam_min[0]:.4g} to {self.lam_min[1]:.4g} Pa, W2 for this control "
                    f"from {self.w2[0]:+.3g} to {self.w2[1]:+.3g}")
        if self.outcome == "discontinuous":
            return (f"discontinuous at eps1 = {e(self.delta_max)}: along the equilibrium path the "
                    f"platen displacement turns back there, short of the {e(self.delta_target)} "
                    f"asked, while det K_ff keeps its sign ({self.det_sign[0]:+d}, "
                    f"{self.det_sign[1]:+d}; lam_min {self.lam_min[0]:.4g}, {self.lam_min[1]:.4g} "
                    "Pa): a jump of the material's response, not W2 = 0")
        return f"{self.outcome}: the scan reached eps1 = {e(self.delta_max)} of {e(self.delta_target)}"


class StaticLoss(Exception):
    """A load step without a static state under the applied control (``verdict``: a
    StaticVerdict); not a RuntimeError: the caller ends its path with it as a result."""

    def __init__(self, msg, verdict: StaticVerdict):
        super().__init__(msg)
        self.verdict = verdict


def _control_block(K, free) -> tuple:
    """(det sign, lam_min of the symmetric part [Pa], normalized W2 of its eigenvector) of the
    free dofs' stiffness K_ff."""
    from .indicators import det_sign, lam_min_sym
    Kff = K[free][:, free].tocsc()
    sign, _ = det_sign(Kff)
    S = 0.5 * (Kff + Kff.T)
    if Kff.shape[0] <= 2000:
        w, V = np.linalg.eigh(S.toarray())
        lam, v = float(w[0]), V[:, 0]
        return sign, lam, float(lam / np.linalg.norm(Kff @ v))
    lam, _ = lam_min_sym(S)
    return sign, float(lam), math.nan


def static_scan(prob, u_n: np.ndarray, delta_n: float, h: float, last=None,
                rtol: float = 1e-10, max_iter: int = 25, max_points: int = 400) -> StaticVerdict:
    """Is there a static state beyond the committed one (displacement ``u_n``, platen
    ``delta_n``) when the step to ``delta_n + h`` fails however it is cut? A one-parameter scan
    of the controlled variable (the platen displacement delta) along the equilibrium path
    (Riks's arc-length): unknowns y = (u_free, delta), equations r_free(u) = 0 and
    d.(y - y_n) = t, d the unit vector of ``last`` (the last converged increment (du (ndofs,),
    d delta); default: delta alone), each point Newton on the bordered system
    [[K_ff, K_fp g], [d_u, d_delta]], g = d u_prescribed / d delta. Steps of t: a quarter of
    ``last``'s length (at most an eighth of the step h along d), halved where Newton fails (down
    to 1/1024), doubled after a success; at most ``max_points``. The material is the committed
    state's, each point's trial from it (nothing committed).

    'exists' once delta reaches delta_n + h (the result: the furthest converged point not past
    it, or the first past it); 'uncontrollable' where delta turns back first (a limit point of
    the displacement-controlled problem: det K_ff changes sign there, W2 = 0 for this control),
    or where the path stops with det K_ff changing sign over its last interval; 'discontinuous'
    where delta turns back with det K_ff keeping its sign; else 'unresolved'."""
    mat = prob.material
    free, presc = prob.free, prob.prescribed
    f_ref = prob.sigma2 * prob.height
    g = prob.prescribed_values(1.0) - prob.prescribed_values(0.0)
    base = prob.prescribed_values(0.0)
    eps_n = prob.strain(u_n)
    nf = free.size
    d = np.zeros(nf + 1)
    if last is not None:
        d[:nf], d[nf] = np.asarray(last[0])[free], float(last[1])
    if not d[nf] > 0:
        d[:] = 0.0
        d[nf] = 1.0
    length = float(np.linalg.norm(d)) if last is not None else math.inf
    d /= np.linalg.norm(d)
    y_n = np.append(u_n[free], delta_n)
    target = delta_n + h
    dt_max = h / d[nf] / 8.0
    dt = min(dt_max, length / 4.0)
    dt_min = dt / 1024.0

    def state(y):
        u = u_n.copy()
        u[free] = y[:nf]
        u[presc] = base + g * y[nf]
        return u

    def solve_at(t, y0):
        y = y0.copy()
        for _ in range(max_iter + 1):
            u = state(y)
            try:
                trial = mat.trial(prob.strain(u) - eps_n)
            except ValueError:
                return None
            f = prob.internal_force(trial.sigma)
            r = (f - prob.f_lat)[free]
            c = float(d @ (y - y_n) - t)
            if not np.isfinite(r).all():
                return None
            rn = float(np.linalg.norm(r)) / f_ref
            if rn <= rtol and abs(c) <= 1e-12 * max(abs(t), h):
                return y, u, f, trial, rn
            K = prob.stiffness(trial.D)
            J = sp.bmat([[K[free][:, free], sp.csr_matrix(K[free][:, presc] @ g[:, None])],
                         [sp.csr_matrix(d[None, :nf]), sp.csr_matrix([[d[nf]]])]]).tocsc()
            try:
                dy = spla.spsolve(J, -np.append(r, c))
            except RuntimeError:
                return None
            if not np.isfinite(dy).all():
                return None
            y = y + dy
        return None

    pts = [(0.0, y_n, u_n, None, None, 0.0)]          # (t, y, u, f, trial, residual)
    t, tang = 0.0, d.copy()
    while len(pts) <= max_points and dt >= dt_min:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", spla.MatrixRankWarning)
            got = solve_at(t + dt, pts[-1][1] + dt * tang)
        if got is None:
            dt *= 0.5
            continue
        y, u, f, trial, rn = got
        tang = (y - pts[-1][1]) / dt
        t += dt
        pts.append((t, y, u, f, trial, rn))
        if y[nf] >= target or y[nf] < pts[-2][1][nf]:
            break                          # reached the step's end, or delta turned back
        dt = min(2.0 * dt, dt_max)
    deltas = np.array([p[1][nf] for p in pts])

    def block(k):
        trial = pts[k][4] if k > 0 else mat.trial(np.zeros_like(eps_n))
        return _control_block(prob.stiffness(trial.D), free)

    def verdict(outcome, a, b):
        return StaticVerdict(outcome, delta_n, target, float(deltas.max()), (a[0], b[0]),
                             (a[1], b[1]), (a[2], b[2]), len(pts) - 1)

    if deltas[-1] >= target and len(pts) > 1:
        below = [k for k in range(1, len(pts)) if delta_n < deltas[k] <= target]
        k = max(below, key=lambda j: deltas[j]) if below else len(pts) - 1
        _, y, u, f, trial, rn = pts[k]
        nan2 = (math.nan, math.nan)
        res = StepResult(u, f, trial, [rn], [0])
        return StaticVerdict("exists", delta_n, target, float(deltas.max()), (0, 0), nan2, nan2,
                             len(pts) - 1, (res, float(y[nf])))
    k = len(pts) - 1
    if k >= 1 and deltas[k] < deltas[k - 1]:
        # delta turns back along the path, between points k - 2 (still rising) and k: a limit
        # point when det K_ff changes sign there
        a, b = block(max(k - 2, 0)), block(k)
        return verdict("uncontrollable" if a[0] != b[0] else "discontinuous", a, b)
    # the path could not be followed further: a limit point within its last interval if det K_ff
    # changed sign there; else nothing is proven (a jump of the material's response, or only
    # Newton's difficulty: the FE can find other states, unlike one material point)
    a, b = block(max(k - 1, 0)), block(k)
    return verdict("uncontrollable" if a[0] != b[0] else "unresolved", a, b)


class LoadStepper:
    """Displacement-driven load steps with automatic cut-back.

    d_eps1 : nominal axial strain increment per step (> 0, compression); a failed step is retried
    with half the increment, up to ``max_cutbacks`` halvings in a row and never below the floor
    d_eps1 / 2**max_cutbacks (a step that already started below the nominal one, after cut-backs,
    is not halved past the floor: approaching a turning point of the platen displacement, every
    step would otherwise succeed at a smaller increment than the last, towards the turning point
    without ever reaching the scan that decides it); after a success the increment grows back
    (x2) towards the nominal one. ``on_step(result, info)`` is called after
    each converged (and committed) step. ``u0`` : (ndofs,) the displacement [m] of the committed
    state the steps start from (default zeros: the initial state); ``du0`` : (ndofs,) the
    displacement per unit platen displacement the first step's predictor extrapolates (default
    none: the first guess moves the prescribed dofs only).
    """

    def __init__(self, prob: Biaxial, d_eps1: float, rtol: float = 1e-10, max_iter: int = 25,
                 max_cutbacks: int = 6, log=None, u0=None, du0=None):
        if not (np.isfinite(d_eps1) and 0 < d_eps1 < 0.05):
            raise ValueError(f"d_eps1 = {d_eps1!r} is out of range: allowed 0 < d_eps1 < 0.05")
        if not (np.isfinite(rtol) and 0 < rtol < 1):
            raise ValueError(f"rtol = {rtol!r} is out of range: allowed 0 < rtol < 1")
        if int(max_iter) < 1:
            raise ValueError(f"max_iter = {max_iter!r} is out of range: allowed max_iter >= 1")
        if int(max_cutbacks) < 0:
            raise ValueError(f"max_cutbacks = {max_cutbacks!r} is out of range: allowed >= 0")
        self.prob = prob
        self.d_eps1 = float(d_eps1)
        self.rtol, self.max_iter, self.max_cutbacks = float(rtol), int(max_iter), int(max_cutbacks)
        self.log = log
        self.u = np.zeros(prob.ndofs) if u0 is None else np.array(u0, dtype=float)
        self.delta = 0.0
        self.step = 0
        self.f_int = prob.internal_force(prob.material.stress())
        self._du_last = None if du0 is None else np.array(du0, dtype=float)
        self._h_last = None if du0 is None else 1.0
        self.solver = FreeSolver(prob.free)
        self.times = {"update": 0.0, "assembly": 0.0, "solve": 0.0, "iterations": 0}

    @property
    def eps1(self) -> float:
        return self.delta / self.prob.height

    def _guess(self, h):
        prob = self.prob
        u = self.u.copy()
        if self._du_last is not None:           # extrapolate the last converged increment
            u += (h / self._h_last) * self._du_last
        u[prob.prescribed] = prob.prescribed_values(self.delta + h)
        return u

    def advance(self, h: float):
        """One load step of platen displacement h [m] with cut-back. Returns (StepResult, h_done,
        cutbacks). A step that still fails after max_cutbacks halvings is decided by
        ``static_scan``: where a static state exists further on, the scan's converged state is
        the step's end (h_done its platen displacement); where none exists under the control,
        StaticLoss (``verdict``: 'uncontrollable' or 'discontinuous'); RuntimeError when the
        scan can decide neither."""
        cut = 0
        floor = self.d_eps1 * self.prob.height / 2 ** self.max_cutbacks
        while True:
            try:
                res = newton_step(self.prob, self.u, self._guess(h), self.rtol, self.max_iter,
                                  self.solver)
                break
            except NewtonError as e:
                if self.log:
                    self.log(f"step {self.step + 1}: d_eps1 = {h / self.prob.height:.3e} failed "
                             f"({e}); residuals {['%.2e' % r for r in e.residuals]}")
                if cut >= self.max_cutbacks or 0.5 * h < floor * (1.0 - 1e-12):
                    res, h = self._decide(h, cut, e)
                    break
                cut += 1
                h *= 0.5
        prob = self.prob
        prob.material.commit(res.trial)
        self._du_last = res.u - self.u
        self._h_last = h
        self.u = res.u
        self.f_int = res.f_int
        self.delta += h
        self.step += 1
        for key in ("update", "assembly", "solve"):
            self.times[key] += res.times.get(key, 0.0)     # a scan's state has none
        self.times["iterations"] += res.iterations
        return res, h, cut

    def _decide(self, h, cut, err):
        """The step to delta + h failed at the floor of its cut-backs: ``static_scan``."""
        H = self.prob.height
        last = None if self._du_last is None else (self._du_last, self._h_last)
        v = static_scan(self.prob, self.u, self.delta, h, last, self.rtol, self.max_iter)
        if self.log:
            self.log(f"step {self.step + 1}: static scan beyond eps1 = {self.eps1:.6g} ({v.points} "
                     f"points): {v.line(H)}")
        if v.outcome == "exists":
            res, delta = v.result
            return res, delta - self.delta
        if v.outcome == "unresolved":
            raise RuntimeError(
                f"load step {self.step + 1} at eps1 = {self.eps1:.6g} did not converge even after "
                f"{cut} cut-backs (last d_eps1 = {h / H:.3e}): {err}; the static scan along the "
                f"equilibrium path could neither continue it nor show that it ends ({v.line(H)}). "
                f"Allowed: a smaller d_eps1, more max_cutbacks (>= 0) or max_iter (>= 1)") from None
        raise StaticLoss(f"load step {self.step + 1}: no static state beyond eps1 = "
                         f"{self.eps1:.6g} under the platen's control: {v.line(H)}", v)

    def run(self, eps1_max: float, on_step=None, until=None):
        """Steps until eps1 = eps1_max, growing the increment back after cut-backs; or, with
        ``until`` (a callable of no argument), up to the first step after which it is true."""
        if not (np.isfinite(eps1_max) and 0 < eps1_max < 0.5):
            raise ValueError(f"eps1_max = {eps1_max!r} is out of range: allowed 0 < eps1_max < 0.5")
        H = self.prob.height
        target = eps1_max * H
        h_nom = self.d_eps1 * H
        h = h_nom
        while self.delta < target * (1 - 1e-12):
            h_try = min(h, target - self.delta)
            old_u, old_f = self.u.copy(), self.f_int.copy()
            res, h_done, cut = self.advance(h_try)
            info = {"cutbacks": cut, "d_eps1": h_done / H, "du": self.u - old_u,
                    "df_int": self.f_int - old_f}
            if on_step is not None:
                on_step(res, info)
            if until is not None and until():
                break
            h = min(2.0 * h_done, h_nom) if cut or h_done < h_nom else h_nom
        return self
