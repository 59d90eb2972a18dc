"""The H-model fitted to a measured drained biaxial curve (issue 19, part 2; docs/fit.md): the fit
of any law (``point.fit``: least squares from several starts, the Jacobian's verdicts) with what
is the H-model's own, its ``FitSpace`` (``SPACE``): the parameters a fit may free, their
bounds, and what a drained curve can determine.

What a drained curve can determine (dimensional analysis of the model, docs/hmodel.md): every
length of a hexagon scales with r_g, every contact force with kn r_g (N1 = kn (2 r_g - d1), T1
from kt d1 d alpha), the volume with h r_g^2 (h the slab thickness). The stress (Love-Weber,
Eq. 23) therefore scales with kn r_g r_g / (h r_g^2) = kn / h, and the drained curve is

    q = p0 Q(eps1; kn/(p0 h), kt/kn, phi_g, alpha0),   eps_v = V(eps1; same groups)

(fabric and n_dir fixed). It depends on kn, r_g and h only through kn/h, and with the thickness
given r_g does not enter at all. ``structural_reduction`` keeps the free parameters that move
these groups independently and reports the others as not determined (held at their given
values); tests/hmodel/test_fit.py checks the invariance to round-off.

The names of the fit of any law stay importable from here (``fit_curve``, ``read_curve``, ...:
the same functions as ``point.fit``'s); ``point.cli`` (``python -m hmodel fit``) writes the files.
"""
from __future__ import annotations

from functools import partial

import numpy as np

from point.fit import (MIN_POINTS, Curve, CurveError, FitResult, FitSpace, _covariance,  # noqa: F401
                       _jsonable, _Problem, check_free_bounds, correlation_dict, curve_check,
                       fit_curve, format_result, jacobian, make_curve, model_curve, noise_sd,
                       plot_fit, read_curve, summary_dict)
from point.fit import parse_bounds as _parse_bounds, parse_free as _parse_free

from .params import HParams

__all__ = ["FREE_CHOICES", "DEFAULT_FREE", "LOG_PARAMS", "UNITS", "FD_STEP", "SPACE",
           "MIN_POINTS", "Curve", "CurveError", "read_curve", "make_curve", "parse_free",
           "parse_bounds", "default_bounds", "check_free_bounds", "structural_reduction",
           "groups", "noise_sd", "curve_check", "model_curve", "FitResult", "fit_curve",
           "jacobian", "summary_dict", "correlation_dict", "format_result", "plot_fit"]

# the parameters a fit may free, in the order ``structural_reduction`` keeps them
FREE_CHOICES = ("kn", "kt", "phi_g", "alpha0", "p0", "r_g")
DEFAULT_FREE = ("kn", "kt", "phi_g", "alpha0")
# positive scale parameters, fitted as their logarithm (a factor is what matters for them)
LOG_PARAMS = frozenset({"kn", "kt", "r_g", "p0"})
UNITS = {"kn": "N/m", "kt": "N/m", "phi_g": "deg", "alpha0": "deg", "r_g": "m", "p0": "Pa"}
# central finite-difference steps of the Jacobian in the fitted coordinates: 0.1 % of a scale
# parameter, 0.01 deg of an angle (tests/hmodel/test_fit.py: halving them changes the Jacobian
# by less than 1e-3 of its norm, the model's Newton tolerance is 1e-10 of the stress)
FD_STEP = {"log": 1e-3, "deg": 1e-2}
BOUNDS_TEXT = "x/100 to x*100 of the start for kn, kt, r_g, p0; phi_g 2:60; alpha0 31:70"

# the command line's parsers of --free and --bounds, the H-model's names
parse_free = partial(_parse_free, choices=FREE_CHOICES)
parse_free.__name__ = "parse_free"
parse_bounds = partial(_parse_bounds, choices=FREE_CHOICES)
parse_bounds.__name__ = "parse_bounds"


def default_bounds(name: str, value: float) -> tuple[float, float]:
    """Bounds of a free parameter when none are given: a factor 100 either side of the start
    for kn, kt, r_g, p0; 2-60 deg for phi_g; 31-70 deg for alpha0 (above about 70 deg the
    hexagons open early in the drained path and the model cannot hold the lateral stress)."""
    if name in LOG_PARAMS:
        return value / 100.0, value * 100.0
    return {"phi_g": (2.0, 60.0), "alpha0": (31.0, 70.0)}[name]


def _group_matrix(base: HParams) -> dict:
    """d(groups)/d(fitted coordinates): the groups are ln(kn/(p0 h)), ln(kt/kn), phi_g, alpha0,
    ln p0 (the drained curve depends on nothing else: module docstring); the coordinates are
    ln kn, ln kt, phi_g, alpha0, ln p0, ln r_g. h = 2 r_g unless the thickness is given."""
    r_h = -1.0 if base.thickness is None else 0.0
    return {"kn": (1, -1, 0, 0, 0), "kt": (0, 1, 0, 0, 0), "phi_g": (0, 0, 1, 0, 0),
            "alpha0": (0, 0, 0, 1, 0), "p0": (-1, 0, 0, 0, 1), "r_g": (r_h, 0, 0, 0, 0)}


def structural_reduction(free, base: HParams) -> tuple[tuple, dict]:
    """Split the free parameters into those a drained curve can determine together and those
    it cannot (dimensional analysis, module docstring). Walks ``FREE_CHOICES`` in order and
    keeps a parameter if it moves the groups in a direction the kept ones do not.
    Returns (fitted names, {name: why not determined})."""
    A = _group_matrix(base)
    kept, dropped = [], {}
    for n in FREE_CHOICES:
        if n not in free:
            continue
        M = np.array([A[k] for k in kept + [n]], dtype=float)
        if np.linalg.matrix_rank(M) == len(kept) + 1:
            kept.append(n)
        elif base.thickness is not None and n == "r_g":
            dropped[n] = (f"does not enter the drained curve: with the thickness given (h = "
                          f"{base.thickness:g} m) the stress scales as kn/h, free of r_g "
                          "(dimensional analysis); held at its given value")
        else:
            # the combination of kept parameters that n repeats: M^T c = 0, c[-1] != 0
            c = np.linalg.svd(M.T)[2][-1]
            others = [k for k, ck in zip(kept, c[:-1]) if abs(ck) > 1e-9 * abs(c[-1])]
            dropped[n] = (f"trades off exactly against {', '.join(others)} (free): changed together they "
                          "keep kn/(p0 h), kt/kn, phi_g, alpha0 and p0, and the drained curve with them "
                          "(dimensional analysis); held at its given value")
    return tuple(kept), dropped


def groups(params: HParams) -> dict:
    """The combinations a drained curve determines: kn/h [Pa], kt/kn [-], kn/(p0 h) [-]
    (docs/hmodel.md: about 2500 for Table I), phi_g, alpha0 [deg], p0 [Pa]."""
    return {"kn_over_h": params.kn / params.h, "kt_over_kn": params.kt / params.kn,
            "kn_over_p0h": params.kn / (params.p0 * params.h), "phi_g": params.phi_g,
            "alpha0": params.alpha0, "p0": params.p0}


# the H-model's fit space (``point.fit.FitSpace``): ``HModel.fit_space`` returns it
SPACE = FitSpace(FREE_CHOICES, DEFAULT_FREE, LOG_PARAMS,
                 lambda name, base: default_bounds(name, getattr(base, name)), BOUNDS_TEXT,
                 lambda name: FD_STEP["log"] if name in LOG_PARAMS else FD_STEP["deg"],
                 peak=("phi_g", "alpha0"), reduction=structural_reduction, groups=groups)
