"""Any law of the material point fitted to a measured drained biaxial curve (issue 19, part 2;
issue 40; docs/fit.md).

A measured curve q(eps1) (and eps_v(eps1) where present) at the confining stress sigma2 is
compared with the law's drained path from the isotropic state at p0 = sigma2
(``experiment.biaxial_test``); the free parameters are found by weighted least squares
(``scipy.optimize.least_squares``, trust-region reflective within bounds) from several starts.

What a fit may free, and how, is the law's ``FitSpace`` (``space_of``: the law's ``fit_space()``;
the H-model's in ``hmodel.fit``, Drucker-Prager's in ``point.drucker_prager``): the record's
fields a fit may free, the default free set, which are positive scales fitted as their
logarithm, their default bounds, the finite-difference steps, the fields that set the peak
(they need a curve with one), and the structural reduction (the free parameters a drained curve
cannot tell apart, by the law's dimensional analysis: the H-model's kn, r_g and h enter only as
kn/h), held at their given values. What the data can fix among the rest is judged from the
Jacobian at the optimum (``fit_curve``): a parameter whose 95 % confidence interval reaches
beyond its bounds is reported as not determined.

Functions here write nothing; ``point.cli`` (``python -m point fit``, ``python -m hmodel fit``)
writes the files.
"""
from __future__ import annotations

import math
import time
from typing import Callable, NamedTuple

import numpy as np

from common.io import read_csv, save_figure

from common.paramfile import values_of

from .contract import MaterialError, ParamError, material_of
from .driver import MixedControlError
from .experiment import biaxial_test

__all__ = ["FitSpace", "space_of", "generic_space", "MIN_POINTS", "Curve", "CurveError",
           "read_curve", "make_curve", "parse_free", "parse_bounds", "check_free_bounds",
           "structural_reduction", "noise_sd", "curve_check", "model_curve", "FitResult",
           "fit_curve", "jacobian", "summary_dict", "correlation_dict", "format_result",
           "plot_fit"]

# fewer points than this cannot tell up to 6 parameters, the noise and the misfit apart
MIN_POINTS = 20
# a drained test holds sigma2: its recorded values may spread by this fraction of their median
SIGMA2_SPREAD_MAX = 0.10
Z95 = 1.959963984540054      # two-sided 95 % quantile of the normal distribution


class FitSpace(NamedTuple):
    """What a fit of one law may free, and how (``space_of``).

    choices : the record's fields a fit may free, in the order ``reduction`` keeps them.
    default_free : the free set when none is given. log : the positive scale fields, fitted as
    their logarithm (a factor is what matters for them). bounds(name, base) -> (lo, hi): the
    default bounds of a free field, from the start record ``base``; bounds_text: the same in
    words (the --bounds help). step(name) -> the central finite-difference step of the Jacobian
    in the fitted coordinate. peak : the fields that set the peak (a curve without one cannot
    determine them). reduction(free, base) -> (fitted, {held: why}): the free fields a drained
    curve can determine together (None: all of them). groups(params) -> {name: value}: the
    combinations a drained curve determines (None: none reported)."""

    choices: tuple
    default_free: tuple
    log: frozenset
    bounds: Callable
    bounds_text: str
    step: Callable
    peak: tuple = ()
    reduction: Callable | None = None
    groups: Callable | None = None


def generic_space(law) -> FitSpace:
    """The fit space of a law that names none: every real field but p0 free, bounds a factor 10
    either side of a positive start (a start of 0 or below needs --bounds), steps 1e-3 of the
    coordinate (the logarithm of a positive field)."""
    from common.paramfile import field_kinds
    names = tuple(k for k, kind in field_kinds(law.params_type).items() if kind == "real")
    base = law.params_type()
    log = frozenset(n for n in names if getattr(base, n) > 0)

    def bounds(name, rec):
        v = float(getattr(rec, name))
        if not v > 0:
            raise ValueError(f"no default bounds of {name} = {v:g}: allowed --bounds "
                             f"{name}=LOWER:UPPER")
        return v / 10.0, v * 10.0
    return FitSpace(names, tuple(n for n in names if n != "p0"), log, bounds,
                    "x/10 to x*10 of the start", lambda name: 1e-3)


def space_of(law) -> FitSpace:
    """The fit space of ``law`` (its ``fit_space()``, else ``generic_space``)."""
    f = getattr(law, "fit_space", None)
    return f() if f is not None else generic_space(law)


def _space(params) -> FitSpace:
    return space_of(material_of(params))


def _units(params) -> dict:
    return material_of(params).units


class CurveError(ValueError):
    """A measured curve the fit cannot use (missing column, NaN, too few points, ...)."""


class Curve(NamedTuple):
    """A measured drained biaxial curve, compression positive, SI.

    eps1 : (m,) axial strain [-], increasing, >= 0. q : (m,) s1 - s2 [Pa].
    eps_v : (m,) volumetric strain eps1 + eps2 [-] (contraction > 0), or None.
    sigma2 : the confining stress of the test [Pa]; sigma2_from : how it was obtained (text).
    source : the file (or a label).
    """

    eps1: np.ndarray
    q: np.ndarray
    eps_v: np.ndarray | None
    sigma2: float
    sigma2_from: str
    source: str = ""


def read_curve(path, sigma2: float | None = None) -> Curve:
    """Read a CSV with a header row: columns eps1, q (required), eps_v (or eps2, giving
    eps_v = eps1 + eps2), s2 or sigma2 (optional). The confining stress is ``sigma2`` [Pa] if
    given, else the median of the column s2 (or sigma2): the servo of a drained test holds it up
    to noise. Raises CurveError (one line) for anything the fit cannot use."""
    try:
        cols = read_csv(path)
    except OSError as e:
        raise CurveError(f"cannot read it ({e.strerror or e})") from None
    except (ValueError, TypeError) as e:
        first = (str(e).strip().splitlines() or [""])[0].rstrip(" !:")
        raise CurveError(f"not a CSV of numbers with a header row ({first})") from None
    names = list(cols)
    if "eps1" not in cols or "q" not in cols:
        raise CurveError(f"columns {names}: allowed a CSV with columns eps1 and q (and eps_v or "
                         "eps2, s2 or sigma2 where present)")
    eps_v = cols.get("eps_v")
    v_from = "eps_v"
    if eps_v is None and "eps2" in cols:
        eps_v, v_from = cols["eps1"] + cols["eps2"], "eps1 + eps2"
    s2 = cols.get("s2", cols.get("sigma2"))
    s2_name = "s2" if "s2" in cols else "sigma2"
    used = {"eps1": cols["eps1"], "q": cols["q"]}
    if eps_v is not None:
        used[v_from] = eps_v
    if sigma2 is None and s2 is not None:
        used[s2_name] = s2
    for k, v in used.items():
        bad = ~np.isfinite(v)
        if bad.any():
            raise CurveError(f"column {k} has {int(bad.sum())} missing or non-numeric values "
                             f"(first at row {int(np.argmax(bad)) + 1}): allowed finite numbers")
    return make_curve(cols["eps1"], cols["q"], eps_v, sigma2=sigma2, s2=s2, s2_name=s2_name,
                      source=str(path))


def make_curve(eps1, q, eps_v=None, sigma2: float | None = None, s2=None, s2_name="s2",
               source="") -> Curve:
    """A checked ``Curve`` from arrays (``read_curve`` without the file)."""
    eps1 = np.asarray(eps1, dtype=float)
    q = np.asarray(q, dtype=float)
    m = eps1.size
    if m < MIN_POINTS:
        raise CurveError(f"{m} points: allowed at least {MIN_POINTS} (the residual variance and "
                         "up to 6 parameters need them)")
    if q.shape != eps1.shape or (eps_v is not None and np.shape(eps_v) != eps1.shape):
        raise CurveError("columns of different lengths")
    if np.any(eps1 < 0):
        raise CurveError(f"eps1 down to {eps1.min():.3g}: allowed eps1 >= 0 (compression positive, "
                         "counted from the isotropic state)")
    if np.any(np.diff(eps1) <= 0):
        k = int(np.argmax(np.diff(eps1) <= 0))
        raise CurveError(f"eps1 does not increase at row {k + 2}: allowed a strain-driven drained "
                         "test, eps1 increasing")
    if not np.max(q) > 0:
        raise CurveError("q <= 0 throughout: allowed a compression test, q = s1 - s2 > 0 "
                         "(compression positive)")
    if eps_v is not None:
        eps_v = np.asarray(eps_v, dtype=float)
        if not np.any(eps_v != 0):
            raise CurveError("eps_v is zero throughout: allowed a measured eps_v (or leave the "
                             "column out)")
    if sigma2 is not None:
        how = "given (--sigma2)"
    elif s2 is not None:
        s2 = np.asarray(s2, dtype=float)
        sigma2 = float(np.median(s2))
        spread = float((s2.max() - s2.min()) / sigma2) if sigma2 > 0 else math.inf
        if not sigma2 > 0 or spread > SIGMA2_SPREAD_MAX:
            raise CurveError(f"column {s2_name} from {s2.min():.4g} to {s2.max():.4g} Pa: allowed a "
                             f"drained test at a constant confining stress > 0 (spread within "
                             f"{SIGMA2_SPREAD_MAX:.0%} of its median)")
        how = (f"median of column {s2_name}, from {s2.min():.6g} to {s2.max():.6g} Pa "
               f"(spread {spread:.2%})")
    else:
        raise CurveError("no confining stress: allowed a column s2 (or sigma2) [Pa], or --sigma2")
    if not (math.isfinite(sigma2) and sigma2 > 0):
        raise CurveError(f"confining stress {sigma2!r}: allowed a finite value > 0 [Pa]")
    return Curve(eps1, q, eps_v, float(sigma2), how, source)


# -- parameters, bounds, what a drained curve determines ----------------------------------------
def parse_free(text: str, choices=None) -> tuple:
    """'kn,kt,phi_g' -> ('kn', 'kt', 'phi_g'); a name not in ``choices`` (None: any name, the
    law's space checks it later) or repeated is a ValueError."""
    names = tuple(t.strip() for t in text.split(",") if t.strip())
    allowed = ", ".join(choices) if choices else "field names"
    for n in names:
        if (choices and n not in choices) or not n.isidentifier():
            raise ValueError(f"{n!r} is not a parameter the fit can free: allowed a comma-separated "
                             "list of " + allowed)
    if not names or len(set(names)) != len(names):
        raise ValueError(f"{text!r}: allowed one or more of {allowed}, each once")
    return names


def parse_bounds(text: str, choices=None) -> dict:
    """'kn=1e5:1e8,phi_g=5:45' -> {'kn': (1e5, 1e8), 'phi_g': (5.0, 45.0)} (SI, degrees); a name
    not in ``choices`` (None: any name) is a ValueError."""
    out = {}
    for item in (t.strip() for t in text.split(",") if t.strip()):
        name, _, rng = item.partition("=")
        lo, sep, hi = rng.partition(":")
        try:
            lo, hi = float(lo), float(hi)
        except ValueError:
            lo = hi = math.nan
        name = name.strip()
        if ((choices and name not in choices) or not name.isidentifier() or not sep
                or not (math.isfinite(lo) and math.isfinite(hi))):
            raise ValueError(f"{item!r}: allowed NAME=LOWER:UPPER with NAME one of "
                             f"{', '.join(choices) if choices else 'the free parameters'} and "
                             "finite numbers (SI, degrees)")
        if name in out:
            raise ValueError(f"{name} given twice: allowed each parameter once")
        out[name] = (lo, hi)
    return out


def check_free_bounds(free, bounds: dict | None, base) -> dict:
    """Check the free parameters and their bounds; returns {name: (lo, hi)} for every free one.

    Raises ValueError naming what is wrong: a name not among the law's choices (``FitSpace``), a
    repeated one, bounds of a parameter that is not free, lo >= hi, a bound outside the
    record's range (its ``ParamError``, whose ``name`` is the field), a start (``base``) outside
    its bounds.
    """
    space = _space(base)
    units = _units(base)
    free = tuple(free)
    if not free:
        raise ValueError("no free parameter: allowed one or more of " + ", ".join(space.choices))
    for n in free:
        if n not in space.choices:
            raise ValueError(f"free parameter {n!r}: allowed " + ", ".join(space.choices))
    if len(set(free)) != len(free):
        raise ValueError(f"free parameters {', '.join(free)}: each at most once")
    bounds = dict(bounds or {})
    for n in bounds:
        if n not in free:
            raise ValueError(f"bounds given for {n!r}, which is not free: allowed bounds of "
                             + ", ".join(free))
    out = {}
    for n in free:
        v = float(getattr(base, n))
        lo, hi = bounds[n] if n in bounds else space.bounds(n, base)
        if not lo < hi:
            raise ValueError(f"bounds of {n}: {lo:g}:{hi:g}: allowed lower < upper")
        if n in space.log and not lo > 0:
            raise ValueError(f"bounds of {n}: {lo:g}:{hi:g}: allowed {n} > 0 (fitted as its logarithm)")
        for b in (lo, hi):
            base.replace(**{n: b})        # the record's own range check (ParamError names the field)
        if not lo <= v <= hi:
            raise ValueError(f"start {n} = {v:g} {units[n]} lies outside its bounds {lo:g}:{hi:g}: "
                             "allowed a start inside the bounds")
        out[n] = (float(lo), float(hi))
    return out


def structural_reduction(free, base) -> tuple[tuple, dict]:
    """Split the free parameters into those a drained curve can determine together and those
    it cannot (the law's ``FitSpace.reduction``: the H-model's dimensional analysis, in
    ``hmodel.fit``). Returns (fitted names, {name: why not determined}), the fitted ones in the
    order of the space's choices."""
    space = _space(base)
    if space.reduction is not None:
        return space.reduction(free, base)
    return tuple(n for n in space.choices if n in free), {}


# -- the data: noise, peak ------------------------------------------------------------------------
def noise_sd(y) -> float:
    """Robust estimate of the standard deviation of white noise on a smooth sampled curve:
    1.4826 MAD of the second differences / sqrt(6) (var(y[i+1] - 2 y[i] + y[i-1]) = 6 s^2; the
    curvature of a finely sampled curve adds little). Correlated noise (a DEM's stick-slip) is
    underestimated."""
    d2 = np.diff(np.asarray(y, dtype=float), 2)
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / math.sqrt(6.0))


def curve_check(curve: Curve) -> dict:
    """Does the measured q(eps1) show a peak? The rule (stated, docs/fit.md):

    * noise s_q = ``noise_sd(q)``; window w = max(5, m // 20) points; S = moving mean of q over w;
    * a peak: the maximum of S lies before its last window and S ends lower than that maximum
      by more than 5 s_q / sqrt(w) (5 standard errors of a window mean: a plateau of noise
      passes this with a probability of about 1 %);
    * elastic: a straight line q = a + b eps1 fits q with an RMS residual within 2 s_q.
    Both thresholds are at least 1e-6 max q (round-off, for curves without noise).

    Returns the numbers and ``has_peak``, ``elastic``, ``reason`` (None when it has a peak).
    """
    q, e1 = curve.q, curve.eps1
    m = q.size
    s = noise_sd(q)
    w = max(5, m // 20)
    S = np.convolve(q, np.ones(w) / w, mode="valid")
    k = int(np.argmax(S))
    drop = float(S[k] - S[-1])
    floor = 1e-6 * float(np.max(np.abs(q)))
    thr = max(5.0 * s / math.sqrt(w), floor)
    has_peak = bool(k < S.size - w and drop > thr)
    A = np.column_stack([np.ones(m), e1])
    coef, *_ = np.linalg.lstsq(A, q, rcond=None)
    line_rms = float(np.sqrt(np.mean((A @ coef - q) ** 2)))
    elastic = bool(line_rms <= max(2.0 * s, floor))
    if elastic:
        reason = (f"a straight line (purely elastic: q = {coef[1] / 1e6:.4g} MPa x eps1) fits q within "
                  f"its noise (RMS {line_rms:.3g} Pa, noise {s:.3g} Pa): no sliding, no peak")
    elif not has_peak:
        reason = (f"no peak: q rises to the end of the curve or stays level (smoothed maximum at "
                  f"eps1 = {e1[k + w // 2]:.4g}, the curve ends {drop:.3g} Pa below it, within "
                  f"5 standard errors {thr:.3g} Pa)")
    else:
        reason = None
    return {"noise_q": s, "window": w, "eps1_peak": float(e1[k + w // 2]), "q_peak_smoothed": float(S[k]),
            "drop_to_end": drop, "drop_threshold": thr, "has_peak": has_peak and not elastic,
            "line_rms": line_rms, "elastic": elastic, "reason": reason}


# -- the model's curve ------------------------------------------------------------------------------
def model_curve(params, eps1, d_eps1: float):
    """The law's drained curve at sigma2 = ``params.p0`` at the axial strains ``eps1`` (m,):
    (q [Pa], eps_v [-], eps1_fail). The path runs in steps ``d_eps1`` from the isotropic state
    to the last of ``eps1`` and is interpolated linearly. ``eps1_fail`` is NaN, or the axial
    strain where the path ended before the data's last strain: no static state under the drained
    control there (``PathResult.end``: 'uncontrollable' or 'discontinuous', e.g. the H-model's
    hexagons opening early with alpha0 > 90 deg - phi_g), or a Newton failure the driver could
    not resolve, or a state the law refuses to go on from (``MaterialError``: Drucker-Prager's
    apex), or no isotropic state at p0 at all (0). The penalty (docs/fit.md): beyond it the
    model has no strength, q = 0, and eps_v stays at its last value, so that every data point
    beyond costs its own q (relative residual q_data / max q) and the search moves away."""
    eps1 = np.asarray(eps1, dtype=float)
    n = max(1, int(math.ceil(eps1[-1] / d_eps1 - 1e-9)))
    fail = math.nan
    try:
        r = biaxial_test(params, params.p0, d_eps1, n * d_eps1)
        if r.end.outcome != "complete":
            fail = float(r.eps[-1, 0])
    except (MixedControlError, MaterialError) as e:
        r = getattr(e, "partial", None)
        if r is None:                  # no isotropic state at p0 (driver.isotropic_state)
            return np.zeros_like(eps1), np.zeros_like(eps1), 0.0
        fail = float(r.eps[-1, 0])
    e1 = r.eps[:, 0]
    _, q, _ = r.invariants()
    ev = r.eps[:, 0] + r.eps[:, 1]
    qi = np.interp(eps1, e1, q)
    vi = np.interp(eps1, e1, ev)
    if not math.isnan(fail):
        qi[eps1 > e1[-1]] = 0.0
    return qi, vi, fail


class _Problem:
    """The weighted residuals of a curve as a function of the fitted coordinates x (ln of a
    scale parameter, degrees of an angle). Weights: q divided by max |q| of the data, eps_v by
    max |eps_v| times ``w_epsv`` (both series count alike at equal relative error)."""

    def __init__(self, curve: Curve, base, names, w_epsv: float):
        self.curve, self.base, self.names = curve, base, tuple(names)
        self.space = _space(base)
        self.scale_q = float(np.max(np.abs(curve.q)))
        self.use_v = curve.eps_v is not None and w_epsv > 0
        self.scale_v = float(np.max(np.abs(curve.eps_v))) / w_epsv if self.use_v else math.nan
        self.n_eval = 0

    def params(self, x):
        return self.base.replace(**{n: (math.exp(v) if n in self.space.log else float(v))
                                    for n, v in zip(self.names, x)})

    def x_of(self, params) -> np.ndarray:
        return np.array([math.log(getattr(params, n)) if n in self.space.log else
                         float(getattr(params, n)) for n in self.names])

    def curves(self, x, d_eps1):
        """The model's curve at x; a point the record refuses (two free fields crossing a rule
        between them, e.g. Drucker-Prager's mu0 < mu_p) has no strength: the penalty of
        ``model_curve``'s failure at eps1 = 0."""
        self.n_eval += 1
        try:
            params = self.params(x)
        except ParamError:
            z = np.zeros_like(self.curve.eps1)
            return z, z, 0.0
        return model_curve(params, self.curve.eps1, d_eps1)

    def residuals(self, x, d_eps1):
        q, v, _ = self.curves(x, d_eps1)
        return self.weigh(q, v)

    def weigh(self, q, v):
        r = [(q - self.curve.q) / self.scale_q]
        if self.use_v:
            r.append((v - self.curve.eps_v) / self.scale_v)
        return np.concatenate(r)

    def steps(self):
        return np.array([self.space.step(n) for n in self.names])


def jacobian(problem: _Problem, x, d_eps1: float, steps=None) -> np.ndarray:
    """Central finite differences of the weighted residuals (m, n) at x, steps of the law's
    ``FitSpace.step`` (the model is continuous but only piecewise smooth in its parameters: a
    hexagon's sliding starts at another step; these steps straddle many such events)."""
    h = problem.steps() if steps is None else np.asarray(steps, dtype=float)
    cols = []
    for j in range(len(x)):
        e = np.zeros(len(x))
        e[j] = h[j]
        cols.append((problem.residuals(x + e, d_eps1) - problem.residuals(x - e, d_eps1)) / (2 * h[j]))
    return np.column_stack(cols)


def _starts(x0, lo, hi, n_starts, seed):
    """The given start, then n_starts - 1 points of a Latin hypercube (seeded) in the central
    90 % of the bounds (fitted coordinates)."""
    rng = np.random.default_rng(seed)
    pts = [np.array(x0, dtype=float)]
    k = n_starts - 1
    if k > 0:
        u = np.column_stack([(rng.permutation(k) + rng.random(k)) / k for _ in range(len(x0))])
        pts += list(lo + (hi - lo) * (0.05 + 0.9 * u))
    return pts


class FitResult(NamedTuple):
    """What ``fit_curve`` found (everything the CLI writes; SI, degrees).

    status : 'fitted' or 'not fittable' (then ``reason`` says why and params is None).
    params : the fitted record of the law (free ones at the optimum, the rest as given).
    free, fitted : the free parameters, and those the curve determines structurally.
    estimates : {name: {value, sd, ci95, determined, why}} of the fitted ones (sd and ci95 of a
        scale parameter are relative: sd of its logarithm, interval in its units).
    undetermined : {name: why}, structural or from the data.
    correlation : (n, n) of the fitted ones; singular_values (n,), singular_vectors (n, n) rows
        of the Jacobian of the noise-scaled residuals (fitted coordinates).
    starts : one dict per start (start, end, cost, evaluations, message, time).
    chosen : index of the start kept; cost : 0.5 sum of the weighted squared residuals.
    model_q, model_eps_v : (m,) the fitted model at the data's eps1 (None if not fitted).
    residuals_q [Pa], residuals_eps_v [-] : model - data.
    info : the rest (bounds, weights, check of the data, noise, groups, timings).
    """

    status: str
    reason: str | None
    params: object
    free: tuple
    fitted: tuple
    estimates: dict
    undetermined: dict
    correlation: np.ndarray | None
    singular_values: np.ndarray | None
    singular_vectors: np.ndarray | None
    starts: list
    chosen: int | None
    cost: float | None
    model_q: np.ndarray | None
    model_eps_v: np.ndarray | None
    residuals_q: np.ndarray | None
    residuals_eps_v: np.ndarray | None
    info: dict


def fit_curve(curve: Curve, base, free=None, bounds: dict | None = None,
              n_starts: int = 8, seed: int = 0, w_epsv: float = 1.0, d_eps1: float = 1e-5,
              d_eps1_search: float = 1e-4, max_nfev: int = 100,
              progress: Callable[[str], None] | None = None) -> FitResult:
    """Fit the free parameters of the law of ``base`` (its ``FitSpace``: ``free`` among its
    choices, None its default free set) to ``curve``; the others as in ``base`` (its p0 is
    replaced by the curve's confining stress, the start of p0 if free).

    1. The curve must show a peak if a field that sets it is free (``FitSpace.peak``: the
       H-model's phi_g, alpha0; ``curve_check``): otherwise 'not fittable', nothing fitted.
    2. ``structural_reduction``: the parameters a drained curve cannot tell apart are held.
    3. From the given start and n_starts - 1 Latin-hypercube starts (``seed``), least squares
       with the model's path in steps ``d_eps1_search``; the lowest cost is polished with steps
       ``d_eps1`` (its change is reported in standard deviations: ``info['search_vs_final_in_sd']``).
    4. At the optimum, the covariance s^2 (J^T J)^-1 of the fitted coordinates, s^2 the residual
       variance times (1 + rho)/(1 - rho), rho the lag-1 correlation of the residuals (an AR(1)
       allowance for correlated noise and misfit along the curve). A parameter is determined
       when its 95 % interval (+- 1.96 sd) lies inside its bounds; else the bounds, not the
       data, fix it and it is reported as not determined.
    ``max_nfev``: residual evaluations per start (each Jacobian costs 2 n more).
    """
    from scipy.optimize import least_squares

    say = progress or (lambda text: None)
    space = _space(base)
    units = _units(base)
    free = tuple(space.default_free if free is None else free)
    if not (0 <= w_epsv < math.inf):
        raise ValueError(f"w_epsv = {w_epsv!r}: allowed a weight >= 0")
    if int(n_starts) < 1:
        raise ValueError(f"n_starts = {n_starts!r}: allowed an integer >= 1")
    base = base.replace(p0=curve.sigma2)
    bnd = check_free_bounds(free, bounds, base)
    check = curve_check(curve)
    info = {"bounds": bnd, "check": check, "sigma2": curve.sigma2, "sigma2_from": curve.sigma2_from,
            "w_epsv": w_epsv, "d_eps1": d_eps1, "d_eps1_search": d_eps1_search, "n_starts": int(n_starts),
            "seed": int(seed), "max_nfev": int(max_nfev), "base": values_of(base)}
    empty = dict(correlation=None, singular_values=None, singular_vectors=None, starts=[], chosen=None,
                 cost=None, model_q=None, model_eps_v=None, residuals_q=None, residuals_eps_v=None)
    strength = [n for n in space.peak if n in free]
    if strength and check["reason"] is not None:
        why = f"{check['reason']}; {' and '.join(strength)} set the peak and cannot be determined"
        return FitResult("not fittable", why, None, free, (), {}, {n: why for n in free}, info=info, **empty)
    fitted, undetermined = structural_reduction(free, base)
    if not fitted:
        raise ValueError("none of the free parameters enters the drained curve: "
                         + "; ".join(f"{n} {w}" for n, w in undetermined.items()))
    prob = _Problem(curve, base, fitted, w_epsv)
    lo = np.array([_x(space, n, bnd[n][0]) for n in fitted])
    hi = np.array([_x(space, n, bnd[n][1]) for n in fitted])
    info["weight_q"] = 1.0 / prob.scale_q
    info["weight_eps_v"] = 1.0 / prob.scale_v if prob.use_v else 0.0
    info["weights"] = {"q": f"1 / {prob.scale_q:.6g} Pa (max |q| of the data)",
                       "eps_v": (f"{w_epsv:g} / {prob.scale_v * w_epsv:.6g} (w_epsv / max |eps_v| of the data)"
                                 if prob.use_v else "not fitted (no eps_v, or w_epsv = 0)")}
    t_all = time.perf_counter()

    def solve(x0, de):
        return least_squares(prob.residuals, x0, jac=lambda x, *a: jacobian(prob, x, de), bounds=(lo, hi),
                             x_scale="jac", method="trf", args=(de,), max_nfev=max_nfev,
                             xtol=1e-8, ftol=1e-10, gtol=1e-10)

    starts = []
    for k, x0 in enumerate(_starts(prob.x_of(base), lo, hi, int(n_starts), seed)):
        t0, n0 = time.perf_counter(), prob.n_eval
        r = solve(x0, d_eps1_search)
        starts.append({"start": _named(prob, x0), "end": _named(prob, r.x), "cost": float(r.cost),
                       "evaluations": prob.n_eval - n0, "status": int(r.status), "message": r.message,
                       "time_s": time.perf_counter() - t0, "x": r.x})
        say(f"start {k + 1}/{n_starts}: cost {r.cost:.4g} after {prob.n_eval - n0} model paths "
            f"({time.perf_counter() - t0:.1f} s)")
    chosen = int(np.argmin([s["cost"] for s in starts]))
    best_cost = starts[chosen]["cost"]
    t0 = time.perf_counter()
    final = solve(starts[chosen]["x"], d_eps1)
    say(f"polished start {chosen + 1} with steps d_eps1 = {d_eps1:g}: cost {final.cost:.4g} "
        f"({time.perf_counter() - t0:.1f} s)")
    x = final.x
    J = jacobian(prob, x, d_eps1)
    q_m, v_m, fail = prob.curves(x, d_eps1)
    r = prob.weigh(q_m, v_m)
    m, n = r.size, x.size
    s2 = float(r @ r) / max(m - n, 1)
    rho = _lag1(r, curve.eps1.size)
    infl = (1.0 + rho) / (1.0 - rho)
    cov, sv, Vt = _covariance(J, s2 * infl)
    sd = np.sqrt(np.diag(cov))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(sd, sd)
    sd_search = {nm: (starts[chosen]["x"][j] - x[j]) / sd[j] if sd[j] > 0 else math.nan
                 for j, nm in enumerate(fitted)}
    params = prob.params(x)
    estimates = {}
    for j, nm in enumerate(fitted):
        a, b = x[j] - Z95 * sd[j], x[j] + Z95 * sd[j]
        at_bound = final.active_mask[j] != 0
        inside = bool(np.isfinite(sd[j]) and a >= lo[j] and b <= hi[j])
        if at_bound:
            why = (f"at its {'lower' if final.active_mask[j] < 0 else 'upper'} bound "
                   f"{bnd[nm][0 if final.active_mask[j] < 0 else 1]:g} {units[nm]}: the optimum lies "
                   "outside the allowed range")
        elif not inside:
            why = (f"its 95 % interval [{_v(space, nm, a):.4g}, {_v(space, nm, b):.4g}] {units[nm]} reaches beyond "
                   f"its bounds [{bnd[nm][0]:g}, {bnd[nm][1]:g}]: the bounds, not the data, fix it")
        else:
            why = None
        estimates[nm] = {"value": getattr(params, nm), "unit": units[nm],
                         "sd": float(sd[j]), "sd_of": "ln" if nm in space.log else units[nm],
                         "ci95": [_v(space, nm, a), _v(space, nm, b)], "determined": why is None,
                         "why": why}
        if why is not None:
            undetermined[nm] = why
    info.update({
        "structural": {n: undetermined[n] for n in free if n not in fitted},
        "residual_variance": s2, "lag1_correlation": rho, "variance_inflation": infl,
        "rms_q": float(np.sqrt(np.mean((q_m - curve.q) ** 2))),
        "rms_eps_v": float(np.sqrt(np.mean((v_m - curve.eps_v) ** 2))) if curve.eps_v is not None else None,
        "lack_of_fit_q": float(np.sqrt(np.mean((q_m - curve.q) ** 2)) / check["noise_q"])
        if check["noise_q"] > 0 else None,
        **({"groups": space.groups(params)} if space.groups else {}),
        "search_cost": best_cost, "search_vs_final_in_sd": sd_search,
        "optima": _optima(starts),
        "path_failed_at_eps1": None if math.isnan(fail) else fail,
        "optimizer": {"status": int(final.status), "message": final.message},
        "n_model_paths": prob.n_eval, "time_s": time.perf_counter() - t_all,
        "fd_steps": dict(zip(fitted, prob.steps().tolist())),
    })
    for s in starts:
        s.pop("x")
    return FitResult("fitted", None, params, free, fitted, estimates, undetermined, corr, sv, Vt,
                     starts, chosen, float(final.cost), q_m, v_m if curve.eps_v is not None else None,
                     q_m - curve.q, (v_m - curve.eps_v) if curve.eps_v is not None else None, info)


def _optima(starts) -> list:
    """The distinct ends of the starts: ends whose costs agree within 1e-3 (relative) are one
    optimum; listed by cost with the starts (1-based) that reached each."""
    out = []
    for k in np.argsort([s["cost"] for s in starts], kind="stable"):
        s = starts[k]
        if out and s["cost"] <= out[-1]["cost"] * (1 + 1e-3):
            out[-1]["starts"].append(int(k) + 1)
        else:
            out.append({"cost": s["cost"], "end": s["end"], "starts": [int(k) + 1]})
    for o in out:
        o["starts"].sort()
    return out


def _x(space, name, value):
    return math.log(value) if name in space.log else float(value)


def _v(space, name, x):
    return math.exp(x) if name in space.log else float(x)


def _named(prob, x):
    return {n: _v(prob.space, n, v) for n, v in zip(prob.names, x)}


def _lag1(r, m) -> float:
    """Lag-1 autocorrelation of the residuals along each series (q, then eps_v; ``m`` points
    each), pooled, clipped to [0, 0.99]."""
    series = [r[i:i + m] for i in range(0, r.size, m)]
    num = sum(float(s[1:] @ s[:-1]) for s in series)
    den = sum(float(s @ s) for s in series)
    return float(min(max(num / den, 0.0), 0.99)) if den > 0 else 0.0


def _covariance(J, s2):
    """s2 (J^T J)^-1 through the SVD of J; a direction with a singular value below 1e-10 of the
    largest is not determined at all: infinite variance for every parameter it involves.
    Returns (cov, singular values, right singular vectors as rows)."""
    U, sv, Vt = np.linalg.svd(J, full_matrices=False)
    null = sv <= 1e-10 * (sv[0] if sv.size else 0.0)
    inv2 = np.where(null, 0.0, 1.0 / np.where(null, 1.0, sv) ** 2)
    cov = s2 * (Vt.T * inv2) @ Vt
    hit = np.any(np.abs(Vt[null]) > 1e-8, axis=0) if null.any() else np.zeros(J.shape[1], bool)
    cov[hit, :] = np.inf
    cov[:, hit] = np.inf
    return cov, sv, Vt


def summary_dict(res: FitResult, curve: Curve) -> dict:
    """The fit as a JSON-ready dict (summary.json); starts are numbered from 1 there."""
    i = dict(res.info)
    out = {"status": res.status, "reason": res.reason, "data": curve.source,
           "n_points": int(curve.eps1.size), "eps1_range": [float(curve.eps1[0]), float(curve.eps1[-1])],
           "sigma2": curve.sigma2, "sigma2_from": curve.sigma2_from, "free": list(res.free),
           "bounds": {k: list(v) for k, v in i.pop("bounds").items()}, "check_of_the_data": i.pop("check"),
           "fitted": res.estimates, "undetermined": res.undetermined,
           "params": values_of(res.params) if res.params is not None else None,
           "starts": res.starts, "chosen_start": None if res.chosen is None else res.chosen + 1,
           "cost": res.cost}
    out.update(i)
    return _jsonable(out)


def correlation_dict(res: FitResult, strong: float = 0.95) -> dict:
    """correlation.json: the fitted parameters' correlation matrix and standard deviations (in
    the fitted coordinates: ln of a scale parameter, degrees of an angle), the singular values
    and right singular vectors (rows) of the Jacobian of the residuals scaled by their standard
    deviation, and the pairs with |correlation| > ``strong`` (the curve fixes mainly their
    combination)."""
    names = list(res.fitted)
    C = res.correlation
    pairs = [[a, b, float(C[i, j])] for i, a in enumerate(names) for j, b in enumerate(names)
             if j > i and np.isfinite(C[i, j]) and abs(C[i, j]) > strong]
    s = math.sqrt(res.info["residual_variance"] * res.info["variance_inflation"])
    return _jsonable({
        "parameters": names, "coordinates": [_coordinate(res, n) for n in names],
        "sd": [res.estimates[n]["sd"] for n in names], "correlation": C,
        "singular_values": res.singular_values / s if s > 0 else res.singular_values,
        "singular_vectors": res.singular_vectors, "strongly_correlated": pairs,
        "strong_threshold": strong})


def _coordinate(res: FitResult, name) -> str:
    """The fitted coordinate of ``name``: "ln kn", "phi_g [deg]"."""
    base = res.params
    return f"ln {name}" if name in _space(base).log else f"{name} [{_units(base)[name]}]"


def format_result(res: FitResult, curve: Curve) -> str:
    """A few lines for the terminal: each fitted parameter with its 95 % interval and verdict,
    the ones not determined, the cost and the starts."""
    lines = [f"fit to {curve.source} ({curve.eps1.size} points), sigma2 = {curve.sigma2:.6g} Pa "
             f"({curve.sigma2_from})"]
    for n, e in res.estimates.items():
        lo, hi = e["ci95"]
        unit = "" if e["unit"] == "-" else f" {e['unit']}"
        lines.append(f"  {n} = {e['value']:.5g}{unit} (95 %: {lo:.4g} to {hi:.4g})"
                     + ("" if e["determined"] else f": NOT DETERMINED, {e['why']}"))
    for n, why in res.info["structural"].items():
        lines.append(f"  {n} = {getattr(res.params, n):.5g} {_units(res.params)[n]}: NOT "
                     f"DETERMINED, {why}")
    i = res.info
    opt = i["optima"]
    lines.append(f"cost {res.cost:.4g}: RMS q {i['rms_q']:.4g} Pa"
                 + (f", RMS eps_v {i['rms_eps_v']:.3g}" if i["rms_eps_v"] is not None else "")
                 + f"; best of {len(res.starts)} starts (reached by {len(opt[0]['starts'])}; "
                 f"{len(opt)} distinct optima); {i['n_model_paths']} model paths")
    if i["path_failed_at_eps1"] is not None:
        lines.append(f"the fitted model's drained path fails at eps1 = {i['path_failed_at_eps1']:.4g}")
    return "\n".join(lines)


def _jsonable(o):
    if isinstance(o, dict):
        return {str(k): _jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_jsonable(v) for v in o]
    if isinstance(o, np.ndarray):
        return _jsonable(o.tolist())
    if isinstance(o, (np.floating, float)):
        return float(o) if math.isfinite(o) else None
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, np.bool_):
        return bool(o)
    return o


def plot_fit(curve: Curve, res: FitResult, path, label: str = "H-model") -> None:
    """fig_fit.png: measured (dots) and fitted (line) q [kPa] and eps_v [%] against eps1 [%],
    compression positive; the fitted parameters in the title; ``label``: the law's name in the
    legend and title. For a curve that is not fittable, the data alone and the reason."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    two = curve.eps_v is not None
    fig, axes = plt.subplots(1, 2 if two else 1, figsize=(11 if two else 6, 4.3), squeeze=False)
    ax_q = axes[0, 0]
    e = 100 * curve.eps1
    ax_q.plot(e, curve.q / 1e3, ".", ms=3, color="0.35", label="measured")
    if res.model_q is not None:
        ax_q.plot(e, res.model_q / 1e3, "C3-", lw=1.6, label=f"{label}, fitted")
    ax_q.set_xlabel(r"axial strain $\varepsilon_1$ [%]")
    ax_q.set_ylabel(r"deviatoric stress $q = \sigma_1 - \sigma_2$ [kPa]")
    if two:
        ax_v = axes[0, 1]
        ax_v.plot(e, 100 * curve.eps_v, ".", ms=3, color="0.35", label="measured")
        if res.model_eps_v is not None:
            ax_v.plot(e, 100 * res.model_eps_v, "C3-", lw=1.6, label=f"{label}, fitted")
        ax_v.set_xlabel(r"axial strain $\varepsilon_1$ [%]")
        ax_v.set_ylabel(r"volumetric strain $\varepsilon_v$ [%] (contraction > 0)")
    for a in axes.ravel():
        a.grid(alpha=0.3)
        a.legend(fontsize=8)
    if res.status == "fitted":
        p = res.params
        est = res.estimates
        units = _units(p)
        txt = ", ".join(f"{n} = {getattr(p, n):.4g} {units[n]}{'' if est[n]['determined'] else ' (not determined)'}"
                        for n in res.fitted)
        title = (f"{label} fitted at $\\sigma_2$ = {curve.sigma2 / 1e3:.4g} kPa: {txt}")
    else:
        title = "not fittable: " + (res.reason or "")
    fig.suptitle(_wrap(title, 110), fontsize=9)
    save_figure(fig, path)


def _wrap(text, width):
    import textwrap
    return "\n".join(textwrap.wrap(text, width))
