"""Command line: python -m dem {biaxial, probes, domain, burst, params, bench, calibrate} (over
the library), its options from the vocabulary of ``common.options``. The cross-check of the
three parts moved above them (``python -m crosscheck``, issue 33): ``python -m dem crosscheck``
answers in one line where it went (``MOVED``)."""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

from common import options as opt     # the command-line rules shared by every CLI
from common.io import atomic_write_bytes, fmt
from point.burst_rule import RELEASE

from .params import OPTIONS


def _params(a):
    """DemParams of a command: --params FILE (or the paper's set), then the options given;
    ``a.params_note`` says where the values came from (``dem.params.params_from_args``)."""
    from .params import params_from_args
    return params_from_args(a)


def _check_state_params(own, a):
    """A state carries its parameters ``own``: refuse a --params file that differs (after the
    --damping override of a sensitivity check, if any)."""
    from .params import load_params
    if not getattr(a, "params", None):
        return
    given = load_params(a.params)
    if getattr(a, "damping", None) is not None:
        given = given.replace(damping=a.damping)
    if given != own:
        diff = [k for k in own.to_dict() if own.to_dict()[k] != given.to_dict()[k]]
        raise ValueError(f"--params {a.params} conflicts with the parameters the state carries "
                         f"({', '.join(diff)}); allowed: the state's own, or no --params")


def add_param_options(p, n_default=None, n_text="the file's, or 12000"):
    """--params FILE and the main DemParams fields as options (None: from the file / defaults),
    checked by DemParams (``params_from_args``); --n by the parser (its cap is the CLI's)."""
    from .params import DemParams
    d = DemParams()
    add = opt.add
    g = p.add_argument_group("DEM parameters (the paper's set unless --params FILE; an option "
                             "given overrides the file)")
    add(g, "--params", metavar="FILE", note="of the DEM: python -m dem params --out FILE",
        default_text="the paper's set")
    add(g, "--n", n_default, default_text=n_text)
    for option, field in OPTIONS.items():
        if option != "--n":
            add(g, option, record="DemParams", metavar=field.upper(),
                default_text=f"the file's, else {getattr(d, field):g}")


def cmd_params(a):
    from .params import save_params
    p = _params(a)
    save_params(a.out, p, f"python -m dem params; {a.params_note}")
    print(a.params_note)
    print(f"params: {a.out}")


def _directions(a):
    from .probes import directions
    if a.directions:
        if len(set(a.directions)) != len(a.directions):
            raise opt.OptionError(f"--directions {a.directions}: allowed distinct angles [deg]")
        return [float(v) for v in a.directions]
    return directions(a.step_q3, a.step_other)


def _threads(a):
    from common.threads import set_default_threads
    set_default_threads(getattr(a, "threads", None))


def cmd_biaxial(a):
    from .experiment import run_biaxial
    _threads(a)
    t0 = time.time()
    res = run_biaxial(_params(a), a.out, rate=a.rate, confining=a.sigma2, eta_a=a.eta_a,
                      eps_max=a.eps1_max, compaction_friction_deg=a.compaction_phi_g,
                      resume=a.resume, vtk=not a.no_vtk,
                      save_fractions=tuple(a.save_fractions), save_etas=tuple(a.save_etas),
                      params_note=f"python -m dem biaxial; {a.params_note}", verbose=not a.quiet,
                      allow_soft=a.allow_soft)
    print(a.params_note)
    print(f"biaxial: {len(res.rows)} rows -> {os.path.join(a.out, 'biaxial.csv')}; "
          f"stateA={res.state_a_path} (eta {a.eta_a:g} "
          f"{'reached' if res.eta_a_reached else 'not reached: the fallback state, see summary.json'}); "
          f"porosity after compaction {fmt(res.compaction.get('porosity'), '.4f')}; "
          f"wall time {time.time() - t0:.1f} s")


def _probe_options(a):
    from .probes import ProbeOptions
    try:
        return ProbeOptions(norm=a.stress_norm, ramp_steps=a.ramp_steps,
                            unbalanced_tol=a.unbalanced_tol, stress_tol=a.stress_tol,
                            max_steps=a.max_steps, relax_max_steps=a.relax_max_steps,
                            plastic_tol=a.plastic_tol, strain_tol=a.strain_tol, ke_tol=a.ke_tol,
                            window=a.window, runaway_ratio=a.runaway_ratio,
                            fail_ratio=a.fail_ratio).validate()
    except ValueError as e:       # name the option as the command line spells it
        raise opt.record_error(e, "ProbeOptions") from None


def cmd_probes(a):
    from . import io
    from .params import record_params
    from .probes import reference_state, run_probes, write_probe_files
    opts = _probe_options(a)
    alphas = _directions(a)
    _threads(a)
    t0 = time.time()
    state, meta = io.load_state(a.state)
    note = f"parameters: the state's own ({a.state})"
    if a.damping is not None:
        note += f"; --damping {a.damping:g} overrides the state's damping {state.params.damping:g}"
        state = state._replace(params=state.params.replace(damping=a.damping))
    _check_state_params(state.params, a)
    os.makedirs(a.out, exist_ok=True)
    record_params(a.out, state.params, f"python -m dem probes; {note}")
    ck = os.path.join(a.out, "probe_runs.jsonl")
    if not a.resume and os.path.exists(ck):
        # keep the earlier sweep until the new one replaces it
        os.replace(ck, os.path.join(a.out, "probe_runs.previous.jsonl"))
        print(f"[probes] {a.out} held an earlier sweep: moved to probe_runs.previous.jsonl; "
              "probes.csv and the figures are replaced at the end (--resume keeps a sweep)",
              file=sys.stderr)
    state, ref = reference_state(state, a.out, opts, relax=not a.no_relax, resume=a.resume,
                                 verbose=not a.quiet)
    rows = run_probes(state, alphas, opts, workers=a.workers, scheduler=a.scheduler,
                      checkpoint=ck, verbose=not a.quiet)
    s2 = state.control.s_to[0]
    write_probe_files(rows, a.out, note=f"{state.params.n} disks, $\\sigma_2$ = {s2 / 1e3:.0f} kPa")
    from collections import Counter
    cnt = Counter(r["outcome"] for r in rows)
    summary = {"state": os.path.abspath(a.state), "parameters": note, "reference": ref,
               "n_disks": state.params.n,
               "sigma2": s2, "directions": len(rows), "outcomes": dict(cnt),
               "options": opts._asdict(), "regime": a.regime, "wall_time": time.time() - t0}
    atomic_write_bytes(os.path.join(a.out, "summary.json"),
                          json.dumps(summary, indent=1, default=float).encode())
    print(note)
    print(f"probes: {len(rows)} directions -> {os.path.join(a.out, 'probes.csv')}; "
          f"reference: {ref}; " + ", ".join(f"{cnt[k]} {k}" for k in ("equilibrium", "failure",
                                                                       "undecided"))
          + f"; wall time {time.time() - t0:.1f} s")


def cmd_domain(a):
    from .domain import run_domain
    opts = _probe_options(a)
    alphas = _directions(a)
    _threads(a)
    t0 = time.time()
    states = [s for s in a.states.split(",") if s] if a.states else None
    if a.params:
        from .domain import load_states
        todo, _ = load_states(a.biaxial, states)
        for _, st, _ in todo:
            _check_state_params(st.params, a)
    from .domain import eta_lim_text
    rows, b, _ = run_domain(a.biaxial, a.out, states=states, alphas=alphas, opts=opts,
                         workers=a.workers, scheduler=a.scheduler, resume=a.resume,
                         hmodel=not a.no_hmodel, verbose=not a.quiet, allow_soft=a.allow_soft)
    print(f"domain: {len(rows)} states -> {os.path.join(a.out, 'domain.csv')}; lower boundary: "
          f"{b['lower_state']} (eta {b['lower_eta']:.4f}, {b['lower_eta_fraction']:.3f} of the "
          f"peak {b['eta_peak']:.4f}, {b['lower_why']}); {eta_lim_text(b)}; "
          f"wall time {time.time() - t0:.1f} s")


def parse_ratios(text):
    """argparse type of --ratios: comma-separated R < 0 (R = 0, R > 0, not finite: why not);
    also ``python -m crosscheck``'s."""
    from .burst import check_ratio
    try:
        vals = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        vals = []
    if not vals:
        raise argparse.ArgumentTypeError(f"{text!r} is not a comma-separated list of numbers: "
                                         "allowed R < 0")
    try:
        return [check_ratio(v, option=None) for v in vals]
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def _burst_options(a):
    """BurstOptions of the command line, its ranges checked (``BurstOptions.validate``), before
    the states load; the rule of the sample's size: ``_burst_size``."""
    from .burst import BurstOptions
    try:
        return BurstOptions(rate=a.rate, path_strain=a.path_strain, peak_drop=a.peak_drop,
                            peak_strain=a.peak_strain, below_rise=a.below_rise, dc=a.dc,
                            unbalanced_tol=a.unbalanced_tol, stress_tol=a.stress_tol,
                            strain_tol=a.strain_tol, ke_tol=a.ke_tol, window=a.window,
                            max_steps=a.max_steps, fail_strain=a.fail_strain, hold=a.hold,
                            wall_mass=a.wall_mass, wall_period_steps=a.wall_period_steps,
                            relax_max_steps=a.relax_max_steps, stairs=a.stairs,
                            max_holds=a.max_holds, probes=not a.no_probes,
                            probe_d_eps1=a.probe_d_eps1,
                            probe_rate=a.probe_rate).validate()
    except ValueError as e:       # name the option as the command line spells it
        raise opt.record_error(e, "BurstOptions") from None


def _burst_size(a, opts):
    """The rule of the sample's size (``BurstOptions.check_size``) at the disk count of the
    states of --biaxial, read from its summary.json before any state loads
    (``dem.burst.check_sample_size``, as ``run_burst`` checks it)."""
    from .burst import check_sample_size
    try:
        check_sample_size(a.biaxial, opts)
    except ValueError as e:       # name the option as the command line spells it
        raise opt.record_error(e, "BurstOptions") from None


def cmd_burst(a):
    from .burst import run_burst
    _threads(a)
    t0 = time.time()
    rows, s = run_burst(a.biaxial, a.out, a.ratios, a.start_fractions, a.burst_options,
                        workers=a.workers, threads=a.threads, params_file=a.params,
                        stage=a.stage, resume=a.resume, scheduler=a.scheduler,
                        verbose=not a.quiet, allow_soft=a.allow_soft)
    a.stage.wrote("params.json", "burst.csv", "history.csv", "paths.csv", "rest.csv",
                  "stairs.csv", "probes.csv", "summary.json", "fig_burst_c.png",
                  "fig_burst_ke.png", "fig_burst_strain.png", "fig_burst_ledger.png",
                  "fig_burst_anatomy.png", "fig_burst_k.png")
    for r in rows:
        loaded = (f"loaded {r['c_loaded'] / 1e3:.2f} kPa" if math.isfinite(r["c_loaded"]) else
                  "past the loaded path's last record")
        release = (f"E_c passed {RELEASE:g} W2_ext at {r['t_release']:.3g} s" if r["released"]
                   else f"E_c at most {r['ke_w2ext_max']:.2g} W2_ext")
        print(f"R = {r['ratio']:g}, f = {r['start_fraction']:g}, {r['switch']} (c at rest "
              f"{r['c_switch'] / 1e3:.2f} kPa, {loaded}, + dc, eta {r['eta_switch']:.4f}, "
              f"{r['hold'].replace('_', ' ')}, k_path at the start {r['k_path_switch']:.3g} Pa): "
              f"{r['outcome']} after {r['steps']} steps; {release}, backbone E_c at the end "
              f"{r['ke_end_over_bound']:.3g} x the equilibrium bound; W2_int at the end "
              f"{r['w2_int_end']:.3g} J; unstable contacts up to {r['n_unstable_max']:.0f} "
              f"(held without a change of load: up to {r['unstable_noise_max']:.0f}); "
              f"bookkeeping of Eq. 1 closes to {r['eq1_bookkeeping']:.1e}")
    for p in s["paths"]:
        v = p.get("theory") or {}
        if v:
            print(f"R = {p['ratio']:g}, f = {p['start_fraction']:g}: theory {v['verdict']}: "
                  f"{v['why']}; k_path = 0 at c = {v['c_cross'] / 1e3:.3f} kPa, the dead load "
                  f"held {v['overshoot_c']:.0f} Pa (eps1 {v['overshoot_eps1']:.2e}) past it")
    print(f"burst: {len(rows)} runs -> {os.path.join(a.out, 'burst.csv')}, history.csv, "
          f"paths.csv, figures; wall time {time.time() - t0:.1f} s")


def cmd_bench(a):
    from .bench import bench
    res = bench(params=_params(a), steps=a.steps, cache_dir=a.cache, busy=a.busy_core,
                rounds=a.rounds, allow_soft=a.allow_soft)
    for k, v in res.items():
        if k != "ledger_cost":
            print(f"{k}: {fmt(v, '.4g') if isinstance(v, float) else v}")
    print(f"ledger_cost: {res['ledger_cost']:.3f} (a step's time with the energy ledger over "
          "without it)")
    print(f"particle-steps/s: {res['particle_steps_per_s_auto']:.4g}")


def _calibration_options(a):
    """The calibration's options of the command line (``CalibrationOptions``), validated with
    the start set by the rule ``run_calibration`` applies too, before anything is computed or
    written: an OptionError of one line naming the option otherwise."""
    from .calibrate import CalibrationOptions
    if a.n is None and a.params is None:
        a.n = 2000                       # calibrate's default sample (see its --help)
    return CalibrationOptions(target=a.target, vary=a.vary, bounds=a.bounds, seeds=a.seeds,
                              check_seeds=a.check_seeds, initial=a.initial, batch=a.batch,
                              max_evals=a.max_evals, rate=a.rate, confining=a.sigma2,
                              eps_max=a.eps1_max, post_peak_strain=a.post_peak_strain,
                              smooth=a.smooth, decide_on_first_run=not a.no_first_run_decision,
                              stop_decided_runs=a.stop_decided_runs).validate(_params(a))


def cmd_calibrate(a):
    from .calibrate import run_calibration
    options = getattr(a, "calibration", None) or _calibration_options(a)
    t0 = time.time()
    s = run_calibration(a.out, _params(a), options=options, workers=a.workers,
                        scheduler=a.scheduler, resume=a.resume,
                        stage=getattr(a, "stage", None), params_note=a.params_note,
                        verbose=not a.quiet, allow_soft=a.allow_soft)
    print(a.params_note)
    print("\n".join(s["verdict"]["text"]))
    print(f"calibrate: {s['evaluations']} parameter sets, {s['runs']} runs ({s['run_now']} run "
          f"now, {s['taken_from_checkpoint']} from the checkpoint), stopped: {s['stopped']}; "
          f"{os.path.join(a.out, 'calibrated.json')}, report.md, calibration.csv, "
          f"calibration.png; wall time {time.time() - t0:.1f} s")


DESCRIPTION = """The compact 2D DEM (Numba) and the paper's DEM experiment: a sample compacted and
tested in drained biaxial compression, stress probes and the bifurcation domain, the burst, the
calibration against the H-model (the cross-check of the three parts: python -m crosscheck).
python -m dem COMMAND --help lists a command's options, each with its unit and default. --out is
required: a folder (the parameter file for params) that records the command that wrote it
(command.json); another command refuses that folder unless --force."""


def _equilibrium_options(p, record):
    """The equilibrium rule of dem.settle: its tolerances, shared by probes, domain (checked by
    ProbeOptions) and burst (by BurstOptions)."""
    add = opt.add
    g = p.add_argument_group("equilibrium (dem.settle's rule)")
    add(g, "--unbalanced-tol", 1e-4, record=record)
    add(g, "--stress-tol", 25.0, record=record)
    add(g, "--strain-tol", 0.01, record=record)
    add(g, "--ke-tol", 1e-10, record=record)
    add(g, "--window", 20_000, record=record)


def _probe_parser_options(p):
    """The options of every directional analysis (probes, domain), checked by ProbeOptions."""
    add = opt.add
    PO = "ProbeOptions"
    _equilibrium_options(p, PO)
    g = p.add_argument_group("stress probes")
    add(g, "--stress-norm", 2500.0, record=PO)
    add(g, "--step-q3", 5.0)
    add(g, "--step-other", 10.0)
    add(g, "--directions", default_text="every --step-q3 in the third quadrant, --step-other "
        "elsewhere (45 directions)")
    add(g, "--ramp-steps", 5000, record=PO)
    add(g, "--max-steps", 400_000, record=PO, note="of a probe (about 20 windows: 400,000 at "
        "1000 disks, 1,400,000 at 12,000)")
    add(g, "--runaway-ratio", 100.0, record=PO)
    add(g, "--fail-ratio", 1000.0, record=PO)
    add(g, "--plastic-tol", 0.05, record=PO)
    add(g, "--relax-max-steps", 2_000_000, record=PO, note="of the state into the reference")
    add(g, "--threads", default_text="auto (common.threads)", note="of the relaxation; each probe "
        "runs on one")
    add(g, "--workers", default_text="the cores")
    add(g, "--scheduler", default_text="none (local processes)")


def build_parser() -> opt.Parser:
    """The parser of ``python -m dem`` (every subcommand and option, from the vocabulary of
    ``common.options``), built without running anything: ``main`` parses with it, the tests
    check commands against it."""
    add = opt.add
    ap = opt.Parser(prog="python -m dem", description=DESCRIPTION)
    sub = ap.add_subparsers(dest="cmd", required=True, parser_class=opt.Parser, metavar="COMMAND")

    b = sub.add_parser("biaxial", help="compaction and drained biaxial test, states saved along "
                                       "the path (Figs. 13-14)")
    opt.add_out(b)
    add_param_options(b)
    g = b.add_argument_group("the test")
    add(g, "--sigma2", 200e3, note="held on the lateral walls")
    add(g, "--rate", 0.01)
    add(g, "--eta-a", 1.029, note="the state saved as stateA.npz")
    add(g, "--eps1-max", 0.10)
    add(g, "--compaction-phi-g", 0.0)
    add(g, "--save-fractions", [0.8, 0.85, 0.9, 0.93, 0.95, 0.97])
    add(g, "--save-etas", [], default_text="none")
    add(g, "--resume", note="from --out/checkpoint.npz")
    add(g, "--no-vtk")
    add(g, "--allow-soft")
    add(g, "--threads", default_text="auto (common.threads)")
    opt.add_quiet(g)
    b.set_defaults(func=cmd_biaxial)

    p = sub.add_parser("probes", help="directional analysis (stress probes) from a saved state "
                                      "(Figs. 15-17)")
    add(p, "--state", required=True, metavar="FILE")
    opt.add_out(p)
    _probe_parser_options(p)
    add(p, "--no-relax")
    add(p, "--allow-soft", note="the state's parameters at its confining stress")
    add(p, "--damping", record="DemParams", note="overrides the state's (a sensitivity check)",
        default_text="the state's")
    add(p, "--params", metavar="FILE", note="refused unless it is the state's own (a state "
        "carries its parameters)", default_text="the state's")
    add(p, "--resume", note="the runs in --out/probe_runs.jsonl (and --out/stateR.npz); only the "
        "missing ones run")
    opt.add_quiet(p)
    p.set_defaults(func=cmd_probes)

    d = sub.add_parser("domain", help="the DEM's bifurcation domain: directional analyses of the "
                                      "states saved along a biaxial test")
    add(d, "--biaxial", required=True, metavar="DIR")
    opt.add_out(d)
    add(d, "--states", default_text="all")
    _probe_parser_options(d)
    add(d, "--params", metavar="FILE", note="refused unless it is the states' own",
        default_text="the states'")
    add(d, "--no-hmodel")
    add(d, "--allow-soft", note="the states' parameters at the test's sigma2")
    add(d, "--resume", note="the references and probe runs in --out")
    opt.add_quiet(d)
    d.set_defaults(func=cmd_domain)

    u = sub.add_parser("burst", help="failure made to happen: the proportional strain path "
                                     "d eps2 = R d eps1 from states of a biaxial test and its "
                                     "conjugate stress c = s1 + R s2 held below and past its "
                                     "peak (docs/burst.md, docs/dem.md)")
    BO = "BurstOptions"
    add(u, "--biaxial", required=True, metavar="DIR")
    opt.add_out(u)
    g = u.add_argument_group("the paths and the switch")
    add(g, "--ratios", [-2.0], parse=parse_ratios)
    add(g, "--start-fractions", [0.9], note="among those dem biaxial --save-fractions saved")
    add(g, "--dc", 100.0, record=BO, note="dG = W t dc")
    add(g, "--rate", 0.01, record=BO, note="of the path")
    add(g, "--path-strain", 0.03, record=BO, note="the path ends there without a c peak")
    add(g, "--peak-drop", 150e3, record=BO)
    add(g, "--peak-strain", 5e-3, record=BO)
    add(g, "--below-rise", 0.5, record=BO)
    add(g, "--hold", "dead_load", record=BO, choices=("dead_load", "servo"))
    add(g, "--wall-mass", record=BO, default_text="the rule: the walls' period on their "
        "contacts = --wall-period-steps steps")
    add(g, "--wall-period-steps", 200.0, record=BO)
    add(g, "--relax-max-steps", 1_000_000, record=BO, note="at least two equilibrium windows")
    add(g, "--stairs", 8, record=BO)
    add(g, "--max-holds", 40, record=BO)
    add(g, "--probe-d-eps1", 1e-5, record=BO)
    add(g, "--probe-rate", None, record=BO,
        default_text="the rate at which the probe's move lasts one equilibrium window "
                     "(1.5e-4 at 2000 disks, 6.2e-5 at 12,000; docs/burst.md)")
    add(g, "--no-probes")
    add(g, "--max-steps", 1_000_000, record=BO, note="of a switched run")
    add(g, "--fail-strain", 0.01, record=BO)
    _equilibrium_options(u, BO)
    g = u.add_argument_group("the run")
    add(g, "--resume", note="the paths, relaxations, holds and probes in --out "
        "(burst_runs.jsonl, rest/)")
    add(g, "--scheduler", default_text="none (local processes)")
    add(g, "--workers", default_text="the cores", note="the paths, then every run of the rest "
        "searches: each staircase's holds one after another, its probes, below run and "
        "baselines beside it on the other workers as their states come; one thread each "
        "(the staircase of a single path on --threads)")
    add(g, "--threads", default_text="auto (common.threads)", note="of a run alone in the process")
    add(g, "--params", metavar="FILE", note="refused unless it is the states' own",
        default_text="the states'")
    add(g, "--allow-soft", note="the states' parameters at the test's sigma2")
    opt.add_quiet(g)
    u.set_defaults(func=cmd_burst)

    q = sub.add_parser("params", help="write a DemParams file (the paper's set, or the options "
                                      "given)")
    add_param_options(q)
    opt.add_out(q, "file")
    q.set_defaults(func=cmd_params)

    c = sub.add_parser("bench", help="particle-steps/s on a dense confined sample")
    add_param_options(c)
    add(c, "--steps", 2000)
    add(c, "--cache", os.path.join(os.path.expanduser("~"), ".cache", "dem"), metavar="DIR")
    add(c, "--rounds", 1)
    add(c, "--busy-core")
    add(c, "--allow-soft", note="the sample's parameters at 200 kPa")
    c.set_defaults(func=cmd_bench)

    from .calibrate import CalibrationOptions, TARGETS, bounds_type, seeds_type, vary_type
    k = sub.add_parser("calibrate", help="fit DEM parameters to the H-model's drained biaxial "
                                         "test (peak q, eps1 at 95 %% of it, secant modulus, "
                                         "dilatancy ratio)",
                       description="Fit the --vary fields of the start set (--params / the "
                                   "options, the paper's set by default; --n defaults to 2000 "
                                   "here) so that the DEM's drained biaxial test matches the "
                                   "H-model's: peak q within 5 %, eps1 where q first reaches "
                                   "95 % of its peak within 25 %, secant modulus q/eps1 at "
                                   "eps1 = 0.25 % within 20 %, dilatancy ratio 1 - d eps_v/"
                                   "d eps1 over the 1 % after that strain within 5 % (means "
                                   "over --seeds); a global "
                                   "search that stops when they are met or when its model of "
                                   "the figures shows that no set within the bounds can meet "
                                   "them. See docs/dem.md.")
    opt.add_out(k)
    add_param_options(k, n_text="the file's, else 2000")
    # the search's and each test's options: checked by CalibrationOptions (its one table of
    # ranges, and the rules between two values), as run_calibration checks them; its defaults
    CO, D = "CalibrationOptions", CalibrationOptions()
    ranged = lambda g, option, field, **kw: add(g, option, getattr(D, field), record=CO,
                                                allowed=CalibrationOptions.allowed_text(field),
                                                **kw)
    g = k.add_argument_group("the fit")
    add(g, "--target", D.target, choices=TARGETS, note="the H-model's, Table I, at --sigma2")
    add(g, "--vary", D.vary, parse=vary_type)
    add(g, "--bounds", parse=bounds_type, default_text="kn_over_d 2e9:32e9 log, phi_g 10:50, "
        "kt_over_kn 0.2:1, rolling_friction 0:0.3, rolling_stiffness 0.25:4 log; others 0.5-2 x "
        "the start value")
    add(g, "--seeds", D.seeds, parse=seeds_type)
    add(g, "--check-seeds", D.check_seeds, parse=seeds_type)
    add(g, "--no-first-run-decision")
    add(g, "--stop-decided-runs")
    ranged(g, "--initial", "initial")
    ranged(g, "--batch", "batch")
    ranged(g, "--max-evals", "max_evals")
    g = k.add_argument_group("each test")
    ranged(g, "--rate", "rate")
    ranged(g, "--sigma2", "confining")
    ranged(g, "--eps1-max", "eps_max", note="also ends --post-peak-strain after the peak")
    ranged(g, "--post-peak-strain", "post_peak_strain", note="with q below 0.98 of it")
    ranged(g, "--smooth", "smooth")
    g = k.add_argument_group("the run")
    add(g, "--workers", default_text="the cores", note="each evaluation runs on one thread")
    add(g, "--scheduler", default_text="none (local processes)")
    add(g, "--resume", note="every evaluation in --out/evaluations.jsonl is taken")
    add(g, "--allow-soft", note="the softest set of --bounds at --sigma2")
    opt.add_quiet(g)
    k.set_defaults(func=cmd_calibrate)
    return ap


BIAXIAL_FOLDER = "the output folder of python -m dem biaxial (its states/ and summary.json)"
STATE_FILE = ("a DEM state file: an .npz written by python -m dem biaxial (its stateA.npz or "
              "states/state_f*.npz)")


def check_state(path, option="--state"):
    """A DEM state file, or an OptionError of one line naming what a state file is."""
    from . import io
    opt.check_file(path, option, STATE_FILE)
    try:
        io.load_state(path)
    except ValueError as e:
        why = str(e)
        head = f"state file {path}"
        why = why[len(head):].lstrip(":, ") if why.startswith(head) else why
        raise opt.OptionError(f"{option} {path}: {why}; allowed {STATE_FILE}") from None


BENCH_STRESS = 200e3      # the confining stress of dem bench's sample (dem.bench.confined_sample)


def check_regime_of(a):
    """The granular regime of a command's parameters at its confining stress
    (``dem.regime.check_regime``), before anything runs: a SoftContactError (a ValueError: one
    line, exit 2) outside it unless --allow-soft; returns what the summary records (None for a
    command that runs nothing). biaxial, bench: the parameters at --sigma2 (bench: 200 kPa);
    probes: the state's at its confining stress; domain, burst: the states' at the biaxial test's
    sigma2; calibrate: the softest set of its search space at --sigma2."""
    from . import regime as R
    soft = bool(getattr(a, "allow_soft", False))
    if a.cmd in ("biaxial", "bench"):
        P = _params(a)
        sigma = a.sigma2 if a.cmd == "biaxial" else BENCH_STRESS
        given = ([f"--params {a.params}"] if a.params else []) + (
            [f"--kn-over-d {a.kn_over_d:g}"] if a.kn_over_d is not None else []) + (
            [f"--sigma2 {sigma:g}"] if a.cmd == "biaxial" and sigma != BENCH_STRESS else [])
        where = ", ".join(given) or "the paper's set"
        return R.check_regime(P, sigma, soft, where, "--sigma2" if a.cmd == "biaxial" else "")
    if a.cmd == "probes":
        from . import io
        st, _ = io.load_state(a.state)
        from .simulation import confining_stress
        return R.check_regime(st.params, confining_stress(st), soft,
                              f"--state {a.state} (its parameters)", "")
    if a.cmd in ("domain", "burst"):
        return R.check_biaxial_regime(a.biaxial, soft)
    if a.cmd == "calibrate":
        from .calibrate import make_space
        o = a.calibration
        space = make_space(o.vary, _params(a), o.bounds)
        soft_set, where = R.softest(space, _params(a))
        return R.check_regime(soft_set, o.confining, soft, where, "--sigma2")
    return None


def check_run_options(a):
    """--workers or --scheduler (not both; the scheduler's address reachable, dask.distributed
    installed) and --threads, before anything runs: the DEM commands' and python -m crosscheck's."""
    if getattr(a, "scheduler", None) and getattr(a, "workers", None):
        raise opt.OptionError("--workers and --scheduler: allowed one of them")
    if getattr(a, "scheduler", None):
        from .probes import check_scheduler
        check_scheduler(a.scheduler)
    if getattr(a, "threads", None) is not None:
        from common.threads import check_threads
        check_threads(a.threads)


def compile_kernels_once():
    """Compile the DEM kernels now if Numba has none cached (saying so in one line, and how long
    it took), so that a command's own timers leave the compilation out."""
    from . import kernels
    if opt.announce_compilation([kernels.advance, kernels.build_pairs, kernels.contact_snapshot]):
        from .simulation import compile_kernels
        t = time.time()
        compile_kernels()
        print(f"compiled in {time.time() - t:.1f} s", file=sys.stderr, flush=True)


# commands that moved out of python -m dem: one line says where (exit 2)
MOVED = {"crosscheck": "python -m crosscheck"}


def moved_line(argv) -> str | None:
    """The line that answers a command of ``MOVED`` (the first word of ``argv`` that is no
    option), or None."""
    word = next((w for w in argv if not w.startswith("-")), None)
    if word not in MOVED:
        return None
    return (f"error: python -m dem {word} moved to {MOVED[word]}, with the same options "
            f"(see {MOVED[word]} --help)")


def main(argv=None):
    line = moved_line(sys.argv[1:] if argv is None else argv)
    if line:
        print(line, file=sys.stderr)
        sys.exit(2)

    def run(a, stage):
        if a.cmd == "params":
            opt.check_out_file(a.out)
        elif hasattr(a, "out"):
            opt.check_out_dir(a.out)
        if getattr(a, "cache", None):
            opt.check_out_dir(a.cache, "--cache")
        # a bad parameter file or option is refused before the compilation
        from .params import load_params
        if hasattr(a, "kn_over_d"):          # a command of add_param_options
            _params(a)
        elif getattr(a, "params", None):     # probes, domain: compared with the states' later
            load_params(a.params)
        check_run_options(a)
        if getattr(a, "directions", None):
            _directions(a)            # bad input before the compilation
        if a.cmd in ("probes", "domain"):
            _probe_options(a)
        if a.cmd == "calibrate":
            a.calibration = _calibration_options(a)     # before the compilation, as every check
        if getattr(a, "damping", None) is not None and a.cmd == "probes":
            from .params import DemParams
            try:
                DemParams().replace(damping=a.damping)
            except ValueError as e:
                raise opt.record_error(e, "DemParams") from None
        if getattr(a, "state", None):
            check_state(a.state)      # a missing or foreign state file, before the compilation
        if getattr(a, "biaxial", None):
            opt.check_folder(a.biaxial, "--biaxial", BIAXIAL_FOLDER, ("python -m dem biaxial",))
        if a.cmd == "burst":
            from .burst import load_starts
            # bad options and input files before the compilation: the options' ranges, then the
            # rule of the sample's size (its disk count read cheaply), both before the states load
            a.burst_options = _burst_options(a)
            _burst_size(a, a.burst_options)
            starts, _, _ = load_starts(a.biaxial, a.start_fractions, a.params)
            if a.resume:              # a folder of other states is refused before the kernels
                from .burst import checkpoint_header, read_checkpoint
                read_checkpoint(a.out, checkpoint_header(starts, a.ratios, a.burst_options))
        elif getattr(a, "biaxial", None):
            from .domain import load_states
            load_states(a.biaxial, [s for s in (getattr(a, "states", None) or "").split(",") if s])
        a.regime = check_regime_of(a)   # a set outside the granular regime, before any run
        stage.at(f"dem {a.cmd}" + (" (run it again with --resume to continue)"
                                   if hasattr(a, "resume") else ""))
        if a.cmd != "params":
            compile_kernels_once()    # before the command's own timers start
        a.stage = stage           # a command may say where it is (dem calibrate)
        from .regime import UnsoundState
        try:
            a.func(a)
        except UnsoundState as e:     # a run's failure, not bad input: one line, exit 1
            from .io import save_unsound
            kept = save_unsound(e, getattr(a, "out", None) if a.cmd != "params" else None)
            print(f"stopped: {e}" + (f"; the state is kept in {kept}" if kept else ""),
                  file=sys.stderr)
            return 1
        return 0

    code = opt.run_cli(build_parser(), argv, run, errors=(ValueError, RuntimeError))
    if code:
        sys.exit(code)


if __name__ == "__main__":
    main()
