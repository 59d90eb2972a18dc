"""A constitutive law of one's own, written as a user would, run through the toolkit (the
material point's drained test, domain and probes, and the FE specimen): a plane
version of Kolymbas' four-term hypoplastic law (Kolymbas 1991), which has no yield surface and
no elastic range (its response is incrementally non-linear: the tangent depends on the
direction of the strain increment), compression positive:

    d sigma = c1 tr(sigma) d eps + c2 tr(sigma d eps) / tr(sigma) sigma
              + (c3 sigma^2 + c4 s^2) / tr(sigma) |d eps|,          s = sigma - tr(sigma)/2 I,

integrated explicitly over an increment from the stress at its start, so that the stress of an
increment is exactly differentiable and the consistent tangent is L + N (x) d eps / |d eps|.
The constants are Kolymbas' for a medium-dense sand, c3 reduced so that the plane version
reaches a drained limit near q/p = 0.8 (not a calibration).
"""
from dataclasses import dataclass, fields, replace
from typing import NamedTuple

import numpy as np

from fem.biaxial import BiaxialConfig, run_biaxial
from point import Material, MaterialError, ParamError, check_tangent, register
from point.experiment import biaxial_test, domain_point
from point.probes import arcs, directional_sweep, format_arcs


@dataclass(frozen=True)
class HypoParams:
    """c1 .. c4 [-] (c1 > 0: the stiffness c1 tr(sigma)), p0 [Pa] the isotropic state."""
    c1: float = 101.2
    c2: float = 962.1
    c3: float = -600.0
    c4: float = 1229.0
    p0: float = 200e3

    def __post_init__(self):
        for f in fields(self):
            if not np.isfinite(getattr(self, f.name)):
                raise ParamError(f.name, getattr(self, f.name), "a finite number", record="HypoParams")
        if not self.c1 > 0:
            raise ParamError("c1", self.c1, "c1 > 0", record="HypoParams")
        if not self.p0 > 0:
            raise ParamError("p0", self.p0, "p0 > 0 [Pa]", record="HypoParams")

    def replace(self, **changes):
        return replace(self, **changes)          # validated again by __post_init__


class HypoState(NamedTuple):
    eps: np.ndarray                              # (2, 2, *batch) strain from the isotropic state
    stress: np.ndarray                           # (2, 2, *batch) [Pa]

    @property
    def batch_shape(self):
        return self.stress.shape[2:]


class Hypoplastic(Material):
    name = "hypoplastic-plane"
    params_type = HypoParams
    units = {"c1": "-", "c2": "-", "c3": "-", "c4": "-", "p0": "Pa"}

    def initial_state(self, params, batch_shape=()):
        eye = np.eye(2).reshape((2, 2) + (1,) * len(batch_shape))
        s = params.p0 * eye * np.ones(batch_shape)
        return HypoState(np.zeros_like(s), s)

    def update(self, state, d_eps, params):
        s = state.stress
        tr = s[0, 0] + s[1, 1]
        if np.any(tr <= 0):
            raise MaterialError(f"material {self.name}: tension (tr sigma <= 0), not described")
        ones = (1,) * (s.ndim - 2)
        eye = np.eye(2).reshape((2, 2) + ones)
        de = 0.5 * (d_eps + np.swapaxes(d_eps, 0, 1))
        norm = np.sqrt(np.einsum("ij...,ij...->...", de, de))
        dev = s - 0.5 * tr * eye
        N = (params.c3 * np.einsum("ik...,kj...->ij...", s, s)
             + params.c4 * np.einsum("ik...,kj...->ij...", dev, dev)) / tr
        L = (params.c1 * tr * np.einsum("ik,jl->ijkl", np.eye(2), np.eye(2)).reshape((2, 2, 2, 2) + ones)
             + params.c2 * np.einsum("ij...,kl...->ijkl...", s, s) / tr)
        with np.errstate(invalid="ignore", divide="ignore"):
            u = np.where(norm > 0, de / np.where(norm > 0, norm, 1.0), 0.0)
        C = L + np.einsum("ij...,kl...->ijkl...", N, u)
        C = 0.5 * (C + np.swapaxes(C, 2, 3))      # d eps12 = d eps21: both minor symmetries
        new = HypoState(state.eps + de, s + np.einsum("ijkl...,kl...->ij...", L, de) + N * norm)
        return new.stress, C, new


HYPOPLASTIC = register(Hypoplastic())


if __name__ == "__main__":
    P = HypoParams()
    law = HYPOPLASTIC
    s0 = law.initial_state(P)
    tc = check_tangent(law, s0, P, np.diag([1e-4, -3e-5]))
    print(f"{law.name}: tangent against finite differences of the stress: {tc.error:.1e} "
          f"({'ok' if tc.ok else 'wrong'})")
    r = biaxial_test(P, d_eps1=1e-4, eps1_max=0.06)
    p, q, eta = r.invariants()
    k = int(np.argmax(q))
    print(f"drained biaxial at {P.p0:g} Pa: q/p reaches {eta[k]:.3f} at eps1 = {r.eps[k, 0]:.2%}")
    for sigma2 in (100e3, 200e3, 400e3):
        d = domain_point(P, sigma2, d_eps1=1e-4, eps1_max=0.06, n_dir_probe=180)
        print(f"sigma2 = {sigma2:g} Pa: first W2 <= 0 at q/p = {d.q_w2 / d.p_w2:.3f} "
              f"(eps1 = {d.eps1_w2:.2%}), the limit at q/p = {d.q_peak / d.p_peak:.3f}")
    kA = int(np.argmax(eta >= 0.78))
    rA = biaxial_test(P, d_eps1=1e-4, eps1_max=r.eps[kA, 0])
    sw = directional_sweep(rA.state, P, n=360)
    print(f"at q/p = {eta[kA]:.3f}: the cone W2 <= 0 in alpha_sigma "
          f"{format_arcs(arcs(sw.alpha_sigma, sw.w2 <= 0))} deg, min w2 = {np.min(sw.w2):.4f}")
    # the FE specimen of the same law: the structure loses uniqueness where its points do
    cfg = BiaxialConfig(nx=2, ny=4, eps1_max=0.01, d_eps1=2e-4, fields=False, n_sphere=100)
    ev = run_biaxial(cfg.with_params(P)).summary["events"]
    print(f"FE specimen (2 x 4 quads): lam_min(K_s) <= 0 under force control at q/p = "
          f"{ev['lam_min_ks_f']['eta']:.3f}, the points' min W2 <= 0 at {ev['local_w2']['eta']:.3f}")
