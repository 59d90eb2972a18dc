"""The one place where the compression-positive material meets the tension-positive FE.

Material (hmodel): compression positive, axis 1 = axial, axis 2 = lateral.
FE (skfem): tension positive, axis x (index 0) = lateral, axis y (index 1) = vertical = axial.
So, with the index relabelling p = (1, 0) (FE index i <-> material index p[i]):

    eps_model[a, b]   = -eps_fe[p[a], p[b]]
    sigma_fe[i, j]    = -sigma_model[p[i], p[j]]
    D_fe[i, j, k, l]  =  D_model[p[i], p[j], p[k], p[l]]      (both signs flip: same tangent)

The relabelling is a passive change of component names, not a physical reflection, so the
material sees its axis 1 along the specimen axis whatever its fabric.

``MaterialField`` holds the state of every quadrature point (flat batch of ``npts`` points in
the (element, quadrature point) C order of skfem's ``Basis.dx``), possibly split into groups with
different parameters (the imperfection), and gives trial updates that are committed only when
the global Newton iteration has converged.
"""
from __future__ import annotations

from typing import NamedTuple, Sequence

import numba
import numpy as np

from hmodel import HParams, broadcast_state, _kernels
from point.driver import isotropic_state
from hmodel.material import (HState, PARALLEL_MIN_POINTS, check_state, kernel_args, to_voigt,
                             from_voigt, stress_work, _material_args, _refuse_non_finite)

__all__ = ["strain_to_model", "stress_to_fe", "tangent_to_fe", "MaterialField", "Trial"]

_P = [1, 0]


def strain_to_model(eps_fe: np.ndarray) -> np.ndarray:
    """(2, 2, *batch) FE strain (tension +, x lateral) -> material strain (compression +, 1 axial)."""
    return -eps_fe[_P][:, _P]


def stress_to_fe(sigma_model: np.ndarray) -> np.ndarray:
    """(2, 2, *batch) material stress [Pa] -> FE stress [Pa]."""
    return -sigma_model[_P][:, _P]


def stress_to_model(sigma_fe: np.ndarray) -> np.ndarray:
    """Inverse of stress_to_fe (the relabelling and the sign flip are involutions)."""
    return -sigma_fe[_P][:, _P]


def tangent_to_fe(D_model: np.ndarray) -> np.ndarray:
    """(2, 2, 2, 2, *batch) material tangent [Pa] -> FE tangent [Pa] (same values, relabelled)."""
    return D_model[_P][:, _P][:, :, _P][:, :, :, _P]


# The kernel's (npts, 3, 3) tangent T[p, a, b] = d sigma_a / d v_b (v = (e11, e22, e12)) -> the FE
# tangent in one gather: D_fe[i, j, k, l] = C[p_i, p_j, p_k, p_l], C[i, j, k, l] = T[I_ij, I_kl] *
# (1/2 where I_kl is the shear entry), as hmodel.material.tangent_from_voigt and tangent_to_fe
# compute it (the same products: the same bits)
_VI = np.array([[0, 2], [2, 1]])[_P][:, _P]
_VH = np.where(_VI == 2, 0.5, 1.0)
_VA = _VI[:, :, None, None]
_VB = _VI[None, None, :, :]


def _tangent_fe_from_kernel(T: np.ndarray) -> np.ndarray:
    Tt = T.transpose(1, 2, 0)                                   # (3, 3, npts), a view
    return Tt[_VA, _VB] * _VH[None, None, :, :, None]


def _stress_fe_from_kernel(sig: np.ndarray, out: np.ndarray) -> None:
    """(npts, 3) material stress (11, 22, 12) -> FE stress out (2, 2, npts): sigma_fe[i, j] =
    -sigma_model[p_i, p_j] (stress_to_fe of from_voigt)."""
    out[0, 0] = -sig[:, 1]
    out[1, 1] = -sig[:, 0]
    out[0, 1] = -sig[:, 2]
    out[1, 0] = -sig[:, 2]


@numba.njit(cache=True)
def _row_fractions(flags):
    """(npts,) fraction of the True flags of each row of (npts, n_dir) bools: the integer count
    / n_dir, the value (and bits) of flags.mean(axis=-1), without numpy's conversion of the
    flags to numbers."""
    npts, n = flags.shape
    out = np.empty(npts)
    for p in range(npts):
        c = 0
        for i in range(n):
            c += flags[p, i]
        out[p] = c / n
    return out


@numba.njit(cache=True)
def _n_differ(a, b):
    """Number of entries where two bool arrays of the same shape differ."""
    x = a.ravel()
    y = b.ravel()
    c = 0
    for i in range(x.size):
        c += x[i] != y[i]
    return c


class Trial(NamedTuple):
    """A trial update of every point (nothing committed).

    sigma : (2, 2, npts) FE stress [Pa]; D : (2, 2, 2, 2, npts) FE tangent [Pa];
    states : one new HState per group (their sliding / is_open flags are the pattern, compared
    between Newton iterates by MaterialField.pattern_changes); sliding, opened : (npts,) fractions
    of hexagons sliding / open at each point.
    """

    sigma: np.ndarray
    D: np.ndarray
    states: list
    sliding: np.ndarray
    opened: np.ndarray


class MaterialField:
    """H-model states of ``npts`` points split into groups of (params, point indices).

    groups : sequence of (HParams, index array); the indices partition range(npts). Each group
    starts in the isotropic state of its own parameters (same p0 for all, so the initial stress is
    uniform and the specimen starts in equilibrium).
    allow_sliding : False gives the purely elastic material (tests of Newton convergence).
    """

    def __init__(self, npts: int, groups: Sequence, allow_sliding: bool = True):
        self.npts = int(npts)
        seen = np.zeros(self.npts, dtype=int)
        self.groups = []
        p0 = None
        for params, idx in groups:
            idx = np.asarray(idx, dtype=np.int64)
            if idx.size == 0:
                continue
            seen[idx] += 1
            if p0 is None:
                p0 = params.p0
            elif params.p0 != p0:
                raise ValueError("all material groups must share p0 (uniform initial stress)")
            self.groups.append((params, idx))
        if np.any(seen != 1):
            raise ValueError("material groups must partition the quadrature points exactly once")
        self.allow_sliding = bool(allow_sliding)
        self.states = [broadcast_state(isotropic_state(params), (idx.size,))
                       for params, idx in self.groups]
        self.n_dir = {params.n_dir for params, _ in self.groups}

    def stress(self, states=None) -> np.ndarray:
        """(2, 2, npts) FE stress [Pa] of the committed (or given) states."""
        states = self.states if states is None else states
        out = np.empty((2, 2, self.npts))
        for (params, idx), st in zip(self.groups, states):
            out[:, :, idx] = stress_to_fe(st.stress)
        return out

    def trial(self, d_eps_fe: np.ndarray, elastic: bool = False) -> Trial:
        """Update every point from the committed state by the FE strain increment
        ``d_eps_fe`` (2, 2, npts) (the total increment of the load step: the sliding pattern of
        the H-model is decided by the increment from the committed state). ``elastic``: with
        sliding prevented (the elastic tangent of the state, e.g. for its lowest period).

        The same update as ``hmodel.update_full(state, d_eps, params, extras=False)`` (same
        checks, the same bits), by hmodel's kernel called here directly; the FE stress and tangent
        are gathered from the kernel's outputs at once (no Lagrangian tangent, increment or T3
        conversions the FE never reads). The outputs are new arrays at every call, as in
        ``update_full``: pooled buffers saved a few page faults but changed how the process's
        heap serves other large arrays (the benchmark's batch baseline, interleaved with the run,
        then took ~4500 page faults a call and twice the time)."""
        d_eps_fe = np.asarray(d_eps_fe, dtype=float).reshape(2, 2, self.npts)
        if not np.all(np.isfinite(d_eps_fe)):
            raise ValueError("d_eps contains non-finite values (nan or inf)")
        de_m = strain_to_model(d_eps_fe)
        one = len(self.groups) == 1
        sigma = np.empty((2, 2, self.npts))
        D = None if one else np.empty((2, 2, 2, 2, self.npts))
        sliding = np.empty(self.npts)
        opened = np.empty(self.npts)
        states = []
        for g, ((params, idx), st) in enumerate(zip(self.groups, self.states)):
            de = to_voigt(de_m if one else de_m[:, :, idx])
            ns, sig, tan = self._update(g, params, st, de, self.allow_sliding and not elastic)
            if one:
                _stress_fe_from_kernel(sig, sigma)
                D = _tangent_fe_from_kernel(tan)
            else:
                s_g = np.empty((2, 2, idx.size))
                _stress_fe_from_kernel(sig, s_g)
                sigma[:, :, idx] = s_g
                D[..., idx] = _tangent_fe_from_kernel(tan)
            sliding[idx] = _row_fractions(ns.sliding)
            opened[idx] = _row_fractions(ns.is_open)
            states.append(ns)
        return Trial(sigma, D, states, sliding, opened)

    def _update(self, g: int, params: HParams, st: HState, de: np.ndarray, allow_sliding: bool):
        """(new state, kernel stress (n, 3), kernel tangent (n, 3, 3)) of group ``g`` for the
        material strain increment ``de`` (n, 3) (11, 22, 12): hmodel.update_full's steps."""
        check_state(st, params)
        args = kernel_args(st, params)          # 10 hexagon fields, was_open, eps, V0, eps
        npts, ndir = args[0].shape
        out = _kernels.allocate_outputs(npts, ndir)
        kern = _kernels.update_parallel if npts >= PARALLEL_MIN_POINTS else _kernels.update_serial
        kern(*args[:-1], de, *_material_args(params), allow_sliding, False, *out)
        sig, tan = out[12], out[13]
        if not (np.isfinite(sig).all() and np.isfinite(tan).all()):
            _refuse_non_finite(st)
        batch = st.batch_shape
        ns = HState(*out[:10], eps=st.eps + from_voigt(de, batch), stress=from_voigt(sig, batch),
                    V0=np.array(st.V0, dtype=float), sliding=out[10], is_open=out[11],
                    params_key=st.params_key)
        return ns, sig, tan

    def stress_work(self, new_states, ref_states, weights: np.ndarray) -> float:
        """sum_p weights_p ((s_p + s'_p) / 2 - s0_p) : (e'_p - e_p) [J/m for weights dx in
        m^2, per unit thickness]: the internal second-order work of the increment from the
        committed states (stress s, strain e) to ``new_states`` (a trial's), s0 the stress of
        ``ref_states``, from the material's own stress and strain records
        (``hmodel.material.stress_work``), not from nodal forces. weights : (npts,)."""
        w = np.asarray(weights, float)
        return float(sum(np.sum(w[idx] * stress_work(old, new, ref.stress))
                         for (_, idx), old, new, ref in zip(self.groups, self.states, new_states,
                                                            ref_states)))

    def fractions(self) -> tuple:
        """(sliding, opened): (npts,) fractions of the hexagons of each point that slid / are open
        in the committed state (the pattern of the last converged step)."""
        sliding = np.empty(self.npts)
        opened = np.empty(self.npts)
        for (params, idx), st in zip(self.groups, self.states):
            sliding[idx] = st.sliding.mean(axis=-1)
            opened[idx] = st.is_open.mean(axis=-1)
        return sliding, opened

    def commit(self, trial: Trial) -> None:
        self.states = list(trial.states)

    @staticmethod
    def pattern_changes(a: Trial, b: Trial) -> int:
        """Number of hexagons whose sliding or opening flag differs between two trials (a Newton
        iteration where this is non-zero is not expected to converge quadratically)."""
        return int(sum(_n_differ(x.sliding, y.sliding) + _n_differ(x.is_open, y.is_open)
                       for x, y in zip(a.states, b.states)))
