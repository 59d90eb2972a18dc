"""One mixed-control step of a single material point: the control (``MixedControl``: which of
the three variables (11, 22, 12), or of their linear combinations, have a prescribed strain
increment, which a prescribed stress), the step by Newton (``mixed_step``) and its failure
(``MixedControlError``).

Any material of the contract (``point.contract``): the step is Newton on ``Material.update``,
or the law's own faster ``mixed_step_fast`` where it has one (the H-model's Numba kernel, the
same algorithm). The floor below the two users of a step: ``driver`` (paths of steps, cut in
substeps) and ``controllability`` (the decision at the floor of the cuts, whose scan solves
steps), so that neither imports the other's module to reach it. ``driver`` names them too
(their public home).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .contract import MaterialError, material_of
from .tensors import from_voigt, to_voigt, voigt_tangent

__all__ = ["MixedControl", "MixedControlError", "mixed_step", "Step"]


class MixedControlError(RuntimeError):
    """A mixed-control step whose Newton iterations did not converge (in a path: a static
    solution exists, ``controllability.decide`` found it, yet not within the tolerance)."""


@dataclass(frozen=True)
class MixedControl:
    """Per-step control of three variables: the components (11, 22, 12) themselves, or, with a
    ``control_matrix`` A, linear combinations of the normal ones (a kinematic tie and the stress
    conjugate to it: the generalized loading variables of the Grenoble school).

    strain_controlled : which variables have a prescribed strain increment (the others a
        prescribed stress increment).
    d_eps : strain increment per step of the strain-controlled variables (others ignored) [-].
    d_sigma : stress increment per step of the stress-controlled variables (others ignored) [Pa].
    control_matrix : None (the components themselves) or a 2 x 2 matrix A of the normal
        components: the variables are e' = (A (de11, de22), de12) and their conjugate stresses
        s' = (A^-T (s11, s22), s12), so that s'.e' = s11 de11 + s22 de22 + s12 de12: the second-order
        work of an increment is the same in either set. E.g. the proportional strain path
        d eps22 = R d eps11 under the stress c = s11 + R s22 conjugate to it is
        A = ((1, 0), (-R, 1)): e'1 = de11, e'2 = de22 - R de11 (held at 0: the tie), s'1 = c
        (``proportional_strain_stress``).
    """

    strain_controlled: tuple = (True, False, True)
    d_eps: tuple = (1e-5, 0.0, 0.0)
    d_sigma: tuple = (0.0, 0.0, 0.0)
    control_matrix: tuple | None = None

    def __post_init__(self):
        sc = tuple(bool(b) for b in self.strain_controlled)
        if len(sc) != 3:
            raise ValueError("MixedControl.strain_controlled needs 3 flags for (11, 22, 12)")
        for name in ("d_eps", "d_sigma"):
            v = np.asarray(getattr(self, name), dtype=float)
            if v.shape != (3,) or not np.all(np.isfinite(v)):
                raise ValueError(f"MixedControl.{name} must be 3 finite numbers for (11, 22, 12), got {v}")
            object.__setattr__(self, name, tuple(float(x) for x in v))
        object.__setattr__(self, "strain_controlled", sc)
        if self.control_matrix is not None:
            A = np.asarray(self.control_matrix, dtype=float)
            if A.shape != (2, 2) or not np.all(np.isfinite(A)):
                raise ValueError(f"MixedControl.control_matrix must be a finite 2 x 2 matrix of the "
                                 f"normal components (11, 22), got {self.control_matrix!r}")
            if not np.linalg.cond(A) < 1e12:
                raise ValueError(f"MixedControl.control_matrix {A.tolist()} is singular: allowed an "
                                 "invertible matrix (the variables must determine the strain)")
            object.__setattr__(self, "control_matrix", tuple(tuple(float(x) for x in row) for row in A))

    def matrices(self):
        """(general, A, A^-1): A (3, 3) maps the strain increment (11, 22, 12) to the controlled
        variables; general is False (and A the identity) without a control_matrix."""
        if self.control_matrix is None:
            return False, np.eye(3), np.eye(3)
        A = np.eye(3)
        A[:2, :2] = self.control_matrix
        return True, A, np.linalg.inv(A)

    def to_controlled(self, v_strain=None, v_stress=None):
        """The controlled variables of a strain increment (A de) or of a stress (A^-T sigma),
        rows (..., 3) in (11, 22, 12)."""
        _, A, Ainv = self.matrices()
        if v_strain is not None:
            return np.asarray(v_strain, float) @ A.T
        return np.asarray(v_stress, float) @ Ainv



class Step(NamedTuple):
    """One update of a single point (what ``mixed_step`` returns first): stress (2, 2) [Pa],
    tangent (2, 2, 2, 2) [Pa], the new state. A law's fast step may return a record with more
    fields (the H-model's ``Increment``): callers read these three."""

    stress: np.ndarray
    tangent: np.ndarray
    state: object


def mixed_step(state, params, control: MixedControl, sigma_target,
               guess=None, rtol: float = 1e-10, max_iter: int = 40, tol: float | None = None):
    """One mixed-control step of a single material point of any law.

    sigma_target : (3,) stress [Pa] the stress-controlled variables must reach (with a
        ``control_matrix``: the conjugate stresses s' = A^-T sigma, e.g. c = s11 + R s22).
    guess : (3,) initial strain increment (11, 22, 12) (the strain-controlled variables are
        overwritten by the prescribed ones).
    Newton with backtracking on the free variables (the stress is continuous but may be only
    piecewise smooth), Jacobian A^-T (d sigma / d de) A^-1 from the update's consistent tangent,
    stops at a largest stress residual <= ``tol`` [Pa], by default ``rtol`` x max(|target|,
    1e-3 p0).
    Returns (Step, d_eps (3,), iterations), d_eps the strain increment (11, 22, 12).
    Raises MixedControlError if Newton fails.
    """
    law = material_of(params)
    law.check_state(state, params)
    target = np.asarray(sigma_target, dtype=float)
    if tol is None:
        tol = rtol * max(float(np.max(np.abs(target))), 1e-3 * params.p0)
    fast = getattr(law, "mixed_step_fast", None)
    if fast is not None:
        it, rn, inc, de_out = fast(state, params, control, target, guess, tol, int(max_iter))
    else:
        it, rn, inc, de_out = _newton(law, state, params, control, target, guess, tol, int(max_iter))
    if it < 0:
        raise MixedControlError(_failure_message(it, max_iter, rn, tol))
    return inc, de_out, int(it)


def _newton(law, state, params, control, target, guess, tol, max_iter):
    """The algorithm of the H-model's ``mixed_step_single`` kernel on ``law.update``: returns
    (iterations or -1 (no convergence) or -2 (singular block), residual, Step, d_eps (3,))."""
    sc = np.array(control.strain_controlled, dtype=bool)
    general, A, Ainv = control.matrices()
    free = np.flatnonzero(~sc)
    ep = np.zeros(3) if guess is None else np.array(guess, dtype=float)
    if general:
        ep = A @ ep
    ep[sc] = np.asarray(control.d_eps)[sc]

    def at(ep):
        de = Ainv @ ep if general else ep.copy()
        stress, tangent, new = law.update(state, from_voigt(de[None, :], ()), params)
        sig = to_voigt(stress)[0]
        sv = sig @ Ainv if general else sig
        return de, Step(stress, tangent, new), sv

    if free.size == 0:              # every strain prescribed: the law's answer, or its refusal
        de, step, sv = at(ep)
        return 1, 0.0, step, de
    try:
        de, step, sv = at(ep)
    except MaterialError:
        # the law refuses the start guess (e.g. Drucker-Prager's apex): a step to cut
        return -1, math.inf, None, ep
    rn = float(np.max(np.abs(sv[free] - target[free])))
    for it in range(1, max_iter + 1):
        if rn <= tol:
            return it, rn, step, de
        r = sv[free] - target[free]
        T = voigt_tangent(step.tangent)[0]
        J = (Ainv.T @ T @ Ainv)[np.ix_(free, free)] if general else T[np.ix_(free, free)]
        jmax = float(np.max(np.abs(J)))
        if not (jmax > 0.0) or abs(np.linalg.det(J)) <= 1e-13 * jmax ** free.size:
            return -2, rn, step, de
        dx = np.linalg.solve(J, r)
        lam = 1.0
        while True:
            trial = ep.copy()
            trial[free] = ep[free] - lam * dx
            try:
                tde, tstep, tsv = at(trial)
                rt = float(np.max(np.abs(tsv[free] - target[free])))
            except MaterialError:       # a trial the law refuses: shorter
                rt = math.inf
            if not math.isfinite(rt) and lam >= 1e-8:
                lam *= 0.5
                continue
            if rt < (1.0 - 1e-4 * lam) * rn or lam < 1e-8:
                break
            lam *= 0.5
        if not math.isfinite(rt):
            return -1, rn, step, de
        ep, de, step, sv, rn = trial, tde, tstep, tsv, rt
    if rn <= tol:
        return max_iter, rn, step, de
    return -1, rn, step, de


def _failure_message(code, max_iter, rn, tol):
    if code == -2:
        return (f"singular tangent on the stress-controlled components (no stiffness left, e.g. "
                f"every hexagon open); stress residual {rn:.3e} Pa")
    return (f"mixed-control step did not converge in {max_iter} Newton iterations (last stress "
            f"residual {rn:.3e} Pa, tolerance {tol:.3e} Pa)")
