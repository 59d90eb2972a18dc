"""Parameters of the H-microdirectional model (Table I of Nicot, Hadda & Darve 2013)."""
from __future__ import annotations

import argparse
import math
import numbers
from dataclasses import dataclass, field, fields

import numpy as np

from point import params as _pp
from point.contract import ParamError as _ContractParamError, material_named

__all__ = ["HParams", "ParamError", "UNITS", "load_params", "save_params", "add_param_options",
           "params_from", "record_params", "param_option_error", "PARAM_OPTIONS"]

# Grains 2-6 touch when alpha <= 30 deg (l2 = 4 r sin alpha <= 2 r); grains 1-4 when alpha >= 90 deg.
ALPHA0_MIN_DEG = 30.0
ALPHA0_MAX_DEG = 90.0

# the unit of every field, as a parameter file records it (common.paramfile)
UNITS = {"kn": "N/m", "kt": "N/m", "phi_g": "deg", "r_g": "m", "alpha0": "deg", "p0": "Pa",
         "thickness": "m", "n_dir": "-", "fabric_a": "-", "fabric_b": "deg"}


@dataclass(frozen=True)
class HParams:
    """Constitutive parameters, validated on construction.

    Units: SI (N/m for stiffnesses, m for lengths, Pa for stress); angles in degrees.

    Attributes
    ----------
    kn, kt : normal / tangential contact stiffness [N/m] (Table I: 1e6, 0.5e6).
    phi_g : contact friction angle [deg], in (0, 90) (Table I: 20).
    r_g : grain radius [m] (Table I: 1e-3).
    alpha0 : initial opening angle of every hexagon [deg], in (30, 90) (Table I: 42.8).
    p0 : isotropic confining stress of the initial state [Pa] (Table I: 200e3).
    thickness : out-of-plane thickness h of the slab [m]; None means 2 r_g (docs/hmodel.md, the formulation).
    n_dir : number of hexagon orientations theta in [0, pi), at least 8.
    fabric_a, fabric_b : fabric omega(theta) = (1 + a cos 2(theta - b)) / n_dir, |a| < 1, b in deg.
    """

    kn: float = 1.0e6
    kt: float = 0.5e6
    phi_g: float = 20.0
    r_g: float = 1.0e-3
    alpha0: float = 42.8
    p0: float = 200.0e3
    thickness: float | None = None
    n_dir: int = 180
    fabric_a: float = 0.0
    fabric_b: float = 0.0
    _h: float = field(init=False, repr=False, compare=False, default=0.0)

    # what a field's None stands for (the options' help: "null (2 r_g)")
    none_means = {"thickness": "2 r_g"}

    def __post_init__(self):
        for f in fields(self):
            if f.name.startswith("_"):
                continue
            v = getattr(self, f.name)
            if v is None:
                continue
            # a real number, not a string that float() would read ('1e6') nor a bool
            if isinstance(v, (bool, np.bool_)) or not isinstance(v, numbers.Real):
                raise ParamError(f.name, v, "a real number", f"HParams.{f.name} must be a real "
                                 f"number, got {v!r} ({type(v).__name__})")
            if not math.isfinite(float(v)):
                raise ParamError(f.name, v, "a finite number", f"HParams.{f.name} must be finite, got {v!r}")
        _check(self.kn > 0, "kn", "kn > 0 [N/m]", self.kn)
        _check(self.kt >= 0, "kt", "kt >= 0 [N/m]", self.kt)
        _check(0.0 < self.phi_g < 90.0, "phi_g", "0 < phi_g < 90 [deg]", self.phi_g)
        _check(self.r_g > 0, "r_g", "r_g > 0 [m]", self.r_g)
        _check(ALPHA0_MIN_DEG < self.alpha0 < ALPHA0_MAX_DEG, "alpha0",
               f"{ALPHA0_MIN_DEG:g} < alpha0 < {ALPHA0_MAX_DEG:g} [deg] (hexagon geometry)", self.alpha0)
        _check(self.p0 > 0, "p0", "p0 > 0 [Pa]", self.p0)
        if self.thickness is not None:
            _check(self.thickness > 0, "thickness", "thickness > 0 [m] (or None for 2 r_g)", self.thickness)
        _check(float(self.n_dir) == int(self.n_dir) and int(self.n_dir) >= 8, "n_dir",
               "an integer n_dir >= 8", self.n_dir)
        _check(abs(self.fabric_a) < 1.0, "fabric_a", "-1 < fabric_a < 1 (omega > 0)", self.fabric_a)
        object.__setattr__(self, "n_dir", int(self.n_dir))
        object.__setattr__(self, "_h", float(self.thickness) if self.thickness is not None else 2.0 * self.r_g)

    # -- derived quantities -------------------------------------------------------------
    @property
    def h(self) -> float:
        """Out-of-plane thickness actually used [m]."""
        return self._h

    @property
    def mu(self) -> float:
        """Contact friction coefficient tan(phi_g)."""
        return math.tan(math.radians(self.phi_g))

    @property
    def theta(self) -> np.ndarray:
        """Hexagon orientations theta_i = i pi / n_dir [rad], shape (n_dir,)."""
        return np.pi * np.arange(self.n_dir) / self.n_dir

    @property
    def omega(self) -> np.ndarray:
        """Fabric weights omega_i (sum 1), shape (n_dir,)."""
        w = 1.0 + self.fabric_a * np.cos(2.0 * (self.theta - math.radians(self.fabric_b)))
        return w / self.n_dir

    @property
    def state_key(self) -> tuple:
        """The constants the update uses (kn, kt, phi_g, r_g, n_dir, fabric_a, fabric_b): a state
        carries the key of the parameters it was made with (``HState.params_key``). p0, alpha0
        and the thickness only shape the initial state and its volume, which the state holds."""
        return (float(self.kn), float(self.kt), float(self.phi_g), float(self.r_g), int(self.n_dir),
                float(self.fabric_a), float(self.fabric_b))

    def replace(self, **changes) -> "HParams":
        """A copy with some fields changed (validated again)."""
        kw = {f.name: getattr(self, f.name) for f in fields(self) if not f.name.startswith("_")}
        kw.update(changes)
        return HParams(**kw)


class ParamError(_ContractParamError):
    """An HParams field out of range: ``name`` (the field), ``value``, ``allowed`` (the range, as
    text), so that a command line can name its own option instead of the field (the contract's
    ``point.ParamError`` of this record: a command line of any law catches it so)."""

    def __init__(self, name, value, allowed, message=None):
        super().__init__(name, value, allowed, message, record="HParams")


def _check(ok, name, allowed, value):
    if not ok:
        raise ParamError(name, value, allowed)


# -- the parameter file and the command-line options: those of any law (``point.params``), for
# the H-model alone
def _law():
    return material_named("hmodel")


def save_params(path, params: HParams, note: str | None = None) -> None:
    """Write ``params`` as a parameter file (docs/parameters.md; ``thickness`` null: 2 r_g)."""
    _pp.save_params(path, params, note)


def load_params(path, option: str = "--params") -> HParams:
    """The HParams of a parameter file; ValueError of one line naming the file and the key."""
    return _pp.load_params(path, option, law=_law())


def param_option_error(e, options=None):
    """The OptionError of an HParams ``ParamError`` ``e``, naming the command-line option of the
    field (``--phi-g`` for phi_g, ``--sigma2`` for p0, or ``options[field]``)."""
    return _pp.param_option_error(e, "HParams", options)


# the options of the HParams fields (p0 is the confining stress of a test: --sigma2)
PARAM_OPTIONS = _pp.record_options("HParams")


def add_param_options(ap: argparse.ArgumentParser, file_note: str | None = None):
    """--params FILE (``file_note``: what file it takes, default the H-model's) and an option
    for every HParams field but p0 (the commands' --sigma2), all None unless given: the file (or
    Table I) supplies the rest (``params_from``), HParams checks them."""
    _pp.add_param_options(ap, _law(), file_note=file_note)


def params_from(args, p0=None, base=None):
    """The HParams of a command: the --params file (or Table I; ``base``: the file's record
    already read), then the options given on top (``point.params.params_from`` of the H-model:
    it sets ``args.params_note``)."""
    return _pp.params_from(args, _law(), p0, base=base)


record_params = _pp.record_params
