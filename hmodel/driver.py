"""Material-point driver: any mix of controlled stress and strain components.

Components are numbered in the order (11, 22, 12) with tensor shear; axis 1 is axial. Each step
prescribes the strain increment of the strain-controlled components and the stress increment of
the stress-controlled ones; the unknown strain increments are found by Newton with the consistent
tangent of the update (the stress of a step is exactly differentiable for a fixed sliding pattern).
"""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from typing import Callable, NamedTuple, Sequence

import numpy as np

from .material import HState, reference_state, update_full, to_voigt
from .params import HParams

__all__ = [
    "MixedControl", "PathResult", "MixedControlError", "mixed_step", "run_path",
    "isotropic_state", "drained_biaxial", "undrained_biaxial", "proportional_strain",
    "isotropic_compression", "stress_invariants",
]


class MixedControlError(RuntimeError):
    """A mixed-control step whose Newton iterations did not converge."""


@dataclass(frozen=True)
class MixedControl:
    """Per-step control of the components (11, 22, 12).

    strain_controlled : which components have a prescribed strain increment (the others a
        prescribed stress increment).
    d_eps : strain increment per step of the strain-controlled components (others ignored) [-].
    d_sigma : stress increment per step of the stress-controlled components (others ignored) [Pa].
    """

    strain_controlled: tuple = (True, False, True)
    d_eps: tuple = (1e-5, 0.0, 0.0)
    d_sigma: tuple = (0.0, 0.0, 0.0)

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


class PathResult(NamedTuple):
    """History of a loading path, one row per state (row 0 is the start).

    eps : (n+1, 3) strain since the start of the path, (11, 22, 12), compression positive.
    sigma : (n+1, 3) Cauchy stress [Pa].
    newton_iters : (n+1,) Newton iterations of each step (0 for the start).
    n_sliding, n_open : (n+1,) number of sliding / open hexagons after each step.
    state : the final HState.
    states : list of the HState of every row when asked (keep_states=True), else None.
    """

    eps: np.ndarray
    sigma: np.ndarray
    newton_iters: np.ndarray
    n_sliding: np.ndarray
    n_open: np.ndarray
    state: HState
    states: list | None

    def invariants(self):
        """(p, q, eta) arrays of the 2D invariants p = (s1+s2)/2, q = s1-s2, eta = q/p."""
        return stress_invariants(self.sigma)


def stress_invariants(sigma):
    """p = (s11 + s22)/2, q = s11 - s22, eta = q/p for rows (…, 3) in (11, 22, 12) order."""
    sigma = np.asarray(sigma)
    p = 0.5 * (sigma[..., 0] + sigma[..., 1])
    q = sigma[..., 0] - sigma[..., 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        eta = np.where(p != 0, q / np.where(p != 0, p, 1.0), 0.0)
    return p, q, eta


def _tensor(v):
    return np.array([[v[0], v[2]], [v[2], v[1]]])


def mixed_step(state: HState, params: HParams, control: MixedControl, sigma_target,
               guess=None, rtol: float = 1e-10, max_iter: int = 40):
    """One mixed-control step of a single material point.

    sigma_target : (3,) stress [Pa] the stress-controlled components must reach.
    guess : (3,) initial strain increment (the strain-controlled entries are overwritten).
    Returns (Increment, d_eps (3,), iterations). Raises MixedControlError if Newton fails.
    """
    sc = np.array(control.strain_controlled)
    free = np.flatnonzero(~sc)
    de = np.zeros(3) if guess is None else np.array(guess, dtype=float)
    de[sc] = np.asarray(control.d_eps)[sc]
    target = np.asarray(sigma_target, dtype=float)
    scale = max(float(np.max(np.abs(target))), 1e-3 * params.p0)
    tol = rtol * scale
    n_eval = 0

    def evaluate(x):
        inc = update_full(state, _tensor(x), params)
        r = to_voigt(inc.stress)[0][free] - target[free]
        return inc, r, float(np.max(np.abs(r))) if free.size else 0.0

    inc, r, rn = evaluate(de)
    n_eval += 1
    for it in range(1, max_iter + 1):
        if rn <= tol:
            return inc, de, it
        J = _voigt_tangent(inc.tangent)[np.ix_(free, free)]
        try:
            step = np.linalg.solve(J, r)
        except np.linalg.LinAlgError:
            raise MixedControlError(
                f"singular tangent on the stress-controlled components {free.tolist()}") from None
        # Backtracking on the residual: the stress is continuous but only piecewise smooth in
        # d_eps (sliding-pattern switches), where a full Newton step can cycle.
        lam = 1.0
        while True:
            trial = de.copy()
            trial[free] -= lam * step
            inc_t, r_t, rn_t = evaluate(trial)
            n_eval += 1
            if rn_t < (1.0 - 1e-4 * lam) * rn or lam < 1e-8:
                break
            lam *= 0.5
        de, inc, r, rn = trial, inc_t, r_t, rn_t
    if rn <= tol:
        return inc, de, max_iter
    raise MixedControlError(
        f"mixed-control step did not converge in {max_iter} Newton iterations "
        f"(last stress residual {rn:.3e} Pa, tolerance {tol:.3e} Pa); try a smaller step")


def _voigt_tangent(C):
    """(2,2,2,2) tangent -> 3x3 d sigma_a / d v_b, v = (e11, e22, e12 tensor)."""
    idx = ((0, 0), (1, 1), (0, 1))
    T = np.empty((3, 3))
    for a, (i, j) in enumerate(idx):
        for b, (k, l) in enumerate(idx):
            T[a, b] = C[i, j, k, l] + (C[i, j, l, k] if b == 2 else 0.0)
    return T


def run_path(state: HState, params: HParams, control: MixedControl, n_steps: int,
             until: Callable[[np.ndarray, np.ndarray], bool] | None = None,
             keep_states: bool = False, progress: bool = False, label: str = "path") -> PathResult:
    """Run ``n_steps`` steps of ``control`` from ``state`` (a single point), or stop after the
    first step for which ``until(eps, sigma)`` is true (eps, sigma: (3,) arrays).

    Stress targets accumulate from the start stress: sigma_target = sigma_0 + k d_sigma.
    """
    if state.batch_shape != ():
        raise ValueError("run_path drives a single material point (batch shape ())")
    if int(n_steps) < 1:
        raise ValueError(f"n_steps must be >= 1, got {n_steps}")
    n_steps = int(n_steps)
    sig0 = to_voigt(state.stress)[0]
    dsig = np.asarray(control.d_sigma)
    eps_hist = [np.zeros(3)]
    sig_hist = [sig0.copy()]
    iters = [0]
    nsl = [int(state.sliding.sum())]
    nop = [int(state.is_open.sum())]
    states = [state] if keep_states else None
    eps = np.zeros(3)
    guess = np.zeros(3)
    bar = _Progress(n_steps, label) if progress else None
    for k in range(1, n_steps + 1):
        target = sig0 + k * dsig
        inc, de, it = mixed_step(state, params, control, target, guess=guess)
        state = inc.state
        guess = de
        eps = eps + de
        sig = to_voigt(inc.stress)[0]
        eps_hist.append(eps.copy())
        sig_hist.append(sig)
        iters.append(it)
        nsl.append(int(state.sliding.sum()))
        nop.append(int(state.is_open.sum()))
        if keep_states:
            states.append(state)
        if bar is not None:
            bar.update(k)
        if until is not None and until(eps, sig):
            break
    if bar is not None:
        bar.close()
    return PathResult(eps=np.array(eps_hist), sigma=np.array(sig_hist), newton_iters=np.array(iters),
                      n_sliding=np.array(nsl), n_open=np.array(nop), state=state, states=states)


class _Progress:
    """A one-line progress bar on stderr (no dependency)."""

    def __init__(self, total, label):
        self.total, self.label, self.t0, self.last = total, label, time.time(), -1.0

    def update(self, k):
        now = time.time()
        if now - self.last < 0.2 and k < self.total:
            return
        self.last = now
        f = k / self.total
        bar = "#" * int(30 * f)
        sys.stderr.write(f"\r{self.label}: [{bar:<30s}] {k}/{self.total} {now - self.t0:6.1f} s")
        sys.stderr.flush()

    def close(self):
        sys.stderr.write("\n")
        sys.stderr.flush()


# -- standard paths ----------------------------------------------------------------------------
def isotropic_compression(params: HParams, p_target: float, state: HState | None = None,
                          n_steps: int = 20) -> PathResult:
    """Stress-controlled isotropic compression from ``state`` (default: the zero-force
    reference) to p = s11 = s22 = ``p_target`` [Pa] in ``n_steps`` equal steps."""
    if not (np.isfinite(p_target) and p_target > 0):
        raise ValueError(f"p_target must be > 0 [Pa], got {p_target!r}")
    state = reference_state(params) if state is None else state
    s0 = to_voigt(state.stress)[0]
    d = (np.array([p_target, p_target, 0.0]) - s0) / n_steps
    ctl = MixedControl(strain_controlled=(False, False, False), d_eps=(0, 0, 0), d_sigma=tuple(d))
    return run_path(state, params, ctl, n_steps)


def isotropic_state(params: HParams, p0: float | None = None) -> HState:
    """The isotropic initial state of spec/hmodel.md: from d1 = d2 = 2 r_g, alpha = alpha0,
    compressed isotropically to p0 (default ``params.p0``); strains of a test count from it."""
    return isotropic_compression(params, params.p0 if p0 is None else p0).state


def _check_step(d, name="d_eps1"):
    if not (np.isfinite(d) and d != 0):
        raise ValueError(f"{name} must be a finite non-zero strain increment, got {d!r}")


def drained_biaxial(d_eps1: float = 1e-5) -> MixedControl:
    """Axial strain driven (compression positive), lateral stress s22 held, no shear strain."""
    _check_step(d_eps1)
    return MixedControl(strain_controlled=(True, False, True), d_eps=(d_eps1, 0.0, 0.0))


def undrained_biaxial(d_eps1: float = 1e-5) -> MixedControl:
    """Isochoric biaxial: d_eps22 = -d_eps11 (the 2D undrained test)."""
    _check_step(d_eps1)
    return MixedControl(strain_controlled=(True, True, True), d_eps=(d_eps1, -d_eps1, 0.0))


def proportional_strain(d_eps1: float = 1e-5, ratio: float = -0.5) -> MixedControl:
    """Proportional strain path d_eps22 = ratio * d_eps11."""
    _check_step(d_eps1)
    if not np.isfinite(ratio):
        raise ValueError(f"ratio must be finite, got {ratio!r}")
    return MixedControl(strain_controlled=(True, True, True), d_eps=(d_eps1, ratio * d_eps1, 0.0))
