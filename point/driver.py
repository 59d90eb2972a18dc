"""Material-point driver: any mix of controlled stress and strain components.

Components are numbered in the order (11, 22, 12) with tensor shear; axis 1 is axial. Each step
prescribes the strain increment of the strain-controlled components and the stress increment of
the stress-controlled ones; the unknown strain increments are found by Newton with the consistent
tangent of the update (the stress of a step is exactly differentiable for a fixed sliding pattern).
"""
from __future__ import annotations

import dataclasses
import sys
import time
from typing import Callable, NamedTuple

import numpy as np

from .contract import material_of
from .mixed import MixedControl, MixedControlError, mixed_step
from .controllability import (PathEnd, Verdict, control_scan, decide, describe_control,
                              stress_name)
from .tensors import to_voigt

__all__ = [
    "MixedControl", "PathResult", "MixedControlError", "mixed_step", "run_path", "MAX_CUTS",
    "isotropic_state", "drained_biaxial", "undrained_biaxial", "proportional_strain",
    "isotropic_compression", "stress_invariants", "proportional_strain_stress", "counts",
]


# a step that does not converge is cut in halves down to 1 / 2**MAX_CUTS of itself (the floor)
MAX_CUTS = 10


class PathResult(NamedTuple):
    """History of a loading path, one row per state (row 0 is the start).

    eps : (n+1, 3) strain since the start of the path, (11, 22, 12), compression positive.
    sigma : (n+1, 3) Cauchy stress [Pa].
    newton_iters : (n+1,) Newton iterations of each step (0 for the start).
    n_sliding, n_open : (n+1,) the law's counts after each step (``counts``): the H-model's
        sliding / open hexagons; a law without patterns: 1 where the step loaded the material
        (plastic), and 0.
    state : the final state.
    states : list of the HState of every row when asked (keep_states=True), else None.
    cuts : (n+1,) halvings of each step (0: the step converged whole; k: its smallest substep
        was 1 / 2**k of it; row 0 and the steps of a path run without cuts: 0).
    end : the ``controllability.PathEnd``: 'complete', or where and why no static state exists
        under the control (the last row is then the last state reached, a step's fraction).
    """

    eps: np.ndarray
    sigma: np.ndarray
    newton_iters: np.ndarray
    n_sliding: np.ndarray
    n_open: np.ndarray
    state: object
    states: list | None
    cuts: np.ndarray | None = None
    end: PathEnd | None = None

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



def run_path(state, params, control: MixedControl, n_steps: int,
             until: Callable[[np.ndarray, np.ndarray], bool] | None = None,
             keep_states: bool = False, progress: bool = False, label: str = "path",
             rtol: float = 1e-10, max_iter: int = 40, chunk: int = 250,
             max_cuts: int = MAX_CUTS) -> PathResult:
    """Run ``n_steps`` steps of ``control`` from ``state`` (a single point of any law), or stop
    after the first step for which ``until(eps, sigma)`` is true (eps, sigma: (3,) arrays, eps
    counted from the start of the path).

    Stress targets accumulate from the start stress: sigma_target = sigma_0 + k d_sigma (in the
    controlled variables: s'_0 + k d_sigma, s'_0 = A^-T sigma_0, with a control_matrix). The steps
    run one by one (``mixed_step``), or in the law's own loop where it has one
    (``run_path_fast``: the H-model's Numba loop, ``chunk`` steps at a time, ``until`` checked
    between chunks and the chunk replayed up to the first step that satisfies it; the same
    numbers as the step-by-step loop, which ``keep_states`` always takes).

    A step whose Newton iterations do not converge is cut in halves (``_Cutter``: the
    substeps reach the step's own end, growing back x2 after each success; ``cuts`` records the
    halvings per step) down to 1 / 2**``max_cuts`` of it. A substep of that floor that still
    does not converge is decided by ``controllability.decide``: its root, where a static state
    exists (the path goes on from it); else the path ends there, ``end`` saying why
    ('uncontrollable': W2 = 0 for this control, the controlled block's determinant changing sign;
    'discontinuous': the controlled stress jumps across its target), the last row being the
    last state reached. A root that does not meet the tolerance raises MixedControlError
    carrying the path so far as ``.partial`` (so does an interruption, KeyboardInterrupt).
    """
    if state.batch_shape != ():
        raise ValueError("run_path drives a single material point (batch shape ())")
    if int(n_steps) < 1:
        raise ValueError(f"n_steps must be >= 1, got {n_steps}")
    if not (float(max_cuts) == int(max_cuts) and int(max_cuts) >= 0):
        raise ValueError(f"max_cuts = {max_cuts!r} is out of range: allowed an integer >= 0")
    law = material_of(params)
    law.check_state(state, params)
    n_steps = int(n_steps)
    sig0 = to_voigt(state.stress)[0]
    general, A, Ainv = control.matrices()
    s0 = control.to_controlled(v_stress=sig0) if general else sig0
    cut = _Cutter(params, control, s0, rtol, max_iter, int(max_cuts))
    fast = getattr(law, "run_path_fast", None)
    if keep_states or fast is None:
        cut.tol = None          # mixed_step's own tolerance, as the step-by-step loop always had
        return _run_path_steps(state, params, control, n_steps, until, progress, label, cut)
    return fast(state, params, control, n_steps, until, progress, label, cut, rtol, max_iter, chunk)


class _Cut(NamedTuple):
    """One step by substeps (``_Cutter.step``): the state reached, its stress (3,), the strain
    increment (3,) and Newton iterations of the substeps together, the halvings, the fraction
    of the step reached, and the end (None, or the ``Verdict`` that ended the path)."""

    state: object
    sigma: np.ndarray
    de: np.ndarray
    iterations: int
    cuts: int
    fraction: float
    end: object


class _Cutter:
    """The substeps of a step that did not converge whole (MTest's substepping): halves, then
    growing back x2 after each success, within the step's own end; at the floor
    1 / 2**max_cuts the decision of ``controllability.decide``."""

    def __init__(self, params, control, s0, rtol, max_iter, max_cuts):
        self.params, self.control, self.s0 = params, control, np.asarray(s0, float)
        self.rtol, self.max_iter, self.max_cuts = rtol, int(max_iter), int(max_cuts)
        self.tol = None
        self.d_eps = np.asarray(control.d_eps, float)
        self.d_sig = np.asarray(control.d_sigma, float)

    def target(self, k, f):
        """The controlled stresses at fraction f of step k (1-based): s0 + (k - 1 + f) d_sigma."""
        return self.s0 + (k - 1 + f) * self.d_sig

    def step(self, state, k: int, guess) -> _Cut:
        """Step k (1-based) from ``state``, whose whole did not converge, in substeps; ``guess``
        the previous step's strain increment (the substeps' guesses scale it)."""
        rate = np.asarray(guess, float)         # strain increment per unit fraction of the step
        sig = to_voigt(state.stress)[0]
        floor = 0.5 ** self.max_cuts
        h, depth = (0.5, 1) if self.max_cuts > 0 else (1.0, 0)     # (without cuts: decide at once)
        frac, its, de_sum = 0.0, 0, np.zeros(3)
        while frac < 1.0:
            h = min(h, 1.0 - frac)
            tgt = self.target(k, frac + h)
            got = self._attempt(state, h, tgt, rate) if h < 1.0 else None
            if got is None and h * 0.5 >= floor:
                h *= 0.5
                depth = max(depth, int(round(-np.log2(h))))
                continue
            if got is None:
                got = self._decide(state, k, h, tgt)
                if isinstance(got, Verdict):            # no static state: the path ends here
                    return _Cut(state, sig, de_sum, its, depth, frac, got)
            inc, de, it = got
            state = inc.state
            sig = to_voigt(inc.stress)[0]
            de_sum = de_sum + de
            its += it
            rate = de / h
            frac += h
            h *= 2.0
        return _Cut(state, sig, de_sum, its, depth, 1.0, None)

    def _attempt(self, state, h, tgt, rate):
        """The substep of fraction h by Newton: (Increment, d_eps, iterations), or None."""
        ctl = dataclasses.replace(self.control, d_eps=tuple(h * self.d_eps))
        try:
            return mixed_step(state, self.params, ctl, tgt, guess=h * rate, rtol=self.rtol,
                              max_iter=self.max_iter, tol=self.tol)
        except MixedControlError:
            return None

    def _decide(self, state, k, h, tgt):
        """The substep of fraction h at the floor: ``controllability.decide``'s root as
        (Increment, d_eps, iterations), or its Verdict when no static state exists; raises
        MixedControlError when it can neither find nor exclude one."""
        params, control = self.params, self.control
        tol = self.tol if self.tol is not None else \
            self.rtol * max(float(np.max(np.abs(tgt))), 1e-3 * params.p0)
        de_p = h * self.d_eps                        # the controlled variables of the substep
        v = decide(state, params, control, tgt, de_p, tol)
        if v.outcome in ("uncontrollable", "discontinuous"):
            return v
        if v.outcome == "unresolved":
            raise MixedControlError(
                f"step {k}: no static state found and none excluded: the controlled stress comes "
                f"closest to its target ({v.reached:.6g} of {v.target:.6g} Pa) at the end of the "
                f"largest bracket |d e'| <= {v.bracket:g}")
        if v.residual > tol:
            raise MixedControlError(
                f"step {k}: a static state exists (the controlled stress reaches its target "
                f"continuously at d e'{v.variable + 1} = {v.at:.6g}) but not within the "
                f"tolerance: residual {v.residual:.3e} Pa > {tol:.3e} Pa")
        # the scan's root: the static state of this substep, every strain now known
        ep = np.asarray(de_p, float).copy()
        ep[v.variable] = v.at
        de = control_scan(state, params, control, ep, tgt, [v.at], v.variable)[2][0]
        return mixed_step(state, params, MixedControl((True, True, True), tuple(de)), tgt)


def _run_path_steps(state, params, control, n_steps, until, progress, label, cut):
    """The step-by-step Python loop of run_path, keeping every state."""
    sig0 = to_voigt(state.stress)[0]
    s0 = control.to_controlled(v_stress=sig0) if control.control_matrix is not None else sig0
    dsig = np.asarray(control.d_sigma)
    eps_hist, sig_hist, iters = [np.zeros(3)], [sig0.copy()], [0]
    law = material_of(params)
    c0 = counts(law, state)
    nsl, nop, cuts = [c0[0]], [c0[1]], [0]
    states = [state]
    eps = np.zeros(3)
    guess = np.zeros(3)
    bar = _Progress(n_steps, label) if progress else None
    end = None

    def result():
        pe = PathEnd("complete", 0, 1.0, eps_hist[-1].copy(), sig_hist[-1].copy(),
                     describe_control(control), None)
        if end is not None:
            v, k, f = end
            pe = pe._replace(outcome=v.outcome, step=k, fraction=f, verdict=v,
                         stress=stress_name(control, v.variable))
        return PathResult(eps=np.array(eps_hist), sigma=np.array(sig_hist),
                          newton_iters=np.array(iters), n_sliding=np.array(nsl),
                          n_open=np.array(nop), state=states[-1], states=states,
                          cuts=np.array(cuts), end=pe)

    try:
        for k in range(1, n_steps + 1):
            try:
                inc, de, it = mixed_step(state, params, control, s0 + k * dsig, guess=guess,
                                         rtol=cut.rtol, max_iter=cut.max_iter)
                c = _Cut(inc.state, to_voigt(inc.stress)[0], de, it, 0, 1.0, None)
            except MixedControlError:
                c = cut.step(state, k, guess)
            if c.fraction > 0:
                state, guess = c.state, c.de
                eps = eps + c.de
                eps_hist.append(eps.copy()); sig_hist.append(c.sigma); iters.append(c.iterations)
                c1 = counts(law, state)
                nsl.append(c1[0]); nop.append(c1[1])
                cuts.append(c.cuts)
                states.append(state)
            if c.end is not None:
                end = (c.end, k, c.fraction)
                break
            if bar is not None:
                bar.update(k)
            if until is not None and until(eps, c.sigma):
                break
    except BaseException as e:
        if not hasattr(e, "partial"):
            e.partial = result()
        raise
    finally:
        if bar is not None:
            bar.close()
    return result()


def counts(law, state) -> tuple:
    """(n_sliding, n_open) of a single-point state for a path's records: the law's
    ``counts`` (the H-model's sliding and open hexagons), else (1 if the step that made it
    loaded the material, 0)."""
    f = getattr(law, "counts", None)
    if f is not None:
        return f(state)
    p = getattr(state, "plastic", None)
    return (int(bool(np.any(p))) if p is not None else 0), 0


class _Progress:
    """Progress on stderr (no dependency): a one-line bar redrawn in place (``\\r``) on a
    terminal; elsewhere (a log file, a pipe) plain lines, one at each tenth of the path
    (``PLAIN_PARTS``) and at most one every ``PLAIN_MIN_S`` seconds, so that a log reads."""

    PLAIN_PARTS = 10        # a plain line at each tenth of the path
    PLAIN_MIN_S = 2.0       # and at most one every 2 s (the last one always)

    def __init__(self, total, label, stream=None):
        self.total, self.label, self.t0, self.last = total, label, time.time(), -1.0
        self.stream = sys.stderr if stream is None else stream
        try:
            self.tty = self.stream.isatty()
        except (AttributeError, ValueError):
            self.tty = False
        self.part = 0

    def update(self, k):
        now = time.time()
        f = k / self.total
        if self.tty:
            if now - self.last < 0.2 and k < self.total:
                return
            self.last = now
            bar = "#" * int(30 * f)
            self.stream.write(f"\r{self.label}: [{bar:<30s}] {k}/{self.total} {now - self.t0:6.1f} s")
        else:
            if k < self.total and (k * self.PLAIN_PARTS < (self.part + 1) * self.total
                                   or now - self.last < self.PLAIN_MIN_S):
                return
            self.last = now
            self.part = k * self.PLAIN_PARTS // self.total
            self.stream.write(f"{self.label}: {k}/{self.total} steps ({100 * f:.0f} %), "
                              f"{now - self.t0:.1f} s\n")
        self.stream.flush()

    def close(self):
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()


# -- standard paths ----------------------------------------------------------------------------
def isotropic_compression(params, p_target: float, state=None,
                          n_steps: int = 20) -> PathResult:
    """Stress-controlled isotropic compression from ``state`` (default: the law's zero-force
    reference, ``reference_state``) to p = s11 = s22 = ``p_target`` [Pa] in ``n_steps`` equal
    steps."""
    if not (np.isfinite(p_target) and p_target > 0):
        raise ValueError(f"p_target must be > 0 [Pa], got {p_target!r}")
    state = material_of(params).reference_state(params) if state is None else state
    s0 = to_voigt(state.stress)[0]
    d = (np.array([p_target, p_target, 0.0]) - s0) / n_steps
    ctl = MixedControl(strain_controlled=(False, False, False), d_eps=(0, 0, 0), d_sigma=tuple(d))
    return run_path(state, params, ctl, n_steps)


def isotropic_state(params, p0: float | None = None):
    """The isotropic initial state of the law at p0 (default ``params.p0``;
    ``Material.initial_state``); strains of a test count from it. The H-model's is compressed
    isotropically from its zero-force reference (d1 = d2 = 2 r_g, alpha = alpha0); it raises
    MixedControlError (``.partial`` None) when the compression has no static state on its way
    to p0 (``PathResult.end``)."""
    p0 = params.p0 if p0 is None else p0
    return material_of(params).initial_state(params if p0 == params.p0 else params.replace(p0=p0))


def compressed_state(params, p0: float | None = None):
    """The isotropic state at p0 reached by ``isotropic_compression`` from the law's reference
    state (the H-model's ``initial_state``); MixedControlError when it has no static state."""
    p0 = params.p0 if p0 is None else p0
    r = isotropic_compression(params, p0)
    if r.end.outcome != "complete":
        e = MixedControlError(f"no isotropic state at p0 = {p0:g} Pa: the isotropic compression "
                              f"ends {r.end.line()}")
        e.partial = None
        raise e
    return r.state


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


def proportional_strain_stress(ratio: float, d_c: float = 0.0) -> MixedControl:
    """The proportional strain path d eps22 = ``ratio`` d eps11 (no shear strain) under control
    of the stress conjugate to it, c = s11 + ratio s22 (``d_c`` [Pa] a step; c is held with 0):
    the tie kept, d eps11 free (docs/burst.md). Along the path W2 = d eps11 dc, so a static
    solution with dc > 0 exists only while c rises."""
    if not (np.isfinite(ratio) and ratio != 0):
        raise ValueError(f"ratio = {ratio!r} is out of range: allowed a finite non-zero ratio")
    if not np.isfinite(d_c):
        raise ValueError(f"d_c must be finite, got {d_c!r}")
    return MixedControl(strain_controlled=(False, True, True), d_eps=(0.0, 0.0, 0.0),
                        d_sigma=(d_c, 0.0, 0.0), control_matrix=((1.0, 0.0), (-ratio, 1.0)))


def proportional_strain(d_eps1: float = 1e-5, ratio: float = -0.5) -> MixedControl:
    """Proportional strain path d_eps22 = ratio * d_eps11."""
    _check_step(d_eps1)
    if not np.isfinite(ratio):
        raise ValueError(f"ratio must be finite, got {ratio!r}")
    return MixedControl(strain_controlled=(True, True, True), d_eps=(d_eps1, ratio * d_eps1, 0.0))
