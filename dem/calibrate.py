"""Calibration of DEM parameters against the H-model's drained biaxial test (issue 12 §3).

The paper says its DEM parameters "were calibrated to fit with the results obtained with the
H-microdirectional model over the drained biaxial test under 200 kPa".  ``python -m dem
calibrate`` does that fit: it varies chosen float fields of ``DemParams`` so that the DEM's
drained biaxial test (``dem.experiment.run_biaxial``: a seeded compaction of the sample with its
own parameters, then the test at constant axial strain rate, lateral walls at the confining
stress) matches the H-model's (Table I, ``hmodel.driver``) in three figures:

  peak q                                   within TOLERANCES["peak_q"]    (5 %)
  eps1 at the peak                         within TOLERANCES["eps1_peak"] (25 %)
  secant modulus (q - q0) / eps1 at 0.25 % within TOLERANCES["secant"]    (20 %)

(``curve_figures``: the peak of q smoothed over a strain window ``smooth``; the secant by
linear interpolation of the raw q; relative errors ``dem / hmodel - 1``).

Search (``pattern_search``, deterministic): every varied parameter is mapped onto u in [0, 1]
over its range (``Space``: logarithmic for stiffness-like fields, linear otherwise; values
rounded to 4 significant digits).  The start set (the paper's, or --params) is evaluated first,
then a full grid of ``grid`` points per parameter, then a compass search around the best point:
+- h along each axis (h = half the grid spacing), moving to a better point or halving h, until
the best point meets every target, h < ``min_step`` or ``max_evals`` evaluations were made.
Every batch is a set of independent runs (one thread each) spread over local processes or a dask
cluster (``dem.probes._map``); the search only decides once a whole batch is in and breaks ties
by evaluation order, so the result does not depend on where or in which order the runs finished.
Ranking: a set meeting all three targets first, then the smaller score sum((err_i / tol_i)^2).

Checkpoint: DIR/evaluations.jsonl, a header line (the options that define the search) and one
line per finished evaluation (its parameters, curve and figures).  ``resume=True`` re-drives the
same deterministic search and takes every evaluation already there (and any finished in
DIR/work/ but not yet logged) instead of running it; an evaluation interrupted half-way
continues from its run_biaxial checkpoint in DIR/work/<key>/.  A folder made with other options
is refused.
"""
from __future__ import annotations

import argparse
import dataclasses
import hashlib
import itertools
import json
import math
import os
import shutil
import sys
import tempfile
import time

import numpy as np

from .params import OPTIONS, DemParams, record_params, save_params

TOLERANCES = {"peak_q": 0.05, "eps1_peak": 0.25, "secant": 0.20}
FIGURE_TEXT = {"peak_q": "peak q", "eps1_peak": "eps1 at the peak",
               "secant": "secant modulus q/eps1 at eps1 = 0.25 %"}
SECANT_STRAIN = 0.0025
TARGETS = ("hmodel",)
DEFAULT_VARY = "kn_over_d,friction,rolling_friction"
# float fields that are numerical settings, not material parameters: never calibrated
NUMERICAL = ("thickness", "damping", "normal_damping_ratio", "dt_safety", "skin_factor",
             "servo_gain", "servo_smoothing", "servo_vmax")
# default search range (lo, hi, logarithmic) of the usual fields
DEFAULT_BOUNDS = {"kn_over_d": (2e9, 32e9, True), "friction_deg": (20.0, 50.0, False),
                  "kt_over_kn": (0.2, 1.0, False), "rolling_friction": (0.0, 0.3, False),
                  "rolling_stiffness": (0.25, 4.0, True)}
LOG_FIELDS = ("kn_over_d", "rolling_stiffness", "r_min", "r_max", "density")
# options of the header that may differ on --resume (they do not change the search)
RESUME_FREE = ("max_evals",)
FORMAT = "dem-calibration"
FORMAT_VERSION = 1
CSV_FIXED = ["peak_q", "eps1_peak", "secant", "err_peak_q", "err_eps1_peak", "err_secant",
             "met_peak_q", "met_eps1_peak", "met_secant", "met", "score", "past_peak",
             "peak_q_raw", "porosity", "steps", "wall_time"]


# -- the three figures of a curve ----------------------------------------------------------------
def smoothed(eps1, q, window):
    """q averaged over eps1 in [e - window/2, e + window/2] at every point (window 0: q)."""
    e = np.asarray(eps1, float)
    q = np.asarray(q, float)
    if window <= 0 or len(q) < 3:
        return q.copy()
    c = np.concatenate([[0.0], np.cumsum(q)])
    half = 0.5 * window * (1 + 1e-6)       # points on the window's edges count on both sides
    lo = np.searchsorted(e, e - half, side="left")
    hi = np.searchsorted(e, e + half, side="right")
    return (c[hi] - c[lo]) / (hi - lo)


def curve_figures(eps1, q, smooth=0.001, secant_strain=SECANT_STRAIN) -> dict:
    """peak_q and eps1_peak (the maximum of q smoothed over the strain window ``smooth``),
    peak_q_raw (max q), secant = (q(secant_strain) - q(0)) / (secant_strain - eps1(0)) with q
    interpolated linearly on the raw curve.  eps1 must increase; ValueError if the curve stops
    before ``secant_strain``."""
    e = np.asarray(eps1, float)
    q = np.asarray(q, float)
    if len(e) < 2 or not np.all(np.diff(e) > 0):
        raise ValueError("curve_figures: eps1 must be increasing, at least 2 points")
    if e[-1] < secant_strain:
        raise ValueError(f"curve_figures: the curve stops at eps1 = {e[-1]:.4g}, before the "
                         f"secant strain {secant_strain:g}")
    qs = smoothed(e, q, smooth)
    i = int(np.argmax(qs))
    sec = (float(np.interp(secant_strain, e, q)) - q[0]) / (secant_strain - e[0])
    return {"peak_q": float(qs[i]), "eps1_peak": float(e[i]), "secant": float(sec),
            "peak_q_raw": float(np.max(q))}


def compare(fig, target) -> dict:
    """Relative errors err_X = fig/target - 1, met_X = |err_X| <= TOLERANCES[X], met (all)
    and score = sum((err_X / tol_X)^2)."""
    out = {}
    for k, tol in TOLERANCES.items():
        err = fig[k] / target[k] - 1.0
        out["err_" + k] = float(err)
        out["met_" + k] = bool(abs(err) <= tol)
    out["met"] = all(out["met_" + k] for k in TOLERANCES)
    out["score"] = float(sum((out["err_" + k] / t) ** 2 for k, t in TOLERANCES.items()))
    return out


def rank(rec):
    """Sort key of an evaluation: meets every target first, then the score, then its order."""
    return (not rec["met"], rec["score"], rec["index"])


# -- the H-model's curve ----------------------------------------------------------------------
HMODEL_EPS_MIN = 0.05      # the H-model's curve runs at least this far (its peak: 2.09 %)


def hmodel_curve(confining=200e3, eps_max=0.035, d_eps1=1e-5):
    """The H-model's drained biaxial test (Table I parameters, p0 = confining) to
    max(eps_max, HMODEL_EPS_MIN), so that it is past its peak whatever the DEM's eps_max:
    dict of eps1, q, eps_v, p lists."""
    eps_max = max(eps_max, HMODEL_EPS_MIN)
    from hmodel.driver import MixedControlError, drained_biaxial, isotropic_state, run_path
    from hmodel.params import HParams
    P = HParams(p0=float(confining))
    n = int(math.ceil(eps_max / d_eps1))
    try:
        r = run_path(isotropic_state(P), P, drained_biaxial(d_eps1), n)
    except MixedControlError as e:      # softening past what the driver can follow: keep it
        r = e.partial
    s1, s2 = r.sigma[:, 0], r.sigma[:, 1]
    return {"eps1": r.eps[:, 0].tolist(), "q": (s1 - s2).tolist(),
            "eps_v": (r.eps[:, 0] + r.eps[:, 1]).tolist(), "p": (0.5 * (s1 + s2)).tolist()}


# -- the parameters that are varied ----------------------------------------------------------
def calibratable_fields():
    """The float fields of DemParams that may be calibrated (this version's)."""
    return [f.name for f in dataclasses.fields(DemParams)
            if f.type in ("float", float) and f.name not in NUMERICAL]


def _aliases():
    """Command-line names of fields (``friction`` -> ``friction_deg``, from dem.params.OPTIONS)."""
    return {o[2:].replace("-", "_"): f for o, f in OPTIONS.items()}


def _allowed_text():
    inv = {f: a for a, f in _aliases().items() if a != f}
    return ", ".join(f"{inv[f]} ({f})" if f in inv else f for f in calibratable_fields())


def resolve_field(name):
    """The DemParams field of a --vary / --bounds name; ValueError (no option prefix) if none."""
    f = _aliases().get(name, name)
    if f in calibratable_fields():
        return f
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


def vary_type(text):
    """argparse type of --vary."""
    try:
        return parse_vary(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def bounds_type(text):
    """argparse type of --bounds NAME=LO:HI[,NAME=LO:HI...] -> {field: (lo, hi)}."""
    out = {}
    for item in [s.strip() for s in text.split(",") if s.strip()]:
        try:
            name, rng = item.split("=")
            lo, hi = (float(v) for v in rng.split(":"))
        except ValueError:
            raise argparse.ArgumentTypeError(f"{item!r}: allowed NAME=LO:HI, e.g. "
                                             "kn_over_d=2e9:32e9") from None
        try:
            f = resolve_field(name.strip())
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e)) from None
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise argparse.ArgumentTypeError(f"{item}: allowed finite LO < HI")
        out[f] = (lo, hi)
    if not out:
        raise argparse.ArgumentTypeError(f"{text!r}: allowed NAME=LO:HI[,NAME=LO:HI...]")
    return out


def _round(v):
    return float(f"{v:.4g}")


@dataclasses.dataclass(frozen=True)
class Space:
    """The varied fields, their ranges [lo, hi] and scales; u in [0, 1]^d <-> values."""
    names: tuple
    lo: tuple
    hi: tuple
    log: tuple

    def values(self, u):
        out = []
        for j, x in enumerate(u):
            a, b = self.lo[j], self.hi[j]
            x = min(max(float(x), 0.0), 1.0)
            v = a * (b / a) ** x if self.log[j] else a + (b - a) * x
            out.append(min(max(_round(v), a), b))
        return tuple(out)

    def u_of(self, values):
        """u of values inside the ranges, or None."""
        u = []
        for j, v in enumerate(values):
            a, b = self.lo[j], self.hi[j]
            if not a <= v <= b:
                return None
            u.append(math.log(v / a) / math.log(b / a) if self.log[j] else (v - a) / (b - a))
        return tuple(u)

    def params(self, base: DemParams, values) -> DemParams:
        return base.replace(**dict(zip(self.names, values)))


def make_space(vary, base: DemParams, bounds=None) -> Space:
    """The search space of the fields ``vary`` (ValueError naming --bounds when a range is
    missing, or gives parameters DemParams refuses)."""
    bounds = dict(bounds or {})
    extra = sorted(set(bounds) - set(vary))
    if extra:
        raise ValueError(f"--bounds {', '.join(extra)}: not in --vary {','.join(vary)}; allowed "
                         "ranges of the varied parameters only")
    lo, hi, log = [], [], []
    for f in vary:
        if f in bounds:
            a, b = bounds[f]
            lg = f in LOG_FIELDS and a > 0
        elif f in DEFAULT_BOUNDS:
            a, b, lg = DEFAULT_BOUNDS[f]
        else:
            v = getattr(base, f)
            if not v > 0:
                raise ValueError(f"--bounds: {f} has no default range (its start value is {v}); "
                                 f"allowed: give one, e.g. --bounds {f}=LO:HI")
            a, b, lg = 0.5 * v, 2.0 * v, True
        for x in (a, b):
            try:
                base.replace(**{f: x})
            except ValueError as e:
                raise ValueError(f"--bounds {f}={a:g}:{b:g}: {e}") from None
        lo.append(float(a)); hi.append(float(b)); log.append(bool(lg))
    return Space(tuple(vary), tuple(lo), tuple(hi), tuple(log))


# -- the search ---------------------------------------------------------------------------------
def pattern_search(space: Space, evaluate, start=None, grid=3, min_step=1 / 16, max_evals=60):
    """Deterministic grid + compass search (module docstring).

    ``evaluate(list of value tuples, stage) -> list of records`` (dicts with at least met, score,
    index), called once per batch with the points not evaluated yet.  ``start``: the value
    tuple evaluated first (the start set; inside the ranges or not).  Returns (best record,
    {values: record}, trace, why it stopped)."""
    if grid < 2:
        raise ValueError(f"grid={grid!r}; allowed an integer >= 2")
    seen = {}
    trace = []
    state = {"full": False}

    def batch(points, stage):
        todo = []
        for v in points:
            if v not in seen and v not in todo:
                todo.append(v)
        room = max_evals - len(seen)
        if len(todo) > room:
            todo, state["full"] = todo[:max(room, 0)], True
        recs = evaluate(todo, stage) if todo else []
        seen.update(zip(todo, recs))
        trace.append({"stage": stage, "points": len(points), "evaluated": len(todo)})

    def best(inside=False):
        pool = [(v, r) for v, r in seen.items() if not inside or space.u_of(v) is not None]
        return min(pool, key=lambda vr: rank(vr[1])) if pool else (None, None)

    if start is not None:
        batch([tuple(start)], "start")
    axes = [[i / (grid - 1) for i in range(grid)]] * len(space.names)
    if not state["full"]:
        batch([space.values(u) for u in itertools.product(*axes)], "grid")
    h = 0.5 / (grid - 1)
    k = 0
    why = None
    while True:
        if best()[1]["met"]:
            why = "targets met"
            break
        if state["full"] or len(seen) >= max_evals:
            why = "max_evals reached"
            break
        if h < min_step * (1 - 1e-9):
            why = f"step {h:.4g} below min_step {min_step:g}"
            break
        k += 1
        cv, cr = best(inside=True)
        cu = space.u_of(cv)
        pts = []
        for j in range(len(cu)):
            for s in (-1.0, 1.0):
                u = list(cu)
                u[j] = min(max(u[j] + s * h, 0.0), 1.0)
                pts.append(space.values(u))
        batch(pts, f"refine{k}")
        trace[-1]["step"] = h
        _, nr = best(inside=True)
        if rank(nr) >= rank(cr):
            h *= 0.5
    return best()[1], seen, trace, why


# -- one evaluation (runs in a worker) ----------------------------------------------------------
def params_key(d: dict) -> str:
    return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:16]


def _evaluate_task(a):
    """One DEM evaluation: compaction + drained biaxial test of a["params"] on one thread.
    In a["work_dir"] (local runs: resumable, result.json written there when done) or in a
    temporary folder (dask workers); returns the curve and the run's figures."""
    from . import threads
    from .experiment import run_biaxial
    old = threads._default
    threads.set_default_threads(1)
    tmp = None
    try:
        wd = a["work_dir"]
        if wd is None:
            wd = tmp = tempfile.mkdtemp(prefix="dem-calibrate-")
        params = DemParams.from_dict(a["params"])
        res = run_biaxial(params, wd, rate=a["rate"], confining=a["confining"],
                          eps_max=a["eps_max"], post_peak_strain=a["post_peak_strain"],
                          resume=a["resume"], verbose=False, figures=False, vtk=False,
                          save_fractions=())
        rows = np.asarray(res.rows, float)
        with open(os.path.join(wd, "summary.json")) as f:
            comp = json.load(f).get("compaction", {})
        out = {"key": a["key"], "params": a["params"],
               "curve": {"eps1": rows[:, 2].tolist(), "q": rows[:, 8].tolist(),
                         "eps_v": rows[:, 4].tolist(), "p": rows[:, 7].tolist()},
               "porosity": comp.get("porosity"), "compaction_converged": comp.get("converged"),
               "steps": int(rows[-1, 0]), "wall_time": float(res.wall_time)}
        if tmp is None:
            from .io import atomic_write_bytes
            atomic_write_bytes(os.path.join(wd, "result.json"), json.dumps(out).encode())
            for name in os.listdir(wd):          # the run's files are not needed any more
                p = os.path.join(wd, name)
                if name != "result.json":
                    shutil.rmtree(p) if os.path.isdir(p) else os.unlink(p)
        return out
    finally:
        threads._default = old
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)


def _past_peak(curve, post_peak_strain):
    """The run went past its peak: it stopped by run_biaxial's post-peak rule (post_peak_strain
    after the raw maximum with q below 0.98 of it), not at eps_max."""
    e, q = np.asarray(curve["eps1"]), np.asarray(curve["q"])
    i = int(np.argmax(q))
    return bool(e[-1] >= e[i] + post_peak_strain and q[-1] < 0.98 * q[i])


# -- the command --------------------------------------------------------------------------------
def _header(target, space, base, grid, min_step, max_evals, rate, confining, eps_max,
            post_peak_strain, smooth):
    return {"format": FORMAT, "format_version": FORMAT_VERSION, "target": target,
            "n": base.n, "seed": base.seed, "vary": list(space.names),
            "bounds": {f: [a, b, "log" if lg else "linear"]
                       for f, a, b, lg in zip(space.names, space.lo, space.hi, space.log)},
            "grid": grid, "min_step": min_step, "max_evals": max_evals, "rate": rate,
            "confining": confining, "eps_max": eps_max, "post_peak_strain": post_peak_strain,
            "smooth": smooth, "secant_strain": SECANT_STRAIN, "tolerances": TOLERANCES,
            "start_params": base.to_dict()}


def current_params(d: dict) -> dict:
    """A parameter dict written by an earlier version, with the DemParams fields added since at
    their defaults (a new field's default keeps the earlier behaviour, e.g. rolling_friction 0 =
    free rotation), so that a checkpoint made before a field existed still matches."""
    missing = {f.name: f.default for f in dataclasses.fields(DemParams) if f.name not in d}
    return {**missing, **d}


def read_checkpoint(path, header):
    """{key: record} of the finished evaluations of ``path`` made with the same options
    (ValueError naming what differs otherwise); a torn last line is dropped.  Parameters of
    the file are read with ``current_params``."""
    if not os.path.exists(path):
        return {}
    with open(path) as f:
        lines = f.read().split("\n")
    try:
        head = json.loads(lines[0])["header"]
    except (ValueError, KeyError, TypeError):
        raise ValueError(f"--resume: {path} is not a calibration checkpoint; allowed another "
                         "--out") from None
    if isinstance(head.get("start_params"), dict):
        head["start_params"] = current_params(head["start_params"])
    diff = [k for k in sorted(set(head) | set(header))
            if k not in RESUME_FREE and head.get(k) != header.get(k)]
    if diff:
        what = [f"{k}: {head.get(k)!r} there, {header.get(k)!r} now" for k in diff
                if k != "start_params"]
        if "start_params" in diff:
            more = _param_diff(head.get("start_params"), header.get("start_params"),
                               skip=("n", "seed"))
            if more:
                what.append("start parameters " + more)
        raise ValueError(f"--resume: {os.path.dirname(path) or '.'} was made with other options "
                         f"({'; '.join(what)}); allowed the same options (only --max-evals, "
                         "--workers, --scheduler may change), or another --out")
    done = {}
    for line in lines[1:]:
        try:
            rec = json.loads(line)
        except ValueError:
            continue
        if isinstance(rec, dict) and "key" in rec and "curve" in rec:
            rec["params"] = current_params(rec["params"])
            rec["key"] = params_key(rec["params"])
            done[rec["key"]] = rec
    return done


def _param_diff(a, b, skip=()):
    a, b = a or {}, b or {}
    return ", ".join(f"{k}: {a.get(k)!r} there, {b.get(k)!r} now"
                     for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k) and k not in skip)


def _fmt_values(names, values):
    return ", ".join(f"{n}={v:.4g}" for n, v in zip(names, values))


def _fmt_figs(rec, target):
    return (f"peak q = {rec['peak_q'] / 1e3:.1f} kPa ({rec['err_peak_q']:+.1%}), eps1 at the "
            f"peak = {100 * rec['eps1_peak']:.2f} % ({rec['err_eps1_peak']:+.1%}"
            f"{'' if rec.get('past_peak', True) else ', not past the peak'}), secant = "
            f"{rec['secant'] / 1e6:.1f} MPa ({rec['err_secant']:+.1%})")


def run_calibration(out_dir, base: DemParams, vary, bounds=None, target="hmodel", grid=3,
                    min_step=1 / 16, max_evals=60, rate=0.01, confining=200e3, eps_max=0.035,
                    post_peak_strain=0.01, smooth=0.001, workers=None, scheduler=None,
                    resume=False, verbose=True, task=None, stage=None, params_note=None):
    """Fit the fields ``vary`` of ``base`` (the start set) to the target's drained biaxial test
    (module docstring).  Writes out_dir/evaluations.jsonl (checkpoint), calibration.csv,
    params.json (a parameter file: the start set ``base``; ``params_note`` says where it came
    from), calibrated.json (a parameter file: the best set), curves.csv, calibration.png,
    calibration_search.png and summary.json; returns the summary.  ``task``: the evaluation
    function (default: the DEM run ``_evaluate_task``; tests pass a cheap one).  ``stage``: an
    ``hmodel.options.Stage`` told where the run is and what it has written (for the line of an
    interrupted command)."""
    t0 = time.time()
    if target not in TARGETS:
        raise ValueError(f"--target {target!r}; allowed: {', '.join(TARGETS)}")
    vary = tuple(resolve_field(v) for v in vary)
    for name, val, ok, rng in (
            ("--grid", grid, isinstance(grid, int) and 2 <= grid <= 9, "an integer in [2, 9]"),
            ("--min-step", min_step, 0 < min_step <= 0.5, "0 < value <= 0.5"),
            ("--max-evals", max_evals, isinstance(max_evals, int) and max_evals >= 1,
             "an integer >= 1"),
            ("--rate", rate, rate > 0, "value > 0 [1/s]"),
            ("--confining", confining, confining > 0, "value > 0 [Pa]"),
            ("--eps-max", eps_max, 2 * SECANT_STRAIN <= eps_max < 0.5,
             f"{2 * SECANT_STRAIN:g} <= value < 0.5"),
            ("--post-peak-strain", post_peak_strain, 0 < post_peak_strain < eps_max,
             "0 < value < --eps-max"),
            ("--smooth", smooth, 0 <= smooth < 0.05, "0 <= value < 0.05")):
        if not ok or (isinstance(val, float) and not math.isfinite(val)):
            raise ValueError(f"{name} {val!r}: allowed {rng}")
    space = make_space(vary, base, bounds)
    header = _header(target, space, base, grid, min_step, max_evals, rate, confining, eps_max,
                     post_peak_strain, smooth)
    ck = os.path.join(out_dir, "evaluations.jsonl")
    work = os.path.join(out_dir, "work")
    done = read_checkpoint(ck, header) if resume else {}
    th = time.time()
    hcurve = hmodel_curve(confining, eps_max)
    # the H-model's curve is smooth (1e-5 strain steps): its figures are taken raw, as
    # quoted in the issue (2.09 %); the moving average is for the DEM's noise only
    hfig = curve_figures(hcurve["eps1"], hcurve["q"], 0.0)
    if hfig["eps1_peak"] >= 0.98 * hcurve["eps1"][-1]:
        raise RuntimeError(f"the {target}'s curve has no peak before eps1 = "
                           f"{hcurve['eps1'][-1]:g} at --confining {confining:g}")
    _say(verbose, f"[calibrate] target {target}: peak q = {hfig['peak_q'] / 1e3:.1f} kPa at eps1 = "
                  f"{100 * hfig['eps1_peak']:.2f} %, secant at {100 * SECANT_STRAIN:g} % = "
                  f"{hfig['secant'] / 1e6:.1f} MPa ({time.time() - th:.1f} s)")
    # -- from here on, files are written
    from . import io
    os.makedirs(out_dir, exist_ok=True)
    record_params(out_dir, base, "python -m dem calibrate: the start set (the best set is "
                  "calibrated.json)" + (f"; {params_note}" if params_note else ""))
    if not resume and os.path.exists(ck):
        os.replace(ck, os.path.join(out_dir, "evaluations.previous.jsonl"))
        _say(verbose, f"[calibrate] {out_dir} held an earlier calibration: moved to "
                      "evaluations.previous.jsonl (--resume continues one)")
    io.atomic_write_bytes(ck, ("\n".join([json.dumps({"header": header})]
                                         + [json.dumps(r) for r in done.values()]) + "\n").encode())
    if done:
        _say(verbose, f"[calibrate] --resume: {len(done)} finished evaluations in {ck} "
                      "(not run again)")
    records = []            # in search order
    counts = {"run": 0, "taken": 0}
    sink = open(ck, "a")
    task = task or _evaluate_task
    where = stage

    def finish(rec, values, stage):
        rec = dict(rec)
        rec.update(index=len(records), stage=stage, values=list(values))
        fig = curve_figures(rec["curve"]["eps1"], rec["curve"]["q"], smooth)
        rec.update(fig)
        rec.update(compare(fig, hfig))
        rec["past_peak"] = _past_peak(rec["curve"], post_peak_strain)
        records.append(rec)
        return rec

    def evaluate(points, stage):
        got = {}
        tasks = []
        for i, v in enumerate(points):
            d = space.params(base, v).to_dict()
            key = params_key(d)
            res = done.get(key)
            if res is None and resume:    # finished in work/ but not logged before the interruption
                try:
                    with open(os.path.join(work, key, "result.json")) as f:
                        res = json.load(f)
                    _log(sink, res)
                    done[key] = res
                    shutil.rmtree(os.path.join(work, key), ignore_errors=True)
                except (OSError, ValueError):
                    res = None
            if res is not None:
                counts["taken"] += 1
                got[i] = res
                continue
            wd = None if scheduler else os.path.join(work, key)
            tasks.append((i, {"key": key, "params": d, "rate": rate, "confining": confining,
                              "eps_max": eps_max, "post_peak_strain": post_peak_strain,
                              "work_dir": wd, "resume": bool(resume)}))

        def collect(i, res):
            _log(sink, res)
            done[res["key"]] = res
            got[i] = res
            counts["run"] += 1
            wd = os.path.join(work, res["key"])
            if os.path.isdir(wd):
                shutil.rmtree(wd, ignore_errors=True)
            if verbose:
                r = {**res, **curve_figures(res["curve"]["eps1"], res["curve"]["q"], smooth)}
                r.update(compare(r, hfig))
                r["past_peak"] = _past_peak(res["curve"], post_peak_strain)
                _say(True, f"[calibrate] evaluation {len(records) + len(got)} of "
                           f"{len(records) + len(points)} so far ({stage}; at most {max_evals}): "
                           f"{_fmt_values(space.names, points[i])}: {_fmt_figs(r, hfig)}; "
                           f"score {r['score']:.3g}{'; MEETS ALL TARGETS' if r['met'] else ''}; "
                           f"run {res['wall_time']:.0f} s, elapsed {time.time() - t0:.0f} s")

        if where is not None:
            where.at(f"dem calibrate, {stage} batch after {len(records)} evaluations (run it "
                     "again with --resume to continue: finished evaluations are not rerun)")
        if tasks and verbose:
            _say(True, f"[calibrate] {stage}: {len(tasks)} evaluations to run"
                       + (f", {len(got)} taken from the checkpoint" if got else ""))
        from .probes import _map
        _map(tasks, collect, workers, scheduler, fn=task)
        out = [finish(got[i], v, stage) for i, v in enumerate(points)]
        _write_csv(out_dir, space, records, hfig)
        if where is not None and not where.written:
            where.wrote("evaluations.jsonl (every finished evaluation)", "calibration.csv")
        return out

    try:
        start = tuple(getattr(base, f) for f in space.names)
        best, seen, trace, why = pattern_search(space, evaluate, start=start, grid=grid,
                                                min_step=min_step, max_evals=max_evals)
    finally:
        sink.close()
    start_rec = records[0]
    _write_csv(out_dir, space, records, hfig)
    best_params = DemParams.from_dict(best["params"])
    save_params(os.path.join(out_dir, "calibrated.json"), best_params,
                f"python -m dem calibrate: the best set of {len(records)} evaluations ({why})")
    paper = DemParams(n=base.n, seed=base.seed)
    start_label = "DEM, paper set" if base == paper else "DEM, start set"
    curves = [("hmodel", hcurve), ("dem_start", start_rec["curve"]),
              ("dem_calibrated", best["curve"])]
    io.write_csv(os.path.join(out_dir, "curves.csv"), ["curve", "eps1", "q", "eps_v"],
                 [[name, e, q, v] for name, c in curves
                  for e, q, v in zip(c["eps1"], c["q"], c["eps_v"])])
    _figure(out_dir, hcurve, hfig, start_rec, best, start_label, space)
    _search_figure(out_dir, space, records, best)
    verdict = _verdict(space, records, best, hfig)
    summary = {"target": target, "target_figures": hfig, "tolerances": TOLERANCES,
               "options": header, "stopped": why, "evaluations": len(records),
               "run_now": counts["run"], "taken_from_checkpoint": counts["taken"],
               "trace": trace, "met": best["met"], "verdict": verdict,
               "best": {k: best[k] for k in ["index", "stage", "values", "score", "met",
                                            "past_peak", "porosity", "steps", "wall_time"]
                        + list(CSV_FIXED[:9])},
               "best_params": {f: v for f, v in zip(space.names, best["values"])},
               "start": {k: start_rec[k] for k in ["values", "score", "met", "past_peak"]
                         + list(CSV_FIXED[:9])},
               "start_label": start_label,
               "mean_wall_time_per_evaluation": (float(np.mean([r["wall_time"] for r in records]))
                                                 if records else None),
               "wall_time": time.time() - t0,
               "files": ["params.json", "calibrated.json", "calibration.csv", "curves.csv", "calibration.png",
                         "calibration_search.png", "evaluations.jsonl", "summary.json"]}
    io.atomic_write_bytes(os.path.join(out_dir, "summary.json"),
                          json.dumps(summary, indent=1, default=float).encode())
    if os.path.isdir(work) and not os.listdir(work):
        os.rmdir(work)
    return summary


def _say(verbose, msg):
    if verbose:
        print(msg, file=sys.stderr, flush=True)


def _log(sink, res):
    sink.write(json.dumps(res) + "\n")
    sink.flush()
    os.fsync(sink.fileno())


def _write_csv(out_dir, space, records, hfig):
    from . import io
    cols = ["kind", "index", "stage"] + list(space.names) + CSV_FIXED
    rows = [["hmodel", "", "target"] + [""] * len(space.names)
            + [hfig["peak_q"], hfig["eps1_peak"], hfig["secant"]] + [0.0] * 3 + [1] * 4
            + [0.0, 1, hfig["peak_q_raw"], "", "", ""]]
    for r in sorted(records, key=lambda r: r["index"]):
        rows.append(["dem", r["index"], r["stage"]] + list(r["values"])
                    + [int(r[c]) if isinstance(r[c], bool) else r[c] for c in CSV_FIXED])
    io.write_csv(os.path.join(out_dir, "calibration.csv"), cols, rows)


def _verdict(space, records, best, hfig):
    """Which targets the best set meets, how close it came, and, for each target it misses,
    the closest any evaluation came to that target alone (and with which parameters)."""
    lines = []
    for k, tol in TOLERANCES.items():
        e = best["err_" + k]
        line = {"figure": FIGURE_TEXT[k], "target": hfig[k], "best_value": best[k], "error": e,
                "tolerance": tol, "met": best["met_" + k]}
        if not best["met_" + k]:
            c = min(records, key=lambda r: (abs(r["err_" + k]), r["index"]))
            line["closest"] = {"index": c["index"], "error": c["err_" + k], "met": c["met_" + k],
                               "params": dict(zip(space.names, c["values"]))}
        lines.append(line)
    pairs = {}
    for a, b in itertools.combinations(TOLERANCES, 2):
        pairs[f"{a}+{b}"] = any(r["met_" + a] and r["met_" + b] for r in records)
    text = []
    if best["met"]:
        text.append(f"all targets met with {_fmt_values(space.names, best['values'])}")
    else:
        miss = [l["figure"] for l in lines if not l["met"]]
        text.append(f"targets NOT all met: {', '.join(miss)} missed by the best set "
                    f"({_fmt_values(space.names, best['values'])})")
    for l in lines:
        s = (f"{l['figure']}: {l['best_value']:.4g} vs {l['target']:.4g} ({l['error']:+.1%}, "
             f"tolerance {l['tolerance']:.0%}) {'met' if l['met'] else 'NOT met'}")
        if "closest" in l:
            c = l["closest"]
            s += (f"; closest of all evaluations {c['error']:+.1%} (evaluation {c['index']}, "
                  f"{_fmt_values(c['params'], c['params'].values())})")
        text.append(s)
    return {"lines": lines, "pairs_met_together": pairs, "text": text}


def _figure(out_dir, hcurve, hfig, start, best, start_label, space):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.3))
    x_end = max(start["curve"]["eps1"][-1], best["curve"]["eps1"][-1], 1.3 * hfig["eps1_peak"])
    keep = np.asarray(hcurve["eps1"]) <= x_end * (1 + 1e-9)
    hshown = {k: np.asarray(v)[keep] for k, v in hcurve.items()}
    curves = [(hshown, "H-model (Table I)", "k", "-"),
              (start["curve"], f"{start_label}: {_fmt_values(space.names, start['values'])}",
               "0.55", "-"),
              (best["curve"], f"DEM, calibrated: {_fmt_values(space.names, best['values'])}",
               "C3", "-")]
    for c, label, col, ls in curves:
        e = 100 * np.asarray(c["eps1"])
        axes[0].plot(e, np.asarray(c["q"]) / 1e3, ls, color=col, lw=1.2, label=label)
        axes[1].plot(e, 100 * np.asarray(c["eps_v"]), ls, color=col, lw=1.2, label=label)
    for r, col in ((hfig, "k"), (start, "0.55"), (best, "C3")):
        axes[0].plot([100 * r["eps1_peak"]], [r["peak_q"] / 1e3], "o", color=col, ms=5)
    # the tolerance box of the peak
    e0, q0 = 100 * hfig["eps1_peak"], hfig["peak_q"] / 1e3
    axes[0].add_patch(plt.Rectangle((e0 * (1 - TOLERANCES["eps1_peak"]), q0 * (1 - TOLERANCES["peak_q"])),
                                    2 * e0 * TOLERANCES["eps1_peak"], 2 * q0 * TOLERANCES["peak_q"],
                                    fill=False, ls=":", ec="k", lw=0.8))
    for ax in axes:
        ax.set_xlim(0, 100 * x_end)
    axes[0].set_ylabel("q = s1 - s2 [kPa]")
    axes[1].set_ylabel("eps_v = eps1 + eps2 [%] (compression positive)")
    for ax in axes:
        ax.set_xlabel("axial strain eps1 [%]")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, loc="lower right")
    axes[0].set_title(f"best: {_fmt_figs(best, hfig)}", fontsize=7)
    axes[1].set_title("dotted box on the left: the peak tolerances", fontsize=7)
    fig.tight_layout()
    _save(fig, out_dir, "calibration.png")


def _search_figure(out_dir, space, records, best):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter
    fig, ax = plt.subplots(figsize=(5.5, 4.3))
    sc = np.array([r["score"] for r in records])
    x = np.array([r["values"][0] for r in records])
    if len(space.names) == 1:
        ax.plot(x, sc, "o", color="C0")
        ax.plot([best["values"][0]], [best["score"]], "*", color="C3", ms=12)
        ax.set_ylabel("score sum (err/tol)^2")
        ax.set_yscale("log")
    else:
        y = np.array([r["values"][1] for r in records])
        s = ax.scatter(x, y, c=np.log10(np.maximum(sc, 1e-6)), cmap="viridis_r", s=30)
        fig.colorbar(s, ax=ax, label="log10 score, sum (err/tol)^2")
        ax.plot([best["values"][0]], [best["values"][1]], "*", color="C3", ms=14)
        for r in records:
            ax.annotate(str(r["index"]), (r["values"][0], r["values"][1]), fontsize=6,
                        textcoords="offset points", xytext=(3, 3))
        ax.set_ylabel(space.names[1])
        if space.log[1]:
            ax.set_yscale("log")
            ax.yaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel(space.names[0])
    if space.log[0]:
        ax.set_xscale("log")
        ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_title("evaluations (numbers: order); star: best", fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    _save(fig, out_dir, "calibration_search.png")


def _save(fig, out_dir, name):
    from hmodel.io import save_figure       # the project's one atomic figure writer
    save_figure(fig, os.path.join(out_dir, name), dpi=120)
