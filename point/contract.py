"""The material contract: what a constitutive law of the plane implements so that the whole
analysis of this project (driver, probes, second-order work, cones, bifurcation domain,
controllability, burst, the FE specimen) runs on it.

A material is a ``Material`` (one instance per law), paired with its parameter record::

    stress, tangent, new_state = material.update(state, d_eps, params)

* ``d_eps`` (2, 2, *batch): a strain increment, compression positive, axis 1 axial; only its
  symmetric part acts.
* ``stress`` (2, 2, *batch) [Pa]: the Cauchy stress at the end of the increment, compression
  positive; ``tangent`` (2, 2, 2, 2, *batch) [Pa]: d stress / d d_eps, consistent with the
  returned stress (what Newton needs), both minor symmetries.
* ``state``: an immutable record (a NamedTuple) of the batch of points, never modified; it has
  ``stress`` and ``eps`` (2, 2, *batch) [Pa, -] (the total strain since the material's
  reference), and ``batch_shape``.

The parameter record is a frozen dataclass with a field ``p0`` [Pa] (the confining stress of the
isotropic initial state), a method ``replace(**changes)`` that validates again, and the class
attribute ``material`` set by ``register`` (so that ``material_of(params)`` finds the law from
the record alone: every analysis function takes ``(state, params)``). Its validation raises
``ParamError`` (field, value, allowed range) so that a command line names its own option.

What a law may add (``Material.provides`` names it, and the outputs say what is absent):
``"lagrangian"`` (the Lagrangian increment dPi, the transport term T3, the volume: the H-model's
Eq. 10 W2 and its Eulerian split), ``"micro"`` (the micro sums of Eqs. 36-37), ``"patterns"``
(the sliding / opening flags of the H-model's hexagons). A law may override ``update_rows``,
``update_voigt`` (a field of points: the FE's quadrature points), ``mixed_step_fast`` and
``path_fast`` with faster code (the H-model's Numba kernels) that must give the numbers the
generic code gives from ``update``; and ``point_fractions`` / ``flags_changed`` (what a field
records of its points' mechanisms: the H-model's hexagons, by default the plastic flag). The
class attribute ``tangent_is_rate`` says whether a step's consistent tangent is the rate tangent
at the state it reaches (the H-model: yes; by default no, and the bifurcation criteria of a field
are computed from ``rate_tangent``).
"""
from __future__ import annotations

import importlib
from typing import NamedTuple

import numpy as np

from .tensors import from_voigt, mandel_tangent, tangent_from_voigt, to_voigt, voigt_tangent

__all__ = ["Material", "MaterialError", "ParamError", "register", "material_of", "material_named",
           "MATERIALS", "Rows", "check_tangent", "TangentCheck", "check_update_output",
           "check_law"]


class MaterialError(ValueError):
    """A material cannot go on from a state, or broke its contract: one line that names the
    material and what failed (the command lines print it as ``error: ...`` and exit 2)."""


class ParamError(ValueError):
    """A parameter field out of range: ``name`` (the field), ``value``, ``allowed`` (the range,
    as text), so that a command line can name its own option instead of the field."""

    def __init__(self, name, value, allowed, message=None, record="params"):
        self.name, self.value, self.allowed = name, value, allowed
        super().__init__(message or f"{record}.{name} = {value!r} is out of range: allowed {allowed}")


class Rows(NamedTuple):
    """The update of copies of one point, one copy per strain increment (``Material.update_rows``).

    stress : (n, 3) [Pa] rows (11, 22, 12); tangent : (n, 3, 3) [Pa] rows T[p, a, b] =
    d sigma_a / d v_b, v = (de11, de22, de12) tensor shear; plastic : (n,) bool, the increment
    loaded the material (not elastic); extras : a dict of what the law provides besides
    (the H-model: its kernel's outputs by name), empty otherwise.
    """

    stress: np.ndarray
    tangent: np.ndarray
    plastic: np.ndarray
    extras: dict


# name -> module that registers it on import (a law named in a parameter file is found without
# importing every law up front; ``register`` adds a user's law)
_BUILTIN = {"hmodel": "hmodel.law", "drucker-prager": "point.drucker_prager"}
MATERIALS: dict = {}


def register(material: "Material") -> "Material":
    """Make ``material`` the law of its parameter record (``material.params_type.material``) and
    known by its name (parameter files). Returns it."""
    if not (isinstance(material.name, str) and material.name):
        raise MaterialError(f"{type(material).__name__}: a material needs a name (a non-empty str)")
    P = material.params_type
    if P is None or not hasattr(P, "__dataclass_fields__") or "p0" not in P.__dataclass_fields__:
        raise MaterialError(f"material {material.name}: params_type must be a dataclass with a "
                            "field p0 (the confining stress of the isotropic state [Pa])")
    P.material = material
    MATERIALS[material.name] = material
    return material


def material_named(name: str) -> "Material":
    """The registered material called ``name`` (a parameter file's "model")."""
    if name not in MATERIALS and name in _BUILTIN:
        importlib.import_module(_BUILTIN[name])
    if name not in MATERIALS:
        known = sorted(set(MATERIALS) | set(_BUILTIN))
        raise MaterialError(f"no material named {name!r}: allowed {', '.join(known)} (or a law "
                            "registered with point.register)")
    return MATERIALS[name]


def material_of(params) -> "Material":
    """The law of a parameter record (``register`` set it on the record's class)."""
    m = getattr(type(params), "material", None)
    if not isinstance(m, Material):
        raise MaterialError(f"{type(params).__name__} is no registered material's parameter "
                            "record (point.register(material) with material.params_type = it)")
    return m


class Material:
    """A constitutive law of the plane (module docstring). Subclasses set ``name``,
    ``params_type``, ``units`` (field -> unit) and implement ``initial_state`` and ``update``;
    the rest has defaults that a law may override. ``label``: its name in figures and prose
    (default ``name``); ``defaults_name``: where its default record comes from, as the command
    lines say it ("Table I", "the benchmark set")."""

    name: str = ""
    params_type: type = None
    units: dict = {}
    provides: frozenset = frozenset()
    description: str = ""
    # Is the consistent tangent of a step the rate tangent at the state the step reaches? True
    # for a law whose tangent is constant on a branch (the H-model, for a fixed sliding pattern):
    # the tangent criteria of a converged step (an FE step's local indicators and global check)
    # may then be read from the step's own tangent. False (the default, which is always right):
    # they are computed from ``rate_tangent`` at the state reached, in the step's direction (the
    # Drucker-Prager's D_alg differs from its D by O(G d lambda / tau)).
    tangent_is_rate: bool = False
    label: str = ""                 # its name in figures and prose ("H-model"); default ``name``
    defaults_name: str = "the defaults"     # where its default record comes from ("Table I")

    # -- what every law implements ----------------------------------------------------------
    def initial_state(self, params, batch_shape: tuple = ()):
        """The isotropic state at the confining stress ``params.p0`` [Pa] (stress p0 I),
        copied for every point of ``batch_shape``; strains of a test count from it."""
        raise NotImplementedError

    def update(self, state, d_eps, params):
        """``(stress, tangent, new_state)`` (module docstring); ``state`` left unchanged."""
        raise NotImplementedError

    # -- defaults -------------------------------------------------------------------------------
    def check_state(self, state, params) -> None:
        """Refuse a state that ``params`` cannot continue (default: nothing to check)."""

    def broadcast(self, state, batch_shape: tuple):
        """Copies of the single-point ``state`` for every point of ``batch_shape``. The default
        takes every array field of the record to have its batch axes last (the project's
        convention: a single point's field is the field without them); scalars and None stay."""
        batch_shape = tuple(batch_shape)
        if tuple(state.batch_shape) != ():
            raise ValueError(f"broadcast needs a single-point state, got batch {state.batch_shape}")
        out = []
        for v in state:
            if isinstance(v, np.ndarray):
                a = np.asarray(v)
                v = np.ascontiguousarray(np.broadcast_to(a.reshape(a.shape + (1,) * len(batch_shape)),
                                                         a.shape + batch_shape))
            out.append(v)
        return type(state)(*out)

    def take(self, state, index):
        """The points ``index`` (an index along the flattened batch) of a state (default: batch
        axes last, as ``broadcast``)."""
        nb = len(state.batch_shape)
        out = []
        for v in state:
            if isinstance(v, np.ndarray):
                lead = v.shape[:v.ndim - nb]
                v = v.reshape(lead + (-1,))[..., np.asarray(index)]
            out.append(v)
        return type(state)(*out)

    def update_rows(self, state, de: np.ndarray, params, elastic: bool = False) -> Rows:
        """The update of copies of the single-point ``state``, one per row of ``de`` (n, 3)
        (11, 22, 12, tensor shear): what the probes and scans need. ``elastic``: the elastic
        response (``elastic_update``). The default broadcasts the state and calls ``update``
        once on the batch (n,)."""
        de = np.asarray(de, dtype=float)
        n = de.shape[0]
        many = self.broadcast(state, (n,))
        d_eps = from_voigt(de, (n,))
        if elastic:
            stress, tangent, new = self.elastic_update(many, d_eps, params)
        else:
            stress, tangent, new = self.update(many, d_eps, params)
        return Rows(to_voigt(stress), voigt_tangent(tangent), self.plastic(new, (n,)), {})

    def update_voigt(self, state, de: np.ndarray, params, elastic: bool = False) -> tuple:
        """The update of a flat batch ``state`` (batch (n,)) by one strain increment a point,
        the rows ``de`` (n, 3) (11, 22, 12, tensor shear): ``(new_state, stress (n, 3) [Pa] rows
        (11, 22, 12), tangent (n, 3, 3) [Pa] rows T[p, a, b] = d sigma_a / d v_b)``, what a
        field of points (the FE's quadrature points) needs. ``elastic``: ``elastic_update``.
        The default is ``update`` with the rows as tensors; a law may override it with a faster
        route to the same numbers (the H-model: its kernel's outputs as they come)."""
        de = np.asarray(de, dtype=float)
        batch = tuple(state.batch_shape)
        f = self.elastic_update if elastic else self.update
        stress, tangent, new = f(state, from_voigt(de, batch), params)
        return new, to_voigt(stress), voigt_tangent(tangent)

    def point_fractions(self, state) -> tuple:
        """``(sliding, opened)`` of a flat batch ``state``: (n,) fractions of each point's
        mechanisms that slid in the step that made the state, and that are open (a field's
        records). Default, a law without patterns: ``sliding`` is the plastic flag (1.0 where the
        step loaded the material, ``plastic``), ``opened`` None (absent)."""
        n = int(np.prod(state.batch_shape, dtype=int))
        return self.plastic(state, state.batch_shape).reshape(n).astype(float), None

    def flags_changed(self, a, b) -> int:
        """The number of mechanism flags that differ between two states of the same points (two
        Newton iterates of a field: a non-zero count means the iteration changed branch, so no
        quadratic convergence is expected there). Default: the points whose plastic flag
        differs."""
        sb = tuple(a.batch_shape)
        return int(np.count_nonzero(self.plastic(a, sb) != self.plastic(b, sb)))

    def plastic(self, new_state, batch_shape) -> np.ndarray:
        """(*batch,) bool: the step that made ``new_state`` loaded the material (default: the
        state's field ``plastic`` if it has one, else all False)."""
        p = getattr(new_state, "plastic", None)
        return np.zeros(batch_shape, dtype=bool) if p is None else np.asarray(p, dtype=bool)

    def elastic_update(self, state, d_eps, params):
        """The purely elastic response from ``state`` (no plastic flow): the tangent of the
        lowest period of a dynamic run. The default is ``update`` itself (a law whose zero
        increment is elastic gives its elastic tangent there)."""
        return self.update(state, d_eps, params)

    def rate_tangent(self, state, direction, params, norm: float = 1e-6) -> np.ndarray:
        """(2, 2, 2, 2, *batch) the tangent of the rate problem at ``state`` on the branch that
        the strain direction ``direction`` (2, 2, *batch) selects (loading or unloading): what
        the tangent criteria (det D, its symmetric part, the cone) are computed from. Default:
        the consistent tangent of the increment ``norm`` direction / |direction|, exact for a
        law whose tangent is constant on a branch (the H-model, for a fixed pattern); a law
        whose consistent tangent depends on the step's size overrides it with the exact rate
        tangent. A zero direction (no step) gives the tangent of the zero increment."""
        d = np.asarray(direction, dtype=float)
        mag = np.sqrt(np.einsum("ab...,ab...->...", d, d))
        with np.errstate(invalid="ignore", divide="ignore"):
            d = np.where(mag > 0, norm * d / mag, 0.0)
        return self.update(state, d, params)[1]

    def mechanism(self, state, params):
        """The single plastic mechanism of a single-point state where the law has one
        (``point.closed_forms.Mechanism``: E, P, Q, h), so that every criterion has a closed form
        to stand beside the analysis's; None (the default) for a law without one."""
        return None

    def describe(self, params) -> str:
        """One line naming the law and its parameters (summaries)."""
        vals = ", ".join(f"{k} {getattr(params, k):g}" for k in params.__dataclass_fields__
                         if not k.startswith("_") and isinstance(getattr(params, k), (int, float)))
        return f"{self.name} ({vals})"

    def absent(self) -> list:
        """The optional outputs this law does not provide (named in summaries)."""
        return [k for k in ("lagrangian", "micro", "patterns") if k not in self.provides]


# -- the contract checked ---------------------------------------------------------------------
def check_update_output(material: Material, state, d_eps, out) -> None:
    """Refuse an update whose outputs break the contract: wrong shapes, non-finite values, a
    state without ``stress`` / ``eps``. One line naming the material and what failed
    (MaterialError)."""
    name = material.name or type(material).__name__
    if not (isinstance(out, tuple) and len(out) == 3):
        raise MaterialError(f"material {name}: update must return (stress, tangent, new_state), "
                            f"got {type(out).__name__}")
    stress, tangent, new = out
    batch = tuple(np.shape(d_eps)[2:])
    for what, v, shape in (("stress", stress, (2, 2) + batch), ("tangent", tangent, (2, 2, 2, 2) + batch)):
        if np.shape(v) != shape:
            raise MaterialError(f"material {name}: update returned a {what} of shape "
                                f"{np.shape(v)}, allowed {shape} (tensor axes first, batch last)")
        if not np.all(np.isfinite(v)):
            raise MaterialError(f"material {name}: update returned a non-finite {what} "
                                f"({int(np.count_nonzero(~np.isfinite(v)))} entries nan or inf)")
    for f in ("stress", "eps"):
        if np.shape(getattr(new, f, None)) != (2, 2) + batch:
            raise MaterialError(f"material {name}: the new state has no field {f} of shape "
                                f"{(2, 2) + batch} (the contract's state records stress and eps)")


class TangentCheck(NamedTuple):
    """``check_tangent``'s result: the largest relative difference of the returned tangent from
    central finite differences of the returned stress, over the probes; the step used; pass."""

    error: float
    step: float
    ok: bool
    worst: tuple
    tol: float = 1e-5


def check_tangent(material: Material, state, params, d_eps, rel_step: float = 1e-6,
                  tol: float = 1e-5) -> TangentCheck:
    """Does the tangent ``update`` returns agree with its own stress? At the increment ``d_eps``
    (2, 2) from the single-point ``state``: each column of the tangent (Mandel basis) against
    the central difference (stress(d_eps + h e_b) - stress(d_eps - h e_b)) / 2h,
    h = ``rel_step`` max(|d_eps|, 1e-6). The truncation error is O(h^2) for a smooth branch
    (the increment must not sit on a branch change); the round-off O(ulp |stress| / h). ``tol``:
    the relative error (to the tangent's largest entry) a pass allows."""
    d_eps = np.asarray(d_eps, dtype=float)
    stress, tangent, _ = material.update(state, d_eps, params)
    D = mandel_tangent(tangent)
    scale = float(np.max(np.abs(D)))
    h = rel_step * max(float(np.linalg.norm(d_eps)), 1e-6)
    basis = [np.array([[1.0, 0.0], [0.0, 0.0]]), np.array([[0.0, 0.0], [0.0, 1.0]]),
             np.array([[0.0, 1.0], [1.0, 0.0]]) / np.sqrt(2.0)]
    err, worst = 0.0, (0, 0)
    from .tensors import to_mandel
    for b, e in enumerate(basis):
        sp = to_mandel(material.update(state, d_eps + h * e, params)[0])
        sm = to_mandel(material.update(state, d_eps - h * e, params)[0])
        fd = (sp - sm) / (2.0 * h)
        diff = np.abs(fd - D[:, b]) / scale
        a = int(np.argmax(diff))
        if diff[a] > err:
            err, worst = float(diff[a]), (a, b)
    return TangentCheck(err, h, err <= tol, worst, tol)


# a step of the drained path's direction (axial compression, lateral extension): the increment
# ``check_law`` updates the law with, and the direction of its loaded state
CHECK_STEP = np.diag([1e-5, -0.3e-5])
# the loaded state of ``check_law``: this many strain-controlled steps of LOAD_STEP from the
# isotropic state (axial strain 0.5 %: Drucker-Prager's default set yields at 0.03 %, the
# H-model's Table I hexagons slide from the start)
LOAD_STEPS = 10
LOAD_STEP = np.diag([5e-4, -1.5e-4])


def check_law(material: Material, params, tangent: bool = False) -> list:
    """Hold a law to its contract before a command uses it: its isotropic state has ``stress``
    and ``eps`` (2, 2); the first update of the command (``CHECK_STEP`` from it, single point)
    and the same update of a batch of two points pass ``check_update_output``. With ``tangent``:
    ``check_tangent`` at the isotropic state and at a loaded state (``LOAD_STEPS`` steps of
    ``LOAD_STEP``), each for the increment ``CHECK_STEP``. A failure is a MaterialError of one
    line naming the material and what failed. Returns [(where, TangentCheck)] of the tangent's
    checks ([] without ``tangent``)."""
    name = material.name or type(material).__name__
    s0 = material.initial_state(params)
    for f in ("stress", "eps"):
        if np.shape(getattr(s0, f, None)) != (2, 2):
            raise MaterialError(f"material {name}: its isotropic state has no field {f} of shape "
                                "(2, 2) (the contract's state records stress and eps)")
    check_update_output(material, s0, CHECK_STEP, material.update(s0, CHECK_STEP, params))
    two = material.broadcast(s0, (2,))
    d2 = np.stack([CHECK_STEP, 2.0 * CHECK_STEP], axis=-1)
    check_update_output(material, two, d2, material.update(two, d2, params))
    if not tangent:
        return []
    loaded = s0
    for _ in range(LOAD_STEPS):
        loaded = material.update(loaded, LOAD_STEP, params)[2]
    out = []
    for where, st in (("the isotropic state", s0), ("a loaded state", loaded)):
        c = check_tangent(material, st, params, CHECK_STEP)
        if not c.ok:
            raise MaterialError(
                f"material {name}: --check-tangent: the tangent update returns disagrees with "
                f"central differences of its own stress at {where}: relative error {c.error:.3g} "
                f"(Mandel entry {c.worst}, step {c.step:.3g}), allowed <= {c.tol:g}")
        out.append((where, c))
    return out
