"""Failure made to happen at the material point: the proportional strain path, its conjugate
stress c controlled past its peak, and the burst of kinetic energy (paper Eq. 1; docs/burst.md).

From a state of the drained path (a fraction of the drained peak eta), the proportional strain
path d eps2 = R d eps1 (R < 0, no shear strain) is followed under strain control while the
stress conjugate to it, c = s1 + R s2, is recorded: along the path W2 = d eps1 dc, so W2 = 0
exactly where c peaks. Then the control switches to c (``driver.proportional_strain_stress``,
the tie kept):

* statically: the c-controlled Newton step to c_switch + dc converges below the peak and has no
  solution past it (``static_check`` also scans c over a bracket of d eps1 to show that no
  strain along the tie reaches the target: the Newton failure is not a bad start);
* dynamically: the material point stands for the homogeneous specimen B x H of the FE defaults,
  reduced to its one kinematic degree of freedom U1 = H (eps1 - eps1_switch) along the tie
  (consistent mass m_G = rho B H (1/3 + R^2 B^2 / (12 H^2)) per unit thickness, internal force
  G = B c): m_G U1'' + C U1' + B c(U1) = G_switch + B dc, integrated by Newmark's average
  acceleration with mass-proportional damping C = 2 zeta omega_1 m_G (``hold``). The outcome is
  decided by ``hmodel.burst_rule`` from E_c and W2_ext; W2_int, the damping work and the residual
  of the discrete energy balance (exact for this integrator) are recorded at every step.

Functions here return arrays and write nothing (``hmodel.cli`` writes the files).
"""
from __future__ import annotations

import math
import time
from typing import NamedTuple

import numpy as np

from .burst_rule import BurstRule, decide as decide_outcome, ke_growth
from .controllability import control_scan, decide, verdict_text
from .driver import (MAX_CUTS, MixedControlError, PathResult, mixed_step, proportional_strain,
                     proportional_strain_stress, run_path, stress_invariants)
from .experiment import DOMAIN_EPS1_MAX, biaxial_test, state_at_eta
from .material import HState, to_voigt, update, update_full
from .params import HParams

__all__ = ["check_ratio", "Specimen", "Dynamics", "PathInfo", "HoldResult", "conjugate_stress", "path_direction",
           "drained_peak_eta", "proportional_path", "CPeak", "static_check", "hold", "run_burst",
           "BurstResult", "BELOW_RISE", "cone_entries", "cone_at", "BURST_COLUMNS", "HISTORY_COLUMNS",
           "PATH_COLUMNS"]

BELOW_RISE = 0.95     # ``below``: c_start + BELOW_RISE (c_peak - c_start), docs/burst.md
SCAN_STRAIN = 2e-3    # static_check: the bracket |d eps1| <= this of the scan along the tie


class Specimen(NamedTuple):
    """The homogeneous specimen the material point stands for (the FE defaults), per unit
    thickness: width B [m], height H [m], density rho [kg/m^3] (dry granular bulk: 1500-1700)."""

    width: float = 0.05
    height: float = 0.1
    density: float = 1600.0

    def mass(self, ratio: float) -> float:
        """m_G [kg/m]: the kinetic energy of the homogeneous velocity field along the tie (bottom
        fixed, lateral faces moving symmetrically) is m_G U1'^2 / 2, U1 = H eps1:
        rho int (eps1'^2 y^2 + eps2'^2 (x - B/2)^2) dA / 2 with eps2 = R eps1."""
        B, H = self.width, self.height
        return self.density * B * H * (1.0 / 3.0 + ratio ** 2 * B ** 2 / (12.0 * H ** 2))

    def validate(self):
        for name in ("width", "height", "density"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} = {v!r} is out of range: allowed a finite {name} > 0")
        return self


class Dynamics(NamedTuple):
    """The time integration after the switch: mass-proportional damping ratio zeta of the lowest
    (elastic) mode, time step T1 / steps_per_period, the outcome rule."""

    damping_ratio: float = 0.05
    steps_per_period: float = 20.0
    rule: BurstRule = BurstRule()

    def validate(self):
        z, n = self.damping_ratio, self.steps_per_period
        if not (math.isfinite(z) and 0 <= z < 1):
            raise ValueError(f"damping_ratio = {z!r} is out of range: allowed 0 <= zeta < 1")
        if not (math.isfinite(n) and n >= 10):
            raise ValueError(f"steps_per_period = {n!r} is out of range: allowed >= 10 (a time step "
                             "that resolves the lowest period)")
        self.rule.validate()
        return self


def conjugate_stress(sigma, ratio: float):
    """c = s11 + R s22 [Pa] of stress rows (..., 3) in (11, 22, 12): the stress conjugate to the
    proportional strain path d eps22 = R d eps11 (W2 = d eps11 dc)."""
    sigma = np.asarray(sigma, float)
    return sigma[..., 0] + ratio * sigma[..., 1]


def path_direction(ratio: float) -> float:
    """alpha_eps [deg, 0-360) of the path's strain direction in the (d eps1, d eps2) plane, the
    angle of the project's strain probes (d eps = |d eps| (cos a, sin a))."""
    return float(np.degrees(np.arctan2(ratio, 1.0)) % 360.0)


def check_ratio(ratio: float, option: str | None = "--ratios") -> float:
    """R of a proportional path, or a ValueError naming ``option`` (if any) and the allowed
    range: R < 0 (the burst commands of the three parts and the cross-check share it)."""
    if isinstance(ratio, bool) or not isinstance(ratio, (int, float, np.floating)) \
            or not math.isfinite(ratio) or ratio >= 0:
        why = ("R = 0 is the oedometric path (no lateral strain)" if ratio == 0 else
               "R > 0 compresses both axes, a contractant path along which c = s1 + R s2 hardens"
               if isinstance(ratio, (int, float)) and ratio > 0 else "R must be a finite number")
        raise ValueError(f"{option + ' ' if option else ''}{ratio!r}: {why}; allowed range: "
                         "R < 0 (lateral extension, the dilatant paths along which c can peak; "
                         "-1 is isochoric)")
    return float(ratio)


def drained_peak_eta(params: HParams, d_eps1: float = 1e-5, eps1_max: float = 0.05) -> tuple:
    """(eta_peak, drained PathResult) of the drained biaxial test at params.p0."""
    r = biaxial_test(params, params.p0, d_eps1, eps1_max)
    _, q, eta = r.invariants()
    k = int(np.argmax(q))
    if k == len(q) - 1:
        why = "" if r.end.outcome == "complete" else f"; the path ends {r.end.line()}"
        raise ValueError(f"the drained test does not peak within eps1 = {eps1_max}{why}")
    return float(eta[k]), r


class CPeak:
    """The peak of c = s1 + R s2 along a proportional strain path, by the rule of docs/burst.md:
    the largest c, confirmed once c has fallen below it by ``FALL`` of its rise from the start
    (c_peak - c_start; a margin far above the Newton tolerance of c, far below a step's change
    near the peak), so that a peak is a peak. Feed c state by state (row 0 the start) with
    ``add``, which returns True once the peak is confirmed (a path's ``until``)."""

    FALL = 1e-3

    def __init__(self, c_start: float):
        self.c = [float(c_start)]
        self.k_max = 0
        self.confirmed = False

    def add(self, c: float) -> bool:
        self.c.append(float(c))
        if self.c[-1] > self.c[self.k_max]:
            self.k_max = len(self.c) - 1
        rise = self.c[self.k_max] - self.c[0]
        fall = self.FALL * rise if rise > 0 else 1e-12 * abs(self.c[0])
        self.confirmed = self.confirmed or self.c[self.k_max] - self.c[-1] > fall
        return self.confirmed

    @property
    def peak(self):
        """Row of the confirmed peak, or None (c has not peaked on the path so far)."""
        return self.k_max if self.confirmed else None

    def below(self, fraction: float = None):
        """Row of the ``below`` switch: the first state where c has risen by ``fraction``
        (default BELOW_RISE) of its rise from the start to the peak; without a peak, the last
        row (the end of the path); None when the peak is the start itself (c falls at once: no
        state of the path lies below it)."""
        if not self.confirmed:
            return len(self.c) - 1
        if self.k_max == 0:
            return None
        th = self.c[0] + (BELOW_RISE if fraction is None else fraction) * (self.c[self.k_max] - self.c[0])
        return next(k for k, c in enumerate(self.c) if c >= th)

    def dc_below(self, k: int, dc: float) -> float:
        """The step of c held by the run switched at row ``k`` below the peak: at most half of
        what is left of the rise, so that the held c stays below the peak (a larger one would
        make it a ``past`` run); dc itself past the peak or without a peak."""
        if self.peak is None or k >= self.peak:
            return dc
        return min(dc, 0.5 * (self.c[self.peak] - self.c[k]))


def proportional_path(state: HState, params: HParams, ratio: float, d_eps1: float = 1e-5,
                      path_strain: float = 0.03) -> tuple:
    """The proportional strain path d eps2 = R d eps1 from ``state`` under strain control, steps
    d_eps1, until c has peaked (``CPeak``) or eps1 = path_strain (counted from the state).
    Returns (PathResult, CPeak)."""
    check_ratio(ratio, None)
    s0 = to_voigt(state.stress)[0]
    peak = CPeak(s0[0] + ratio * s0[1])
    n = max(1, int(round(path_strain / d_eps1)))
    r = run_path(state, params, proportional_strain(d_eps1, ratio), n, label="proportional path",
                 until=lambda e, s: peak.add(s[0] + ratio * s[1]))
    return r, peak


class PathInfo(NamedTuple):
    """A proportional path from a start state: the path (eps counted from its start), c along
    it, the peak and the switch rows (None where there is none), the start state."""

    ratio: float
    start_fraction: float
    eta_start: float
    eps1_start: float
    path: PathResult
    c: np.ndarray
    k_peak: int | None
    k_below: int | None
    start: HState

    @property
    def eta(self):
        return stress_invariants(self.path.sigma)[2]

    @property
    def eta_peak_c(self):
        return float(self.eta[self.k_peak]) if self.k_peak is not None else math.nan


def static_check(state: HState, params: HParams, ratio: float, c_target: float,
                 scan_strain: float = SCAN_STRAIN, n_scan: int = 801) -> dict:
    """Does a static state with c = ``c_target`` exist next to ``state`` along the tie?

    ``converged``: the c-controlled Newton step (``proportional_strain_stress``) from ``state``;
    ``c_max_scan``: the largest c of the one-step responses to d eps = (e, R e, 0) for e over
    [-scan_strain, scan_strain] (n_scan values, each deciding its own sliding pattern,
    ``controllability.control_scan``): below ``c_target``, no strain along the tie within the
    bracket reaches it, so the Newton failure is the absence of a static solution, not a bad
    start. ``d_eps1`` of the converged step. Where Newton fails, ``verdict`` is the decision of
    ``controllability.decide`` ('uncontrollable' past the c peak: W2 = d eps1 dc = 0 there, the
    block dc/d eps1 changing sign) and ``verdict_line`` its words; 'exists' where it converged."""
    ctl = proportional_strain_stress(ratio)
    target = np.array([c_target, 0.0, 0.0])
    out = {"c_target": float(c_target), "verdict": "exists", "verdict_line": ""}
    try:
        _, de, it = mixed_step(state, params, ctl, target)
        out.update(converged=True, d_eps1=float(de[0]), iterations=int(it))
    except MixedControlError as e:
        out.update(converged=False, d_eps1=math.nan, iterations=-1, why=str(e))
        tol = 1e-10 * max(abs(float(c_target)), 1e-3 * params.p0)     # mixed_step's
        v = decide(state, params, ctl, target, np.zeros(3), tol)
        out.update(verdict=v.outcome, verdict_line=verdict_text(v, "c"))
    e = np.linspace(-scan_strain, scan_strain, n_scan)
    c = control_scan(state, params, ctl, np.zeros(3), target, e, 0)[0][:, 0]
    k = int(np.argmax(c))
    out.update(c_max_scan=float(c[k]), d_eps1_c_max=float(e[k]), scan_strain=float(scan_strain))
    return out


class HoldResult(NamedTuple):
    """A run held at c_hold after the switch: outcome, lowest elastic period T1 [s], time step
    [s], generalized mass [kg/m] and stiffness [N/m^2], and the history (dict of arrays, one row a
    step, row 0 the switch): t [s], U1 [m], v [m/s], eps1, eps2 (from the start of the path), c
    [Pa], G_int [N/m], ke, w_ext, w_int, w2_ext, w2_int, damping [J/m], energy_residual [-],
    newton_iters. cut_steps: {step: halvings} of the steps run in substeps; failure: why the run
    ended as a failure when a time step could not converge at all ('' otherwise)."""

    outcome: str
    T1: float
    dt: float
    mass: float
    stiffness: float
    history: dict
    cut_steps: dict = {}
    failure: str = ""


def _tie_response(state, params, ratio, x):
    """(c, dc/dx, new state) of the increment d eps = (x, R x, 0) from ``state``."""
    d = np.zeros((2, 2))
    d[0, 0], d[1, 1] = x, ratio * x
    s, C, ns = update(state, d, params)
    c = s[0, 0] + ratio * s[1, 1]
    dc = C[0, 0, 0, 0] + ratio * C[0, 0, 1, 1] + ratio * (C[1, 1, 0, 0] + ratio * C[1, 1, 1, 1])
    return float(c), float(dc), ns


def path_stiffness(state: HState, params: HParams, ratio: float, d_eps1: float, n: int):
    """The path's own W2 along the proportional path from ``state``, from the material's
    consistent tangent: for each of ``n`` increments d eps = (d_eps1, R d_eps1, 0), c [Pa] at
    its start and k_path = dc/d eps1 [Pa] of the increment (the tangent along the tie: W2 =
    k_path d eps1^2 per unit volume, zero where c peaks). Returns (c (n,), k (n,)), the c of the
    same states as ``proportional_path``'s records 0 .. n-1."""
    c, k = np.empty(n), np.empty(n)
    st = state
    for i in range(n):
        s = to_voigt(st.stress)[0]
        c[i] = s[0] + ratio * s[1]
        _, k[i], st = _tie_response(st, params, ratio, d_eps1)
    return c, k


def elastic_stiffness(state: HState, params: HParams, ratio: float) -> float:
    """dc/d eps1 [Pa] along the tie for sliding prevented (the elastic tangent of the state)."""
    C = update_full(state, np.zeros((2, 2)), params, allow_sliding=False, extras=False).tangent
    return float(C[0, 0, 0, 0] + ratio * C[0, 0, 1, 1] + ratio * (C[1, 1, 0, 0] + ratio * C[1, 1, 1, 1]))


def hold(state: HState, params: HParams, ratio: float, c_hold: float, eps_switch=(0.0, 0.0),
         specimen: Specimen = Specimen(), dynamics: Dynamics = Dynamics(),
         rtol: float = 1e-13, max_iter: int = 40) -> HoldResult:
    """The material point's specimen held at G = B ``c_hold`` from ``state`` (at rest, in
    equilibrium at its own c), the tie kept: Newmark average acceleration (gamma 1/2, beta 1/4)
    on U1, Newton on each step's d eps1 with the exact tangent dc/d eps1 (backtracking: the
    stress is only piecewise smooth), mass-proportional damping C = 2 zeta omega_1 m_G with
    omega_1 = sqrt(K_el / m_G), K_el = (B/H) dc/d eps1 of sliding prevented; dt = T1 /
    steps_per_period. Stops at the first outcome of ``hmodel.burst_rule.decide`` or, undecided,
    at rule.max_periods T1. ``eps_switch``: (eps1, eps2) of the state from the start of the path
    (for the history's strains). Newton stops at |residual| <= rtol x B (|s1| + |R s2|) [N/m]
    (the scale of the round-off of B c): the energy balance's residual per step is the Newton
    residual times dU1."""
    check_ratio(ratio, None)
    specimen.validate()
    dynamics.validate()
    B, H = specimen.width, specimen.height
    m = specimen.mass(ratio)
    c0 = float(conjugate_stress(to_voigt(state.stress)[0], ratio))
    k_el = (B / H) * elastic_stiffness(state, params, ratio)
    if not k_el > 0:
        raise ValueError(f"the state has no elastic stiffness along the tie (dc/deps1 = {k_el})")
    omega = math.sqrt(k_el / m)
    T1 = 2.0 * math.pi / omega
    dt = T1 / dynamics.steps_per_period
    damp = 2.0 * dynamics.damping_ratio * omega * m
    rule = dynamics.rule
    window = rule.window_periods * T1
    n_max = int(math.ceil(rule.max_periods * dynamics.steps_per_period))
    G0, G_ext = B * c0, B * c_hold
    s = to_voigt(state.stress)[0]
    tol = rtol * B * (abs(s[0]) + abs(ratio * s[1]))      # the round-off scale of B c
    # the run starts at rest with the force G_ext applied: a0 from the equation of motion
    u, v, a = 0.0, 0.0, (G_ext - G0) / m
    cols = {k: [0.0] for k in ("t", "U1", "v", "c", "ke", "w_ext", "w_int", "w2_ext", "w2_int",
                               "damping", "energy_residual")}
    cols["c"] = [c0]
    cols["newton_iters"] = [0]
    e1 = [float(eps_switch[0])]
    G_int = G0
    st = state
    x = 0.0                       # d eps1 of the step (guess: none)
    outcome = None
    cut_steps = {}
    floor = 0.5 ** MAX_CUTS
    for n in range(1, n_max + 1):
        # the step, whole or (its Newton failing) in substeps: halves, growing back x2 after
        # each success, down to dt / 2**MAX_CUTS; each substep Newmark's own (its balance exact)
        frac, h, depth = 0.0, 1.0, 0
        dw = dict.fromkeys(("w_ext", "w_int", "w2_ext", "w2_int", "damping"), 0.0)
        ke0, its, failed = 0.5 * m * v * v, 0, None
        while frac < 1.0:
            h = min(h, 1.0 - frac)
            try:
                x, c, ns, it = _tie_newmark(st, params, ratio, m, damp, B, H, G_ext, h * dt, v, a,
                                            h * x, tol, max_iter)
            except _NewtonFailed as e:
                if h * 0.5 >= floor:
                    h *= 0.5
                    depth += 1
                    continue
                failed = str(e)
                break
            du = H * x
            hs = h * dt
            a1 = 4.0 * (du - hs * v) / hs ** 2 - a
            v1 = 2.0 * du / hs - v
            G1 = B * c
            # the work of each force over the substep (trapezoid: exact for the balance)
            dw["w_ext"] += du * G_ext
            dw["w_int"] += du * 0.5 * (G_int + G1)
            dw["damping"] += du * damp * 0.5 * (v + v1)
            dw["w2_ext"] += du * (G_ext - G0)
            dw["w2_int"] += du * 0.5 * ((G_int - G0) + (G1 - G0))
            u, v, a, G_int, st, c_end = u + du, v1, a1, G1, ns, c
            its += it
            x /= h                        # the next (sub)step's guess, per whole step
            frac += h
            h *= 2.0
        if depth:
            cut_steps[n] = depth
        if failed is not None:
            # no time step, however small, converges: the specimen's collapse outruns the
            # integrator (the step was cut to dt / 2**MAX_CUTS): recorded as the failure
            outcome = "failure"
            cut_steps[n] = MAX_CUTS
            fail_why = (f"time step {n} did not converge even in substeps of dt / 2**{MAX_CUTS} "
                        f"({failed})")
            if frac == 0.0:
                break
        ke1 = 0.5 * m * v * v
        dke = ke1 - ke0
        scale = max(abs(dke), abs(dw["w2_ext"]), abs(dw["w2_int"]), abs(dw["damping"]))
        res = (abs(dke - (dw["w2_ext"] - dw["w2_int"] - dw["damping"])) / scale
               if scale > 0 else 0.0)
        cols["t"].append((n - 1 + frac) * dt); cols["U1"].append(u); cols["v"].append(v)
        cols["c"].append(c_end)
        cols["ke"].append(ke1)
        for k, d in dw.items():
            cols[k].append(cols[k][-1] + d)
        cols["energy_residual"].append(res)
        cols["newton_iters"].append(its)
        e1.append(e1[0] + u / H)
        if outcome is not None:
            break
        outcome = decide_outcome(cols["t"], np.array(cols["ke"]), cols["w2_ext"], e1, window, rule)
        if outcome is not None:
            break
    hist = {k: np.asarray(vals, float) for k, vals in cols.items()}
    hist["eps1"] = np.asarray(e1)
    hist["eps2"] = float(eps_switch[1]) + ratio * (hist["eps1"] - e1[0])
    hist["G_int"] = B * hist["c"]
    return HoldResult(outcome or "undecided", T1, dt, m, k_el, hist, cut_steps,
                      fail_why if failed is not None else "")


class _NewtonFailed(RuntimeError):
    """A time step of ``hold`` whose Newton did not converge."""


def _tie_newmark(st, params, ratio, m, damp, B, H, G_ext, dt, v, a, x, tol, max_iter):
    """One Newmark (average acceleration) step of length ``dt`` of the tied specimen from
    ``st`` at velocity ``v``, acceleration ``a``: Newton with backtracking on x = d eps1 from the
    guess ``x``, m a(x) + C v(x) + B c(x) = G_ext, a(x) = 4 (H x - dt v)/dt^2 - a,
    v(x) = 2 H x / dt - v. Returns (x, c, new state, iterations); raises _NewtonFailed."""
    def residual(x):
        c, dc, ns = _tie_response(st, params, ratio, x)
        a1 = 4.0 * (H * x - dt * v) / dt ** 2 - a
        v1 = 2.0 * H * x / dt - v
        return (m * a1 + damp * v1 + B * c - G_ext,
                m * 4.0 * H / dt ** 2 + damp * 2.0 * H / dt + B * dc, c, ns)
    r, J, c, ns = residual(x)
    it = 0
    while abs(r) > tol:
        if it >= max_iter or not J > 0:
            raise _NewtonFailed(f"the dynamic Newton did not converge (residual {r:.3e} N/m after "
                                f"{it} iterations)")
        dx = -r / J
        lam = 1.0
        while True:
            r1, J1, c1, ns1 = residual(x + lam * dx)
            if abs(r1) < (1.0 - 1e-4 * lam) * abs(r) or lam < 1e-8:
                break
            lam *= 0.5
        x, r, J, c, ns = x + lam * dx, r1, J1, c1, ns1
        it += 1
    return x, c, ns, it


class BurstResult(NamedTuple):
    """Everything ``run_burst`` found: rows of burst.csv (dicts), the histories (list of dicts
    of arrays with their keys), the paths (PathInfo), the drained reference (eta_peak, path),
    static checks per run, wall time [s]."""

    rows: list
    histories: list
    paths: list
    eta_peak: float
    drained: PathResult
    wall_time: float


def run_burst(params: HParams, ratios, start_fractions, dc: float, specimen: Specimen = Specimen(),
              dynamics: Dynamics = Dynamics(), d_eps1: float = 1e-5, path_strain: float = 0.03,
              progress=None, path_d_eps1: float | None = None) -> BurstResult:
    """The whole material-point experiment of docs/burst.md at params.p0: for each start fraction
    and each R, the proportional path, its c peak, the ``below`` and ``past`` switches (each
    checked statically and held dynamically at c_switch + dc). ``d_eps1``: the axial strain step
    of the drained path, ``path_d_eps1`` the proportional paths' (None: ``d_eps1``).
    ``progress``: None or a callable taking one line of text."""
    t0 = time.perf_counter()
    pd_eps1 = d_eps1 if path_d_eps1 is None else path_d_eps1
    for R in ratios:
        check_ratio(R, None)
    fr = [float(f) for f in start_fractions]
    if any(not (0 < f < 1) for f in fr):
        raise ValueError(f"start fractions {fr} out of range: allowed 0 < f < 1 of the drained peak eta")
    if not (math.isfinite(dc) and dc >= 0):
        raise ValueError(f"dc = {dc!r} is out of range: allowed a finite dc >= 0 [Pa]")
    say = progress or (lambda s: None)
    eta_peak, drained = drained_peak_eta(params, d_eps1)
    say(f"drained path: peak eta = {eta_peak:.4f}")
    rows, hists, paths = [], [], []
    for f in fr:
        r0, s0 = state_at_eta(params, f * eta_peak, params.p0, d_eps1)
        eta0 = float(r0.invariants()[2][-1])
        for R in ratios:
            p, pk = proportional_path(s0, params, R, pd_eps1, path_strain)
            c = conjugate_stress(p.sigma, R)
            k_peak, k_below = pk.peak, pk.below()
            info = PathInfo(float(R), f, eta0, float(r0.eps[-1, 0]), p, c, k_peak, k_below, s0)
            paths.append(info)
            peak_txt = (f"c peaks at eta = {info.eta_peak_c:.4f} ({info.eta_peak_c / eta_peak:.3f} "
                        f"of the drained peak), eps1 = {p.eps[k_peak, 0]:.4%} from the start"
                        if k_peak is not None else f"c does not peak within {path_strain:g}")
            say(f"f = {f:g} (eta {eta0:.4f}), R = {R:g}: {peak_txt}")
            for switch, k in (("below", k_below), ("past", k_peak)):
                if k is None:
                    continue
                st = s0 if k == 0 else run_path(s0, params, proportional_strain(pd_eps1, R), k).state
                c_sw = float(c[k])
                dc_run = pk.dc_below(k, dc)
                stat = static_check(st, params, R, c_sw + dc_run)
                run = hold(st, params, R, c_sw + dc_run, (p.eps[k, 0], p.eps[k, 1]), specimen,
                           dynamics)
                h = run.history
                row = {
                    "ratio": float(R), "start_fraction": f, "eta_start": eta0,
                    "eta_peak_c": info.eta_peak_c,
                    "fraction_peak_c": info.eta_peak_c / eta_peak,
                    "eps1_peak_c": float(p.eps[k_peak, 0]) if k_peak is not None else math.nan,
                    "c_start": float(c[0]),
                    "c_peak": float(c[k_peak]) if k_peak is not None else math.nan,
                    "switch": switch, "eta_switch": float(info.eta[k]),
                    "eps1_switch": float(p.eps[k, 0]), "c_switch": c_sw, "dc": float(dc_run),
                    "static_solution": bool(stat["converged"]), "c_max_scan": stat["c_max_scan"],
                    "static_verdict": stat["verdict"], "static_verdict_line": stat["verdict_line"],
                    "outcome": run.outcome, "ke_growth": ke_growth(h["ke"]),
                    "ke_max": float(np.max(h["ke"])), "w2_ext_end": float(h["w2_ext"][-1]),
                    "w2_int_end": float(h["w2_int"][-1]), "damping_end": float(h["damping"][-1]),
                    "t_end": float(h["t"][-1]), "steps": int(len(h["t"]) - 1),
                    "energy_residual": float(np.max(h["energy_residual"])),
                    "T1": run.T1, "dt": run.dt, "mass": run.mass, "stiffness": run.stiffness,
                    "time_steps_cut": run.cut_steps, "failure_reason": run.failure,
                }
                rows.append(row)
                hists.append({"ratio": float(R), "start_fraction": f, "switch": switch, **h})
                say(f"  {switch}: c held at {c_sw + dc_run:.6g} Pa: static solution "
                    f"{'exists' if stat['converged'] else 'none'} (max c along the tie "
                    f"{stat['c_max_scan']:.6g}); dynamics: {run.outcome} after "
                    f"{row['steps']} steps ({row['t_end']:.4g} s, T1 = {run.T1:.3g} s), "
                    f"E_c up {row['ke_growth']:.3g}x")
    return BurstResult(rows, hists, paths, eta_peak, drained, time.perf_counter() - t0)


def cone_entries(params: HParams, ratios, d_eps1: float = 1e-5, check_every: int = 25,
                 eps1_max: float = DOMAIN_EPS1_MAX, norm: float = 1e-6) -> dict:
    """Where each path's strain direction enters the cone W2 <= 0 of the directional analysis
    along the drained path: for each R, the first drained state whose strain probe in the
    direction alpha_eps of d eps = (1, R) (the probe deciding its own sliding pattern, as in
    ``probes.strain_probes``) has W2 <= 0; every ``check_every`` steps one probe per direction,
    then bisection within the block (a direction that enters the cone stays in it up to the
    peak, as the domain's bisection assumes). Returns {R: {"alpha_eps" [deg], "eta", "eps1"}},
    eta and eps1 nan where the direction does not enter it before the drained peak."""
    from .driver import drained_biaxial, isotropic_state
    from .probes import strain_probes
    ratios = [float(R) for R in ratios]
    alphas = [path_direction(R) for R in ratios]
    out = {R: {"alpha_eps": a, "eta": math.nan, "eps1": math.nan} for R, a in zip(ratios, alphas)}
    todo = set(ratios)
    st = isotropic_state(params)
    ctl = drained_biaxial(d_eps1)
    q_prev, eps1 = -np.inf, 0.0
    w2 = lambda s, a: strain_probes(s, params, a, norm=norm).w2
    for _ in range(int(eps1_max / (d_eps1 * check_every))):
        r = run_path(st, params, ctl, check_every)
        _, q, eta = r.invariants()
        neg = [R for R, w in zip(ratios, w2(r.state, alphas)) if R in todo and w <= 0]
        if neg:
            rs = run_path(st, params, ctl, check_every, keep_states=True)   # the block's states
            for R in neg:
                a = [path_direction(R)]
                lo, hi = 0, len(rs.states) - 1
                while hi - lo > 1:
                    mid = (lo + hi) // 2
                    lo, hi = (lo, mid) if w2(rs.states[mid], a)[0] <= 0 else (mid, hi)
                out[R].update(eta=float(eta[hi]), eps1=eps1 + float(r.eps[hi, 0]))
                todo.discard(R)
        if not todo or q[-1] < q_prev:
            break                                     # all found, or past the drained peak
        q_prev = q[-1]
        eps1 += float(r.eps[-1, 0])
        st = r.state
    return out


def cone_at(params: HParams, eta: float, d_eps1: float = 1e-5, n: int = 360) -> dict:
    """The cone W2 <= 0 in strain directions at the first drained state with eta >= ``eta``
    (adaptive sweep, ``probes.directional_sweep``): its arcs of alpha_eps [deg] and the range of
    R = tan(alpha_eps) of the part with d eps1 > 0 > d eps2 (the proportional paths of R < 0)."""
    from .probes import arcs, directional_sweep
    _, st = state_at_eta(params, eta, params.p0, d_eps1)
    sw = directional_sweep(st, params, n=n)
    neg = sw.w2 <= 0
    a = np.asarray(sw.alpha_eps)[neg] % 360.0
    q4 = a[(a > 270.0) & (a < 360.0)]
    R = np.tan(np.radians(q4))
    return {"eta": float(eta), "alpha_eps_arcs": arcs(sw.alpha_eps, neg),
            "ratio_range": [float(R.min()), float(R.max())] if R.size else None}


BURST_COLUMNS = ["ratio", "start_fraction", "eta_start", "eta_peak_c", "fraction_peak_c",
                 "eps1_peak_c", "c_start", "c_peak", "switch", "eta_switch", "eps1_switch",
                 "c_switch", "dc", "static_solution", "c_max_scan", "outcome", "ke_growth",
                 "ke_max", "w2_ext_end", "w2_int_end", "damping_end", "t_end", "steps",
                 "energy_residual", "T1", "dt", "mass", "stiffness"]
HISTORY_COLUMNS = ["ratio", "start_fraction", "switch", "step", "t", "U1", "v", "eps1", "eps2",
                   "c", "G_int", "ke", "w_ext", "w_int", "w2_ext", "w2_int", "damping",
                   "energy_residual", "newton_iters"]
PATH_COLUMNS = ["ratio", "start_fraction", "eps1", "eps2", "s1", "s2", "p", "q", "eta", "c"]
