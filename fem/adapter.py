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

import numpy as np

from hmodel import HParams, update_full, broadcast_state
from hmodel.driver import isotropic_state

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

    def trial(self, d_eps_fe: np.ndarray) -> Trial:
        """Update every point from the committed state by the FE strain increment
        ``d_eps_fe`` (2, 2, npts) (the total increment of the load step: the sliding pattern of
        the H-model is decided by the increment from the committed state)."""
        de_m = strain_to_model(np.asarray(d_eps_fe, dtype=float).reshape(2, 2, self.npts))
        sigma = np.empty((2, 2, self.npts))
        D = np.empty((2, 2, 2, 2, self.npts))
        sliding = np.empty(self.npts)
        opened = np.empty(self.npts)
        states = []
        for (params, idx), st in zip(self.groups, self.states):
            one = len(self.groups) == 1
            de = de_m if one else de_m[:, :, idx]
            # extras=False: the FE reads the stress, the tangent and the new state only (the
            # probe-only extras cost a third of the update)
            inc = update_full(st, de, params, allow_sliding=self.allow_sliding, extras=False)
            sigma[:, :, idx] = stress_to_fe(inc.stress)
            D[..., idx] = tangent_to_fe(inc.tangent)
            ns = inc.state
            sliding[idx] = ns.sliding.mean(axis=-1)
            opened[idx] = ns.is_open.mean(axis=-1)
            states.append(ns)
        return Trial(sigma, D, states, sliding, opened)

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
        return int(sum(np.count_nonzero(x.sliding != y.sliding) + np.count_nonzero(x.is_open != y.is_open)
                       for x, y in zip(a.states, b.states)))
