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
  decided by ``hmodel.burst_rule`` from E_c and W2_ext ('not_converged' when a time step
  converges at no substep), the growth measure is its ``energy_release``; W2_int, the damping
  work, Newmark's own balance (the work of the Newton residual) and the energy check from the
  material's stress and strain and the field's kinetic energy (``burst_rule.EnergyCheck``) are
  recorded at every step.

Functions here return arrays and write nothing (``hmodel.cli`` writes the files).
"""
from __future__ import annotations

import math
import time
from typing import NamedTuple

import numpy as np

from common.options import vocabulary_range

from .burst_rule import (RELEASE, BurstRule, EnergyCheck, check_columns, decide as decide_outcome,
                         ke_growth, release_columns)
from .controllability import control_scan, decide, verdict_text
from .driver import (MAX_CUTS, MixedControlError, PathResult, drained_biaxial, isotropic_state,
                     mixed_step, proportional_strain, proportional_strain_stress, run_path,
                     stress_invariants)
from .experiment import DOMAIN_EPS1_MAX, biaxial_test, state_at_eta
from .contract import material_of
from .probes import arcs, directional_sweep, strain_probes
from .tensors import stress_work, to_voigt

__all__ = ["check_ratio", "Specimen", "Dynamics", "PathInfo", "HoldResult", "conjugate_stress", "path_direction",
           "drained_peak_eta", "proportional_path", "CPeak", "static_check", "hold", "run_burst",
           "BurstResult", "BELOW_RISE", "cone_entries", "cone_at", "BURST_COLUMNS", "HISTORY_COLUMNS",
           "PATH_COLUMNS"]

BELOW_RISE = 0.95     # ``below``: c_start + BELOW_RISE (c_peak - c_start), docs/burst.md
SCAN_STRAIN = 2e-3    # static_check: the bracket |d eps1| <= this of the scan along the tie
# run_burst's name in the vocabulary's terms (``common.options.VOCABULARY``: the fields
# "hmodel.run_burst.dc", "hmodel.run_burst.path_strain" of --dc and --path-strain)
RECORD = "hmodel.run_burst"


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

    def kinetic_energy(self, u1_rate: float, ratio: float) -> float:
        """E_c [J/m] of the homogeneous velocity field along the tie at U1' = ``u1_rate`` [m/s]:
        rho/2 int |u'|^2 dA over B x H, u' = (-eps2' (x - B/2), -eps1' y), eps1' = U1'/H,
        eps2' = R eps1', by 2 x 2 Gauss-Legendre points (exact for the quadratic integrand).
        The field integrated, not ``mass``: the energy check's kinetic energy
        (``burst_rule.EnergyCheck``), which a wrong m_G in the integrator must not share."""
        B, H = self.width, self.height
        g = np.array([-1.0, 1.0]) / math.sqrt(3.0)
        x, y = 0.5 * B * (g + 1.0), 0.5 * H * (g + 1.0)      # the points; weights B/2, H/2 each
        e1 = float(u1_rate) / H
        X, Y = np.meshgrid(x, y, indexing="ij")
        v2 = (ratio * e1 * (X - 0.5 * B)) ** 2 + (e1 * Y) ** 2
        return 0.5 * self.density * 0.25 * B * H * float(np.sum(v2))

    def validate(self):
        # width and height: the ranges of the vocabulary's --width and --height (written once,
        # there); density: its own (--density's term has no range)
        for name in ("width", "height"):
            v, r = getattr(self, name), vocabulary_range("Specimen", name)
            if not r.contains(v):
                raise ValueError(f"{name} = {v!r} is out of range: allowed a finite {r.text(name)}")
        v = self.density
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise ValueError(f"density = {v!r} is out of range: allowed a finite density > 0")
        return self


class Dynamics(NamedTuple):
    """The time integration after the switch: mass-proportional damping ratio zeta of the lowest
    (elastic) mode, time step T1 / steps_per_period, the outcome rule."""

    damping_ratio: float = 0.05
    steps_per_period: float = 20.0
    rule: BurstRule = BurstRule()

    def validate(self):
        # the ranges of the vocabulary's --damping-ratio and --steps-per-period (written once,
        # there); steps_per_period read as a real (its default 20.0: a whole number of steps per
        # period is not needed by the integration here, only enough of them)
        z, n = self.damping_ratio, self.steps_per_period
        r = vocabulary_range("Dynamics", "damping_ratio")
        if not r.contains(z):
            raise ValueError(f"damping_ratio = {z!r} is out of range: allowed {r.text('zeta')}")
        r = vocabulary_range("Dynamics", "steps_per_period")._replace(kind="real")
        if not r.contains(n):
            raise ValueError(f"steps_per_period = {n!r} is out of range: allowed "
                             f"{r.text('steps_per_period')} (a time step that resolves the lowest "
                             "period)")
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


def drained_peak_eta(params, d_eps1: float = 1e-5, eps1_max: float = 0.05) -> tuple:
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

    def missed(self) -> float:
        """The sizing rule of dc [Pa] (docs/burst.md): how far above the sampled peak the path's
        c can rise between two samples, at most the slope of the last step before the peak
        times the step, c_peak - c_(peak - 1) (c concave near its peak: its slope beyond the
        peak row is at most that secant). A ``past`` run held at c_peak + dc with dc above this
        is past the path's true peak. nan without a confirmed peak after the start."""
        if self.peak is None or self.k_max == 0:
            return math.nan
        return self.c[self.k_max] - self.c[self.k_max - 1]

    def dc_below(self, k: int, dc: float) -> float:
        """The step of c held by the run switched at row ``k`` below the peak: at most half of
        what is left of the rise, so that the held c stays below the peak (a larger one would
        make it a ``past`` run); dc itself past the peak or without a peak."""
        if self.peak is None or k >= self.peak:
            return dc
        return min(dc, 0.5 * (self.c[self.peak] - self.c[k]))


def proportional_path(state, params, ratio: float, d_eps1: float = 1e-5,
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
    start: object

    @property
    def eta(self):
        return stress_invariants(self.path.sigma)[2]

    @property
    def eta_peak_c(self):
        return float(self.eta[self.k_peak]) if self.k_peak is not None else math.nan


def static_check(state, params, ratio: float, c_target: float,
                 scan_strain: float = SCAN_STRAIN, n_scan: int = 801) -> dict:
    """Does a static state with c = ``c_target`` exist next to ``state`` along the tie?

    ``converged``: the c-controlled Newton step (``proportional_strain_stress``) from ``state``;
    ``c_max_scan``: the largest c of the one-step responses to d eps = (e, R e, 0) for e over
    [-scan_strain, scan_strain] (n_scan values, each deciding its own sliding pattern,
    ``controllability.control_scan``): below ``c_target``, no strain along the tie within the
    bracket reaches it, so the Newton failure is the absence of a static solution, not a bad
    start (an increment the law refuses, ``MaterialError``, is left out of the scan). ``d_eps1``
    of the converged step. Where Newton fails, ``verdict`` is the decision of
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
    k = int(np.nanargmax(c))          # NaN: an increment the law refuses (controllability._rows)
    out.update(c_max_scan=float(c[k]), d_eps1_c_max=float(e[k]), scan_strain=float(scan_strain))
    return out


class HoldResult(NamedTuple):
    """A run held at c_hold after the switch: outcome (``burst_rule.OUTCOMES``), lowest elastic
    period T1 [s], time step [s], generalized mass [kg/m] and stiffness [N/m^2], and the history
    (dict of arrays, one row a step, row 0 the switch; ``HISTORY_COLUMNS``): t [s], U1 [m], v
    [m/s], eps1, eps2 (from the start of the path), c [Pa], G_int [N/m], ke, w_ext, w_int,
    w2_ext, w2_int, damping [J/m] (the integrator's: E_c = m_G v^2 / 2, works of its forces),
    newton_work [-] (Newmark's balance, the work of the Newton residual), the energy check's
    ke_mid, w2_int_stress, damping_mid and its residual energy_check [J/m]
    (``burst_rule.EnergyCheck``; ``check_columns`` makes them relative), newton_iters. cut_steps: {step: halvings} of the steps run in
    substeps; failure_reason: what did not converge when the outcome is 'not_converged' ('' for
    every other outcome)."""

    outcome: str
    T1: float
    dt: float
    mass: float
    stiffness: float
    history: dict
    cut_steps: dict = {}
    failure_reason: str = ""


def _tie_response(state, params, ratio, x):
    """(c, dc/dx, new state) of the increment d eps = (x, R x, 0) from ``state``."""
    d = np.zeros((2, 2))
    d[0, 0], d[1, 1] = x, ratio * x
    s, C, ns = material_of(params).update(state, d, params)
    c = s[0, 0] + ratio * s[1, 1]
    dc = C[0, 0, 0, 0] + ratio * C[0, 0, 1, 1] + ratio * (C[1, 1, 0, 0] + ratio * C[1, 1, 1, 1])
    return float(c), float(dc), ns


def path_stiffness(state, params, ratio: float, d_eps1: float, n: int):
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


def elastic_stiffness(state, params, ratio: float) -> float:
    """dc/d eps1 [Pa] along the tie for sliding prevented (the elastic tangent of the state)."""
    C = material_of(params).elastic_update(state, np.zeros((2, 2)), params)[1]
    return float(C[0, 0, 0, 0] + ratio * C[0, 0, 1, 1] + ratio * (C[1, 1, 0, 0] + ratio * C[1, 1, 1, 1]))


# the history of ``hold``, one row a step (HoldResult)
HOLD_COLUMNS = ("t", "U1", "v", "c", "ke", "w_ext", "w_int", "w2_ext", "w2_int", "damping",
                "newton_work", "ke_mid", "w2_int_stress", "damping_mid", "energy_check")


def hold(state, params, ratio: float, c_hold: float, eps_switch=(0.0, 0.0),
         specimen: Specimen = Specimen(), dynamics: Dynamics = Dynamics(),
         rtol: float = 1e-13, max_iter: int = 40) -> HoldResult:
    """The material point's specimen held at G = B ``c_hold`` from ``state`` (at rest, in
    equilibrium at its own c), the tie kept: Newmark average acceleration (gamma 1/2, beta 1/4)
    on U1, Newton on each step's d eps1 with the exact tangent dc/d eps1 (backtracking: the
    stress is only piecewise smooth), mass-proportional damping C = 2 zeta omega_1 m_G with
    omega_1 = sqrt(K_el / m_G), K_el = (B/H) dc/d eps1 of sliding prevented; dt = T1 /
    steps_per_period. Stops at the first outcome of ``hmodel.burst_rule.decide`` or, undecided,
    at rule.max_periods T1; 'not_converged' when a time step converges at no substep (down to
    dt / 2**MAX_CUTS; what failed in ``failure_reason``). ``eps_switch``: (eps1, eps2) of the
    state from the start of the path (for the history's strains). Newton stops at |residual| <=
    rtol x B (|s1| + |R s2|) [N/m] (the scale of the round-off of B c).

    Every step records the integrator's energies (E_c = m_G v^2 / 2, the trapezoidal works of
    its forces) and their balance's residual, ``newton_work``: |dE_c - (dW2_ext - dW2_int - dD)|
    over the largest second-order energy so far (E_c, |W2_ext|, |W2_int|, D), an identity of
    Newmark's scheme up to the Newton residual times dU1 (the work of the Newton residual: it
    proves nothing about the mass or the forces); and the energy check that the scheme cannot
    satisfy by itself (``burst_rule.EnergyCheck``): E_c at the step's midpoint of the
    homogeneous velocity field dU1/dt (``Specimen.kinetic_energy``: the field integrated with the
    density, not m_G), W2_int from the material's stress and strain (``stress_work`` x B H), the
    damping's work by the midpoint rule: ``energy_check`` its residual [J/m] (O(dt^2) of the
    run's energies on a healthy run), and W2_int from the stresses beside W2_int of the forces
    (``burst_rule.check_columns``: their relative difference, ``work_check``)."""
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
    alpha = 2.0 * dynamics.damping_ratio * omega        # C = alpha m_G: mass-proportional
    damp = alpha * m
    rule = dynamics.rule
    window = rule.window_periods * T1
    n_max = int(math.ceil(rule.max_periods * dynamics.steps_per_period))
    # the switch's internal force by the function every step uses (a zero increment: c0 to
    # round-off), the held one dG above it: the switch is an equilibrium of the discrete system
    G0 = B * _tie_response(state, params, ratio, 0.0)[0]
    G_ext = G0 + B * (c_hold - c0)
    s = to_voigt(state.stress)[0]
    tol = rtol * B * (abs(s[0]) + abs(ratio * s[1]))      # the round-off scale of B c
    # the run starts at rest with the force G_ext applied: a0 from the equation of motion
    u, v, a = 0.0, 0.0, (G_ext - G0) / m
    cols = {k: [0.0] for k in HOLD_COLUMNS}
    cols["c"] = [c0]
    cols["newton_iters"] = [0]
    e1 = [float(eps_switch[0])]
    G_int = G0
    st = state
    check = EnergyCheck(alpha)
    scale = 0.0                   # the largest second-order energy of the integrator so far
    x = 0.0                       # d eps1 of the step (guess: none)
    outcome = None
    cut_steps = {}
    why = ""
    floor = 0.5 ** MAX_CUTS
    for n in range(1, n_max + 1):
        # the step, whole or (its Newton failing) in substeps: halves, growing back x2 after
        # each success, down to dt / 2**MAX_CUTS; each substep Newmark's own (its balance exact)
        frac, h, depth = 0.0, 1.0, 0
        dw = dict.fromkeys(("w_ext", "w_int", "w2_ext", "w2_int", "damping", "w2_int_stress"),
                           0.0)
        ke0, its, failed, worst, ke_mid = 0.5 * m * v * v, 0, None, 0.0, 0.0
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
            # the energy check: the material's own work, the field's kinetic energy
            dwi = B * H * float(stress_work(st, ns, state.stress))
            dw["w2_int_stress"] += dwi
            ke_mid = specimen.kinetic_energy(du / hs, ratio)
            res = check.step(hs, ke_mid, du * (G_ext - G0), dwi)
            worst = res if abs(res) > abs(worst) else worst
            u, v, a, G_int, st, c_end = u + du, v1, a1, G1, ns, c
            its += it
            x /= h                        # the next (sub)step's guess, per whole step
            frac += h
            h *= 2.0
        if depth:
            cut_steps[n] = depth
        if failed is not None:
            # no time step, however small, converges: the integrator stopped, not the specimen
            outcome = "not_converged"
            cut_steps[n] = MAX_CUTS
            why = (f"time step {n} did not converge even in substeps of dt / 2**{MAX_CUTS} "
                   f"({failed})")
            if frac == 0.0:
                break
        ke1 = 0.5 * m * v * v
        cols["t"].append((n - 1 + frac) * dt); cols["U1"].append(u); cols["v"].append(v)
        cols["c"].append(c_end)
        cols["ke"].append(ke1)
        for k, d in dw.items():
            cols[k].append(cols[k][-1] + d)
        scale = max(scale, ke1, abs(cols["w2_ext"][-1]), abs(cols["w2_int"][-1]),
                    cols["damping"][-1])
        res = abs((ke1 - ke0) - (dw["w2_ext"] - dw["w2_int"] - dw["damping"]))
        cols["newton_work"].append(res / scale if scale > 0 else 0.0)
        cols["ke_mid"].append(ke_mid)
        cols["damping_mid"].append(check.damping)
        cols["energy_check"].append(worst)
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
    return HoldResult(outcome or "undecided", T1, dt, m, k_el, hist, cut_steps, why)


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


def run_burst(params, ratios, start_fractions, dc: float, specimen: Specimen = Specimen(),
              dynamics: Dynamics = Dynamics(), d_eps1: float = 1e-5, path_strain: float = 0.03,
              progress=None, path_d_eps1: float | None = None) -> BurstResult:
    """The whole material-point experiment of docs/burst.md at params.p0: for each start fraction
    and each R, the proportional path, its c peak, the ``below`` and ``past`` switches (each
    checked statically and held dynamically at c_switch + dc). ``d_eps1``: the axial strain step
    of the drained path, ``path_d_eps1`` the proportional paths' (None: ``d_eps1``).
    ``progress``: None or a callable taking one line of text. Failed (an exception), the runs
    finished (complete rows, histories and paths) ride on the exception as ``.partial``, a
    BurstResult (None before the drained peak is known)."""
    t0 = time.perf_counter()
    pd_eps1 = d_eps1 if path_d_eps1 is None else path_d_eps1
    for R in ratios:
        check_ratio(R, None)
    fr = [float(f) for f in start_fractions]
    # --start-fractions' range with its upper end open: a start lies below the drained peak
    r = vocabulary_range(RECORD, "start_fractions", hi_open=True)
    if any(not r.contains(f) for f in fr):
        raise ValueError(f"start fractions {fr} out of range: allowed {r.text('f')} of the drained "
                         "peak eta")
    # the ranges of dc and path_strain are the vocabulary's terms' (--dc, --path-strain), read
    # from them at each call: written once, in the term (as fem.burst's BurstConfig and
    # dem.burst's BurstOptions read them)
    for name, v in (("dc", dc), ("path_strain", path_strain)):
        r = vocabulary_range(RECORD, name)
        if not r.contains(v):
            raise ValueError(f"{name} = {v!r} is out of range: allowed a finite "
                             f"{r.text(name, unit=True)}")
    say = progress or (lambda s: None)
    try:
        eta_peak, drained = drained_peak_eta(params, d_eps1)
    except BaseException as e:
        e.partial = None
        raise
    say(f"drained path: peak eta = {eta_peak:.4f}")
    rows, hists, paths = [], [], []
    try:
        _burst_runs(params, ratios, fr, dc, specimen, dynamics, d_eps1, path_strain, pd_eps1,
                    eta_peak, say, rows, hists, paths)
    except BaseException as e:
        # the runs finished: complete rows with their histories, and the paths they came from
        done = {(r["ratio"], r["start_fraction"]) for r in rows}
        e.partial = BurstResult(rows, hists, [p for p in paths if (p.ratio, p.start_fraction)
                                                in done], eta_peak, drained,
                                time.perf_counter() - t0)
        raise
    return BurstResult(rows, hists, paths, eta_peak, drained, time.perf_counter() - t0)


def _burst_runs(params, ratios, fr, dc, specimen, dynamics, d_eps1, path_strain, pd_eps1,
                eta_peak, say, rows, hists, paths):
    """The runs of ``run_burst``, appended to ``rows``, ``hists`` and ``paths`` as they finish."""
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
                    "dc_rule": pk.missed(),
                    "static_solution": bool(stat["converged"]), "c_max_scan": stat["c_max_scan"],
                    "static_verdict": stat["verdict"], "static_verdict_line": stat["verdict_line"],
                    "outcome": run.outcome,
                    **release_columns(h["t"], h["ke"], h["w2_ext"], run.T1),
                    "ke_growth": ke_growth(h["ke"]),
                    "ke_max": float(np.max(h["ke"])), "w2_ext_end": float(h["w2_ext"][-1]),
                    "w2_int_end": float(h["w2_int"][-1]), "damping_end": float(h["damping"][-1]),
                    "t_end": float(h["t"][-1]), "steps": int(len(h["t"]) - 1),
                    "newton_work": float(np.max(h["newton_work"])), **check_columns(h),
                    "newton_iters_mean": (float(np.mean(h["newton_iters"][1:]))
                                          if len(h["t"]) > 1 else 0.0),
                    "T1": run.T1, "dt": run.dt, "mass": run.mass, "stiffness": run.stiffness,
                    "failure_reason": run.failure_reason, "time_steps_cut": run.cut_steps,
                }
                rows.append(row)
                hists.append({"ratio": float(R), "start_fraction": f, "switch": switch,
                              "T1": run.T1, **h})
                rel = (f"E_c - E_c(0) passed {RELEASE:g} W2_ext at {row['t_release_t1']:.2f} T1"
                       if row["released"] else f"E_c - E_c(0) stayed below {RELEASE:g} W2_ext")
                say(f"  {switch}: c held at {c_sw + dc_run:.6g} Pa: static solution "
                    f"{'exists' if stat['converged'] else 'none'} (max c along the tie "
                    f"{stat['c_max_scan']:.6g}); dynamics: {run.outcome} after "
                    f"{row['steps']} steps ({row['t_end']:.4g} s, T1 = {run.T1:.3g} s), {rel} "
                    f"(largest {row['ke_w2ext_max']:.3g} x W2_ext)"
                    + (f"; {run.failure_reason}" if run.failure_reason else ""))


def cone_entries(params, ratios, d_eps1: float = 1e-5, check_every: int = 25,
                 eps1_max: float = DOMAIN_EPS1_MAX, norm: float = 1e-6) -> dict:
    """Where each path's strain direction enters the cone W2 <= 0 of the directional analysis
    along the drained path: for each R, the first drained state whose strain probe in the
    direction alpha_eps of d eps = (1, R) (the probe deciding its own sliding pattern, as in
    ``probes.strain_probes``) has W2 <= 0; every ``check_every`` steps one probe per direction,
    then bisection within the block (a direction that enters the cone stays in it up to the
    peak, as the domain's bisection assumes). Returns {R: {"alpha_eps" [deg], "eta", "eps1"}},
    eta and eps1 nan where the direction does not enter it before the drained peak."""
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


def cone_at(params, eta: float, d_eps1: float = 1e-5, n: int = 360) -> dict:
    """The cone W2 <= 0 in strain directions at the first drained state with eta >= ``eta``
    (adaptive sweep, ``probes.directional_sweep``): its arcs of alpha_eps [deg] and the range of
    R = tan(alpha_eps) of the part with d eps1 > 0 > d eps2 (the proportional paths of R < 0)."""
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
                 "c_switch", "dc", "dc_rule", "static_solution", "c_max_scan", "outcome",
                 "ke_w2ext_max", "t_release", "t_release_t1", "released", "ke_growth",
                 "ke_max", "w2_ext_end", "w2_int_end", "damping_end", "t_end", "steps",
                 "newton_work", "energy_check", "work_check", "newton_iters_mean", "T1", "dt",
                 "mass", "stiffness", "failure_reason"]
HISTORY_COLUMNS = ["ratio", "start_fraction", "switch", "step", "t", "U1", "v", "eps1", "eps2",
                   "c", "G_int", "ke", "w_ext", "w_int", "w2_ext", "w2_int", "damping",
                   "newton_work", "ke_mid", "w2_int_stress", "damping_mid", "energy_check",
                   "newton_iters"]
PATH_COLUMNS = ["ratio", "start_fraction", "eps1", "eps2", "s1", "s2", "p", "q", "eta", "c"]
