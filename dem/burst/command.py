"""The burst's command (``dem.burst``, ``python -m dem burst``): the start states
(``load_starts``; their disk count read first, ``check_sample_size``), every path then the runs
of every path's staircase spread over processes or a dask cluster (``run_burst``), the checkpoint and
journals of a resume, the files, the figures and the anatomy of the switches' runs."""
from __future__ import annotations

import json
import os
import sys
import time

import numpy as np

from point.burst import check_ratio
from point.burst_rule import RELEASE

from ..anatomy import contact_state
from ..simulation import Simulation
from .journal import _Journal, checkpoint_header, read_checkpoint
from .options import SWITCHES, BurstOptions
from .report import burst_row, write_burst_files
from .runs import PathResult, proportional_path
from .stairs import staircase_runs


# ----------------------------------------------------------------------------------------------
# The command: every (R, f) path, then every switch, spread over processes; files and figures
# ----------------------------------------------------------------------------------------------
def _summary_params(biaxial_dir):
    """The parameters of the biaxial test of ``biaxial_dir`` (its summary.json: those of every
    state ``load_starts`` takes), or None if it has no readable summary.json."""
    from ..params import DemParams
    try:
        with open(os.path.join(biaxial_dir, "summary.json")) as fh:
            return DemParams.from_dict(json.load(fh).get("params", {}))
    except (OSError, ValueError, TypeError, AttributeError):
        return None


def check_sample_size(biaxial_dir, opts: BurstOptions):
    """``opts.check_size`` (the rule of the sample's size) at the disk count of the states of
    ``biaxial_dir``, read cheaply before any state is loaded (its summary.json's parameters, to
    which ``load_starts`` holds every state); returns that count, or None (nothing checked) if
    it has no readable summary.json (``load_starts`` then refuses the folder in one line)."""
    own = _summary_params(biaxial_dir)
    if own is None:
        return None
    opts.check_size(own.n)
    return own.n


def load_starts(biaxial_dir, fractions, params_file=None):
    """[(f, State, meta)] of ``biaxial_dir/states/state_fF.FFF.npz`` for each start fraction,
    the drained peak eta (``summary.json``) and the states' parameters. ValueError (one line,
    naming the option) for a fraction not saved, states of other parameters than the biaxial
    test's, or a ``params_file`` that is not theirs."""
    from ..domain import load_states
    from ..params import DemParams, load_params
    out = []
    for f in fractions:
        (todo, eta_peak) = load_states(biaxial_dir, [f"f={f:g}"], option="--start-fractions")
        out.append((float(f), todo[0][1], todo[0][2]))
    with open(os.path.join(biaxial_dir, "summary.json")) as fh:    # read by load_states
        own = DemParams.from_dict(json.load(fh).get("params", {}))
    for f, st, _ in out:
        if st.params != own:
            raise ValueError(f"--biaxial {biaxial_dir}: state_f{f:.3f}.npz was made with other "
                             "parameters than the biaxial test's summary.json; allowed: the "
                             "states of one biaxial test")
    if params_file:
        given = load_params(params_file)
        if given != own:
            diff = [k for k, v in own.to_dict().items() if given.to_dict()[k] != v]
            raise ValueError(f"--params {params_file} conflicts with the parameters the states "
                             f"carry ({', '.join(diff)}); allowed: the states' own, or no --params")
    return out, eta_peak, own


def _log(msg):
    print(f"[burst] {msg}", file=sys.stderr, flush=True)


def _path_run(state, ratio, fraction, opts, verbose, threads=None):
    """A proportional path, a run of ``dem.pool`` (the first of its staircase's chain)."""
    last = [time.time()]

    def progress(steps, row, peak):
        if verbose and time.time() - last[0] > 10.0:
            last[0] = time.time()
            _log(f"R={ratio:g} f={fraction:g} path: step {steps} eps1={row[1]:.5f} "
                 f"c={row[8] / 1e3:.2f} kPa, largest {peak[8] / 1e3:.2f} kPa at eps1={peak[1]:.5f}")

    return proportional_path(state, ratio, opts, threads, progress)


def _stairs_job(path, ratio, fraction, opts, verbose, base, resume):
    """(tag, make) of one path's staircase for ``dem.pool``: ``make(tasks)`` opens its
    journal and gives the generator of its runs (``staircase_runs``)."""
    log = (lambda m: _log(f"R={ratio:g} f={fraction:g} {m}")) if verbose else None
    return ((ratio, fraction),
            lambda tasks: staircase_runs(path, ratio, opts, log, _Journal(base, resume), tasks))


def run_burst(biaxial_dir, out_dir, ratios, fractions, opts: BurstOptions = BurstOptions(),
              workers=None, threads=None, verbose=True, params_file=None, stage=None,
              resume=False, scheduler=None, allow_soft=False):
    """Every proportional path (one per ratio and start fraction), then the rest search of every
    path (``staircase``: its start relaxed at fixed strain, then G held by steps from rest until
    a hold of +dc fails; the below and past runs, the kinematic probes), spread over
    ``workers`` local processes or a dask cluster at ``scheduler`` (one thread each; ``threads``
    in a single process): each path then its staircase one chain of runs
    (``dem.pool``: the holds of each staircase one after another, its
    probes, the loaded peak's relaxation, the below run and the baselines on the other workers
    as soon as their states exist; the files the same bytes as on one worker, which runs them
    in this process one after another, the probes after the staircase). Every finished path
    goes to ``out_dir``/burst_runs.jsonl and every relaxation, hold and probe of a staircase to
    its journal in ``out_dir``/rest/ as it finishes, so that ``resume`` continues from them
    (refusing a folder of other states or options). Writes
    ``out_dir``/burst.csv, history.csv, paths.csv, rest.csv, stairs.csv, summary.json,
    params.json, the states the switches started from (rest/) and the figures. Returns (burst
    rows as dicts, summary dict). States of parameters outside the granular regime at the test's
    sigma2 (``dem.regime.check_biaxial_regime``) are refused unless ``allow_soft``; summary.json
    records the regime (``regime``)."""
    from ..pool import run_jobs
    jobs, finish = burst_job(biaxial_dir, out_dir, ratios, fractions, opts, verbose,
                             params_file, resume, allow_soft)
    if stage:
        stage.at("dem burst: the paths and their rest search (from rest, G held by steps)")
    # a run in a pool of processes runs on one thread; alone in this process, on ``threads``
    # (None: common.threads chooses), and so does a chain alone on local processes
    chain = threads if threads is not None else (None if len(jobs) == 1 and not scheduler
                                                 else 1)
    return finish(run_jobs(jobs, workers, scheduler, threads, chain))


def burst_job(biaxial_dir, out_dir, ratios, fractions, opts: BurstOptions = BurstOptions(),
              verbose=True, params_file=None, resume=False, allow_soft=False):
    """``run_burst`` in two: the checks, the checkpoint and the parameters' file now, then
    ``(jobs, finish)``: ``jobs`` [(tag, make)] one generator of runs per path for
    ``dem.pool`` (the path, unless a resume has it, then its staircase, ``staircase_runs``),
    ``finish(results)`` the files, the figures and the anatomy from {tag: staircase result};
    ``finish`` returns what ``run_burst`` does. The cross-check runs the jobs beside the
    DEM's directional analysis on one pool."""
    from .. import io
    from common.io import atomic_write_bytes
    from ..pool import Call
    ratios = [check_ratio(float(r)) for r in ratios]
    # the options by the command line's rule: their ranges, then the rule of the sample's size,
    # both before the states load
    opts.validate()
    check_sample_size(biaxial_dir, opts)
    starts, eta_peak, params = load_starts(biaxial_dir, fractions, params_file)
    from ..regime import check_biaxial_regime
    regime = check_biaxial_regime(biaxial_dir, allow_soft)
    header = checkpoint_header(starts, ratios, opts)
    done = read_checkpoint(out_dir, header) if resume else []   # refused before any write
    t0 = time.time()
    os.makedirs(os.path.join(out_dir, "rest"), exist_ok=True)
    # the parameters the run used, in the shared file format (``--params DIR/params.json``)
    from ..params import record_params
    record_params(out_dir, params, f"python -m dem burst; parameters: the start states' own "
                                   f"(--biaxial {biaxial_dir})")
    ck = os.path.join(out_dir, "burst_runs.jsonl")
    if not resume and os.path.exists(ck):
        os.replace(ck, ck[:-len(".jsonl")] + ".previous.jsonl")
    atomic_write_bytes(ck, "".join(json.dumps(r) + "\n" for r in [header] + done).encode())
    combos = [(r, f, st) for r in ratios for f, st, _ in starts]
    log = _log if verbose else (lambda m: None)
    log(f"{len(combos)} proportional paths ({params.n} disks, rate {opts.rate:g}/s): R in "
        f"{ratios}, start fractions {list(fractions)}; then from rest (the start relaxed at "
        f"fixed strain) G held by steps ({'dead load' if opts.hold == 'dead_load' else 'servo'})"
        f" until a step of {opts.dc:g} Pa fails: the c peak at rest; below at "
        f"{opts.below_rise:g} of the rise at rest")
    paths, stairs = {}, {}
    for rec in done:
        key = (rec["ratio"], rec["start_fraction"])
        grid = [(row, io.load_state(os.path.join(out_dir, "rest", f"{_base(*key)}_path{i}.npz"))[0])
                for i, row in enumerate(rec["grid"])]
        paths[key] = PathResult(np.asarray(rec["rows"], float), rec["peak"],
                                rec["confirmed_by"], grid, rec["steps"], rec["wall_time"])
    if done:
        log(f"resumed from {ck}: {len(paths)} paths finished")

    def got_path(key):
        def record(res):
            r, f = key
            for i, (_, st) in enumerate(res.grid):
                io.save_state(os.path.join(out_dir, "rest", f"{_base(r, f)}_path{i}.npz"), st)
            with open(ck, "a") as fh:
                fh.write(json.dumps({"kind": "path", "ratio": r, "start_fraction": f,
                                     "rows": res.rows.tolist(), "peak": res.peak,
                                     "confirmed_by": res.confirmed_by,
                                     "grid": [row for row, _ in res.grid], "steps": res.steps,
                                     "wall_time": res.wall_time}) + "\n")
            paths[key] = res
            pk = (f"loaded c peak {res.rows[res.peak, 8] / 1e3:.2f} kPa at eta "
                  f"{res.rows[res.peak, 7]:.4f} (confirmed by {res.confirmed_by})"
                  if res.peak is not None else "the specimen unloaded"
                  if res.confirmed_by == "unloaded" else "no c peak")
            log(f"R={r:g} f={f:g} path: {pk}, {res.steps} steps, {res.wall_time:.0f} s")
        return record

    def job(r, f, st):
        def make(tasks):
            if (r, f) not in paths:
                yield Call(_path_run, (st, r, f, opts, verbose), {}, got_path((r, f)))
            if paths[(r, f)].confirmed_by == "unloaded":
                return None
            _, inner = _stairs_job(paths[(r, f)], r, f, opts, verbose,
                                   os.path.join(out_dir, "rest", _base(r, f)), resume)
            res = yield from inner(tasks)
            stairs[(r, f)] = res
            log(f"R={r:g} f={f:g}: {res.end}, {len(res.holds)} holds, {res.wall_time:.0f} s")
            return res
        return (r, f), make

    def finish(results):
        # {tag: the staircase} of every path that loaded (the jobs' results; also kept as they
        # ended, in ``stairs``)
        stairs.update({k: v for k, v in results.items() if v is not None})
        rows = []
        for r, f, st in combos:
            if (r, f) not in stairs:
                continue
            for sw, i in sorted(stairs[(r, f)].switches.items(),
                                key=lambda x: SWITCHES.index(x[0])):
                rows.append(burst_row(r, f, sw, paths[(r, f)], stairs[(r, f)], i, opts,
                                      eta_peak, params.n))
        summary = {"biaxial": os.path.abspath(biaxial_dir), "n_disks": params.n,
                   "drained_eta_peak": eta_peak, "ratios": ratios,
                   "start_fractions": list(fractions),
                   "options": opts._asdict(), "params": params.to_dict(), "dt": params.dt,
                   "fingerprints": header["fingerprints"],
                   "paths": [{"ratio": r, "start_fraction": f, "steps": paths[(r, f)].steps,
                              "wall_time": paths[(r, f)].wall_time,
                              "end": (paths[(r, f)].confirmed_by or "path_strain reached"),
                              "rest_search": stairs[(r, f)].end if (r, f) in stairs else None,
                              "holds": len(stairs[(r, f)].holds) if (r, f) in stairs else 0,
                              "rest_search_wall_time": stairs[(r, f)].wall_time
                              if (r, f) in stairs else None,
                              # the kinematic probes and the theory's verdict (``theory_verdict``)
                              "theory": stairs[(r, f)].verdict if (r, f) in stairs else {},
                              "k_path": [{"key": p.key, "c": p.c_before, "eps1": p.eps1_before,
                                          "k_path": p.k_path, "outcome": p.outcome}
                                         for p in stairs[(r, f)].probes.values()]
                              if (r, f) in stairs else []} for r, f, _ in combos],
                   "runs": [{k: row[k] for k in ("ratio", "start_fraction", "switch", "outcome",
                                                 "steps", "ke_w2ext_max", "t_release", "released",
                                                 "ke_end_over_bound", "k_path_switch",
                                                 "n_unstable_max", "unstable_noise_max",
                                                 "n_unstable_excess")} for row in rows],
                   "growth_rule": {"release": RELEASE, "measure": "(E_c - E_c(0)) / W2_ext of the "
                                   "held step, backbone E_c (hmodel.burst_rule.energy_release)"},
                   "regime": regime, "wall_time": time.time() - t0}
        write_burst_files(out_dir, combos, paths, stairs, rows, summary)
        # the states the switches started from stay (rest/R.._f.._switch.npz); the rest served the
        # search and a resume
        from ..anatomy import plot_anatomy, write_anatomy_vtk
        from ..io import save_state
        panels = []
        for r, f, _ in combos:
            j = _Journal(os.path.join(out_dir, "rest", _base(r, f)), resume=True)
            keep = {}
            if (r, f) in stairs:
                res = stairs[(r, f)]
                keep = {sw: j.state(res.starts[i]) for sw, i in res.switches.items()}
                # the anatomy at the onset of a burst (if it came) and at the end of every switch's
                # run: VTU for ParaView, and the first path's figure, below beside past
                for sw in SWITCHES:
                    if sw not in res.switches:
                        continue
                    i = res.switches[sw]
                    s0 = contact_state(Simulation(keep[sw]))
                    for when in ("onset", "end"):
                        if j.has(f"h{i}_{when}"):
                            sim = Simulation(j.state(f"h{i}_{when}"))
                            sp = (contact_state(Simulation(j.state(f"h{i}_{when}_prev")))
                                  if j.has(f"h{i}_{when}_prev") else None)
                            write_anatomy_vtk(os.path.join(out_dir, "anatomy"),
                                              f"{_base(r, f)}_{sw}_{when}", sim, s0, sp)
                            if (r, f) == (combos[0][0], combos[0][1]):
                                t = (sim.step - keep[sw].step) * sim.dt
                                row = next(x for x in rows if x["switch"] == sw and
                                           (x["ratio"], x["start_fraction"]) == (r, f))
                                panels.append((f"{sw}: {res.holds[i][3].outcome}, at the {when} "
                                               f"(t = {t:.3g} s)\nheld with no change of load: "
                                               f"<= {row['unstable_noise_max']:.0f} unstable",
                                               sim, s0, sp))
            for path in j.files() + [os.path.join(out_dir, "rest", f"{_base(r, f)}_path{i}.npz")
                                     for i in range(2)]:
                if os.path.exists(path):
                    os.unlink(path)
            for sw, st in keep.items():
                save_state(os.path.join(out_dir, "rest", f"{_base(r, f)}_{sw}.npz"), st)
        if panels:
            plot_anatomy(os.path.join(out_dir, "fig_burst_anatomy.png"), panels)
        return rows, summary

    return [job(r, f, st) for r, f, st in combos], finish


def _base(ratio, fraction):
    return f"R{ratio:g}_f{fraction:g}"
