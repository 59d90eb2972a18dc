"""The calibration's evaluations (``dem.calibrate``): one DEM run (``_evaluate_task``, in a
worker process or on a dask cluster: the compaction and drained biaxial test of a parameter set on
one seed), the record of a set from its seeds' runs (``_combine``), and the checkpoint
DIR/evaluations.jsonl (``_header``, ``read_checkpoint``: a header line of the options that define
the search, then one line per finished run)."""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import shutil
import tempfile

import numpy as np

from ..params import RENAMED, DemParams, migrate
from .targets import (DILATANCY_STRAIN, PEAK_FRACTION, SECANT_STRAIN, TOLERANCES, compare,
                      curve_figures, score_at_least, stopped_figures)

# options of the header that may differ on --resume (they do not change the search)
RESUME_FREE = ("max_evals",)
FORMAT = "dem-calibration"
FORMAT_VERSION = 2         # 1: grid + compass search, eps1 at the peak (issue 12)


# -- one evaluation (runs in a worker) ----------------------------------------------------------
STOPPED = "/stopped"     # a stopped run's key in the finished runs: beside its whole run's


def params_key(d: dict) -> str:
    return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:16]


def done_key(res: dict) -> str:
    """The key of a finished run among the finished runs: its parameters' (``params_key``),
    with STOPPED after it for a run stopped once decided (the same run run on to its end keeps
    both: a resumed search takes each where the first one took it)."""
    return res["key"] + (STOPPED if res.get("stopped") else "")


def _evaluate_task(a):
    """One DEM evaluation: compaction + drained biaxial test of a["params"] on one thread.
    In a["work_dir"] (local runs: resumable, result.json written there when done) or in a
    temporary folder (dask workers); returns the curve and the run's figures."""
    from common import threads
    from ..experiment import run_biaxial
    from .targets import InRunDecision
    old = threads._default
    threads.set_default_threads(1)
    tmp = None
    try:
        wd = a["work_dir"]
        if wd is None:
            wd = tmp = tempfile.mkdtemp(prefix="dem-calibrate-")
        params = DemParams.from_dict(a["params"])
        rule = a.get("stop")
        decision = None if rule is None else InRunDecision(
            rule["target"], rule["n_seeds"], params.n, rule["smooth"])
        res = run_biaxial(params, wd, rate=a["rate"], confining=a["confining"],
                          eps_max=a["eps_max"], post_peak_strain=a["post_peak_strain"],
                          resume=a["resume"], verbose=False, figures=False, vtk=False,
                          save_fractions=(), allow_soft=a.get("allow_soft", False),
                          stop=None if decision is None else (lambda rows: _decide(decision, rows)))
        rows = np.asarray(res.rows, float)
        comp = res.compaction
        out = {"key": a["key"], "params": a["params"],
               "curve": {"eps1": rows[:, 2].tolist(), "q": rows[:, 8].tolist(),
                         "eps_v": rows[:, 4].tolist(), "p": rows[:, 7].tolist()},
               "porosity": comp.get("porosity"), "compaction_converged": comp.get("converged"),
               "steps": int(rows[-1, 0]), "wall_time": float(res.wall_time)}
        if res.stopped:
            # decided: what its records fix, and its folder kept (checkpoint.npz) so that
            # ``complete`` runs it on from there to the rows of a run never stopped
            out["stopped"] = {**res.stopped, "known": decision.known()}
            if tmp is None:
                from common.io import atomic_write_bytes
                atomic_write_bytes(os.path.join(wd, "result.json"), json.dumps(out).encode())
            return out
        if tmp is None:
            from common.io import atomic_write_bytes
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


def _decide(decision, rows):
    """``decision`` (an ``InRunDecision``) told the rows of a biaxial test it has not seen (all
    from the start of the test: also those of a run resumed from its checkpoint): its decision
    or None."""
    for row in rows[len(decision.e):]:
        if decision.add(row[2], row[8]) is not None:
            break
    return decision.decided


def _past_peak(curve, post_peak_strain):
    """The run went past its peak: it stopped by run_biaxial's post-peak rule (post_peak_strain
    after the raw maximum with q below 0.98 of it), not at eps_max."""
    e, q = np.asarray(curve["eps1"]), np.asarray(curve["q"])
    i = int(np.argmax(q))
    return bool(e[-1] >= e[i] + post_peak_strain and q[-1] < 0.98 * q[i])


def _mean_figures(per, hfig):
    """The figures of a set of samples: each the mean over the samples ``per`` (dicts of one
    run's figures), with their errors against the target ``hfig`` (``compare``).  The targets
    are a set's means by definition: a single 2000-disk sample scatters by about a tolerance
    (docs/dem.md, "A sample's scatter")."""
    rec = {k: float(np.mean([p[k] for p in per]))
           for k in (*TOLERANCES, "eps1_peak", "peak_q_raw")}
    rec.update(compare(rec, hfig))
    return rec


def _check_mean(check, hfig):
    """The check's verdict: the best set's figures as the mean over the check seeds (each run's
    figures in ``check``), compared with the targets as the fit compares the mean over its
    seeds; ``seeds`` lists them."""
    rec = _mean_figures(check, hfig)
    rec["seeds"] = [c["seed"] for c in check]
    return rec


def _sample_scatter(per, n_fit, n_check):
    """The scatter of one sample's figures about the set's mean, from the best set's runs
    ``per`` (fit and check seeds): for each figure the relative standard deviation of a single
    run (sd / mean, ddof 1), the number of runs, and the standard errors of the means over the
    n_fit fitted and n_check check seeds (sd / sqrt(n)), beside the tolerance.  None with
    fewer than two runs."""
    if len(per) < 2:
        return None
    out = {}
    for k in TOLERANCES:
        v = np.array([p[k] for p in per], float)
        sd = float(np.std(v, ddof=1) / np.mean(v))
        out[k] = {"sd": sd, "runs": len(v), "se_fit": sd / math.sqrt(n_fit),
                  "se_check": sd / math.sqrt(n_check) if n_check else None,
                  "tolerance": TOLERANCES[k]}
    return out


def _combine(runs, seeds, smooth, post_peak_strain, hfig):
    """The record of one parameter set from its runs (one per seed): the figures are the means
    over the seeds, spread_X = (max - min) / mean of figure X over them (None for one run)."""
    per = []
    censored = {}
    for s, res in zip(seeds, runs):
        if res.get("stopped"):      # a first run stopped once decided: one seed only
            fig, censored = stopped_figures(res["curve"], res["stopped"]["known"])
        else:
            fig = curve_figures(res["curve"]["eps1"], res["curve"]["q"], smooth,
                                eps_v=res["curve"]["eps_v"])
        per.append({"seed": s, **fig, "past_peak": _past_peak(res["curve"], post_peak_strain),
                    "porosity": res.get("porosity"), "steps": res["steps"],
                    "wall_time": res["wall_time"], "key": res["key"]})
        if res.get("stopped"):
            per[-1]["stopped_at"] = res["stopped"]["eps1"]
    if censored and len(runs) > 1:
        raise ValueError("_combine: a stopped run among several seeds")
    rec = _mean_figures(per, hfig)
    if censored:
        rec.update(censored=censored, stopped_at=per[0]["stopped_at"],
                   score=score_at_least({k: rec["err_" + k] for k in TOLERANCES}, censored))
    for k in TOLERANCES:
        v = [p[k] for p in per]
        rec["spread_" + k] = float((max(v) - min(v)) / np.mean(v)) if len(v) > 1 else None
    por = [p["porosity"] for p in per if p["porosity"] is not None]
    rec.update(past_peak=all(p["past_peak"] for p in per),
               porosity=float(np.mean(por)) if por else None,
               steps=int(sum(p["steps"] for p in per)),
               wall_time=float(sum(p["wall_time"] for p in per)), seeds=per,
               curves=[r["curve"] for r in runs], params=runs[0]["params"])
    return rec


# -- the checkpoint -----------------------------------------------------------------------------
def _header(target, space, base, seeds, initial, batch, max_evals, rate, confining, eps_max,
            post_peak_strain, smooth):
    return {"format": FORMAT, "format_version": FORMAT_VERSION, "target": target,
            "n": base.n, "seeds": list(seeds), "vary": list(space.names),
            "bounds": {f: [a, b, "log" if lg else "linear"]
                       for f, a, b, lg in zip(space.names, space.lo, space.hi, space.log)},
            "search": "surrogate", "initial": initial, "batch": batch, "design_seed": 0,
            "max_evals": max_evals, "rate": rate,
            "confining": confining, "eps_max": eps_max, "post_peak_strain": post_peak_strain,
            "smooth": smooth, "secant_strain": SECANT_STRAIN, "peak_fraction": PEAK_FRACTION,
            "dilatancy_strain": DILATANCY_STRAIN, "tolerances": TOLERANCES,
            "start_params": base.to_dict()}


def _log(sink, res):
    sink.write(json.dumps(res) + "\n")
    sink.flush()
    os.fsync(sink.fileno())


def current_params(d: dict) -> dict:
    """A parameter dict written by an earlier version, with the DemParams fields added since at
    their defaults (a new field's default keeps the earlier behaviour, e.g. rolling_friction 0 =
    free rotation), so that a checkpoint made before a field existed still matches."""
    d = migrate(d)
    missing = {f.name: f.default for f in dataclasses.fields(DemParams) if f.name not in d}
    return {**missing, **d}


def _older_targets(head, header):
    """The checkpoint's header is that of a calibration with fewer targets (before the dilatancy
    target of issue 34: no dilatancy_strain, the tolerances a subset of today's, equal where
    both have them): its runs' curves hold eps_v, so every figure of today can be read off them."""
    old, new = head.get("tolerances"), header.get("tolerances")
    return (isinstance(old, dict) and isinstance(new, dict) and "dilatancy_strain" not in head
            and set(old) < set(new) and all(old[k] == new[k] for k in old))


def read_checkpoint(path, header, notes=None):
    """{key: record} of the finished evaluations of ``path`` made with the same options
    (ValueError naming what differs otherwise); a torn last line is dropped.  Parameters of
    the file are read with ``current_params``.  A checkpoint of a calibration with fewer
    targets (``_older_targets``) is taken when its runs' curves hold eps_v (a line appended to
    ``notes``: the search is today's, its runs reused where it asks for the same sets), refused
    in one line otherwise."""
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
    if isinstance(head.get("vary"), list):         # fields renamed since (friction_deg: phi_g)
        head["vary"] = [RENAMED.get(v, v) for v in head["vary"]]
    if isinstance(head.get("bounds"), dict):
        head["bounds"] = migrate(head["bounds"])
    older = _older_targets(head, header)
    if older:
        head = {**head, "tolerances": header["tolerances"],
                "dilatancy_strain": header.get("dilatancy_strain")}
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
            done[done_key(rec)] = rec
    if older:
        old = json.loads(lines[0])["header"]["tolerances"]
        new = [k for k in header["tolerances"] if k not in old]
        where = f"--resume: {os.path.dirname(path) or '.'} was made with {len(old)} targets, " \
                f"without {', '.join(new)} (before issue 34)"
        if any("eps_v" not in r["curve"] for r in done.values()):
            raise ValueError(f"{where}, and its runs hold no eps_v to read it from; allowed "
                             "another --out")
        if notes is not None:
            notes.append(f"{where}: its {len(done)} runs are read with all "
                         f"{len(header['tolerances'])} (their curves hold eps_v) and taken where "
                         "today's search asks for the same sets")
    return done


def _param_diff(a, b, skip=()):
    a, b = a or {}, b or {}
    return ", ".join(f"{k}: {a.get(k)!r} there, {b.get(k)!r} now"
                     for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k) and k not in skip)
