"""The c peak at rest along a path (``dem.burst``): the staircase of holds from rest
(``staircase``), its below and past runs and their baselines, the kinematic probes of its
equilibria and the theory's verdict on them."""
from __future__ import annotations

import math
import time
from typing import NamedTuple

from .journal import _Journal
from ..pool import WAIT, Call
from .options import SWITCHES, BurstOptions
from .runs import PathResult, hold, path_probe, probe_rate_of, relax
from .theory import staircase_verdict


class StairResult(NamedTuple):
    """The rest search of one path (``staircase``)."""
    relaxed: dict             # "start" and "peak" (the loaded peak's or the end's) -> RelaxResult
    holds: list               # [(role, c_from, c_target, HoldResult)]: the staircase's
                              # ("stair"), the below run ("below"), then each switch's state
                              # held with no change of load ("baseline_below", "baseline_past");
                              # the past run is the last failing stair hold
    c_peak: float             # the largest c at rest held at equilibrium (nan: none)
    eps1_peak: float          # its axial strain
    eta_peak: float
    switches: dict            # "below"/"past" -> index into holds
    end: str                  # how the search ended: "past found", "no loaded peak", ...
    wall_time: float
    starts: list = []         # the journal key of the state each hold started from
    probes: dict = {}         # journal key of an equilibrium -> ProbeResult (path_probe)
    verdict: dict = {}        # staircase_verdict's, with the probes' rule
    baselines: dict = {}      # "below"/"past" -> index into holds of its baseline run


def staircase(path: PathResult, ratio: float, opts: BurstOptions = BurstOptions(), threads=None,
              log=None, journal=None) -> StairResult:
    """The c peak at rest along the path, found from rest as the theory asks it: the path's start
    state relaxed at fixed strain (``relax``), then G held by steps (``hold``, from the last
    equilibrium each time, so every hold starts from rest): the first step is (c_peak_loaded -
    c_rest) / ``opts.stairs``; a step that settles moves the staircase up (its end state, at
    rest, is the next start); one that fails is halved, down to ``opts.dc``; the search ends with
    a failing hold of +dc from an equilibrium at c: the c peak at rest is that c, the ``past``
    run that failing hold. (Each step raises the held force G, the force conjugate to U1, by
    W t times the step from the last equilibrium's, so G rises along the staircase; c = s1 + R
    s2 follows G through the box's shape, c W t = G + R F2 (W/H - W0/H0), and a hold that creeps
    may end at a c below its start: the c peak at rest is the c of the equilibrium under the
    largest G.) ``below``: from the first equilibrium of the staircase whose c reaches
    c_rest + below_rise (c_peak_rest - c_rest), held at its c + dc. Each switch's start state is
    also held with no change of load (its ``baseline`` run: the noise of the anatomy's counts).
    The loaded peak's state is relaxed too: its c at rest and its drop from the loaded c are
    recorded. A path without a loaded peak gets one below run from its end, relaxed. With
    ``opts.probes``, every equilibrium (the relaxed states, the end of every hold that settled)
    is probed along the path (``path_probe``: k_path) and the theory's verdict is drawn
    (``staircase_verdict``). ``journal``: a ``_Journal`` that records every relaxation, hold and
    probe as it finishes (and gives them back on a resume). Every run here, one after another
    on ``threads``; ``run_burst`` on several workers runs the same staircase with its probes,
    the below run and the baselines beside it (``staircase_runs``, ``dem.pool``)."""
    from ..pool import run_inline
    return run_inline(lambda tasks: staircase_runs(path, ratio, opts, log, journal, tasks),
                      threads)


def staircase_runs(path: PathResult, ratio: float, opts: BurstOptions, log, journal, tasks):
    """``staircase`` as a generator of runs (``dem.pool``): ``yield Call(...)`` for a run
    of the chain (the relaxation of the start, each hold of the staircase: the next one needs
    its result), ``tasks.start(...)`` for a run that needs only a state already there (the
    relaxation of the loaded peak when the path has one, the below run and the baselines, the
    probe of every equilibrium: as soon as the state exists when ``tasks.parallel``, else at the
    end in the order of the keys), ``yield WAIT`` for those to finish. Every run is journaled as
    it finishes; returns the StairResult, which does not depend on the order runs finish in."""
    t0 = time.time()
    log = log or (lambda m: None)
    journal = journal or _Journal(None)
    now = tasks.parallel             # probe each equilibrium as soon as it exists
    dc = opts.dc
    relaxed, probes, probing = {}, {}, set()
    holds, starts = [], []

    def probe(key):
        if not opts.probes or key in probing:
            return
        probing.add(key)
        got = journal.probe(key)
        if got is not None:
            probes[key] = got
            return

        def done(pr):
            journal.add_probe(pr)
            log(f"probe at {key}: c {pr.c_before / 1e3:.3f} kPa, k_path {pr.k_path:.3g} Pa "
                f"(dc {pr.c_after - pr.c_before:+.1f} Pa over d eps1 {pr.d_eps1:.3g}), "
                f"{pr.outcome}")
            probes[key] = pr
        tasks.start(path_probe, (journal.state(key), ratio, opts), {"key": key}, done)

    def relaxation_done(name, c_path):
        def done(res):
            journal.add_relaxation(name, res, c_path)
            log(f"{name} state relaxed at fixed strain: c {res.c_loaded / 1e3:.2f} -> "
                f"{res.c_rest / 1e3:.2f} kPa, {res.outcome} after {res.steps} steps")
            relaxed[name] = res
            if now:
                probe("relaxed_" + name)
        return done

    # the loaded peak's relaxation: only rest.csv and its probe need it (beside the staircase, from
    # its start when there are workers for it)
    beside_peak = path.peak is not None
    for name in ("peak", "start") if now and beside_peak else ("start", "peak"):
        row, st = path.grid[0 if name == "start" else 1]
        res = journal.relaxation(name)
        if res is not None:
            relaxed[name] = res
            if now:
                probe("relaxed_" + name)
        elif name == "peak" and beside_peak:
            tasks.start(relax, (st, ratio, opts), {}, relaxation_done(name, path.rows[row, 8]),
                        first=True)
        else:
            yield Call(relax, (st, ratio, opts), {}, relaxation_done(name, path.rows[row, 8]))
    eq = [("relaxed_start", relaxed["start"].c_rest, path.rows[path.grid[0][0], 1])]  # equilibria

    def record(k, got):
        role, c_from, target, _ = holds[k]
        holds[k] = (role, c_from, target, got._replace(end_state=None, onset_state=None,
                                                        onset_prev_state=None,
                                                        end_prev_state=None))
        if now and got.outcome == "equilibrium":
            probe(f"h{k}_end")

    def hold_done(k, key):
        def done(got):
            role, c_from, target, _ = holds[k]
            for when in ("end", "onset", "onset_prev", "end_prev"):   # the next start, figures
                journal.keep(f"h{k}_{when}", getattr(got, f"{when}_state"))
            journal.add_hold(k, role, c_from, target, got, key)
            log(f"{role} hold {k}: c {c_from / 1e3:.3f} -> {target / 1e3:.3f} kPa: "
                f"{got.outcome} after {got.steps} steps")
            record(k, got)
        return done

    def enter(role, key, c_from, target):
        """Hold k's place in the records, and its result if the journal has it (a resume)."""
        k = len(holds)
        holds.append((role, c_from, target, None))
        starts.append(key)
        got = journal.hold(k)
        if got is not None:
            record(k, got)
        return k, got

    def args(key, target):
        return (journal.state(key), ratio, target, opts)

    def held(role, key, c_from, target):
        """A hold of the chain: the staircase waits for it (``yield from``)."""
        k, got = enter(role, key, c_from, target)
        if got is None:
            got = yield Call(hold, args(key, target), {}, hold_done(k, key))
        return got

    def beside(role, key, c_from, target):
        """A hold nothing of the staircase waits for (the below run, the baselines)."""
        k, got = enter(role, key, c_from, target)
        if got is None:
            tasks.start(hold, args(key, target), {}, hold_done(k, key), first=True)
        return k

    switches, baselines = {}, {}
    c_peak = e_peak = eta_peak = math.nan
    if path.peak is None:                           # no loaded peak: below from the path's end
        switches["below"] = beside("below", "relaxed_peak", relaxed["peak"].c_rest,
                                   relaxed["peak"].c_rest + dc)
        end = "no loaded peak"
    else:
        c_s = relaxed["start"].c_rest
        key = "relaxed_start"
        step = max((path.rows[path.peak, 8] - c_s) / opts.stairs, dc)
        end = ""
        while len(holds) < opts.max_holds:
            h = yield from held("stair", key, c_s, c_s + step)
            if h.outcome == "equilibrium":
                key = f"h{len(holds) - 1}_end"
                c_s = h.history[-1, 4]
                eq.append((key, c_s, h.history[-1, 2]))
                continue
            if h.outcome == "undecided":
                end = "a hold undecided at --max-steps"
                break
            if step <= dc:
                end = "past found"
                break
            step = max(0.5 * step, dc)
        else:
            end = f"no failure within {opts.max_holds} holds"
        c_peak, e_peak = eq[-1][1], eq[-1][2]
        if end == "past found":
            switches["past"] = len(holds) - 1
            thr = eq[0][1] + opts.below_rise * (c_peak - eq[0][1])
            kb, cb, _ = next(x for x in eq if x[1] >= thr) if len(eq) > 1 else eq[0]
            switches["below"] = beside("below", kb, cb, cb + dc)
            hp = holds[switches["past"]][3].history
            eta_peak = (hp[0, 10] - hp[0, 11]) / (0.5 * (hp[0, 10] + hp[0, 11]))
    # each switch's start held with no change of load: the anatomy's noise
    for sw in SWITCHES:
        if sw in switches:
            i = switches[sw]
            baselines[sw] = beside(f"baseline_{sw}", starts[i], holds[i][1], holds[i][1])
    log(f"rest search: {end}; c peak at rest {c_peak / 1e3:.3f} kPa, {len(holds)} holds")
    yield WAIT          # the runs beside the staircase, and the probes started so far
    verdict = {}
    if opts.probes:
        keys = ([k for k, _, _ in eq] + ["relaxed_peak"]
                + [f"h{k}_end" for k, (ro, _, _, h) in enumerate(holds)
                   if ro != "stair" and h.outcome == "equilibrium"])
        for key in keys:          # all of them on one worker; on several, none is left
            probe(key)
        yield WAIT
        probes = {key: probes[key] for key in keys}      # in the keys' order, as they finished
        verdict = staircase_verdict(
            eq, [(ro, cf, ct, h.outcome, starts[i]) for i, (ro, cf, ct, h) in enumerate(holds)],
            probes, dc, opts.probe_d_eps1, end)
        st0 = journal.state("relaxed_start")
        verdict["probe_rate"] = probe_rate_of(len(st0.r), st0.params.dt, opts)
        log(f"theory: {verdict['verdict']} ({verdict['why']})")
    return StairResult({k: relaxed[k]._replace(state=None) for k in ("start", "peak")}, holds,
                       c_peak, e_peak, eta_peak, switches, end, time.time() - t0, starts, probes,
                       verdict, baselines)
