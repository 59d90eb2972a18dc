"""The calibration's command-line values (``dem.calibrate``): the DemParams fields that may be
varied and their names on the command line (``--vary``, ``--bounds``), the seeds (``--seeds``,
``--check-seeds``); each a parser raising ValueError and its argparse type."""
from __future__ import annotations

import dataclasses
import math

from common.options import argtype

from ..params import OPTIONS, RENAMED, DemParams

DEFAULT_VARY = "kn_over_d,phi_g,rolling_friction"
# float fields that are numerical settings, not material parameters: never calibrated
NUMERICAL = ("thickness", "damping", "normal_damping_ratio", "dt_safety", "skin_factor",
             "servo_gain", "servo_smoothing", "servo_vmax")


# -- the parameters that are varied ----------------------------------------------------------
def calibratable_fields():
    """The float fields of DemParams that may be calibrated (this version's)."""
    return [f.name for f in dataclasses.fields(DemParams)
            if f.type in ("float", float) and f.name not in NUMERICAL]


def _aliases():
    """Command-line names of fields (``kn-over-d`` -> ``kn_over_d``, from dem.params.OPTIONS)."""
    return {o[2:].replace("-", "_"): f for o, f in OPTIONS.items()}


def _allowed_text():
    inv = {f: a for a, f in _aliases().items() if a != f}
    return ", ".join(f"{inv[f]} ({f})" if f in inv else f for f in calibratable_fields())


def resolve_field(name):
    """The DemParams field of a --vary / --bounds name; ValueError (no option prefix) if none."""
    f = _aliases().get(name, name)
    if f in calibratable_fields():
        return f
    new = {"friction": "phi_g", **RENAMED}.get(name)
    if new is not None:
        raise ValueError(f"{name}: renamed {new} (as the option --phi-g): did you mean {new}?")
    names = {x.name for x in dataclasses.fields(DemParams)}
    why = ("is not a float material parameter of DemParams (an integer or a numerical setting)"
           if f in names else "is not a field of DemParams in this version")
    raise ValueError(f"{name} {why}; allowed: {_allowed_text()}")


def parse_vary(text):
    """Tuple of DemParams fields of a comma-separated --vary list; ValueError without the
    option prefix (``vary_type`` adds it through argparse)."""
    names = [s.strip() for s in str(text).split(",") if s.strip()]
    if not names:
        raise ValueError(f"{text!r}: allowed one or more comma-separated names of "
                         f"{_allowed_text()}")
    out = []
    for s in names:
        try:
            f = resolve_field(s)
        except ValueError as e:
            if str(text) == DEFAULT_VARY:
                raise ValueError(f"{e} (in the default --vary {DEFAULT_VARY}; give --vary "
                                 "with the fields of this version)") from None
            raise
        if f in out:
            raise ValueError(f"{text}: {s} is given twice; allowed distinct names")
        out.append(f)
    return tuple(out)


# argparse type of --vary
vary_type = argtype(parse_vary, "vary_type")


def parse_bounds(value):
    """{field: (lo, hi)} of --bounds: text NAME=LO:HI[,NAME=LO:HI...] or a mapping {name: (lo,
    hi)} (names as --vary takes them); ValueError without the option prefix (``bounds_type``
    adds it through argparse, ``CalibrationOptions`` itself): the one rule of both."""
    if isinstance(value, str):
        items = []
        for item in [s.strip() for s in value.split(",") if s.strip()]:
            try:
                name, rng = item.split("=")
                lo, hi = (float(v) for v in rng.split(":"))
            except ValueError:
                raise ValueError(f"{item!r}: allowed NAME=LO:HI, e.g. kn_over_d=2e9:32e9") from None
            items.append((name.strip(), lo, hi, item))
        if not items:
            raise ValueError(f"{value!r}: allowed NAME=LO:HI[,NAME=LO:HI...]")
    else:
        try:
            items = [(str(k), float(lo), float(hi), f"{k}={lo}:{hi}")
                     for k, (lo, hi) in dict(value).items()]
        except (TypeError, ValueError):
            raise ValueError(f"{value!r}: allowed {{NAME: (LO, HI)}}, e.g. "
                             "{'kn_over_d': (2e9, 32e9)}") from None
    out = {}
    for name, lo, hi, item in items:
        f = resolve_field(name)
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ValueError(f"{item}: allowed finite LO < HI")
        out[f] = (lo, hi)
    return out


# argparse type of --bounds NAME=LO:HI[,NAME=LO:HI...] -> {field: (lo, hi)}
bounds_type = argtype(parse_bounds, "bounds_type")


def parse_seeds(text):
    """Tuple of distinct integer seeds >= 0 of a comma-separated list (ValueError otherwise)."""
    try:
        out = tuple(int(s) for s in str(text).split(",") if s.strip())
    except ValueError:
        out = ()
    if not out or any(s < 0 for s in out) or len(set(out)) != len(out):
        raise ValueError(f"{text!r}: allowed distinct integers >= 0, comma-separated (e.g. 1,2)")
    return out


# argparse type of --seeds and --check-seeds
seeds_type = argtype(parse_seeds, "seeds_type")
