"""Model parameters of the 2D DEM (Nicot, Hadda & Darve 2013, section 4).

All values are SI (m, kg, s, N, Pa).  Defaults are the paper's sample:
12,000 disks, radii uniform in [3, 14] mm, kn/D = 32 GPa (D = mean diameter),
kt/kn = 0.42, interparticle friction 35 deg, density 2600 kg/m^3 (not given in
the paper), out-of-plane thickness 1 m.

The grain friction angle is ``phi_g`` (option ``--phi-g``), as in the H-model; files and states
written before it was (``friction_deg``) load all the same (``RENAMED``, ``migrate``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields, asdict


def _real(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _check(name, value, ok, allowed):
    if not ok:
        raise ValueError(f"{name}={value!r} is invalid; allowed range: {allowed}")


@dataclass(frozen=True)
class DemParams:
    """Contact law, sample and numerical parameters (validated on construction).

    Attributes (units):
      n                      number of disks
      r_min, r_max           radius range [m], radii uniform in [r_min, r_max]
      density                grain density [kg/m^3]
      thickness              out-of-plane length of the disks [m]
      kn_over_d              normal stiffness / mean diameter [Pa]; kn = kn_over_d * (r_min + r_max)
      kt_over_kn             tangential / normal stiffness ratio [-]
      phi_g                  grain (interparticle) friction angle [deg], mu = tan(phi_g)
      damping                Cundall non-viscous damping coefficient lambda [-]
      normal_damping_ratio   viscous dashpot in the normal direction as a fraction of the
                             critical damping of the two-disk system [-] (0 = none; used by tests)
      dt_safety              dt = dt_safety * sqrt(m_min / kn) [-]
      skin_factor            Verlet skin = skin_factor * mean diameter [-]
      servo_gain             fraction of the force error corrected per step by the wall servo [-]
      servo_smoothing        weight of the new wall displacement in the smoothed one [-]
      servo_vmax             cap on the wall speed under stress control [m/s]
      seed                   seed of the sample generator
      rolling_friction       mu_r: the rolling moment of a contact is capped at mu_r R* fn,
                             R* = r_i r_j / (r_i + r_j) [-]; 0 = no rolling resistance (the
                             paper's DEM: free rotation)
      rolling_stiffness      k_r = rolling_stiffness * kt * R*^2 [-] (Iwashita & Oda 1998;
                             1 is LIGGGHTS' EPSD2 choice); used only when rolling_friction > 0
    """

    n: int = 12000
    r_min: float = 0.003
    r_max: float = 0.014
    density: float = 2600.0
    thickness: float = 1.0
    kn_over_d: float = 32e9
    kt_over_kn: float = 0.42
    phi_g: float = 35.0
    damping: float = 0.15
    normal_damping_ratio: float = 0.0
    dt_safety: float = 0.2
    skin_factor: float = 0.1
    servo_gain: float = 0.25
    servo_smoothing: float = 0.5
    servo_vmax: float = 0.5
    seed: int = 1
    rolling_friction: float = 0.0
    rolling_stiffness: float = 1.0

    def __post_init__(self):
        _check("n", self.n, isinstance(self.n, (int,)) and self.n >= 1, "integer >= 1")
        _check("r_min", self.r_min, self.r_min > 0 and math.isfinite(self.r_min), "r_min > 0 [m]")
        _check("r_max", self.r_max, self.r_max >= self.r_min and math.isfinite(self.r_max),
               f"r_max >= r_min = {self.r_min} [m]")
        _check("density", self.density, self.density > 0 and math.isfinite(self.density),
               "density > 0 [kg/m^3]")
        _check("thickness", self.thickness, self.thickness > 0 and math.isfinite(self.thickness),
               "thickness > 0 [m]")
        _check("kn_over_d", self.kn_over_d, self.kn_over_d > 0 and math.isfinite(self.kn_over_d),
               "kn_over_d > 0 [Pa]")
        _check("kt_over_kn", self.kt_over_kn, 0 < self.kt_over_kn < math.inf, "kt_over_kn > 0")
        _check("phi_g", self.phi_g, 0 <= self.phi_g < 90, "0 <= phi_g < 90 [deg]")
        _check("damping", self.damping, 0 <= self.damping < 1, "0 <= damping < 1")
        _check("normal_damping_ratio", self.normal_damping_ratio,
               0 <= self.normal_damping_ratio < 1, "0 <= normal_damping_ratio < 1")
        _check("dt_safety", self.dt_safety, 0 < self.dt_safety <= 0.5, "0 < dt_safety <= 0.5")
        _check("skin_factor", self.skin_factor, 0 < self.skin_factor <= 1, "0 < skin_factor <= 1")
        _check("servo_gain", self.servo_gain, 0 < self.servo_gain <= 1, "0 < servo_gain <= 1")
        _check("servo_smoothing", self.servo_smoothing, 0 < self.servo_smoothing <= 1,
               "0 < servo_smoothing <= 1")
        _check("servo_vmax", self.servo_vmax, self.servo_vmax > 0, "servo_vmax > 0 [m/s]")
        _check("seed", self.seed, isinstance(self.seed, int) and self.seed >= 0, "integer >= 0")
        _check("rolling_friction", self.rolling_friction,
               _real(self.rolling_friction) and 0 <= self.rolling_friction < math.inf,
               "0 <= rolling_friction (0 = no rolling resistance)")
        _check("rolling_stiffness", self.rolling_stiffness,
               _real(self.rolling_stiffness) and 0 < self.rolling_stiffness < math.inf,
               "rolling_stiffness > 0")

    # Derived quantities -------------------------------------------------------------
    @property
    def d_mean(self) -> float:
        """Mean diameter of the radius distribution [m]."""
        return self.r_min + self.r_max

    @property
    def kn(self) -> float:
        """Normal contact stiffness [N/m], one value for the whole sample."""
        return self.kn_over_d * self.d_mean

    @property
    def kt(self) -> float:
        """Tangential contact stiffness [N/m]."""
        return self.kt_over_kn * self.kn

    @property
    def mu(self) -> float:
        return math.tan(math.radians(self.phi_g))

    @property
    def skin(self) -> float:
        return self.skin_factor * self.d_mean

    def mass(self, r):
        """Mass [kg] of a disk of radius ``r`` [m] (a number or an array): density pi r^2
        thickness. The one definition: the simulation's masses, the compaction's, the time step."""
        return self.density * math.pi * (r * r) * self.thickness

    def inertia(self, r):
        """Rotational inertia [kg m^2] of a disk of radius ``r`` [m] about its axis: m r^2 / 2
        (a uniform disk)."""
        return 0.5 * self.mass(r) * (r * r)

    @property
    def dt(self) -> float:
        """Time step [s]: a safety fraction of sqrt(m_min / kn) (stiffest contact, lightest disk)."""
        return self.dt_safety * math.sqrt(self.mass(self.r_min) / self.kn)

    def replace(self, **kw) -> "DemParams":
        d = asdict(self)
        d.update(kw)
        return DemParams(**d)

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "DemParams":
        """The parameters of a state or parameter file: every field, nothing else (ValueError
        naming the unknown or missing keys; no default is filled in silently). A key renamed
        since (``RENAMED``) is read under its new name."""
        d = migrate(d)
        names = {f.name for f in fields(cls)}
        unknown, missing = sorted(set(d) - names), sorted(names - set(d))
        if unknown or missing:
            raise ValueError("DEM parameters: "
                             + (f"unknown keys {unknown}" if unknown else "")
                             + ("; " if unknown and missing else "")
                             + (f"missing keys {missing}" if missing else "")
                             + f"; allowed: exactly {sorted(names)}")
        return cls(**d)


# keys of DemParams renamed: former key -> field (parameter files, states, checkpoints)
RENAMED = {"friction_deg": "phi_g"}


def migrate(d: dict) -> dict:
    """A parameter dict (or a parameter file's, with its "units") with its former keys
    (``RENAMED``) under their new names; a dict holding both is left as it is (refused later
    as having an unknown key)."""
    if not isinstance(d, dict) or not any(k in d for k in RENAMED):
        return d
    out = {}
    for k, v in d.items():
        new = RENAMED.get(k)
        out[new if new is not None and new not in d else k] = v
    if isinstance(out.get("units"), dict):
        out["units"] = migrate(out["units"])
    return out


def hashed_dict(params) -> dict:
    """``params.to_dict()`` under the keys of before their renaming (``RENAMED``), in the same
    order: what a fingerprint or a cache key hashes, so that those of runs made before a
    renaming stay valid (a resumed probe sweep, a cached bench sample)."""
    old = {new: old for old, new in RENAMED.items()}
    return {old.get(k, k): v for k, v in params.to_dict().items()}


def _options():
    from common.options import VOCABULARY
    found = {f.split(".", 1)[1]: t.name for t in VOCABULARY.values() for f in t.fields
             if f.startswith("DemParams.")}
    return {found[f.name]: f.name for f in fields(DemParams) if f.name in found}


# The command-line options of the main parameters: option -> field of DemParams (the terms of
# the vocabulary, common.options.VOCABULARY, checked by DemParams)
OPTIONS = _options()

# the unit of every field, as a parameter file records it (common.paramfile)
UNITS = {"n": "-", "r_min": "m", "r_max": "m", "density": "kg/m^3", "thickness": "m",
         "kn_over_d": "Pa", "kt_over_kn": "-", "phi_g": "deg", "damping": "-",
         "normal_damping_ratio": "-", "dt_safety": "-", "skin_factor": "-", "servo_gain": "-",
         "servo_smoothing": "-", "servo_vmax": "m/s", "seed": "-", "rolling_friction": "-",
         "rolling_stiffness": "-"}


def save_params(path, params: DemParams, note: str | None = None) -> None:
    """Write ``params`` as a parameter file (the format of common.paramfile, docs/parameters.md)."""
    from common.paramfile import write_params
    write_params(path, params, "dem", UNITS, note)


def load_params(path, option: str = "--params") -> DemParams:
    """DemParams from a parameter file (as ``python -m dem params`` writes it, or a file of
    every field and nothing else, the format before units); ValueError of one line naming the
    file and the key. A key renamed since (friction_deg: phi_g) is read under its new name."""
    from common.paramfile import read_params
    return read_params(path, DemParams, "dem", UNITS, option=option, migrate=migrate)


def record_params(out_dir, params: DemParams, note: str = "") -> str:
    """Write ``params`` to ``out_dir``/params.json (``--params out_dir/params.json`` repeats the
    run); returns the file name."""
    import os
    save_params(os.path.join(out_dir, "params.json"), params, note)
    return "params.json"


def params_from_args(a) -> DemParams:
    """The parameters of a command: ``a.params`` (a parameter file) or the paper's set, with
    every main-parameter option given on the command line (not None) on top. Sets
    ``a.params_note``, the line of the run's summary that says where the values came from
    ("parameters: the file p.json; --phi-g 30 overrides the file's phi_g 35"). An option out of
    range is one line naming it and its range (DemParams checks it)."""
    from common.paramfile import override
    path = getattr(a, "params", None)
    base = load_params(path) if path else DemParams()
    given = [(o, f, getattr(a, o[2:].replace("-", "_"))) for o, f in OPTIONS.items()
             if getattr(a, o[2:].replace("-", "_"), None) is not None]
    try:
        P, note = override(base, given, f"the file {path}" if path else "the paper's set (defaults)",
                           base.replace)
    except ValueError as e:
        from common.options import record_error
        raise record_error(e, "DemParams") from None
    a.params_note = note
    return P
