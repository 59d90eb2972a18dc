"""The c peak at rest along a path (``dem.burst``): the staircase of holds from rest
(``staircase``), its below and past runs and their baselines, the kinematic probes of its
equilibria and the theory's verdict on them."""
from __future__ import annotations

import math
import time
from typing import NamedTuple

from .journal import _Journal
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
    probe as it finishes (and gives them back on a resume)."""
    t0 = time.time()
    log = log or (lambda m: None)
    journal = journal or _Journal(None)
    dc = opts.dc
    relaxed = {}
    for name, (row, st) in zip(("start", "peak"), path.grid):
        res = journal.relaxation(name)
        if res is None:
            res = relax(st, ratio, opts, threads)
            journal.add_relaxation(name, res, path.rows[row, 8])
            log(f"{name} state relaxed at fixed strain: c {res.c_loaded / 1e3:.2f} -> "
                f"{res.c_rest / 1e3:.2f} kPa, {res.outcome} after {res.steps} steps")
        relaxed[name] = res
    holds, starts = [], []
    eq = [("relaxed_start", relaxed["start"].c_rest, path.rows[path.grid[0][0], 1])]  # equilibria

    def held(role, key, c_from, target):
        k = len(holds)
        got = journal.hold(k)
        if got is None:
            got = hold(journal.state(key), ratio, target, opts, threads)
            for when in ("end", "onset", "onset_prev", "end_prev"):   # the next start, figures
                journal.keep(f"h{k}_{when}", getattr(got, f"{when}_state"))
            journal.add_hold(k, role, c_from, target, got, key)
            log(f"{role} hold {k}: c {c_from / 1e3:.3f} -> {target / 1e3:.3f} kPa: "
                f"{got.outcome} after {got.steps} steps")
        holds.append((role, c_from, target, got._replace(end_state=None, onset_state=None,
                                                         onset_prev_state=None,
                                                         end_prev_state=None)))
        starts.append(key)
        return got

    switches, baselines = {}, {}
    c_peak = e_peak = eta_peak = math.nan
    if path.peak is None:                           # no loaded peak: below from the path's end
        held("below", "relaxed_peak", relaxed["peak"].c_rest, relaxed["peak"].c_rest + dc)
        switches["below"] = 0
        end = "no loaded peak"
    else:
        c_s = relaxed["start"].c_rest
        key = "relaxed_start"
        step = max((path.rows[path.peak, 8] - c_s) / opts.stairs, dc)
        end = ""
        while len(holds) < opts.max_holds:
            h = held("stair", key, c_s, c_s + step)
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
            held("below", kb, cb, cb + dc)
            switches["below"] = len(holds) - 1
            hp = holds[switches["past"]][3].history
            eta_peak = (hp[0, 10] - hp[0, 11]) / (0.5 * (hp[0, 10] + hp[0, 11]))
    # each switch's start held with no change of load: the anatomy's noise
    for sw in SWITCHES:
        if sw in switches:
            i = switches[sw]
            held(f"baseline_{sw}", starts[i], holds[i][1], holds[i][1])
            baselines[sw] = len(holds) - 1
    log(f"rest search: {end}; c peak at rest {c_peak / 1e3:.3f} kPa, {len(holds)} holds")
    probes, verdict = {}, {}
    if opts.probes:
        keys = ([k for k, _, _ in eq] + ["relaxed_peak"]
                + [f"h{k}_end" for k, (ro, _, _, h) in enumerate(holds)
                   if ro != "stair" and h.outcome == "equilibrium"])
        for key in keys:
            pr = journal.probe(key)
            if pr is None:
                pr = path_probe(journal.state(key), ratio, opts, threads, key)
                journal.add_probe(pr)
                log(f"probe at {key}: c {pr.c_before / 1e3:.3f} kPa, k_path {pr.k_path:.3g} Pa "
                    f"(dc {pr.c_after - pr.c_before:+.1f} Pa over d eps1 {pr.d_eps1:.3g}), "
                    f"{pr.outcome}")
            probes[key] = pr
        verdict = staircase_verdict(
            eq, [(ro, cf, ct, h.outcome, starts[i]) for i, (ro, cf, ct, h) in enumerate(holds)],
            probes, dc, opts.probe_d_eps1, end)
        st0 = journal.state("relaxed_start")
        verdict["probe_rate"] = probe_rate_of(len(st0.r), st0.params.dt, opts)
        log(f"theory: {verdict['verdict']} ({verdict['why']})")
    return StairResult({k: v._replace(state=None) for k, v in relaxed.items()}, holds, c_peak,
                       e_peak, eta_peak, switches, end, time.time() - t0, starts, probes,
                       verdict, baselines)
