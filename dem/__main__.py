"""Command line: python -m dem {biaxial, probes, domain, calibrate, ...} (thin layer over the library)."""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

from hmodel import options as opt     # the command-line rules shared by every CLI
from hmodel.burst_rule import RELEASE
from hmodel.io import fmt

from .threads import available_threads


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


def add_param_options(p, n_default=None):
    """--params FILE and the main DemParams fields as options (None: from the file / defaults)."""
    p.add_argument("--params", default=None, help="DemParams as JSON (python -m dem params --out FILE)")
    p.add_argument("--n", type=opt.integer(1, 10_000_000), default=n_default,
                   help="number of disks (default: the file's, or 12000)")
    p.add_argument("--seed", type=opt.integer(0), default=None)
    p.add_argument("--r-min", type=opt.real(0, 1), default=None, help="[m]")
    p.add_argument("--r-max", type=opt.real(0, 1), default=None, help="[m]")
    p.add_argument("--density", type=opt.real(0, 1e5), default=None, help="[kg/m^3]")
    p.add_argument("--kn-over-d", type=opt.real(0, 1e13), default=None, help="kn / mean diameter [Pa]")
    p.add_argument("--kt-over-kn", type=opt.real(0, 10), default=None)
    p.add_argument("--friction", type=opt.real(0, 90, lo_open=False), default=None, help="[deg]")
    p.add_argument("--damping", type=opt.real(0, 1, lo_open=False), default=None,
                   help="Cundall damping")
    p.add_argument("--dt-safety", type=opt.real(0, 0.5, hi_open=False), default=None)
    p.add_argument("--rolling-friction", type=opt.real(0, 10, lo_open=False), default=None,
                   help="mu_r: rolling moment capped at mu_r R* fn (0 = free rotation, the paper's)")
    p.add_argument("--rolling-stiffness", type=opt.real(0, 1e3), default=None,
                   help="k_r = this * kt * R*^2 (used only with --rolling-friction > 0)")


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
    from .threads import set_default_threads
    set_default_threads(getattr(a, "threads", None))


THREADS = opt.integer(1, available_threads())


def cmd_biaxial(a):
    from .experiment import run_biaxial
    _threads(a)
    t0 = time.time()
    res = run_biaxial(_params(a), a.out, rate=a.rate, confining=a.confining, eta_a=a.eta_a,
                      eps_max=a.eps_max, compaction_friction_deg=a.compaction_friction,
                      resume=a.resume, vtk=not a.no_vtk,
                      save_fractions=tuple(a.save_fractions), save_etas=tuple(a.save_etas),
                      params_note=f"python -m dem biaxial; {a.params_note}", verbose=not a.quiet)
    print(a.params_note)
    print(f"biaxial: {len(res.rows)} rows -> {os.path.join(a.out, 'biaxial.csv')}; "
          f"stateA={res.state_a_path} (eta {a.eta_a:g} "
          f"{'reached' if res.eta_a_reached else 'not reached: the fallback state, see summary.json'}); "
          f"porosity after compaction {fmt(res.compaction.get('porosity'), '.4f')}; "
          f"wall time {time.time() - t0:.1f} s")


def _probe_options(a):
    from .probes import ProbeOptions
    return ProbeOptions(norm=a.norm, ramp_steps=a.ramp_steps, unbalanced_tol=a.unbalanced_tol,
                        stress_tol=a.stress_tol, max_steps=a.max_steps,
                        relax_max_steps=a.relax_max_steps, plastic_tol=a.plastic_tol,
                        strain_tol=a.strain_tol, ke_tol=a.ke_tol, window=a.window,
                        runaway_ratio=a.runaway_ratio, fail_ratio=a.fail_ratio).validate()


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
               "options": opts._asdict(), "wall_time": time.time() - t0}
    io.atomic_write_bytes(os.path.join(a.out, "summary.json"),
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
                         hmodel=not a.no_hmodel, verbose=not a.quiet)
    print(f"domain: {len(rows)} states -> {os.path.join(a.out, 'domain.csv')}; lower boundary: "
          f"{b['lower_state']} (eta {b['lower_eta']:.4f}, {b['lower_eta_fraction']:.3f} of the "
          f"peak {b['eta_peak']:.4f}, {b['lower_why']}); {eta_lim_text(b)}; "
          f"wall time {time.time() - t0:.1f} s")


def _ratios(text):
    """argparse type of --ratios: comma-separated R < 0 (R = 0, R > 0, not finite: why not)."""
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


def _burst_options(a, n_disks=None):
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
                            probe_rate=a.probe_rate).validate(n_disks)
    except ValueError as e:       # name the option as the command line spells it
        msg = str(e)
        name = msg.split("=", 1)[0]
        raise ValueError(f"--{name.replace('_', '-')}{msg[len(name):]}") from None


def cmd_burst(a):
    from .burst import run_burst
    _threads(a)
    t0 = time.time()
    rows, s = run_burst(a.biaxial, a.out, a.ratios, a.start_fractions, a.burst_options,
                        workers=a.workers, threads=a.threads, params_file=a.params,
                        stage=a.stage, resume=a.resume, scheduler=a.scheduler,
                        verbose=not a.quiet)
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
                rounds=a.rounds)
    for k, v in res.items():
        if k != "ledger_cost":
            print(f"{k}: {fmt(v, '.4g') if isinstance(v, float) else v}")
    print(f"ledger_cost: {res['ledger_cost']:.3f} (a step's time with the energy ledger over "
          "without it)")
    print(f"particle-steps/s: {res['particle_steps_per_s_auto']:.4g}")


def cmd_calibrate(a):
    from .calibrate import run_calibration
    if a.n is None and a.params is None:
        a.n = 2000                       # calibrate's default sample (see its --help)
    t0 = time.time()
    s = run_calibration(a.out, _params(a), a.vary, bounds=a.bounds, target=a.target,
                        seeds=a.seeds, check_seeds=a.check_seeds, initial=a.initial,
                        batch=a.batch, max_evals=a.max_evals, rate=a.rate,
                        confining=a.confining, eps_max=a.eps_max,
                        post_peak_strain=a.post_peak_strain, smooth=a.smooth,
                        workers=a.workers, scheduler=a.scheduler, resume=a.resume,
                        stage=getattr(a, "stage", None), params_note=a.params_note,
                        verbose=not a.quiet)
    print(a.params_note)
    print("\n".join(s["verdict"]["text"]))
    print(f"calibrate: {s['evaluations']} parameter sets, {s['runs']} runs ({s['run_now']} run "
          f"now, {s['taken_from_checkpoint']} from the checkpoint), stopped: {s['stopped']}; "
          f"{os.path.join(a.out, 'calibrated.json')}, report.md, calibration.csv, "
          f"calibration.png; wall time {time.time() - t0:.1f} s")


def cmd_crosscheck(a):
    from .crosscheck import run_crosscheck
    t0 = time.time()
    c, timings = run_crosscheck(a.out, full=a.full, n=a.n, seed=a.seed, rate=a.rate,
                                workers=a.workers, skip_dem=a.skip_dem, domain=not a.no_domain,
                                dem_max_steps=a.max_steps, threads=a.threads, resume=a.resume,
                                dem_domain=a.dem_domain, dem_params=a.dem_params,
                                scheduler=a.scheduler, hmodel_params=a.hmodel_params,
                                burst=not a.no_burst, burst_ratios=a.burst_ratios,
                                burst_fractions=a.burst_fractions, verbose=not a.quiet)
    print(open(os.path.join(a.out, "report.md")).read().split("## The paper's conclusions")[1])
    print(f"crosscheck: report {os.path.join(a.out, 'report.md')}; wall time {time.time() - t0:.1f} s")


def build_parser() -> opt.Parser:
    """The parser of ``python -m dem`` (every subcommand and option), built without running
    anything: ``main`` parses with it, the tests check commands against it."""
    ap = opt.Parser(prog="python -m dem", description=__doc__)
    sub = ap.add_subparsers(dest="cmd", required=True, parser_class=opt.Parser)

    b = sub.add_parser("biaxial", help="compact and run the drained biaxial test")
    add_param_options(b)
    b.add_argument("--out", required=True)
    b.add_argument("--rate", type=opt.real(0, 10), default=0.01, help="axial strain rate [1/s]")
    b.add_argument("--confining", type=opt.real(0, 1e9), default=200e3, help="[Pa]")
    b.add_argument("--eta-a", type=opt.real(0, 2), default=1.029,
                   help="eta = q/p of point A (p = (s1 + s2)/2)")
    b.add_argument("--eps-max", type=opt.real(0, 0.5), default=0.10)
    b.add_argument("--compaction-friction", type=opt.real(0, 90, lo_open=False), default=0.0,
                   help="[deg]")
    b.add_argument("--save-fractions", type=opt.reals(0, 1, hi_open=False),
                   default=[0.8, 0.85, 0.9, 0.93, 0.95, 0.97],
                    help="save the first state at these fractions of the peak eta in DIR/states "
                        "(for `dem domain`); comma-separated, in (0, 1]")
    b.add_argument("--save-etas", type=opt.reals(0, 2), default=[],
                    help="also save the first state at these absolute eta (comma-separated)")
    b.add_argument("--resume", action="store_true", help="continue from DIR/checkpoint.npz")
    b.add_argument("--no-vtk", action="store_true")
    opt.add_quiet(b)
    b.add_argument("--threads", type=THREADS, default=None,
                    help="threads (results do not depend on it); default: auto, see dem.threads")
    b.set_defaults(func=cmd_biaxial)

    # the equilibrium rule of dem.settle: its tolerances, shared by probes, domain and burst
    eq = opt.Parser(add_help=False)
    eq.add_argument("--unbalanced-tol", type=opt.real(0, 1), default=1e-4,
                    help="equilibrium: unbalanced-force ratio at every check of the window")
    eq.add_argument("--stress-tol", type=opt.real(0), default=25.0,
                    help="equilibrium: stress error at every check of the window [Pa] (the wall "
                         "stresses' from their targets; dem burst: |c - c_target|)")
    eq.add_argument("--strain-tol", type=opt.real(0, 1), default=0.01,
                    help="equilibrium: strain drift over the window / the strain scale (a "
                         "probe's |de|; dem burst: the larger of the strain since the switch "
                         "and the elastic strain of 2.5 kPa)")
    eq.add_argument("--ke-tol", type=opt.real(0), default=1e-10,
                    help="equilibrium: backbone kinetic energy per disk [J]")
    eq.add_argument("--window", type=opt.integer(1000), default=20_000,
                    help="equilibrium window at 1000 disks [steps] (scaled with sqrt(n))")

    po = opt.Parser(add_help=False, parents=[eq])     # options of every directional analysis
    po.add_argument("--norm", type=opt.real(0, 1e8), default=2500.0, help="|dsigma| [Pa]")
    po.add_argument("--step-q3", type=opt.real(0, 90, hi_open=False), default=5.0,
                    help="[deg] in the third quadrant")
    po.add_argument("--step-other", type=opt.real(0, 90, hi_open=False), default=10.0,
                    help="[deg] elsewhere")
    po.add_argument("--directions", type=opt.reals(0, 360, lo_open=False), default=None,
                    help="comma-separated alpha_sigma [deg] in place of --step-q3/--step-other")
    po.add_argument("--ramp-steps", type=opt.integer(0), default=5000)
    po.add_argument("--max-steps", type=opt.integer(1), default=400_000,
                    help="cap of a probe run [steps]: undecided when reached (about 20 "
                         "windows: 400,000 at 1000 disks, 1,400,000 at 12,000)")
    po.add_argument("--runaway-ratio", type=opt.real(1), default=100.0,
                    help="failure: |de|/|de_elastic| beyond this with the wall stresses lost")
    po.add_argument("--fail-ratio", type=opt.real(1), default=1000.0,
                    help="failure: |de|/|de_elastic| beyond this")
    po.add_argument("--threads", type=THREADS, default=None,
                    help="threads of the relaxation (each probe runs on one); default: auto")
    po.add_argument("--plastic-tol", type=opt.real(0), default=0.05)
    po.add_argument("--relax-max-steps", type=opt.integer(1), default=2_000_000,
                    help="cap of the relaxation of the state into the reference [steps]")
    po.add_argument("--workers", type=opt.integer(1, 1024), default=None, help="local processes")
    po.add_argument("--scheduler", default=None, help="dask.distributed scheduler address")

    p = sub.add_parser("probes", parents=[po], help="directional analysis from a saved state")
    p.add_argument("--state", required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--no-relax", action="store_true",
                    help="probe from the saved state as is (no stress-controlled relaxation)")
    p.add_argument("--damping", type=opt.real(0, 1, lo_open=False), default=None,
                    help="override the Cundall damping of the state (sensitivity check)")
    p.add_argument("--params", default=None,
                    help="DemParams file; refused unless it is the state's own (states carry theirs)")
    p.add_argument("--resume", action="store_true",
                    help="keep the runs already in DIR/probe_runs.jsonl (and DIR/stateR.npz) "
                        "and run only the missing ones")
    opt.add_quiet(p)
    p.set_defaults(func=cmd_probes)

    d = sub.add_parser("domain", parents=[po],
                       help="the DEM's bifurcation domain: directional analyses of the states "
                            "saved along a biaxial test")
    d.add_argument("--biaxial", required=True, help="output folder of `dem biaxial`")
    d.add_argument("--params", default=None,
                    help="DemParams file; refused unless it is the states' own")
    d.add_argument("--out", required=True)
    d.add_argument("--states", default=None,
                    help="comma-separated states (file names or targets of DIR/states/states.csv, "
                        "e.g. f=0.9,f=0.95); default: all")
    d.add_argument("--no-hmodel", action="store_true",
                    help="leave the H-model's boundary out of the figure")
    d.add_argument("--resume", action="store_true",
                    help="keep the references and probe runs already in the output folder")
    opt.add_quiet(d)
    d.set_defaults(func=cmd_domain)

    u = sub.add_parser("burst", parents=[eq], help="failure made to happen: the proportional strain path "
                                     "d eps2 = R d eps1 from states of a biaxial test and its "
                                     "conjugate stress c = s1 + R s2 held below and past its "
                                     "peak (docs/burst.md, docs/dem.md)")
    u.add_argument("--biaxial", required=True, help="output folder of `dem biaxial` (its states)")
    u.add_argument("--out", required=True)
    u.add_argument("--ratios", type=_ratios, default=[-2.0],
                   help="comma-separated R < 0 of the paths d eps2 = R d eps1 (-1: isochoric)")
    u.add_argument("--start-fractions", type=opt.reals(0, 1, hi_open=False), default=[0.9],
                   help="start states: fractions of the drained peak eta saved by `dem biaxial "
                        "--save-fractions` (comma-separated)")
    u.add_argument("--dc", type=opt.real(0, lo_open=False), default=100.0,
                   help="the held step of c after the switch [Pa] (dG = W t dc)")
    u.add_argument("--rate", type=opt.real(0, 10, hi_open=False), default=0.01,
                   help="axial strain rate of the path [1/s]")
    u.add_argument("--path-strain", type=opt.real(0, 0.5), default=0.03,
                   help="the path ends this axial strain from its start without a c peak")
    u.add_argument("--peak-drop", type=opt.real(0), default=150e3,
                   help="c this far below its largest confirms the peak [Pa]")
    u.add_argument("--peak-strain", type=opt.real(0, 0.5), default=5e-3,
                   help="or the path this far beyond the largest c [-]")
    u.add_argument("--below-rise", type=opt.real(0, 1), default=0.5,
                   help="below: from the first equilibrium of the staircase whose c reaches "
                        "c_start + this (c_peak - c_start), all at rest (0 < below-rise < 1)")
    u.add_argument("--hold", choices=("dead_load", "servo"), default="dead_load",
                   help="how G is held after the switch: a dead load on the tied walls (one "
                        "dynamic degree of freedom, no servo) or the servo on c")
    u.add_argument("--wall-mass", type=opt.real(0), default=None,
                   help="the walls' generalized mass m_G under the dead load [kg] (default: the "
                        "rule, their period on their contacts = --wall-period-steps steps)")
    u.add_argument("--wall-period-steps", type=opt.real(20, lo_open=False), default=200.0,
                   help="the wall-mass rule: the walls' period on their contact stiffness in "
                        "time steps (>= 20)")
    u.add_argument("--relax-max-steps", type=opt.integer(1), default=1_000_000,
                   help="cap of a relaxation at fixed strain [steps] (at least two equilibrium "
                        "windows)")
    u.add_argument("--stairs", type=opt.integer(1), default=8,
                   help="the staircase's first step of c: (loaded peak - c at rest) / this")
    u.add_argument("--max-holds", type=opt.integer(2), default=40,
                   help="cap of the staircase's holds (the search then ends without a past run)")
    u.add_argument("--probe-d-eps1", type=opt.real(0, 1e-3, hi_open=False), default=1e-5,
                   help="the kinematic probe at every equilibrium: axial strain moved along the "
                        "path, 0 < value <= 1e-3 [-] (default 1e-5; docs/burst.md: the rule)")
    u.add_argument("--probe-rate", type=opt.real(0, 10, hi_open=False), default=1e-3,
                   help="the probe's axial strain rate [1/s], 0 < value <= --rate (default 0.001)")
    u.add_argument("--no-probes", action="store_true",
                   help="no kinematic probes (no k_path, no verdict of the theory)")
    u.add_argument("--resume", action="store_true",
                   help="keep the paths, relaxations and holds already in DIR (burst_runs.jsonl, "
                        "rest/)")
    u.add_argument("--scheduler", default=None,
                   help="dask.distributed scheduler address: the runs go to its workers")
    u.add_argument("--max-steps", type=opt.integer(1), default=1_000_000,
                   help="cap of a switched run [steps]: undecided when reached")
    u.add_argument("--fail-strain", type=opt.real(0, 1), default=0.01,
                   help="failure: |d eps| since the switch beyond this [-]")
    u.add_argument("--workers", type=opt.integer(1, 1024), default=None,
                   help="local processes (the paths, then each path's rest search and its runs; one "
                        "thread each)")
    u.add_argument("--threads", type=THREADS, default=None,
                   help="threads of a run alone in the process (results do not depend on it); "
                        "default: auto")
    u.add_argument("--params", default=None,
                   help="DemParams file; refused unless it is the states' own")
    opt.add_quiet(u)
    u.set_defaults(func=cmd_burst)

    q = sub.add_parser("params", help="write a DemParams file (the paper's set, or the options given)")
    add_param_options(q)
    q.add_argument("--out", required=True, help="the JSON file to write")
    q.set_defaults(func=cmd_params)

    c = sub.add_parser("bench", help="particle-steps/s on a dense confined sample")
    add_param_options(c)
    c.add_argument("--steps", type=opt.integer(1), default=2000)
    c.add_argument("--cache", default=os.path.join(os.path.expanduser("~"), ".cache", "dem"))
    c.add_argument("--rounds", type=opt.integer(1, 100), default=1, help="interleaved rounds")
    c.add_argument("--busy-core", action="store_true",
                    help="measure beside a busy-loop process (a shared machine)")
    c.set_defaults(func=cmd_bench)

    from .calibrate import DEFAULT_VARY, TARGETS, bounds_type, seeds_type, vary_type
    k = sub.add_parser("calibrate", help="fit DEM parameters to the H-model's drained biaxial "
                                         "test (peak q, eps1 at 95 %% of it, secant modulus)",
                       description="Fit the --vary fields of the start set (--params / the "
                                   "options, the paper's set by default; --n defaults to 2000 "
                                   "here) so that the DEM's drained biaxial test matches the "
                                   "H-model's: peak q within 5 %, eps1 where q first reaches "
                                   "95 % of its peak within 25 %, secant modulus q/eps1 at "
                                   "eps1 = 0.25 % within 20 % (means over --seeds); a global "
                                   "search that stops when they are met or when its model of "
                                   "the figures shows that no set within the bounds can meet "
                                   "them. See docs/dem.md.")
    add_param_options(k)
    k.add_argument("--target", choices=TARGETS, default="hmodel",
                   help="the curve to fit: the H-model, Table I, at --confining")
    k.add_argument("--out", required=True)
    k.add_argument("--vary", type=vary_type, default=DEFAULT_VARY,
                   help="comma-separated DemParams float fields (or their option names, "
                        "friction = friction_deg) to fit (default: %(default)s)")
    k.add_argument("--bounds", type=bounds_type, default=None,
                   help="search ranges NAME=LO:HI,... (default: kn_over_d 2e9:32e9 log, "
                        "friction 10:50, kt_over_kn 0.2:1, rolling_friction 0:0.3, "
                        "rolling_stiffness 0.25:4 log; others 0.5-2 x the start value)")
    k.add_argument("--seeds", type=seeds_type, default=(1, 2),
                   help="samples every set is run on; its figures are their means "
                        "(default: 1,2)")
    k.add_argument("--check-seeds", type=seeds_type, default=(3,),
                   help="samples the best set is then run on, not among --seeds (default: 3)")
    k.add_argument("--initial", type=opt.integer(3, 4096), default=16,
                   help="sets of the space-filling (Sobol) design before the model proposes "
                        "any (at least the number of varied parameters + 2)")
    k.add_argument("--batch", type=opt.integer(1, 64), default=1,
                   help="sets the model proposes per round")
    k.add_argument("--max-evals", type=opt.integer(1, 100_000), default=32,
                   help="parameter sets at most, the start set included, each run on every "
                        "seed (may be raised on --resume)")
    k.add_argument("--rate", type=opt.real(0, 10), default=0.01, help="axial strain rate [1/s]")
    k.add_argument("--confining", type=opt.real(0, 1e9), default=200e3, help="[Pa]")
    k.add_argument("--eps-max", type=opt.real(0.005, 0.5, lo_open=False), default=0.035,
                   help="end of each test (also ends post-peak-strain after its peak)")
    k.add_argument("--post-peak-strain", type=opt.real(0, 0.5), default=0.01,
                   help="a test stops this strain after its peak (q below 0.98 of it)")
    k.add_argument("--smooth", type=opt.real(0, 0.05, lo_open=False), default=0.001,
                   help="strain window of the moving average of q for the peak (0: raw)")
    k.add_argument("--workers", type=opt.integer(1, 1024), default=None,
                   help="local processes (each evaluation runs on one thread)")
    k.add_argument("--scheduler", default=None, help="dask.distributed scheduler address")
    k.add_argument("--resume", action="store_true",
                   help="take every evaluation already in DIR/evaluations.jsonl, run the rest")
    opt.add_quiet(k)
    k.set_defaults(func=cmd_calibrate)

    x = sub.add_parser("crosscheck", help="H-model, FE and DEM side by side (report.md + figures)")
    x.add_argument("--out", required=True)
    x.add_argument("--dem-params", default=None,
                    help="DemParams file of the DEM sample (default: the paper's stated set)")
    x.add_argument("--hmodel-params", default=None,
                    help="HParams file of the H-model and FE parts (python -m hmodel params; "
                         "default Table I; both at 200 kPa, the FE at 72 orientations)")
    x.add_argument("--full", action="store_true", help="the paper's 12,000 disks at 0.01/s (see README for the time)")
    x.add_argument("--n", type=opt.integer(2, 10_000_000), default=None, help="DEM disks (default 1000, 12000 with --full)")
    x.add_argument("--seed", type=opt.integer(0), default=1)
    x.add_argument("--rate", type=opt.real(0, 10), default=None, help="DEM axial strain rate [1/s] (0.05, 0.01 with --full)")
    x.add_argument("--max-steps", type=opt.integer(1), default=None, help="cap of each DEM probe run [steps]")
    x.add_argument("--workers", type=opt.integer(1, 1024), default=None,
                   help="local processes for the DEM's relaxations and probes")
    x.add_argument("--scheduler", default=None,
                   help="dask.distributed scheduler address for the DEM's relaxations and probes "
                        "(one task a run)")
    x.add_argument("--skip-dem", action="store_true", help="H-model and FE only")
    x.add_argument("--no-domain", action="store_true", help="skip the H-model bifurcation domain")
    x.add_argument("--threads", type=THREADS, default=None,
                    help="threads of the DEM compaction, biaxial test and relaxations "
                        "(results do not depend on it); default: auto, see dem.threads")
    x.add_argument("--resume", action="store_true",
                    help="keep the DEM work an interrupted run left in DIR/dem and do the rest")
    x.add_argument("--dem-domain", action=argparse.BooleanOptionalAction, default=None,
                    help="directional analyses at every saved DEM state (the DEM's bifurcation "
                         "domain); default: on, off with --full (use `dem domain` there)")
    x.add_argument("--no-burst", action="store_true",
                   help="skip the burst section (proportional strain paths, c held below / past "
                        "its peak, in the three parts: docs/burst.md)")
    x.add_argument("--burst-ratios", type=opt.reals(unit="-"), default=None,
                   help="R of the burst section's paths, each finite and < 0 (default -2)")
    x.add_argument("--burst-fractions", type=opt.reals(0, 1), default=None,
                   help="start states of the burst section, fractions of each part's drained "
                        "peak eta, 0 < f < 1, among the DEM's saved ones (default 0.90)")
    opt.add_quiet(x)
    x.set_defaults(func=cmd_crosscheck)
    return ap


def main(argv=None):
    def run(a, stage):
        if a.cmd == "params":
            opt.check_out_file(a.out)
        elif hasattr(a, "out"):
            opt.check_out_dir(a.out)
        # a bad parameter file or option is refused before the compilation
        from .params import load_params
        if hasattr(a, "kn_over_d"):          # a command of add_param_options
            _params(a)
        elif getattr(a, "params", None):     # probes, domain: compared with the states' later
            load_params(a.params)
        if getattr(a, "dem_params", None):
            load_params(a.dem_params, option="--dem-params")
        if getattr(a, "hmodel_params", None):
            from hmodel.params import load_params as load_hparams
            load_hparams(a.hmodel_params, option="--hmodel-params")
        if getattr(a, "scheduler", None) and getattr(a, "workers", None):
            raise opt.OptionError("--workers and --scheduler: allowed one of them")
        if getattr(a, "scheduler", None):
            from .probes import check_scheduler
            check_scheduler(a.scheduler)
        if getattr(a, "directions", None):
            _directions(a)            # bad input before the compilation
        if getattr(a, "state", None):
            from . import io
            io.load_state(a.state)    # a missing or foreign state file, before the compilation
        if a.cmd == "crosscheck" and not a.no_burst:
            from .burst import check_ratio
            from .experiment import SAVE_FRACTIONS
            for r in a.burst_ratios or ():
                check_ratio(r, "--burst-ratios")
            bad = [f for f in a.burst_fractions or () if f not in SAVE_FRACTIONS]
            if bad and not a.skip_dem:
                raise opt.OptionError(f"--burst-fractions {bad}: allowed fractions the DEM's "
                                      f"biaxial test saves, {list(SAVE_FRACTIONS)}")
        if a.cmd == "burst":
            from .burst import load_starts
            _burst_options(a)         # bad options and input files before the compilation
            starts, _, own = load_starts(a.biaxial, a.start_fractions, a.params)
            a.burst_options = _burst_options(a, own.n)
            if a.resume:              # a folder of other states is refused before the kernels
                from .burst import checkpoint_header, read_checkpoint
                read_checkpoint(a.out, checkpoint_header(starts, a.ratios, a.burst_options))
        elif getattr(a, "biaxial", None):
            from .domain import load_states
            load_states(a.biaxial, [s for s in (getattr(a, "states", None) or "").split(",") if s])
        stage.at(f"dem {a.cmd}" + (" (run it again with --resume to continue)"
                                   if hasattr(a, "resume") else ""))
        from . import kernels
        if a.cmd != "params" and opt.announce_compilation([kernels.advance, kernels.build_pairs,
                                                           kernels.contact_snapshot]):
            from .simulation import compile_kernels
            t = time.time()
            compile_kernels()         # before the command's own timers start
            print(f"compiled in {time.time() - t:.1f} s", file=sys.stderr, flush=True)
        a.stage = stage           # a command may say where it is (dem calibrate)
        a.func(a)
        return 0

    code = opt.run_cli(build_parser(), argv, run, errors=(ValueError, RuntimeError))
    if code:
        sys.exit(code)


if __name__ == "__main__":
    main()
