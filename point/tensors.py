"""Plane tensors with the tensor axes first and any batch axes last, in the project's convention
(compression positive, axis 1 axial, axis 2 lateral), and the component vectors the analysis uses.

Two vectors of a symmetric 2x2 tensor:

* rows (11, 22, 12) with the tensor shear t12 (``to_voigt``, ``from_voigt``): the driver's and the
  probes' rows; a:b = a11 b11 + a22 b22 + 2 a12 b12 (``ddot``).
* the orthonormal Mandel basis (11, 22, sqrt 2 12) (``to_mandel``): eps : D : eps = x . D_M x, so
  that eigenvalues, determinants and norms of a tangent are those of the quadratic form.

A tangent C[i, j, k, l] = d sigma_ij / d eps_kl (2, 2, 2, 2, *batch) acts on a general increment
whose symmetric part is what the material sees: it has both minor symmetries.
"""
from __future__ import annotations

import numpy as np

__all__ = ["to_voigt", "from_voigt", "tangent_from_voigt", "voigt_tangent", "to_mandel",
           "from_mandel", "mandel_tangent", "tangent_from_mandel", "ddot", "stress_work",
           "SQRT2"]

SQRT2 = float(np.sqrt(2.0))


def to_voigt(t: np.ndarray) -> np.ndarray:
    """(2, 2, *batch) symmetric tensor -> (npts, 3) rows (11, 22, 12); the 12 entry is the
    symmetric part (t12 + t21) / 2."""
    t = np.asarray(t, dtype=float)
    if t.shape[:2] != (2, 2):
        raise ValueError(f"expected a tensor of shape (2, 2, *batch), got {t.shape}")
    out = np.empty((int(np.prod(t.shape[2:], dtype=int)), 3))
    out[:, 0] = t[0, 0].ravel()
    out[:, 1] = t[1, 1].ravel()
    out[:, 2] = 0.5 * (t[0, 1] + t[1, 0]).ravel()
    return out


def from_voigt(v: np.ndarray, batch_shape: tuple) -> np.ndarray:
    """(npts, 3) rows (11, 22, 12) -> (2, 2, *batch) symmetric tensor."""
    v = np.asarray(v)
    t = np.empty((2, 2) + tuple(batch_shape))
    t[0, 0] = v[:, 0].reshape(batch_shape)
    t[1, 1] = v[:, 1].reshape(batch_shape)
    t[0, 1] = t[1, 0] = v[:, 2].reshape(batch_shape)
    return t


_VOIGT_INDEX = np.array([[0, 2], [2, 1]])          # (i, j) -> position in (11, 22, 12)
_SHEAR_HALF = np.where(_VOIGT_INDEX == 2, 0.5, 1.0)  # d/d eps_kl of a symmetric increment


def tangent_from_voigt(T: np.ndarray, batch_shape: tuple) -> np.ndarray:
    """(npts, 3, 3) d sigma_a / d v_b with v = (e11, e22, e12) -> (2, 2, 2, 2, *batch) with
    C[i, j, k, l] = d sigma_ij / d eps_kl for a general (non-symmetric) increment, whose
    symmetric part is what the material sees: C has both minor symmetries."""
    I = _VOIGT_INDEX
    C = T[:, I[:, :, None, None], I[None, None, :, :]] * _SHEAR_HALF[None, None, None, :, :]
    return np.moveaxis(C, 0, -1).reshape((2, 2, 2, 2) + tuple(batch_shape))


def voigt_tangent(C: np.ndarray) -> np.ndarray:
    """(2, 2, 2, 2, *batch) tangent -> (npts, 3, 3) rows T[p, a, b] = d sigma_a / d v_b,
    v = (e11, e22, e12) tensor shear (the inverse of ``tangent_from_voigt``)."""
    C = np.asarray(C, dtype=float)
    npts = int(np.prod(C.shape[4:], dtype=int))
    C = C.reshape(2, 2, 2, 2, npts)
    idx = ((0, 0), (1, 1), (0, 1))
    T = np.empty((npts, 3, 3))
    for a, (i, j) in enumerate(idx):
        for b, (k, l) in enumerate(idx):
            T[:, a, b] = C[i, j, k, l] + (C[i, j, l, k] if b == 2 else 0.0)
    return T


_MANDEL_W = np.array([1.0, 1.0, SQRT2])


def to_mandel(t: np.ndarray) -> np.ndarray:
    """(2, 2, *batch) symmetric tensor -> (3, *batch) Mandel vector (t11, t22, sqrt 2 t12)."""
    t = np.asarray(t, dtype=float)
    out = np.empty((3,) + t.shape[2:])
    out[0] = t[0, 0]
    out[1] = t[1, 1]
    out[2] = 0.5 * SQRT2 * (t[0, 1] + t[1, 0])
    return out


def from_mandel(x: np.ndarray) -> np.ndarray:
    """(3, *batch) Mandel vector -> (2, 2, *batch) symmetric tensor."""
    x = np.asarray(x, dtype=float)
    out = np.empty((2, 2) + x.shape[1:])
    out[0, 0] = x[0]
    out[1, 1] = x[1]
    out[0, 1] = out[1, 0] = x[2] / SQRT2
    return out


def mandel_tangent(C: np.ndarray) -> np.ndarray:
    """(2, 2, 2, 2, *batch) tangent -> (3, 3, *batch) D_M with eps:C:eps = x.D_M x."""
    C = np.asarray(C, dtype=float)
    idx = ((0, 0), (1, 1), (0, 1))
    D = np.empty((3, 3) + C.shape[4:])
    for a, (i, j) in enumerate(idx):
        for b, (k, l) in enumerate(idx):
            D[a, b] = _MANDEL_W[a] * _MANDEL_W[b] * (
                C[i, j, k, l] if b < 2 else 0.5 * (C[i, j, k, l] + C[i, j, l, k]))
    return D


def tangent_from_mandel(D: np.ndarray) -> np.ndarray:
    """(3, 3, *batch) Mandel matrix -> (2, 2, 2, 2, *batch) tangent with both minor symmetries."""
    D = np.asarray(D, dtype=float)
    idx = np.array([[0, 2], [2, 1]])
    w = np.where(idx == 2, 1.0 / SQRT2, 1.0)
    return D[idx[:, :, None, None], idx[None, None, :, :]] * \
        (w[:, :, None, None] * w[None, None, :, :]).reshape((2, 2, 2, 2) + (1,) * (D.ndim - 2))


def ddot(a, b):
    """a:b for rows (..., 3) of symmetric tensors in (11, 22, 12) order."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + 2.0 * a[..., 2] * b[..., 2]


def stress_work(old, new, stress0) -> np.ndarray:
    """(*batch,) internal second-order work per unit volume [J/m^3] of the increment from the
    state ``old`` to ``new`` (states of the same points, any material: their ``stress`` and
    ``eps``, (2, 2, *batch), compression positive both): ((s_old + s_new) / 2 - ``stress0``) :
    (eps_new - eps_old). The trapezoid of the stress along the strain increment, exact for a
    stress linear in the increment; Eq. 1's W2_int of a held run is its sum from the switch
    (stress0 the stress there), independent of the internal forces an integrator used."""
    ds = 0.5 * (np.asarray(old.stress) + np.asarray(new.stress)) - np.asarray(stress0)
    return np.einsum("ab...,ab...->...", ds, np.asarray(new.eps) - np.asarray(old.eps))
