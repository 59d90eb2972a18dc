"""The H-microdirectional material point: state, pure batched update, consistent tangents.

Conventions: SI units, compression positive, 2x2 tensors with the tensor axes
first and any batch axes last, e.g. a strain increment of shape (2, 2, *batch), a tangent of shape
(2, 2, 2, 2, *batch). Hexagon fields are stored per material point as rows of n_dir orientations:
shape (*batch, n_dir), so that one point's hexagons are contiguous in memory for the kernel.

One contract (FElupe style)::

    stress, tangent, new_state = update(state, d_eps, params)

It never modifies ``state``. ``update_full`` returns the same plus what the directional analysis
of second-order work needs (Lagrangian tangent and increment, transport term T3, micro sums).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from point.tensors import from_voigt, stress_work, tangent_from_voigt, to_voigt

from . import _kernels
from .params import HParams

__all__ = [
    "HState", "HEX_FIELDS", "Increment", "reference_state", "update", "update_full", "update_copies",
    "broadcast_state",
    "to_voigt", "from_voigt", "tangent_from_voigt", "take_points", "check_state", "stress_work",
]

# Above this many points the parallel kernel pays for its thread start-up.
PARALLEL_MIN_POINTS = 64


class HState(NamedTuple):
    """State of a batch of H-model material points (immutable record).

    Hexagon fields, shape (*batch, n_dir): d1, d2 [m] branch lengths, alpha [rad] opening angle,
    N1, T1, N2 [N] contact forces, l1, l2 [m] hexagon lengths along n and t (Eqs. 17-19),
    cos_alpha, sin_alpha [-] cos and sin of alpha, carried along so that the kernel needs no
    trigonometric call for a closed hexagon (it rotates them by the small angle increment; they
    agree with np.cos(alpha), np.sin(alpha) to round-off). ``HEX_FIELDS`` lists these 10 fields.
    eps : (2, 2, *batch) total strain since the zero-force reference (for the volume).
    stress : (2, 2, *batch) Cauchy stress [Pa], compression positive.
    V0 : (*batch,) reference volume [m^3] of the average hexagon, h sum_i omega_i l1_i l2_i.
    sliding, is_open : (*batch, n_dir) bool, the pattern of the step that produced this state.
    params_key : ``HParams.state_key`` of the parameters the state was made with (the material
    constants the update uses); ``update`` refuses a state whose key is not its parameters'
    (None: a state assembled by hand, not checked).
    """

    d1: np.ndarray
    d2: np.ndarray
    alpha: np.ndarray
    N1: np.ndarray
    T1: np.ndarray
    N2: np.ndarray
    l1: np.ndarray
    l2: np.ndarray
    cos_alpha: np.ndarray
    sin_alpha: np.ndarray
    eps: np.ndarray
    stress: np.ndarray
    V0: np.ndarray
    sliding: np.ndarray
    is_open: np.ndarray
    params_key: tuple | None = None

    @property
    def batch_shape(self) -> tuple:
        return self.V0.shape

    @property
    def n_dir(self) -> int:
        return self.d1.shape[-1]

    @property
    def volume(self) -> np.ndarray:
        """Current volume V = V0 det(I - eps) [m^3], shape (*batch,)."""
        e = self.eps
        return self.V0 * ((1.0 - e[0, 0]) * (1.0 - e[1, 1]) - e[0, 1] * e[1, 0])


# The float hexagon fields, shape (*batch, n_dir), in the kernel's argument order.
HEX_FIELDS = HState._fields[:10]
assert HEX_FIELDS[-1] == "sin_alpha"


class Increment(NamedTuple):
    """Everything one update returns; tensors have the tensor axes first.

    stress : (2, 2, *batch) Cauchy stress at the end of the increment [Pa].
    tangent : (2, 2, 2, 2, *batch) d stress / d d_eps, exact for the returned stress [Pa].
    state : the new HState.
    tangent_lagrangian : (2, 2, 2, 2, *batch) d(dPi)/d d_eps [Pa].
    dPi : (2, 2, *batch) Lagrangian (first Piola-Kirchhoff) increment T1 (Eq. 32) [Pa].
    T3 : (2, 2, *batch) transport term, geometry change at fixed forces (Eq. 28) [Pa].
    w2_micro_hex : (*batch,) sum_i omega_i w2_i (Eq. 36, compression-positive lengths) [J].
    w2n, w2t : (*batch,) normal / tangential contact parts of the micro sum [J].
    """

    stress: np.ndarray
    tangent: np.ndarray
    state: HState
    tangent_lagrangian: np.ndarray
    dPi: np.ndarray
    T3: np.ndarray
    w2_micro_hex: np.ndarray
    w2n: np.ndarray
    w2t: np.ndarray


# -- states ------------------------------------------------------------------------------------
def reference_state(params: HParams, batch_shape: tuple = ()) -> HState:
    """The zero-force reference: every hexagon with d1 = d2 = 2 r_g, alpha = alpha0."""
    batch_shape = tuple(batch_shape)
    shape = batch_shape + (params.n_dir,)
    r = params.r_g
    a0 = np.radians(params.alpha0)
    full = lambda v: np.full(shape, float(v))
    l1 = 2.0 * r + 4.0 * r * np.cos(a0)
    l2 = 4.0 * r * np.sin(a0)
    V0 = params.h * float(np.sum(params.omega)) * l1 * l2
    return HState(
        d1=full(2 * r), d2=full(2 * r), alpha=full(a0), N1=full(0), T1=full(0), N2=full(0),
        l1=full(l1), l2=full(l2), cos_alpha=full(np.cos(a0)), sin_alpha=full(np.sin(a0)),
        eps=np.zeros((2, 2) + batch_shape),
        stress=np.zeros((2, 2) + batch_shape), V0=np.full(batch_shape, V0),
        sliding=np.zeros(shape, dtype=bool), is_open=np.zeros(shape, dtype=bool),
        params_key=params.state_key)


def broadcast_state(state: HState, batch_shape: tuple) -> HState:
    """Copies of a single-point state (batch ()) for every point of ``batch_shape``."""
    if state.batch_shape != ():
        raise ValueError(f"broadcast_state needs a single-point state, got batch {state.batch_shape}")
    batch_shape = tuple(batch_shape)
    hexf = lambda a: np.ascontiguousarray(np.broadcast_to(a, batch_shape + a.shape))
    tens = lambda a: np.ascontiguousarray(np.broadcast_to(a.reshape(2, 2, *([1] * len(batch_shape))),
                                                          (2, 2) + batch_shape))
    return HState(*(hexf(getattr(state, f)) for f in HEX_FIELDS),
                  eps=tens(state.eps), stress=tens(state.stress),
                  V0=np.full(batch_shape, float(state.V0)),
                  sliding=hexf(state.sliding), is_open=hexf(state.is_open), params_key=state.params_key)


def take_points(state: HState, index) -> HState:
    """The sub-batch ``index`` (an index along the flattened batch) of a state."""
    n = state.n_dir
    idx = np.asarray(index)
    hexf = lambda a: a.reshape(-1, n)[idx]
    tens = lambda a: a.reshape(2, 2, -1)[:, :, idx]
    return HState(*(hexf(getattr(state, f)) for f in HEX_FIELDS),
                  eps=tens(state.eps), stress=tens(state.stress), V0=state.V0.reshape(-1)[idx],
                  sliding=hexf(state.sliding), is_open=hexf(state.is_open), params_key=state.params_key)


# -- the update --------------------------------------------------------------------------------
def update_full(state: HState, d_eps, params: HParams, allow_sliding: bool = True,
                parallel: bool | None = None, extras: bool = True) -> Increment:
    """Advance every point by the strain increment ``d_eps`` (2, 2, *batch), compression positive.

    Only the symmetric part of ``d_eps`` acts (Eq. 16 sees n.de.n and t.de.t). The sliding /
    opening pattern is decided by this increment from ``state`` (the return rule of docs/hmodel.md).
    ``allow_sliding=False`` gives the purely elastic response (the Coulomb cap off).
    ``extras=False`` skips the Lagrangian tangent and increment, T3 and the micro sums (their
    fields are then NaN): what ``update`` does, since the material contract needs none of them.
    """
    d_eps = np.asarray(d_eps, dtype=float)
    batch = state.batch_shape
    if d_eps.shape != (2, 2) + batch:
        raise ValueError(f"d_eps must have shape (2, 2) + batch = {(2, 2) + batch}, got {d_eps.shape}")
    if not np.all(np.isfinite(d_eps)):
        raise ValueError("d_eps contains non-finite values (nan or inf)")
    check_state(state, params)
    de = to_voigt(d_eps)
    out = _run_kernel(state, kernel_args(state, params)[:-1], de, params, allow_sliding, parallel,
                      extras)
    return increment_from_outputs(state, de, out)


def update_copies(state: HState, de: np.ndarray, params: HParams, allow_sliding: bool = True,
                  extras: bool = True) -> tuple:
    """The kernel's outputs (``_kernels.allocate_outputs`` order, rows = points) for copies of
    the single-point ``state``, one copy per row of the strain increments ``de`` (n, 3) in
    (11, 22, 12) order: the numbers ``update_full(broadcast_state(state, (n,)), ...)`` gives, to
    the bit, without wrapping them in states and tensors (the probes' batches, where that
    wrapping cost as much as the update)."""
    if state.batch_shape != ():
        raise ValueError(f"update_copies needs a single-point state, got batch {state.batch_shape}")
    de = np.ascontiguousarray(de, dtype=float)
    if de.ndim != 2 or de.shape[1] != 3:
        raise ValueError(f"de must have shape (n, 3), got {de.shape}")
    if not np.all(np.isfinite(de)):
        raise ValueError("d_eps contains non-finite values (nan or inf)")
    check_state(state, params)
    n = de.shape[0]
    args = tuple(np.repeat(a, n, axis=0) for a in kernel_args(state, params)[:-1])
    return _run_kernel(state, args, de, params, allow_sliding, None, extras)


def _run_kernel(state, args, de, params, allow_sliding, parallel, extras):
    """The update kernel on the kernel arguments ``args`` (of ``state``, or of copies of it)."""
    npts = args[-1].shape[0]
    out = _kernels.allocate_outputs(npts, state.n_dir)
    if parallel is None:
        parallel = npts >= PARALLEL_MIN_POINTS
    kern = _kernels.update_parallel if parallel else _kernels.update_serial
    kern(*args, de, *_material_args(params), bool(allow_sliding), bool(extras), *out)
    sig, tan = out[12], out[13]
    if not (np.isfinite(sig).all() and np.isfinite(tan).all()):
        _refuse_non_finite(state)
    return out


def check_state(state: HState, params: HParams) -> None:
    """Refuse a state that was not made with ``params``: a different number of orientations, or
    a ``params_key`` (the constants kn, kt, phi_g, r_g, n_dir and fabric the update uses) that is
    not ``params.state_key``. O(1): the key is a tuple carried by every state the library makes,
    exact for every constant (a geometric check could only see r_g and kn, through the
    branch lengths and normal forces, and costs a pass over every hexagon)."""
    if state.n_dir != params.n_dir:
        raise ValueError(f"state has n_dir = {state.n_dir} orientations but params.n_dir = {params.n_dir}")
    if state.params_key is not None and state.params_key != params.state_key:
        names = ("kn", "kt", "phi_g", "r_g", "n_dir", "fabric_a", "fabric_b")
        diff = [f"{n} {a!r} (state) != {b!r}" for n, a, b in zip(names, state.params_key, params.state_key)
                if a != b]
        raise ValueError("the state was made with other parameters than the ones given: "
                         + ", ".join(diff))


def _refuse_non_finite(state: HState):
    """The update gave a non-finite stress or tangent: name the state field that is not finite."""
    for f in HEX_FIELDS + ("eps", "V0"):
        a = np.asarray(getattr(state, f), dtype=float)
        if not np.isfinite(a).all():
            raise ValueError(f"the state has non-finite values (nan or inf) in {f} "
                             f"({int(np.count_nonzero(~np.isfinite(a)))} entries): refused")
    raise ValueError("the update gave a non-finite stress or tangent from a finite state")


def _material_args(params: HParams):
    theta = params.theta
    return (np.cos(theta), np.sin(theta), params.omega, float(params.kn), float(params.kt),
            float(params.mu), float(params.r_g))


def kernel_args(state: HState, params: HParams):
    """The state as the kernel takes it: the 10 ``HEX_FIELDS`` arrays (npts, n_dir), was_open,
    eps (npts, 3), V0 (npts,); the last entry repeats eps for the caller's convenience."""
    n = state.n_dir
    npts = int(np.prod(state.batch_shape, dtype=int))
    hexf = lambda a: np.ascontiguousarray(a, dtype=float).reshape(npts, n)
    eps = to_voigt(state.eps)
    return (*(hexf(getattr(state, f)) for f in HEX_FIELDS),
            np.ascontiguousarray(state.is_open, dtype=np.bool_).reshape(npts, n),
            eps, np.ascontiguousarray(state.V0, dtype=float).reshape(npts), eps)


def increment_from_outputs(state: HState, de: np.ndarray, out) -> Increment:
    """Wrap the kernel outputs ``out`` of the increment ``de`` (npts, 3) from ``state``."""
    batch = state.batch_shape
    n = state.n_dir
    (nd1, nd2, nal, nN1, nT1, nN2, nl1, nl2, nca, nsa, slid, opn, sig, tan, tanL, dPi, T3, w2, w2n,
     w2t) = out
    hshape = batch + (n,)
    stress = from_voigt(sig, batch)
    new_state = HState(
        d1=nd1.reshape(hshape), d2=nd2.reshape(hshape), alpha=nal.reshape(hshape),
        N1=nN1.reshape(hshape), T1=nT1.reshape(hshape), N2=nN2.reshape(hshape),
        l1=nl1.reshape(hshape), l2=nl2.reshape(hshape),
        cos_alpha=nca.reshape(hshape), sin_alpha=nsa.reshape(hshape),
        eps=state.eps + from_voigt(de, batch), stress=stress, V0=np.array(state.V0, dtype=float),
        sliding=slid.reshape(hshape), is_open=opn.reshape(hshape), params_key=state.params_key)
    return Increment(
        stress=stress, tangent=tangent_from_voigt(tan, batch), state=new_state,
        tangent_lagrangian=tangent_from_voigt(tanL, batch), dPi=from_voigt(dPi, batch),
        T3=from_voigt(T3, batch), w2_micro_hex=w2.reshape(batch), w2n=w2n.reshape(batch),
        w2t=w2t.reshape(batch))


def update(state: HState, d_eps, params: HParams):
    """The material contract: ``(stress, tangent, new_state) = update(state, d_eps, params)``.

    stress (2, 2, *batch) [Pa], tangent (2, 2, 2, 2, *batch) [Pa], both compression positive;
    ``state`` is left unchanged.
    """
    inc = update_full(state, d_eps, params, extras=False)
    return inc.stress, inc.tangent, inc.state
