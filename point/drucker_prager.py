"""Non-associated Drucker-Prager in the plane: the benchmark material whose every bifurcation
criterion has a closed form (``point.closed_forms``, docs/materials.md).

Compression positive, 2x2 tensors, plane strain as the H-model treats it. With p = tr(sigma)/2,
the deviator s = sigma - p I and tau = sqrt(s:s / 2) (= q/2 in principal axes):

* isotropic elasticity of the plane, sigma = lambda tr(eps_e) I + 2 G eps_e, lambda = 2 G nu /
  (1 - 2 nu) (plane strain), so that p = K2 tr(eps_e) with the plane bulk modulus
  K2 = lambda + G = G / (1 - 2 nu);
* the yield function f = tau - mu(kappa) p and the plastic potential g = tau - beta p, with
  the yield normal P = df/dsigma = n - mu I/2 and the flow direction Q = dg/dsigma = n - beta I/2,
  n = s / (2 tau) (n:n = 1/2); d eps_p = d lambda Q, whose volume change -beta d lambda is a
  dilation (compression-positive strain < 0) where beta > 0;
* the hardening variable kappa = the accumulated plastic multiplier, which is the plastic shear
  strain eps1_p - eps2_p in principal axes (n = diag(1/2, -1/2) there);
* the mobilized friction mu(kappa) = mu0 + (mu_p - mu0) 2 kappa kappa_p / (kappa^2 + kappa_p^2):
  rising from mu0 with the initial slope 2 (mu_p - mu0) / kappa_p, a peak mu_p at
  kappa = kappa_p (dmu/dkappa = 0 there), softening back towards mu0 beyond;
* the stress-dilatancy rule beta = mu - mu_c (contraction below the characteristic friction
  mu_c, dilation above; beta != mu always: non-associated flow).

The hardening modulus is h = p dmu/dkappa (consistency: P:d sigma = h d lambda), positive before
the peak, 0 at kappa_p, negative past it. On the loading branch (P:E:d eps > 0)

    D = E - (E:Q) (x) (P:E) / (h + P:E:Q),   P:E:Q = G + K2 mu beta.

The update is the exact backward-Euler return mapping (radial in the deviatoric plane: n is the
trial's): with Delta lambda the root of
r = tau_tr - G Delta lambda - mu(kappa_n + Delta lambda) (p_tr + K2 beta Delta lambda) = 0
(safeguarded Newton within [0, tau_tr / G]), tau = tau_tr - G Delta lambda,
p = p_tr + K2 beta Delta lambda, s = (tau / tau_tr) s_tr. Its consistent tangent is

    D_alg = K2 I (x) I + 2 G theta I_dev + 4 G (1 - theta) n (x) n
            - (2 G n - K2 beta~ I) (x) (2 G n - mu K2 I) / H~,

theta = tau / tau_tr, beta~ = beta + mu' Delta lambda, H~ = G + mu' p + mu K2 beta~ (-dr/d Delta
lambda), which tends to D as the step vanishes. ``rate_tangent`` gives D itself (the rate
problem's tangent at a state: the one the bifurcation criteria are about).

The apex (p <= 0, or a return that would reach tau <= 0) is tension, which a granular material
does not carry and this model does not describe: the update refuses it (MaterialError).
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, fields
from typing import NamedTuple

import numpy as np

from .closed_forms import Mechanism
from .contract import Material, MaterialError, ParamError, register
from .tensors import SQRT2, from_mandel, tangent_from_mandel, to_mandel

__all__ = ["DPParams", "DPState", "DruckerPrager", "DRUCKER_PRAGER", "UNITS", "mechanism",
           "invariants"]

UNITS = {"G": "Pa", "nu": "-", "mu0": "-", "mu_p": "-", "kappa_p": "-", "mu_c": "-", "p0": "Pa"}
_I = np.array([1.0, 1.0, 0.0])          # I in the Mandel basis


@dataclass(frozen=True)
class DPParams:
    """Parameters of the plane Drucker-Prager law, validated on construction (SI units).

    G : shear modulus [Pa] (> 0). nu : Poisson's ratio of plane strain [-], 0 <= nu < 0.5
    (K2 = G / (1 - 2 nu) the plane bulk modulus). mu0 : the mobilized friction of the first
    yield [-] (0 < mu0 < mu_p). mu_p : its peak [-] (< 1). kappa_p : the plastic shear strain at
    the peak [-] (> 0). mu_c : the characteristic friction of the dilatancy rule beta = mu - mu_c
    [-] (0 < mu_c; beta = mu - mu_c < mu always). p0 : the isotropic confining stress of the
    initial state [Pa] (> 0).

    The defaults make a drained biaxial path at 200 kPa cross the bifurcation domain's boundary
    (h = h_sym), then Rice's localization condition (h = h_loc > 0), before its peak (h = 0):
    docs/materials.md.
    """

    G: float = 40.0e6
    nu: float = 0.25
    mu0: float = 0.1
    mu_p: float = 0.55
    kappa_p: float = 0.01
    mu_c: float = 0.4
    p0: float = 200.0e3

    model = "drucker-prager"

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, (bool, np.bool_)) or not isinstance(v, numbers.Real):
                raise ParamError(f.name, v, "a real number", record="DPParams")
            if not math.isfinite(float(v)):
                raise ParamError(f.name, v, "a finite number", record="DPParams")
            object.__setattr__(self, f.name, float(v))
        _check(self.G > 0, "G", "G > 0 [Pa]", self.G)
        _check(0.0 <= self.nu < 0.5, "nu", "0 <= nu < 0.5", self.nu)
        # mu_p's own range first, so that a refused mu_p is named as itself (not as mu0's bound)
        _check(0.0 < self.mu_p < 1.0, "mu_p", "0 < mu_p < 1 (and mu_p > mu0)", self.mu_p)
        _check(0.0 < self.mu0 < self.mu_p, "mu0", f"0 < mu0 < mu_p = {self.mu_p:g}", self.mu0)
        _check(self.kappa_p > 0, "kappa_p", "kappa_p > 0", self.kappa_p)
        _check(self.mu_c > 0, "mu_c", "mu_c > 0 (beta = mu - mu_c < mu: non-associated)", self.mu_c)
        _check(self.p0 > 0, "p0", "p0 > 0 [Pa]", self.p0)

    # -- derived ---------------------------------------------------------------------------------
    @property
    def K2(self) -> float:
        """Plane bulk modulus K2 = lambda + G = G / (1 - 2 nu) [Pa]: p = K2 tr(eps_e)."""
        return self.G / (1.0 - 2.0 * self.nu)

    @property
    def lam(self) -> float:
        """Lame's lambda of plane strain, 2 G nu / (1 - 2 nu) [Pa]."""
        return 2.0 * self.G * self.nu / (1.0 - 2.0 * self.nu)

    def mu(self, kappa):
        """The mobilized friction mu(kappa) [-]."""
        k = np.asarray(kappa, dtype=float)
        kp = self.kappa_p
        return self.mu0 + (self.mu_p - self.mu0) * 2.0 * k * kp / (k * k + kp * kp)

    def dmu(self, kappa):
        """d mu / d kappa [-]: 0 at kappa_p, negative beyond."""
        k = np.asarray(kappa, dtype=float)
        kp = self.kappa_p
        d = k * k + kp * kp
        return (self.mu_p - self.mu0) * 2.0 * kp * (kp * kp - k * k) / (d * d)

    def beta(self, kappa):
        """The dilatancy coefficient beta = mu(kappa) - mu_c [-]."""
        return self.mu(kappa) - self.mu_c

    def elastic_mandel(self) -> np.ndarray:
        """(3, 3) the elasticity E in the Mandel basis: lambda i (x) i + 2 G I."""
        return self.lam * np.outer(_I, _I) + 2.0 * self.G * np.eye(3)

    def replace(self, **changes) -> "DPParams":
        """A copy with some fields changed (validated again)."""
        kw = {f.name: getattr(self, f.name) for f in fields(self)}
        kw.update(changes)
        return DPParams(**kw)


def _check(ok, name, allowed, value):
    if not ok:
        raise ParamError(name, value, allowed, record="DPParams")


class DPState(NamedTuple):
    """State of a batch of Drucker-Prager points (immutable; batch axes last).

    eps : (2, 2, *batch) total strain from the stress-free state [-]; stress : (2, 2, *batch)
    [Pa]; eps_p : (2, 2, *batch) plastic strain [-]; kappa : (*batch,) accumulated plastic shear
    strain [-]; plastic : (*batch,) bool, the step that made the state loaded the material."""

    eps: np.ndarray
    stress: np.ndarray
    eps_p: np.ndarray
    kappa: np.ndarray
    plastic: np.ndarray

    @property
    def batch_shape(self) -> tuple:
        return self.kappa.shape


# relative tolerances: a trial with f <= F_TOL (tau + mu p) is elastic (round-off of a stress
# returned to the surface); a state with |f| <= ON_SURFACE (tau + mu p) is on the yield surface
F_TOL = 1e-12
ON_SURFACE = 1e-9
_MAX_NEWTON = 60


class DruckerPrager(Material):
    """The plane non-associated Drucker-Prager law (module docstring)."""

    name = "drucker-prager"
    params_type = DPParams
    units = UNITS
    provides = frozenset()
    description = ("non-associated Drucker-Prager of the plane: isotropic elasticity, friction "
                   "hardening to a peak, stress-dilatancy beta = mu - mu_c")
    label = "Drucker-Prager"
    defaults_name = "the benchmark set"

    def initial_state(self, params: DPParams, batch_shape: tuple = ()) -> DPState:
        """sigma = p0 I from the stress-free state: eps = p0 / (2 K2) I, no plastic strain."""
        b = tuple(batch_shape)
        eye = np.eye(2).reshape((2, 2) + (1,) * len(b))
        stress = np.broadcast_to(params.p0 * eye, (2, 2) + b).copy()
        eps = np.broadcast_to(params.p0 / (2.0 * params.K2) * eye, (2, 2) + b).copy()
        return DPState(eps=eps, stress=stress, eps_p=np.zeros((2, 2) + b), kappa=np.zeros(b),
                       plastic=np.zeros(b, dtype=bool))

    def check_state(self, state, params) -> None:
        if not isinstance(state, DPState):
            raise MaterialError(f"material {self.name}: a state of type {type(state).__name__}, "
                                "allowed a DPState")

    def update(self, state: DPState, d_eps, params: DPParams):
        out = self._update(state, d_eps, params, elastic=False)
        return out[0], out[1], out[2]

    def elastic_update(self, state: DPState, d_eps, params: DPParams):
        out = self._update(state, d_eps, params, elastic=True)
        return out[0], out[1], out[2]

    def _update(self, state: DPState, d_eps, params: DPParams, elastic: bool):
        d_eps = np.asarray(d_eps, dtype=float)
        batch = state.batch_shape
        if d_eps.shape != (2, 2) + batch:
            raise MaterialError(f"material {self.name}: d_eps of shape {d_eps.shape}, allowed "
                                f"(2, 2) + batch = {(2, 2) + batch}")
        if not np.all(np.isfinite(d_eps)):
            raise MaterialError(f"material {self.name}: d_eps has non-finite values (nan or inf)")
        G, K2 = params.G, params.K2
        npts = int(np.prod(batch, dtype=int))
        flat = lambda t: to_mandel(np.asarray(t, dtype=float).reshape(2, 2, npts))   # noqa: E731
        de = flat(d_eps)                                            # the symmetric part acts
        E = params.elastic_mandel()
        sig_tr = flat(state.stress) + E @ de
        p_tr = 0.5 * (sig_tr[0] + sig_tr[1])
        s_tr = sig_tr - p_tr * _I[:, None]
        tau_tr = np.sqrt(0.5 * np.sum(s_tr * s_tr, axis=0))
        k_n = np.asarray(state.kappa, dtype=float).reshape(npts)
        mu_n = params.mu(k_n)
        load = (tau_tr - mu_n * p_tr > F_TOL * (tau_tr + mu_n * np.abs(p_tr)))
        if elastic:
            load[:] = False
        D = np.repeat(E[:, :, None], npts, axis=2)
        sig = sig_tr.copy()
        eps_p = flat(state.eps_p)
        kappa = k_n.copy()
        i = np.flatnonzero(load)
        if i.size:
            pt, tt, kn = p_tr[i], tau_tr[i], k_n[i]
            if np.any(pt <= 0.0):
                raise MaterialError(
                    f"material {self.name}: the trial stress is in tension (p <= 0 at "
                    f"{int(np.count_nonzero(pt <= 0))} points): the cone's apex, which the model "
                    "does not describe (refused)")
            dl = _return(params, pt, tt, kn)
            kk = kn + dl
            mu = params.mu(kk)
            dmu = params.dmu(kk)
            beta = mu - params.mu_c
            tau = tt - G * dl
            p = pt + K2 * beta * dl
            if np.any(tau <= 0.0) or np.any(p <= 0.0):
                raise MaterialError(
                    f"material {self.name}: the return reaches the cone's apex (tau or p <= 0 at "
                    f"{int(np.count_nonzero((tau <= 0) | (p <= 0)))} points): refused (the model "
                    "does not describe tension)")
            n = s_tr[:, i] / (2.0 * tt)                              # (3, m), n:n = 1/2
            theta = tau / tt
            beta_t = beta + dmu * dl
            H = G + dmu * p + mu * K2 * beta_t
            a = 2.0 * G * n - K2 * beta_t * _I[:, None]
            b = 2.0 * G * n - mu * K2 * _I[:, None]
            D[:, :, i] = (K2 * np.outer(_I, _I)[:, :, None]
                          + 2.0 * G * theta * (np.eye(3) - 0.5 * np.outer(_I, _I))[:, :, None]
                          + 4.0 * G * (1.0 - theta) * n[:, None, :] * n[None, :, :]
                          - a[:, None, :] * b[None, :, :] / H)
            sig[:, i] = p * _I[:, None] + 2.0 * tau * n
            eps_p[:, i] += dl * (n - 0.5 * beta * _I[:, None])
            kappa[i] = kk
        tens = lambda x: from_mandel(x).reshape((2, 2) + batch)       # noqa: E731
        new = DPState(eps=np.asarray(state.eps, dtype=float) + tens(de), stress=tens(sig),
                      eps_p=tens(eps_p), kappa=kappa.reshape(batch), plastic=load.reshape(batch))
        return new.stress, tangent_from_mandel(D).reshape((2, 2, 2, 2) + batch), new

    def fit_space(self):
        """What a fit of the law frees, and how (``point.fit.FitSpace``): by default G, mu_p,
        kappa_p and mu_c (the stiffness, the peak's friction, where it lies, the dilatancy),
        nu, mu0 and p0 besides on request. The law is homogeneous of degree one in the stress
        (linear elasticity, a cone, hardening in the plastic strain): q = p0 Q(eps1; G/p0, nu,
        mu0, mu_p, kappa_p, mu_c), so every choice moves the curve on its own (no structural
        reduction). G, kappa_p and p0 are fitted as their logarithm within a factor 100 of the
        start; nu within 0:0.49, mu0 below the start's mu_p, mu_p above the start's mu0 and
        below 0.99, mu_c within 0.01:0.99."""
        from .fit import FitSpace
        return FitSpace(("G", "nu", "mu0", "mu_p", "kappa_p", "mu_c", "p0"),
                        ("G", "mu_p", "kappa_p", "mu_c"), _FIT_LOG, _fit_bounds, FIT_BOUNDS_TEXT,
                        lambda name: 1e-3 if name in _FIT_LOG else 1e-4,
                        peak=("mu_p", "kappa_p"), groups=_fit_groups)

    def mechanism(self, state: DPState, params: DPParams) -> Mechanism:
        """The mechanism of the state (``mechanism``): the closed forms of every criterion."""
        return mechanism(params, state)

    def yield_value(self, state: DPState, params: DPParams) -> np.ndarray:
        """(*batch,) f = tau - mu(kappa) p [Pa] of a state (0 on the yield surface)."""
        p, tau, _ = invariants(state.stress)
        return tau - params.mu(state.kappa) * p

    def on_surface(self, state: DPState, params: DPParams) -> np.ndarray:
        """(*batch,) bool: the state lies on its yield surface (|f| <= ON_SURFACE (tau + mu p))."""
        p, tau, _ = invariants(state.stress)
        mu = params.mu(state.kappa)
        return (np.abs(tau - mu * p) <= ON_SURFACE * (tau + mu * np.abs(p))) & (tau > 0)

    def rate_tangent(self, state: DPState, direction, params: DPParams, norm: float = 1e-6):
        """The exact rate tangent at ``state``: D = E - (E:Q) (x) (P:E) / (h + P:E:Q) where the
        state is on its yield surface and P:E:direction > 0 (loading), E elsewhere."""
        batch = state.batch_shape
        E = params.elastic_mandel()
        D = np.broadcast_to(E.reshape((3, 3) + (1,) * len(batch)), (3, 3) + batch).copy()
        on = self.on_surface(state, params)
        if np.any(on):
            m = mechanism(params, state)
            d = to_mandel(np.asarray(direction, dtype=float))
            PE = np.einsum("a...,ab->b...", m.P, E)
            load = on & (np.einsum("a...,a...->...", PE, d) > 0.0)
            Dp = m.tangent()
            D = np.where(load[None, None], Dp, D)
        return tangent_from_mandel(D)


# the fit (``DruckerPrager.fit_space``): fitted as their logarithm, and the default bounds
_FIT_LOG = frozenset({"G", "kappa_p", "p0"})
FIT_BOUNDS_TEXT = ("x/100 to x*100 of the start for G, kappa_p, p0; nu 0:0.49; mu0 0.001 to "
                   "0.999 mu_p; mu_p mu0 + 0.001 to 0.99; mu_c 0.01:0.99")


def _fit_bounds(name: str, base: DPParams) -> tuple:
    """Default bounds of a free field of the fit (``FIT_BOUNDS_TEXT``), from the start ``base``."""
    v = float(getattr(base, name))
    if name in _FIT_LOG:
        return v / 100.0, v * 100.0
    return {"nu": (0.0, 0.49), "mu0": (1e-3, 0.999 * base.mu_p), "mu_p": (base.mu0 + 1e-3, 0.99),
            "mu_c": (0.01, 0.99)}[name]


def _fit_groups(params: DPParams) -> dict:
    """What a drained curve determines: G/p0 [-] and the dimensionless fields, with p0 [Pa]."""
    return {"G_over_p0": params.G / params.p0, "nu": params.nu, "mu0": params.mu0,
            "mu_p": params.mu_p, "kappa_p": params.kappa_p, "mu_c": params.mu_c, "p0": params.p0}


def invariants(stress):
    """(p, tau, n) of stresses (2, 2, *batch) [Pa]: p = tr/2, tau = sqrt(s:s/2), n = s / (2 tau)
    in the Mandel basis (3, *batch) (NaN where tau = 0)."""
    s = to_mandel(stress)
    p = 0.5 * (s[0] + s[1])
    dev = s - p * _I.reshape((3,) + (1,) * (s.ndim - 1))
    tau = np.sqrt(0.5 * np.sum(dev * dev, axis=0))
    with np.errstate(invalid="ignore", divide="ignore"):
        n = dev / (2.0 * tau)
    return p, tau, n


def mechanism(params: DPParams, state: DPState) -> Mechanism:
    """The mechanism of a state (``point.closed_forms``): P = n - mu I/2, Q = n - beta I/2
    (Mandel, n = s / (2 tau)), h = p dmu/dkappa at the state's kappa, E of the parameters."""
    p, tau, n = invariants(state.stress)
    k = np.asarray(state.kappa, dtype=float)
    mu = params.mu(k)
    beta = mu - params.mu_c
    Ib = _I.reshape((3,) + (1,) * np.ndim(p))
    return Mechanism(params.elastic_mandel(), n - 0.5 * mu * Ib, n - 0.5 * beta * Ib,
                     p * params.dmu(k))


def _return(params: DPParams, p_tr, tau_tr, k_n):
    """Delta lambda (m,) of the return mapping: the root of r(x) = tau_tr - G x -
    mu(k_n + x) (p_tr + K2 beta(k_n + x) x) in [0, tau_tr / G] (r(0) > 0 > r(tau_tr / G) while
    p > 0), by Newton kept inside the bracket (bisection where a Newton step leaves it), to the
    last bits of x. One point (the driver's steps) by ``_return_one``: the same operations on
    floats, the same bits, without numpy's per-call cost."""
    if p_tr.size == 1:
        return np.array([_return_one(params, float(p_tr[0]), float(tau_tr[0]), float(k_n[0]))])
    G, K2, mc = params.G, params.K2, params.mu_c
    lo = np.zeros_like(p_tr)
    hi = tau_tr / G
    x = np.zeros_like(p_tr)
    scale = tau_tr + params.mu(k_n) * p_tr

    def r_and_slope(x):
        k = k_n + x
        mu = params.mu(k)
        dmu = params.dmu(k)
        beta = mu - mc
        p = p_tr + K2 * beta * x
        r = tau_tr - G * x - mu * p
        dr = -G - dmu * p - mu * K2 * (beta + dmu * x)
        return r, dr

    for _ in range(_MAX_NEWTON):
        r, dr = r_and_slope(x)
        lo = np.where(r > 0, x, lo)
        hi = np.where(r < 0, x, hi)
        done = (np.abs(r) <= 4e-16 * scale) | (hi - lo <= 4e-16 * np.maximum(hi, 1e-300))
        if np.all(done):
            break
        with np.errstate(divide="ignore", invalid="ignore"):
            xn = x - r / dr
        bad = ~np.isfinite(xn) | (xn <= lo) | (xn >= hi)
        xn = np.where(bad, 0.5 * (lo + hi), xn)
        x = np.where(done, x, xn)
    else:
        r, _ = r_and_slope(x)
        if np.any(np.abs(r) > 1e-10 * scale):
            raise MaterialError("material drucker-prager: the return mapping did not converge "
                                f"in {_MAX_NEWTON} iterations (residual {float(np.max(np.abs(r))):.3e} Pa)")
    return x


def _return_one(params: DPParams, p_tr: float, tau_tr: float, k_n: float) -> float:
    """``_return`` for one point, on Python floats."""
    G, K2, mc = params.G, params.K2, params.mu_c
    kp, dm, m0 = params.kappa_p, params.mu_p - params.mu0, params.mu0
    lo, hi, x = 0.0, tau_tr / G, 0.0
    scale = tau_tr + (m0 + dm * 2.0 * k_n * kp / (k_n * k_n + kp * kp)) * p_tr

    def r_and_slope(x):
        k = k_n + x
        d = k * k + kp * kp
        mu = m0 + dm * 2.0 * k * kp / d
        dmu = dm * 2.0 * kp * (kp * kp - k * k) / (d * d)
        beta = mu - mc
        p = p_tr + K2 * beta * x
        return tau_tr - G * x - mu * p, -G - dmu * p - mu * K2 * (beta + dmu * x)

    for _ in range(_MAX_NEWTON):
        r, dr = r_and_slope(x)
        if r > 0:
            lo = x
        if r < 0:
            hi = x
        if abs(r) <= 4e-16 * scale or hi - lo <= 4e-16 * max(hi, 1e-300):
            return x
        xn = x - r / dr if dr != 0.0 else math.nan
        if not math.isfinite(xn) or xn <= lo or xn >= hi:
            xn = 0.5 * (lo + hi)
        x = xn
    r, _ = r_and_slope(x)
    if abs(r) > 1e-10 * scale:
        raise MaterialError("material drucker-prager: the return mapping did not converge "
                            f"in {_MAX_NEWTON} iterations (residual {abs(r):.3e} Pa)")
    return x


DRUCKER_PRAGER = register(DruckerPrager())
