"""Exact bifurcation criteria of elastoplasticity with one mechanism (docs/materials.md derives
each): the answers the toolkit's numerical analysis is tested against.

On the loading branch the tangent is D = E - (E:Q) (x) (P:E) / (h + P:E:Q) (yield normal P, flow
direction Q, hardening modulus h > 0 before the limit). Everything here is in the orthonormal
Mandel basis (11, 22, sqrt 2 12), where eps:D:eps = x.D x and a:b is the dot product, and takes
E (3, 3), P, Q (3, *batch), h (*batch) (``point.drucker_prager.mechanism`` builds them for a
Drucker-Prager state).

Each criterion is the value of h at which it fires (the hardening modulus falls along a path,
so the criterion with the largest h fires first):

* ``h_limit`` = 0: det D = det E h / (h + P:E:Q) vanishes (the limit state under stress
  control, the drained peak);
* ``h_sym``: the symmetric part of D loses positive definiteness, min W2 over every direction
  first <= 0 (the bifurcation domain): 1/2 [sqrt((P:E:P)(Q:E:Q)) - P:E:Q];
* ``h_strain_subspace`` / ``h_stress_subspace``: the same over strain / stress probes restricted
  to a subspace (e.g. the probe planes (d eps1, d eps2), (d sigma1, d sigma2));
* ``h_control``: loss of controllability under a mixed control (the controlled block of D,
  in the control's variables, singular);
* ``h_path``: the peak of the stress conjugate to a proportional strain path u (u.D.u = 0);
* ``h_rice``: Rice's localization, det(n.D.n) = 0 for some in-plane normal n (max over n).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

__all__ = ["Mechanism", "h_sym", "h_strain_subspace", "h_stress_subspace",
           "h_control", "h_path", "h_rice", "rice_h_of_angle", "cone_edges", "plane_operator",
           "voigt_to_mandel_matrix", "det_D", "mandel_of_voigt", "golden_section"]

_I = np.array([1.0, 1.0, 0.0])
SQRT2 = math.sqrt(2.0)


class Mechanism(NamedTuple):
    """One plastic mechanism at a state: E (3, 3) [Pa], P and Q (3, *batch) [-] (Mandel), h
    (*batch,) [Pa]."""

    E: np.ndarray
    P: np.ndarray
    Q: np.ndarray
    h: np.ndarray

    @property
    def PEQ(self):
        return np.einsum("a...,ab,b...->...", self.P, self.E, self.Q)

    @property
    def PEP(self):
        return np.einsum("a...,ab,b...->...", self.P, self.E, self.P)

    @property
    def QEQ(self):
        return np.einsum("a...,ab,b...->...", self.Q, self.E, self.Q)

    def tangent(self) -> np.ndarray:
        """(3, 3, *batch) D = E - (E Q) (x) (P E) / (h + P:E:Q)."""
        EQ = np.einsum("ab,b...->a...", self.E, self.Q)
        PE = np.einsum("a...,ab->b...", self.P, self.E)
        nb = np.ndim(self.h)
        E = self.E.reshape((3, 3) + (1,) * nb)
        return E - EQ[:, None] * PE[None, :] / (self.h + self.PEQ)


def det_D(m: Mechanism):
    """det D = det E h / (h + P:E:Q)."""
    return np.linalg.det(m.E) * m.h / (m.h + m.PEQ)


def h_sym(m: Mechanism):
    """The h where sym(D) loses positive definiteness: 1/2 [sqrt(PEP QEQ) - PEQ]."""
    return 0.5 * (np.sqrt(m.PEP * m.QEQ) - m.PEQ)


def _inv_sqrt(S):
    w, V = np.linalg.eigh(S)
    return (V / np.sqrt(w)) @ V.T


def h_strain_subspace(m: Mechanism, basis) -> float:
    """Strain probes x = B y restricted to the span of the orthonormal Mandel columns ``basis``
    (3, k): x.D x first <= 0 at h = 1/2 (|a||b| + a.b) - P:E:Q with a, b = E_ss^-1/2 (E Q)_s,
    (E P)_s (single point)."""
    B = np.asarray(basis, dtype=float).reshape(3, -1)
    Ess = B.T @ m.E @ B
    R = _inv_sqrt(Ess)
    a = R @ (B.T @ (m.E @ m.Q))
    b = R @ (B.T @ (m.E @ m.P))
    return float(0.5 * (np.linalg.norm(a) * np.linalg.norm(b) + a @ b) - m.PEQ)


def h_stress_subspace(m: Mechanism, basis) -> float:
    """Stress probes ds = B y (orthonormal Mandel columns ``basis`` (3, k)): ds.d eps first <= 0
    at h = 1/2 (|a||b| - a.b), a, b = [(E^-1)_SS]^-1/2 Q_S, P_S (d eps = E^-1 ds + Q (P.ds)/h)."""
    B = np.asarray(basis, dtype=float).reshape(3, -1)
    C = B.T @ np.linalg.inv(m.E) @ B
    R = _inv_sqrt(C)
    a = R @ (B.T @ m.Q)
    b = R @ (B.T @ m.P)
    return float(0.5 * (np.linalg.norm(a) * np.linalg.norm(b) - a @ b))


# the driver's variables are rows (11, 22, 12) with tensor shear: x_Mandel = V v
_V = np.diag([1.0, 1.0, SQRT2])


def mandel_of_voigt(v):
    """Mandel vector of a strain row (11, 22, 12) (tensor shear)."""
    return _V @ np.asarray(v, dtype=float)


def voigt_to_mandel_matrix() -> np.ndarray:
    return _V.copy()


def h_control(m: Mechanism, strain_controlled, control_matrix=None) -> float:
    """Loss of controllability under the driver's mixed control (``point.mixed.MixedControl``):
    variables e' = A v (v the strain rows (11, 22, 12), A the identity or the 2x2
    ``control_matrix`` on the normal components), the ``strain_controlled`` ones prescribed, the
    others' conjugate stresses s' = A^-T sigma prescribed. With M' = A^-T M A^-1 (M = d sigma /
    d v), det M'_ff = 0 at h_c = w'_f . (E'_ff)^-1 . u'_f - P:E:Q, u = E:Q and w = P:E as the rows
    M's rank-one term is built from. Equivalently h_c = -P_T . [(E^-1)_TT]^-1 . Q_T over the
    strain-controlled variables T (Nova). Single point; NaN for a fully strain-controlled
    step (no stress target: always controllable)."""
    A = np.eye(3)
    if control_matrix is not None:
        A[:2, :2] = np.asarray(control_matrix, dtype=float)
    Ainv = np.linalg.inv(A)
    free = [i for i, s in enumerate(strain_controlled) if not s]
    if not free:
        return math.nan
    # M = d sigma_rows / d v: sigma_rows = W^-1 ... in Mandel: sigma_M = V sigma_rows ... the
    # rows of stress (11, 22, 12) are V^-1 sigma_M, the Mandel strain V v: M = V^-1 D V
    Vi = np.linalg.inv(_V)
    Ev = Vi @ m.E @ _V
    u = Vi @ (m.E @ m.Q)                 # the stress rows of E:Q
    w = (m.P @ m.E) @ _V                 # d(P:E:x) / dv
    Ep = Ainv.T @ Ev @ Ainv
    up = Ainv.T @ u
    wp = w @ Ainv
    f = np.asarray(free)
    return float(wp[f] @ np.linalg.solve(Ep[np.ix_(f, f)], up[f]) - m.PEQ)


def h_path(m: Mechanism, u) -> float:
    """The peak of the stress conjugate to the proportional strain path of direction ``u`` (a
    strain row (11, 22, 12), e.g. (1, R, 0)): u.D.u = 0 at h_R = (u.E.Q)(P.E.u) / (u.E.u) - P:E:Q
    (single point)."""
    x = mandel_of_voigt(u)
    return float((x @ m.E @ m.Q) * (m.P @ m.E @ x) / (x @ m.E @ x) - m.PEQ)


def _acoustic(E, n):
    """(2, 2) n.E.n for the Mandel matrix E and the unit normal n (2,)."""
    C = _tensor4(E)
    return np.einsum("j,ijkl,l->ik", n, C, n)


def _tensor4(D):
    idx = np.array([[0, 2], [2, 1]])
    w = np.where(idx == 2, 1.0 / SQRT2, 1.0)
    return D[idx[:, :, None, None], idx[None, None, :, :]] * (w[:, :, None, None] * w[None, None, :, :])


def _tensor2(x):
    return np.array([[x[0], x[2] / SQRT2], [x[2] / SQRT2, x[1]]])


def rice_h_of_angle(m: Mechanism, angle):
    """h(n) - for each normal angle [rad] (n = (cos, sin)): det(n.D.n) = 0 at
    h = (n.E:P) . A_e(n)^-1 . (n.E:Q) - P:E:Q (single point; ``angle`` an array)."""
    angle = np.atleast_1d(np.asarray(angle, dtype=float))
    EP = _tensor2(m.E @ m.P)
    EQ = _tensor2(m.E @ m.Q)
    out = np.empty(angle.shape)
    for k, a in enumerate(angle):
        n = np.array([math.cos(a), math.sin(a)])
        Ae = _acoustic(m.E, n)
        out[k] = (n @ EP) @ np.linalg.solve(Ae, EQ @ n) - m.PEQ
    return out


def h_rice(m: Mechanism, n_grid: int = 720) -> tuple[float, float]:
    """Rice's h_loc = max over in-plane normals of ``rice_h_of_angle`` and the normal's angle
    [deg] in [0, 180): a grid of ``n_grid`` angles, then golden-section search around the best
    one to the last bits of the angle (a smooth periodic function of the angle)."""
    a = np.pi * np.arange(n_grid) / n_grid
    v = rice_h_of_angle(m, a)
    k = int(np.argmax(v))
    x, f = golden_section(lambda x: -float(rice_h_of_angle(m, [x])[0]),
                          a[k] - np.pi / n_grid, a[k] + np.pi / n_grid, 1e-15)
    return max(-f, float(v[k])), float(np.degrees(x) % 180.0)


def golden_section(f, lo: float, hi: float, tol: float, max_iter: int = 200) -> tuple:
    """(x, f(x)) of the least of a unimodal ``f`` in [lo, hi] by golden section, to a bracket
    of width ``tol`` (or ``max_iter`` steps): the better of the last two points."""
    g = 0.5 * (math.sqrt(5.0) - 1.0)
    x1, x2 = hi - g * (hi - lo), lo + g * (hi - lo)
    f1, f2 = f(x1), f(x2)
    for _ in range(max_iter):
        if hi - lo < tol:
            break
        if f1 < f2:
            hi, x2, f2 = x2, x1, f1
            x1 = hi - g * (hi - lo)
            f1 = f(x1)
        else:
            lo, x1, f1 = x1, x2, f2
            x2 = lo + g * (hi - lo)
            f2 = f(x2)
    return (x1, f1) if f1 < f2 else (x2, f2)


def plane_operator(D_mandel, plane: str) -> np.ndarray:
    """The 2x2 operator of a plane of probes: 'strain' d sigma_(1,2) = M d eps_(1,2) (the normal
    block of D, d eps12 = 0 and d sigma12 free); 'stress' d eps_(1,2) = C d sigma_(1,2), C the
    normal block of D^-1 (d sigma12 = 0)."""
    D = np.asarray(D_mandel, dtype=float)
    if plane == "strain":
        return D[:2, :2].copy()
    if plane == "stress":
        return np.linalg.inv(D)[:2, :2].copy()
    raise ValueError(f"plane = {plane!r}: allowed 'strain' or 'stress'")


def cone_edges(M) -> list:
    """The edges [deg, in [0, 360)] of the cone of W2 < 0 in a plane of probes x = (cos t, sin t)
    with the 2x2 operator ``M`` (``plane_operator``): W2(t) = A cos^2 + 2 B sin cos + C sin^2
    with [[A, B], [B, C]] = sym(M), W2 = 0 at tan t = (-B +- sqrt(B^2 - A C)) / C. Both roots
    and their opposites (W2(t) = W2(t + 180)): four angles sorted, or [] when B^2 < A C (no
    direction of W2 <= 0)."""
    S = 0.5 * (np.asarray(M) + np.asarray(M).T)
    A, B, C = S[0, 0], S[0, 1], S[1, 1]
    disc = B * B - A * C
    if disc < 0:
        return []
    if C != 0:
        t = [math.atan2(-B + s * math.sqrt(disc), C) for s in (1.0, -1.0)]
    else:                        # A cos^2 + 2 B sin cos = 0: cos = 0 or tan = -A / (2 B)
        t = [math.pi / 2, math.atan2(-A, 2.0 * B)]
    out = sorted({round(math.degrees(x) % 360.0, 12) for x in t}
                 | {round((math.degrees(x) + 180.0) % 360.0, 12) for x in t})
    return out
