"""The material point under the same mixed control as the homogeneous FE specimen.

The FE specimen prescribes the axial strain (platen), the lateral stress (sigma2 on the lateral
faces) and a zero shear stress (smooth platens, free lateral faces): material control
(eps11, sigma22, sigma12), i.e. ``MixedControl(strain_controlled=(True, False, False))``. (The
drained path of hmodel.driver holds eps12 = 0 instead; for the isotropic fabric the two paths are
the same since no shear arises.)

Criteria of the tangent D (Mandel matrix D_M, (e11, e22, sqrt2 e12), model frame) at each step:
- displacement-controlled platen: the free components are (e22, e12): block D_M[1:, 1:]; a
  homogeneous lateral or shear mode is admissible in the FE, so lam_min of the FE K_s goes <= 0
  no later than lam_min of this block's symmetric part;
- force-controlled platen: all three components are free: the full D_M; lam_min(D_s) <= 0 is the
  first strain direction with W2 <= 0 (Hill), and det D_M = 0 is the limit point (the peak of q at
  constant sigma2).
"""
from __future__ import annotations

import numpy as np

from point.contract import material_of
from point.driver import (MixedControl, isotropic_state, mixed_step, run_path, drained_biaxial,
                           stress_invariants)
from point.burst import CPeak, proportional_path
from point.experiment import state_at_eta
from point.tensors import to_voigt

from .indicators import mandel

__all__ = ["material_point_criteria", "material_point_curve", "CPeak", "material_point_path",
           "closed_form_onsets", "FE_CLOSED_FORMS", "closed_form_c_peak"]


def material_point_criteria(params, d_eps1: float, n_steps: int, keep_states: bool = False) -> dict:
    """Step the material point of any law (eps11 += d_eps1, sigma22 = p0, sigma12 = 0) n_steps
    times.

    Returns arrays of length n_steps + 1 (row 0: the isotropic state with the tangent of a zero
    increment is not computed: NaN): eps1, s1, s2, q, p, eta [Pa], and per step
    lam_min_ds_disp, det_disp, lam_min_ds_force, det_force (Mandel matrices, Pa / Pa^n) of the
    rate tangent at the state reached (the step's consistent tangent for a law whose step tangent
    is its rate tangent, ``Material.tangent_is_rate``; else ``Material.rate_tangent`` in the
    step's direction), as the FE's criteria are. ``keep_states``: also "states", the list of
    the n_steps + 1 states.
    """
    ctl = MixedControl(strain_controlled=(True, False, False), d_eps=(d_eps1, 0.0, 0.0))
    law = material_of(params)
    state = isotropic_state(params)
    states = [state]
    target = np.array([0.0, params.p0, 0.0])
    keys = ("eps1", "s1", "s2", "lam_min_ds_disp", "det_disp", "lam_min_ds_force", "det_force")
    out = {k: np.full(n_steps + 1, np.nan) for k in keys}
    s0 = to_voigt(state.stress)[0]
    out["eps1"][0], out["s1"][0], out["s2"][0] = 0.0, s0[0], s0[1]
    guess = np.zeros(3)
    eps1 = 0.0
    for k in range(1, n_steps + 1):
        inc, de, _ = mixed_step(state, params, ctl, target, guess=guess)
        de = np.asarray(de)
        guess = de
        state = inc.state
        states.append(state)
        eps1 += d_eps1
        D = inc.tangent if law.tangent_is_rate else law.rate_tangent(
            state, np.array([[de[0], de[2]], [de[2], de[1]]]), params)
        M = mandel(D)
        Ms = 0.5 * (M + M.T)
        s = to_voigt(inc.stress)[0]
        out["eps1"][k], out["s1"][k], out["s2"][k] = eps1, s[0], s[1]
        out["lam_min_ds_force"][k] = np.linalg.eigvalsh(Ms)[0]
        out["det_force"][k] = np.linalg.det(M)
        out["lam_min_ds_disp"][k] = np.linalg.eigvalsh(Ms[1:, 1:])[0]
        out["det_disp"][k] = np.linalg.det(M[1:, 1:])
    out["q"] = out["s1"] - out["s2"]
    out["p"] = 0.5 * (out["s1"] + out["s2"])
    out["eta"] = out["q"] / out["p"]
    if keep_states:
        out["states"] = states
    return out


def material_point_curve(params, eps1_max: float, d_eps1: float = 1e-5,
                         keep_states: bool = False) -> dict:
    """The drained biaxial curve of point.driver, any law (for the figure and the peak): eps1, q, p, eta,
    the peak (eps1_peak, q_peak, eta_peak), and how the path ended (outcome, end: the line of
    ``PathResult.end``, e.g. 'discontinuous at eps1 = ...' where no static state exists beyond).
    ``keep_states``: also "path", the PathResult with its states (``closed_form_onsets``)."""
    n = max(1, int(round(eps1_max / d_eps1)))
    r = run_path(isotropic_state(params), params, drained_biaxial(d_eps1), n, keep_states=keep_states)
    p, q, eta = r.invariants()
    k = int(np.argmax(q))
    out = {"eps1": r.eps[:, 0], "q": q, "p": p, "eta": eta, "eps1_peak": float(r.eps[k, 0]),
           "q_peak": float(q[k]), "eta_peak": float(eta[k]), "peak_is_interior": k < len(q) - 1,
           "outcome": r.end.outcome, "end": r.end.line()}
    if keep_states:
        out["path"] = r
    return out


def material_point_path(params, eta_start: float, ratio: float, d_eps1: float,
                        path_d_eps1: float, path_strain: float) -> dict:
    """The material point's burst path (docs/burst.md): the drained path (``state_at_eta``,
    steps ``d_eps1``) to the first state with eta >= ``eta_start``, then the proportional strain
    path d eps2 = ``ratio`` d eps1 with every strain component controlled (``proportional_strain``,
    ``run_path``, steps ``path_d_eps1``) until c = s1 + R s2 has peaked (``CPeak``) or the axial
    strain since the start is ``path_strain``.

    Returns rows of the path (row 0 the start): eps1, eps2 (since the isotropic state), s1, s2,
    p, q, eta, c [Pa], and peak (row of the c peak or None), below (row of the below switch),
    cpeak (the ``CPeak``: e.g. its sizing rule ``missed``)."""
    drained, state = state_at_eta(params, eta_start, d_eps1=d_eps1)
    r, peak = proportional_path(state, params, ratio, path_d_eps1, path_strain)
    p, q, eta = stress_invariants(r.sigma)
    e0 = drained.eps[-1]
    return {"eps1": e0[0] + r.eps[:, 0], "eps2": e0[1] + r.eps[:, 1], "s1": r.sigma[:, 0],
            "s2": r.sigma[:, 1], "p": p, "q": q, "eta": eta,
            "c": r.sigma[:, 0] + ratio * r.sigma[:, 1], "peak": peak.peak, "below": peak.below(),
            "cpeak": peak}


# the closed form each FE criterion is held to, for a law with a single mechanism: (the h at which
# it fires, what the FE's field and boundary conditions make of it; docs/fem.md derives them)
FE_CLOSED_FORMS = {
    "lam_min_ks_f": ("h_sym", "exact: every homogeneous field is admissible under the force "
                              "control, K_s = sum w B^T D_s B"),
    "local_lam_Ds": ("h_sym", "exact: the point's own D_s"),
    "local_w2": ("h_sym", "exact up to the sampling of the directions"),
    "local_rice": ("h_loc", "exact up to the sampling of the normals"),
    "fe_peak": ("h0", "exact: the homogeneous specimen's limit point"),
    "det_k_f": ("h0", "the homogeneous null vector is exact at h = 0; banded fields may cross "
                      "in the same steps"),
    "lam_min_ks": ("h_sym", "a lower bound: the displacement control admits no homogeneous "
                            "field with d eps11 != 0; banded fields make it fire after h_sym, "
                            "mesh-dependent"),
    "det_k": ("h_loc", "no exact onset on a finite mesh: banded fields, whose onset in the "
                       "continuum is Rice's h_loc"),
}


def closed_form_onsets(params, path) -> dict:
    """The closed-form onsets along the material point's drained path ``path`` (a PathResult
    with its states: ``material_point_curve(..., keep_states=True)``), for a law with a single
    mechanism (``Material.mechanism``; None otherwise): {"h0" | "h_sym" | "h_loc": {"eps1",
    "eta"} of the root of h = h_crit (``point.onsets``'s interpolation through the path's own
    states), or None where it is not reached}. The homogeneous specimen's control (eps11
    prescribed, sigma22 = p0, sigma12 = 0) and the drained path's (eps12 = 0 instead of
    sigma12 = 0) are the same path for a law whose states stay coaxial (isotropic elasticity,
    a yield function of the invariants: no shear arises)."""
    from point.closed_forms import h_rice, h_sym
    from point.onsets import RICE_STRIDE, first_root, has_mechanism
    if path is None or not has_mechanism(material_of(params)):
        return None
    p, q, eta = path.invariants()
    vals = {"eps1": path.eps[:, 0], "eta": eta}
    out = {}
    for key, h_crit, stride in (("h0", lambda m: 0.0, 1), ("h_sym", h_sym, 1),
                                ("h_loc", lambda m: h_rice(m, n_grid=90)[0], RICE_STRIDE)):
        root = first_root(path.states, params, h_crit, vals, stride)
        out[key] = None if root is None else {"eps1": float(root["eps1"]), "eta": float(root["eta"])}
    return out


def closed_form_c_peak(params, eta_start: float, ratio: float, d_eps1: float, path_d_eps1: float,
                       rows: int):
    """The c peak of the material point's burst path (``material_point_path``'s: the drained path
    to ``eta_start``, then the proportional strain path of ``ratio``) in closed form, for a law
    with a single mechanism (None otherwise, or where it is not reached within ``rows`` steps of
    the proportional path): {"eta", "c", "eps1"} where h = h_R = (u.E.Q)(P.E.u)/(u.E.u) - P:E:Q,
    u = (1, R, 0), interpolated through the path's own states (``point.onsets.first_root``);
    eps1 counted from the path's start."""
    from point.closed_forms import h_path
    from point.driver import proportional_strain
    from point.onsets import first_root, has_mechanism
    if not has_mechanism(material_of(params)):
        return None
    _, state = state_at_eta(params, eta_start, d_eps1=d_eps1)
    r = run_path(state, params, proportional_strain(path_d_eps1, ratio), max(1, int(rows)),
                 keep_states=True)
    p, q, eta = stress_invariants(r.sigma)
    u = (1.0, float(ratio), 0.0)
    root = first_root(r.states, params, lambda m: h_path(m, u),
                      {"eta": eta, "c": r.sigma[:, 0] + ratio * r.sigma[:, 1], "eps1": r.eps[:, 0]})
    return None if root is None else {k: float(root[k]) for k in ("eta", "c", "eps1")}
