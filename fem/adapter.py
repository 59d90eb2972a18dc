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
different parameters (the imperfection), all of one law of the material contract
(``point.contract``: the H-model, the Drucker-Prager, a user's), and gives trial updates that are
committed only when the global Newton iteration has converged. It calls the law through the
contract only (``Material.update_voigt``, ``point_fractions``, ``flags_changed``,
``rate_tangent``): a law's fast path (the H-model's kernel) lives behind it.
"""
from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np

from point.contract import material_of
from point.tensors import stress_work, to_voigt

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


class Trial(NamedTuple):
    """A trial update of every point (nothing committed).

    sigma : (2, 2, npts) FE stress [Pa]; D : (2, 2, 2, 2, npts) FE tangent [Pa], consistent with
    sigma (what Newton needs); states : one new state per group (its law's flags are the
    pattern, compared between Newton iterates by MaterialField.pattern_changes); sliding :
    (npts,) the fraction of each point's mechanisms that slid (H-model: hexagons; a law without
    patterns: 1.0 where the step loaded the point); opened : (npts,) the fraction of open
    hexagons, None for a law without patterns; d_eps : (2, 2, npts) the FE strain increment
    from the committed states (the step's direction, for ``MaterialField.rate_tangent``).
    """

    sigma: np.ndarray
    D: np.ndarray
    states: list
    sliding: np.ndarray
    opened: np.ndarray | None
    d_eps: np.ndarray


class MaterialField:
    """States of ``npts`` points of one law, split into groups of (params, point indices).

    groups : sequence of (parameter record, index array), all records of one law
    (``point.material_of``); the indices partition range(npts). Each group starts in the
    isotropic state of its own parameters (``Material.initial_state``; the same p0 for all, so
    the initial stress is uniform and the specimen starts in equilibrium).
    allow_sliding : False gives the purely elastic material (``Material.elastic_update``: tests of
    Newton convergence).
    """

    def __init__(self, npts: int, groups: Sequence, allow_sliding: bool = True):
        self.npts = int(npts)
        seen = np.zeros(self.npts, dtype=int)
        self.groups = []
        p0 = law = None
        for params, idx in groups:
            idx = np.asarray(idx, dtype=np.int64)
            if idx.size == 0:
                continue
            seen[idx] += 1
            m = material_of(params)
            if law is None:
                law, p0 = m, params.p0
            elif m is not law:
                raise ValueError(f"the material groups must be of one law: got {law.name} and "
                                 f"{m.name}")
            elif params.p0 != p0:
                raise ValueError("all material groups must share p0 (uniform initial stress)")
            self.groups.append((params, idx))
        if np.any(seen != 1):
            raise ValueError("material groups must partition the quadrature points exactly once")
        self.law = law
        self.allow_sliding = bool(allow_sliding)
        self.states = [law.initial_state(params, (idx.size,)) for params, idx in self.groups]

    def stress(self, states=None) -> np.ndarray:
        """(2, 2, npts) FE stress [Pa] of the committed (or given) states."""
        states = self.states if states is None else states
        out = np.empty((2, 2, self.npts))
        for (params, idx), st in zip(self.groups, states):
            out[:, :, idx] = stress_to_fe(st.stress)
        return out

    def trial(self, d_eps_fe: np.ndarray, elastic: bool = False) -> Trial:
        """Update every point from the committed state by the FE strain increment
        ``d_eps_fe`` (2, 2, npts) (the total increment of the load step: a law with a history,
        the H-model's sliding pattern, decides it from the increment from the committed state).
        ``elastic``: the purely elastic response (sliding prevented: the elastic tangent of the
        state, e.g. for its lowest period).

        Each group is one call of its law's ``update_voigt`` (the H-model: its kernel, the same
        checks and bits as ``hmodel.update_full(..., extras=False)``); the FE stress and tangent
        are gathered from the returned rows at once."""
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
        law = self.law
        plain = not (self.allow_sliding and not elastic)
        for (params, idx), st in zip(self.groups, self.states):
            de = to_voigt(de_m if one else de_m[:, :, idx])
            ns, sig, tan = law.update_voigt(st, de, params, elastic=plain)
            if one:
                _stress_fe_from_kernel(sig, sigma)
                D = _tangent_fe_from_kernel(tan)
            else:
                s_g = np.empty((2, 2, idx.size))
                _stress_fe_from_kernel(sig, s_g)
                sigma[:, :, idx] = s_g
                D[..., idx] = _tangent_fe_from_kernel(tan)
            sl, op = law.point_fractions(ns)
            sliding[idx] = sl
            if op is None:
                opened = None
            else:
                opened[idx] = op
            states.append(ns)
        return Trial(sigma, D, states, sliding, opened, d_eps_fe)

    def rate_tangent(self, trial: Trial) -> np.ndarray:
        """(2, 2, 2, 2, npts) FE tangent [Pa] of the rate problem at the trial's states, on the
        branch the trial's increment selects: what the bifurcation criteria of a converged step
        are about. For a law whose step tangent is its rate tangent (``Material.tangent_is_rate``:
        the H-model) the trial's D itself (the same array: the same bits); otherwise the law's
        ``rate_tangent(new state, step increment, params)`` of every group (Drucker-Prager:
        D = E - (E:Q)(P:E)/(h + P:E:Q) where the point loaded, E elsewhere)."""
        if self.law.tangent_is_rate:
            return trial.D
        de_m = strain_to_model(trial.d_eps)
        D = np.empty((2, 2, 2, 2, self.npts))
        for (params, idx), st in zip(self.groups, trial.states):
            D[..., idx] = tangent_to_fe(self.law.rate_tangent(st, de_m[:, :, idx], params))
        return D

    def stress_work(self, new_states, ref_states, weights: np.ndarray) -> float:
        """sum_p weights_p ((s_p + s'_p) / 2 - s0_p) : (e'_p - e_p) [J/m for weights dx in
        m^2, per unit thickness]: the internal second-order work of the increment from the
        committed states (stress s, strain e) to ``new_states`` (a trial's), s0 the stress of
        ``ref_states``, from the material's own stress and strain records
        (``point.tensors.stress_work``), not from nodal forces. weights : (npts,)."""
        w = np.asarray(weights, float)
        return float(sum(np.sum(w[idx] * stress_work(old, new, ref.stress))
                         for (_, idx), old, new, ref in zip(self.groups, self.states, new_states,
                                                            ref_states)))

    def fractions(self) -> tuple:
        """(sliding, opened): (npts,) fractions of each point's mechanisms that slid / are open
        in the committed state (the pattern of the last converged step; ``Trial``); opened None
        for a law without patterns."""
        sliding = np.empty(self.npts)
        opened = np.empty(self.npts)
        for (params, idx), st in zip(self.groups, self.states):
            sl, op = self.law.point_fractions(st)
            sliding[idx] = sl
            if op is None:
                opened = None
            else:
                opened[idx] = op
        return sliding, opened

    def commit(self, trial: Trial) -> None:
        self.states = list(trial.states)

    def pattern_changes(self, a: Trial, b: Trial) -> int:
        """Number of mechanism flags that differ between two trials (the law's
        ``flags_changed``: H-model hexagons whose sliding or opening flag differs; a law
        without patterns, points whose plastic flag differs). A Newton iteration where this is
        non-zero is not expected to converge quadratically."""
        return int(sum(self.law.flags_changed(x, y) for x, y in zip(a.states, b.states)))
