"""Command line: ``python -m hmodel {biaxial,probes,domain,burst,fit,params} ...`` (thin layer
over ``hmodel.experiment``, ``hmodel.burst``, ``hmodel.fit`` and ``hmodel.plots``). The model
parameters of every command: ``--params FILE`` and the options of ``options.add_param_options``,
read by ``options.params_from``; every output folder records them in params.json
(docs/parameters.md). The files of fit, probes and domain are written by ``write_fit``,
``write_probes`` and ``write_domain`` from an HParams record and the library's results, so that
a caller with its own record (``python -m crosscheck.fit``) writes the same folders without an
argv."""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time

import numpy as np

from common import options as opt
from common.io import atomic_open, fmt, json_safe, write_csv

from . import fit as hfit
from . import plots
from .driver import MixedControlError
from .experiment import (DOMAIN_COLUMNS, DOMAIN_EPS1_MAX, biaxial_columns, biaxial_test,
                         bifurcation_domain, compile_kernels, directional_analysis, probe_columns)
from .params import ParamError, add_param_options, params_from, record_params, save_params
from .probes import arcs, format_arcs

# where a loss of the static solution is made to happen dynamically
BURST_POINTER = ("held past such a point the specimen cannot stay at rest: python -m hmodel burst "
                 "makes this failure happen dynamically (docs/burst.md)")
# memory of one step of a path [bytes]: run_path's histories (3 + 3 floats, 3 ints), the
# PathResult rows (6 floats) and the CSV columns (12), all float64 / int64
PATH_BYTES_PER_STEP = 8 * (3 + 3 + 3 + 6 + 12)
# memory of one strain probe per orientation [bytes]: its broadcast state and the update's
# outputs (10 floats + 2 flags each), twice for the refinement's concatenation
PROBE_BYTES_PER_DIR = 2 * 2 * (10 * 8 + 2)


def _check_path(args, eps1_max, options="--d-eps1"):
    """--d-eps1 against the path length ``eps1_max`` and the memory of the path's histories."""
    if args.d_eps1 > eps1_max:
        raise opt.OptionError(f"--d-eps1 {args.d_eps1:g} is out of range: allowed 0 < value <= "
                              f"{eps1_max:g} (the axial strain where the path ends)")
    n = eps1_max / args.d_eps1
    opt.check_memory(n * PATH_BYTES_PER_STEP, f"a path of {n:.3g} steps to eps1 = {eps1_max:g}",
                     options, f"fewer steps ({options})")


def _check_probes(args, P):
    n = 2 * args.n_probes     # the refinement typically doubles the uniform grid near the peak
    opt.check_memory(n * P.n_dir * PROBE_BYTES_PER_DIR, f"{args.n_probes} strain probes of "
                     f"{P.n_dir} orientations", "--n-probes / --n-dir",
                     "fewer directions or orientations")


def _start(args, stage, text):
    """Validated: check the output folder, compile the kernels if this is the first run (apart
    from the timings), and say what starts. Returns the start time of the timings."""
    opt.check_out_dir(args.out)
    compile_kernels()
    stage.quiet = args.quiet
    _say(stage, text)
    return time.time()


def _say(stage, text):
    stage.at(text)
    if not getattr(stage, "quiet", False):
        print(text, file=sys.stderr, flush=True)


def cmd_biaxial(args, stage):
    P = params_from(args)
    sigma2 = P.p0
    _check_path(args, args.eps1_max, "--eps1-max / --d-eps1")
    t0 = _start(args, stage, f"drained biaxial test, sigma2 = {sigma2:g} Pa, to eps1 = {args.eps1_max:g}")
    note = f"python -m hmodel biaxial; {args.params_note}"
    try:
        r = biaxial_test(P, sigma2, args.d_eps1, args.eps1_max, progress=not args.quiet)
    except BaseException as e:
        # interrupted, or a Newton failure where a static state exists: the rows so far stay
        part = getattr(e, "partial", None)
        if part is not None:
            os.makedirs(args.out, exist_ok=True)
            write_csv(os.path.join(args.out, "biaxial.csv"), biaxial_columns(part))
            stage.wrote(f"biaxial.csv ({len(part.eps) - 1} steps)", record_params(args.out, P, note))
        raise
    cols = biaxial_columns(r)
    t_run = time.time() - t0
    end = r.end
    _say(stage, "writing biaxial.csv, summary.json and Figs. 4-5")
    os.makedirs(args.out, exist_ok=True)
    write_csv(os.path.join(args.out, "biaxial.csv"), cols)
    stage.wrote("biaxial.csv", record_params(args.out, P, note))
    cut = {int(k): int(r.cuts[k]) for k in np.flatnonzero(r.cuts)}
    with atomic_open(os.path.join(args.out, "summary.json")) as f:
        json.dump(json_safe({"parameters": args.params_note, "sigma2": sigma2,
                             "outcome": end.outcome, "end": end.as_dict(), "steps": len(r.eps) - 1,
                             "steps_cut": cut, "burst": BURST_POINTER}), f, indent=1)
    stage.wrote("summary.json")
    k_pk = int(np.argmax(cols["q"]))
    hit = np.flatnonzero(cols["eta"] >= args.eta_a)
    a = (cols["eps1"][hit[0]], cols["q"][hit[0]], cols["eps_v"][hit[0]]) if hit.size else None
    mark = (f"no static state beyond: {end.outcome} at {100 * cols['eps1'][-1]:.3f} %"
            if end.outcome != "complete" else None)
    plots.fig_q_eps1([("H-model", cols["eps1"], cols["q"])], os.path.join(args.out, "fig4_q_eps1.png"),
                     point_a=a[:2] if a else None,
                     peak=(cols["eps1"][k_pk], cols["q"][k_pk]) if 0 < k_pk < len(cols["q"]) - 1 else None,
                     title=f"H-model drained biaxial test, $\\sigma_2$ = {sigma2 / 1e3:g} kPa (Fig. 4)",
                     end=(cols["eps1"][-1], cols["q"][-1], mark) if mark else None)
    stage.wrote("fig4_q_eps1.png")
    plots.fig_epsv_eps1([("H-model", cols["eps1"], cols["eps_v"])], os.path.join(args.out, "fig5_epsv_eps1.png"),
                        point_a=(a[0], a[2]) if a else None,
                        title=f"H-model drained biaxial test, $\\sigma_2$ = {sigma2 / 1e3:g} kPa (Fig. 5)",
                        end=(cols["eps1"][-1], cols["eps_v"][-1], mark) if mark else None)
    stage.wrote("fig5_epsv_eps1.png")
    print(args.params_note)
    print(f"drained biaxial, sigma2 = {sigma2:g} Pa, {len(cols['eps1']) - 1} steps in {t_run:.2f} s"
          + (f" ({len(cut)} cut in substeps)" if cut else ""))
    print(f"outcome: {end.line()}")
    if end.outcome != "complete":
        print(f"the path ends there (every computed row written); {BURST_POINTER}")
    print(f"peak: q = {cols['q'][k_pk]:.6g} Pa, eta = {cols['eta'][k_pk]:.4f} at eps1 = {cols['eps1'][k_pk]:.4%}")
    if a:
        print(f"point A (eta >= {args.eta_a}): eps1 = {a[0]:.4%}, q = {a[1]:.6g} Pa"
              f" ({'before' if hit[0] < k_pk else 'after'} the peak)")
    print(f"wrote {args.out}/biaxial.csv, params.json, summary.json, fig4_q_eps1.png, fig5_epsv_eps1.png")


def cmd_probes(args, stage):
    P = params_from(args)
    _check_path(args, DOMAIN_EPS1_MAX)
    _check_probes(args, P)
    t0 = _start(args, stage, f"drained path to point A (eta = {args.eta_a:g}), sigma2 = {P.p0:g} Pa")
    da = directional_analysis(P, args.eta_a, args.d_eps1, args.n_probes, args.strain_norm,
                              args.stress_step, args.stress_norm, progress=lambda m: _say(stage, m))
    tc = da.tangent
    t_run = time.time() - t0
    _say(stage, "writing probes.csv, stress_probes.csv, Figs. 3, 6-9, 11 and summary.json")
    summary = write_probes(args.out, P, args.eta_a, da, args.params_note, stage)
    print(args.params_note)
    print(f"point A: eta = {summary['eta_A']:.4f} at eps1 = {summary['eps1_A']:.4%} "
          f"({summary['n_probes']} strain probes, {t_run:.2f} s)")
    print(f"plastic tensorial zone (alpha_sigma, deg): {format_arcs(summary['plastic_zone_alpha_sigma'])}")
    print(f"instability cone W2 <= 0: {format_arcs(summary['cone_w2_alpha_sigma'])}; "
          f"W2_sigma <= 0: {format_arcs(summary['cone_w2sigma_alpha_sigma'])}")
    print(f"min W2 = {summary['min_w2']:.4f} at alpha_sigma = {summary['alpha_sigma_min_w2']:.2f} deg; "
          f"min W2n = {summary['min_w2n']:.4f}")
    print(f"det(M) = {tc['det_M_cauchy']:.4g}, det(M_sym) = {tc['det_Msym_cauchy']:.4g} (Cauchy, loading pattern)")
    print(f"wrote {args.out}/probes.csv, stress_probes.csv, summary.json, params.json and Figs. 3, 6-9, 11")


def write_probes(out, P, eta_a, da, note, stage=None) -> dict:
    """The files of a directional analysis at A (``experiment.directional_analysis`` of the
    material ``P`` at ``eta_a``) in the folder ``out`` (created): probes.csv, stress_probes.csv,
    params.json (``P``), Figs. 3, 6-9, 11 and summary.json, whose "parameters" is ``note`` (where
    the values came from). Returns the summary; ``stage`` (an ``options.Stage``) hears of each
    file written."""
    stage = stage or opt.Stage()
    sw, targets, sp, tc = da.sweep, da.targets, da.stress, da.tangent
    os.makedirs(out, exist_ok=True)
    write_csv(os.path.join(out, "probes.csv"), probe_columns(sw))
    stage.wrote("probes.csv", record_params(out, P, f"python -m hmodel probes; {note}"))
    cols = {"alpha_sigma_target": targets, "n_solutions": sp.n_solutions}
    cols.update({k: v for k, v in probe_columns(sp.probe).items()})
    write_csv(os.path.join(out, "stress_probes.csv"), cols)
    stage.wrote("stress_probes.csv")
    pth = lambda n: os.path.join(out, n)
    plots.fig_probes(sw, pth("fig3_probes.png"))
    plots.fig_stress_components(sw, 0, pth("fig6_axial_components.png"))
    plots.fig_stress_components(sw, 1, pth("fig7_lateral_components.png"))
    plots.fig_polar_w2([("H-model W2", sw.alpha_sigma, sw.w2, "C0-")], pth("fig8_polar_w2.png"),
                       title=f"Normalized second-order work at A ($\\eta$ = {eta_a}) (Fig. 8)",
                       cone=arcs(sw.alpha_sigma, sw.w2 <= 0), plastic=arcs(sw.alpha_sigma, sw.plastic),
                       no_solution=targets[sp.n_solutions == 0])
    plots.fig_w2_split(sw, pth("fig9_w2_split.png"))
    plots.fig_w2_normal_tangential(sw, pth("fig11_w2_normal_tangential.png"),
                                   title="H-model: normal and tangential parts of W2 (Fig. 11)")
    stage.wrote("Figs. 3, 6-9, 11")
    r = da.path
    p, q, eta = r.invariants()
    summary = {
        "parameters": note, "sigma2": P.p0, "eta_A": float(eta[-1]), "eps1_A": float(r.eps[-1, 0]),
        "p_A": float(p[-1]), "q_A": float(q[-1]), "n_probes": int(len(sw.alpha_eps)),
        "plastic_zone_alpha_sigma": arcs(sw.alpha_sigma, sw.plastic),
        "cone_w2_alpha_sigma": arcs(sw.alpha_sigma, sw.w2 <= 0),
        "cone_w2sigma_alpha_sigma": arcs(sw.alpha_sigma, sw.w2_sigma <= 0),
        "min_w2": float(np.min(sw.w2)), "alpha_sigma_min_w2": float(sw.alpha_sigma[np.argmin(sw.w2)]),
        "min_w2n": float(np.min(sw.w2n)),
        "max_w2t_in_cone": float(np.max(sw.w2t[sw.w2 <= 0])) if np.any(sw.w2 <= 0) else None,
        "max_abs_w2_minus_micro": float(np.max(np.abs(sw.w2 - sw.w2_micro))),
        "stress_probes_without_solution": int(np.sum(sp.n_solutions == 0)),
        "stress_probes_with_several_solutions": int(np.sum(sp.n_solutions > 1)),
        **tc,
    }
    with atomic_open(pth("summary.json")) as f:
        json.dump(summary, f, indent=2)
    stage.wrote("summary.json")
    return summary


def cmd_burst(args, stage):
    from . import burst
    P = params_from(args)
    args.sigma2 = P.p0               # the confining stress of the test: --sigma2, else the file's
    if args.dc is None:
        args.dc = 1e-4 * args.sigma2
    try:
        spec = burst.Specimen(args.width, args.height, args.density).validate()
    except ValueError as e:
        raise opt.record_error(e, "Specimen") from None
    try:
        dyn = burst.Dynamics(args.damping_ratio, args.steps_per_period).validate()
    except ValueError as e:
        raise opt.record_error(e, "Dynamics") from None
    # --start-fractions' range with its upper end open (a state below the drained peak); the
    # parser checked the term's own
    r = opt.vocabulary_range(burst.RECORD, "start_fractions", hi_open=True)
    bad = [f for f in args.start_fractions if not r.contains(f)]
    if bad:
        raise opt.OptionError(f"--start-fractions {bad[0]:g} is out of range: allowed {r.text()} "
                              "(a state below the drained peak)")
    if args.path_d_eps1 > args.path_strain:      # the parser checked the term's range; and:
        t = opt.VOCABULARY["--path-d-eps1"]
        r = opt.Range("hmodel.cmd_burst", "path_d_eps1", "real", t.lo, "path_strain", t.lo_open,
                      False)
        raise opt.OptionError(f"--path-d-eps1 {args.path_d_eps1:g} is out of range: allowed "
                              f"{r.text()} {args.path_strain:g}")
    _check_path(args, DOMAIN_EPS1_MAX)
    t0 = _start(args, stage, f"burst: R = {', '.join(f'{R:g}' for R in args.ratios)}, start at "
                f"{', '.join(f'{f:g}' for f in args.start_fractions)} of the drained peak eta, "
                f"sigma2 = {args.sigma2:g} Pa, dc = {args.dc:g} Pa")
    res = burst.run_burst(P, args.ratios, args.start_fractions, args.dc, spec, dyn, args.d_eps1,
                          args.path_strain, progress=lambda m: _say(stage, m),
                          path_d_eps1=args.path_d_eps1)
    cone = {}
    if not args.no_cone:
        _say(stage, "directional analysis: where each path direction enters the cone W2 <= 0, "
                    "and the first W2 = 0 of the drained path")
        from .experiment import domain_point
        d = domain_point(P, args.sigma2, d_eps1=args.d_eps1)
        cone["eta_first_w2"] = float(d.q_w2 / d.p_w2)
        if np.isfinite(cone["eta_first_w2"]):
            cone["cone_at_first_w2"] = burst.cone_at(P, cone["eta_first_w2"], args.d_eps1)
        cone["paths"] = {f"{R:g}": v for R, v in
                         burst.cone_entries(P, args.ratios, args.d_eps1).items()}
    t_run = time.time() - t0
    _say(stage, "writing burst.csv, history.csv, paths.csv, the figures and summary.json")
    os.makedirs(args.out, exist_ok=True)
    pth = lambda n: os.path.join(args.out, n)
    write_csv(pth("burst.csv"), {k: [r[k] for r in res.rows] for k in burst.BURST_COLUMNS}, nan="")
    stage.wrote("burst.csv")
    hist = {k: [] for k in burst.HISTORY_COLUMNS}
    for h in res.histories:
        n = len(h["t"])
        for k in burst.HISTORY_COLUMNS:
            hist[k].extend([h[k]] * n if k in ("ratio", "start_fraction", "switch")
                           else (range(n) if k == "step" else h[k]))
    write_csv(pth("history.csv"), hist, nan="")
    stage.wrote("history.csv")
    pcols = {k: [] for k in burst.PATH_COLUMNS}
    for pi in res.paths:
        pp, qq, ee = pi.path.invariants()
        n = len(pp)
        vals = {"ratio": [pi.ratio] * n, "start_fraction": [pi.start_fraction] * n,
                "eps1": pi.path.eps[:, 0], "eps2": pi.path.eps[:, 1], "s1": pi.path.sigma[:, 0],
                "s2": pi.path.sigma[:, 1], "p": pp, "q": qq, "eta": ee, "c": pi.c}
        for k in pcols:
            pcols[k].extend(vals[k])
    write_csv(pth("paths.csv"), pcols)
    stage.wrote("paths.csv")
    outcome = {(r["ratio"], r["start_fraction"], r["switch"]): r["outcome"] for r in res.rows}
    for h in res.histories:
        h["outcome"] = outcome[(h["ratio"], h["start_fraction"], h["switch"])]
    _, _, eta_d = res.drained.invariants()
    paths = [{"ratio": pi.ratio, "start_fraction": pi.start_fraction, "eps1_start": pi.eps1_start,
              "eps1": pi.path.eps[:, 0], "eta": pi.eta, "c": pi.c, "k_peak": pi.k_peak,
              "p": pi.path.invariants()[0]}
             for pi in res.paths]
    plots.fig_burst_paths((res.drained.eps[:, 0], eta_d), paths, res.rows, pth("fig_burst_paths.png"),
                          eta_w2=cone.get("eta_first_w2"),
                          title=f"H-model, $\\sigma_2$ = {args.sigma2 / 1e3:g} kPa (drained peak "
                                f"$\\eta$ = {res.eta_peak:.4f})")
    plots.fig_burst_ke(res.histories, pth("fig_burst_ke.png"),
                       title=f"Material point (homogeneous specimen {args.width:g} x {args.height:g} m, "
                             f"{args.density:g} kg/m$^3$, $\\zeta$ = {args.damping_ratio:g}):\n"
                             f"kinetic energy after the switch, c held at c_switch + {args.dc:g} Pa")
    plots.fig_burst_residual(res.histories, pth("fig_burst_residual.png"))
    stage.wrote("fig_burst_paths.png", "fig_burst_ke.png", "fig_burst_residual.png")
    stage.wrote(record_params(args.out, P, f"python -m hmodel burst; {args.params_note}"))
    summary = {"params": {f.name: getattr(P, f.name) for f in dataclasses.fields(P) if f.init},
               "params_note": args.params_note,
               "options": {k: v for k, v in vars(args).items() if k not in ("func", "command")},
               "eta_peak_drained": res.eta_peak, "directional_analysis": cone,
               "runs": res.rows, "wall_time_s": t_run}
    with atomic_open(pth("summary.json")) as f:
        json.dump(json_safe(summary), f, indent=1, allow_nan=False)
    stage.wrote("summary.json")
    print(args.params_note)
    print(f"drained peak eta = {res.eta_peak:.4f} at sigma2 = {args.sigma2:g} Pa"
          + (f"; first W2 = 0 of the directional analysis at eta = "
             f"{fmt(cone['eta_first_w2'], '.4f', 'never (before the peak)')}" if cone else ""))
    # eta_peak_c: none where c does not peak within --path-strain (one below run, at its end);
    # the growth measure (burst_rule.energy_release): the largest (E_c - E_c(0)) / W2_ext and
    # when it passed RELEASE (never: it did not)
    print("    R  start  eta_start  eta_peak_c  (fraction)  switch  static  outcome        "
          "max (E_c-E_c0)/W2_ext  t_release/T1")
    for r in res.rows:
        frac = f"({fmt(r['fraction_peak_c'], '.3f')})" if np.isfinite(r["eta_peak_c"]) else ""
        print(f"{r['ratio']:5g}  {r['start_fraction']:5g}  {r['eta_start']:9.4f}  "
              f"{fmt(r['eta_peak_c'], '10.4f')}  {frac:7s}     {r['switch']:6s}  "
              f"{'yes' if r['static_solution'] else 'none':6s}  {r['outcome']:13s}  "
              f"{fmt(r['ke_w2ext_max'], '21.3g')}  {fmt(r['t_release_t1'], '12.2f', 'never')}")
    if cone.get("cone_at_first_w2"):
        ca = cone["cone_at_first_w2"]
        rr = ca["ratio_range"]
        print(f"cone W2 <= 0 at that state: alpha_eps {format_arcs(ca['alpha_eps_arcs'])} deg"
              + (f", i.e. the proportional paths of R in [{rr[0]:.3f}, {rr[1]:.3f}]" if rr else ""))
    if cone:
        for R, ce in cone["paths"].items():
            where = (f"enters the cone W2 <= 0 of the drained path at eta = {ce['eta']:.4f}"
                     if np.isfinite(ce["eta"]) else
                     "never enters the cone W2 <= 0 of the drained path before its peak")
            print(f"R = {R}: strain direction alpha_eps = {ce['alpha_eps']:.2f} deg {where}")
    if res.rows:
        print(f"energy check (the material's stress and strain, the field's kinetic energy, "
              f"O(dt^2)): largest relative residual {max(r['energy_check'] for r in res.rows):.2e}"
              f"; Newmark's own balance (the work of the Newton residual): largest "
              f"{max(r['newton_work'] for r in res.rows):.2e} a step")
    for r in res.rows:
        if r["failure_reason"]:
            print(f"R = {r['ratio']:g}, start {r['start_fraction']:g}, {r['switch']}: not "
                  f"converged: {r['failure_reason']}")
    print(f"wrote {args.out}/burst.csv, history.csv, paths.csv, params.json, summary.json, fig_burst_*.png "
          f"({t_run:.1f} s)")


DESCRIPTION = """The H-microdirectional model as a material point (Nicot, Hadda & Darve 2013).
python -m hmodel COMMAND --help lists a command's options, each with its unit and default.
--out is required: a folder (the parameter file for params) that records the command that wrote
it (command.json); another command refuses that folder unless --force."""


def build_parser() -> argparse.ArgumentParser:
    add = opt.add
    ap = opt.Parser(prog="python -m hmodel", description=DESCRIPTION,
                    formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="command", required=True, metavar="COMMAND")
    p0 = "the p0 of --params FILE, else Table I's 200e3"

    b = sub.add_parser("biaxial", help="drained biaxial test (Figs. 4-5)")
    opt.add_out(b)
    add(b, "--sigma2", record="HParams", default_text=p0)
    add(b, "--eps1-max", 0.05)
    add(b, "--d-eps1", 1e-5)
    add(b, "--eta-a", 1.029, note="marked on the curves")
    opt.add_quiet(b)
    add_param_options(b)
    b.set_defaults(func=cmd_biaxial)

    p = sub.add_parser("probes", help="directional analysis at point A (Figs. 3, 6-9, 11)")
    opt.add_out(p)
    add(p, "--eta-a", 1.029, note="the state of the probes (q/p < 2 while sigma2 > 0)")
    add(p, "--sigma2", record="HParams", default_text=p0)
    add(p, "--n-probes", 360, note="refined where the response jumps")
    add(p, "--strain-norm", 1e-6)
    add(p, "--d-eps1", 1e-5, note="to point A")
    add(p, "--stress-step", 5.0)
    add(p, "--stress-norm", 2.5e3)
    opt.add_quiet(p)
    add_param_options(p)
    p.set_defaults(func=cmd_probes)

    d = sub.add_parser("domain", help="bifurcation domain over confining stresses (Fig. 10)")
    opt.add_out(d)
    add(d, "--sigma2", many=True, note="comma-separated, one drained path each",
        default_text="p0/2, p0, 2 p0 with the p0 of --params FILE: 100e3,200e3,400e3 for Table I")
    add(d, "--d-eps1", 1e-5)
    add(d, "--n-probes", 180, note="of each check")
    add(d, "--workers", default_text="min(pressures, cores)")
    opt.add_quiet(d)
    add_param_options(d)
    d.set_defaults(func=cmd_domain)

    u = sub.add_parser("burst", help="proportional strain paths, c controlled past its peak: the "
                                     "burst of kinetic energy (docs/burst.md)")
    opt.add_out(u)
    add(u, "--ratios", [-1.0, -1.5, -2.0, -3.0], parse=opt.argtype(_check_ratios))
    add(u, "--start-fractions", [0.90, 0.95], note="f < 1 here (a state below the drained peak)")
    add(u, "--dc", default_text="1e-4 sigma2, as fem burst")
    add(u, "--sigma2", record="HParams", default_text=p0)
    add(u, "--d-eps1", 1e-5, note="to the start states")
    add(u, "--path-d-eps1", 1e-5)
    add(u, "--path-strain", 0.03)
    add(u, "--density", 1600.0, record="Specimen",
        note="bulk, of the homogeneous specimen (dry granular: 1500-1700)")
    add(u, "--width", 0.05, record="Specimen")
    add(u, "--height", 0.1, record="Specimen")
    add(u, "--damping-ratio", 0.05, record="Dynamics")
    add(u, "--steps-per-period", 20, record="Dynamics")
    add(u, "--no-cone")
    opt.add_quiet(u)
    add_param_options(u)
    u.set_defaults(func=cmd_burst)

    f = sub.add_parser("fit", help="fit the H-model to a measured drained biaxial curve (docs/fit.md)")
    opt.add_out(f)
    add(f, "--data", required=True, metavar="CSV")
    add(f, "--free", hfit.DEFAULT_FREE, parse=opt.argtype(hfit.parse_free),
        note=f"of {', '.join(hfit.FREE_CHOICES)}; the others as given")
    add(f, "--bounds", {}, parse=opt.argtype(hfit.parse_bounds),
        default_text="x/100 to x*100 of the start for kn, kt, r_g, p0; phi_g 2:60; alpha0 31:70")
    add(f, "--starts", 8)
    add(f, "--seed", 0, note="of the starts")
    add(f, "--sigma2", note="the data's", default_text="the median of the data's column s2 or "
        "sigma2")
    add(f, "--w-epsv", 1.0)
    add(f, "--d-eps1", 1e-5, note="of the final fit")
    add(f, "--d-eps1-search", 1e-4)
    add(f, "--max-nfev", 100)
    opt.add_quiet(f)
    add_param_options(f)
    f.set_defaults(func=cmd_fit)

    w = sub.add_parser("params", help="write a parameter file: Table I, or --params FILE, with "
                                      "the options given on top (docs/parameters.md)")
    opt.add_out(w, "file")
    add(w, "--sigma2", record="HParams", note="the file's p0", default_text=p0)
    add_param_options(w)
    w.set_defaults(func=cmd_params)
    return ap


def _check_ratios(text):
    """--ratios: comma-separated R, each finite and < 0 (``burst.check_ratio`` says why not)."""
    from .burst import check_ratio
    vals = opt.reals()(text)
    return [check_ratio(v, None) for v in vals]


def main(argv=None) -> int:
    """``python -m hmodel ...``: 0 done (also a path that ends without a static state: a
    result), 1 not fittable (``fit``) or a Newton failure where a static state exists, 2 bad
    option (one line), 130 / 143 interrupted."""
    def run(args, stage):
        try:
            return args.func(args, stage) or 0
        except MixedControlError as e:
            # a static state exists but Newton did not reach it: a failure, not bad input
            print(f"error: {e}", file=sys.stderr)
            return 1
    return opt.run_cli(build_parser(), argv, run, errors=(ValueError,))


def cmd_domain(args, stage):
    P = params_from(args)
    if args.sigma2 is None:
        pressures = [0.5 * P.p0, P.p0, 2.0 * P.p0]
        note = f"{args.params_note}; pressures p0/2, p0, 2 p0"
    else:
        pressures = args.sigma2
        note = f"{args.params_note}; pressures --sigma2 (p0 {P.p0:g} not used)"
    _check_path(args, DOMAIN_EPS1_MAX)
    _check_probes(args, P)
    t0 = _start(args, stage, f"bifurcation domain at sigma2 = {', '.join(f'{s:g}' for s in pressures)} Pa")
    try:
        pts = bifurcation_domain(P, pressures, workers=args.workers, d_eps1=args.d_eps1,
                                 n_dir_probe=args.n_probes, progress=lambda m: _say(stage, m))
    except BaseException as e:
        if getattr(e, "partial", None):     # interrupted: the pressures finished stay
            write_domain_rows(args.out, P, e.partial, len(pressures), note, stage)
        raise
    t_run = time.time() - t0
    write_domain(args.out, P, pts, note, stage)
    print(note)
    pq = lambda p, q: (f"(p, q) = ({p:.4g}, {q:.4g}) Pa" if np.isfinite(p) else "never before the peak")
    for d in pts:
        print(f"sigma2 = {d.sigma2:g} Pa: first W2 <= 0 at {pq(d.p_w2, d.q_w2)}; first W2_sigma <= 0 "
              f"at {pq(d.p_w2sigma, d.q_w2sigma)}; peak at {pq(d.p_peak, d.q_peak)}")
        if d.outcome != "complete":
            print(f"  the drained path at {d.sigma2:g} Pa ends {d.end}")
    print(f"wrote {args.out}/domain.csv, params.json, summary.json, fig10_domain.png ({t_run:.1f} s)")


def write_domain_rows(out, P, pts, n_pressures, note, stage=None):
    """domain.csv of the domain points ``pts`` (``experiment.bifurcation_domain``: ``n_pressures``
    asked for, all of them or those finished) and params.json (``P``, with ``note``: where the
    values came from) in the folder ``out`` (created)."""
    stage = stage or opt.Stage()
    os.makedirs(out, exist_ok=True)
    cols = {k: np.array([getattr(d, k) for d in pts]) for k in DOMAIN_COLUMNS}
    write_csv(os.path.join(out, "domain.csv"), cols)
    stage.wrote(f"domain.csv ({len(pts)} of {n_pressures} pressures)" if len(pts) < n_pressures
                else "domain.csv", record_params(out, P, f"python -m hmodel domain; {note}"))


def write_domain(out, P, pts, note, stage=None):
    """The files of a bifurcation domain (``experiment.bifurcation_domain`` of the material
    ``P``) in the folder ``out`` (created): domain.csv, params.json, summary.json (its
    "parameters": ``note``) and Fig. 10."""
    stage = stage or opt.Stage()
    write_domain_rows(out, P, pts, len(pts), note, stage)
    with atomic_open(os.path.join(out, "summary.json")) as f:
        json.dump(json_safe({"parameters": note, "paths": [
            {"sigma2": d.sigma2, "outcome": d.outcome, "end": d.end or None} for d in pts]}), f, indent=1)
    stage.wrote("summary.json")
    plots.fig_domain(pts, os.path.join(out, "fig10_domain.png"))


def cmd_fit(args, stage):
    """Exit 0 fitted, 1 not fittable (summary.json and fig_fit.png say why), 2 bad option."""
    opt.check_csv(args.data, ("eps1", "q"), "--data",
                  "a CSV file with a header row naming eps1 and q (and eps_v or eps2, s2 or "
                  "sigma2 where present): a drained curve, e.g. the biaxial.csv of a biaxial test")
    try:
        curve = hfit.read_curve(args.data, sigma2=args.sigma2)
    except hfit.CurveError as e:
        raise opt.OptionError(f"--data {args.data}: {e}") from None
    P = params_from(args, p0=curve.sigma2)
    try:
        hfit.check_free_bounds(args.free, args.bounds, P)
    except ParamError as e:
        raise opt.OptionError(f"--bounds {e.name}: {e.value!r} is out of range: allowed {e.allowed}") from None
    except ValueError as e:
        raise opt.OptionError(f"--free / --bounds: {e}") from None
    fitted, held = hfit.structural_reduction(args.free, P)
    if not fitted:
        raise opt.OptionError("--free: none of " + ", ".join(args.free) + " enters a drained curve ("
                              + "; ".join(f"{n} {w}" for n, w in held.items()) + ")")
    e_max = float(curve.eps1[-1])
    _check_path(args, e_max)
    if args.d_eps1_search > e_max:
        raise opt.OptionError(f"--d-eps1-search {args.d_eps1_search:g} is out of range: allowed 0 < "
                              f"value <= {e_max:g} (the last eps1 of the data)")
    t0 = _start(args, stage, f"fit of {', '.join(args.free)} to {args.data} ({curve.eps1.size} points, "
                f"sigma2 = {curve.sigma2:.6g} Pa: {curve.sigma2_from}), {args.starts} starts")
    res = hfit.fit_curve(curve, P, args.free, args.bounds, n_starts=args.starts, seed=args.seed,
                         w_epsv=args.w_epsv, d_eps1=args.d_eps1, d_eps1_search=args.d_eps1_search,
                         max_nfev=args.max_nfev, progress=lambda m: _say(stage, m))
    t_run = time.time() - t0
    write_fit(args.out, curve, res, f"python -m hmodel fit --data {args.data}: fitted "
              f"{', '.join(args.free)}; {args.params_note}",
              {k: v for k, v in vars(args).items() if k != "func"}, t_run, stage)
    if res.status != "fitted":
        print(f"not fittable: {res.reason}", file=sys.stderr)
        print(f"wrote {args.out}/summary.json, fig_fit.png")
        return 1
    print(hfit.format_result(res, curve))
    print(f"wrote {args.out}/params.json, fit.csv, residuals.csv, correlation.json, summary.json, "
          f"fig_fit.png ({t_run:.1f} s)")
    return 0


def write_fit(out, curve, res, note, options=None, wall_time=None, stage=None) -> dict:
    """The files of a fit (``fit.fit_curve``'s result ``res`` on the data ``curve``) in the
    folder ``out`` (created): params.json (the fitted HParams, with ``note``: how they were
    fitted), fit.csv, residuals.csv and correlation.json when it fitted; summary.json
    (``fit.summary_dict`` with the run's ``options`` and ``wall_time`` [s]) and fig_fit.png
    always. Returns the summary (what summary.json holds)."""
    stage = stage or opt.Stage()
    os.makedirs(out, exist_ok=True)
    pth = lambda n: os.path.join(out, n)
    summary = hfit.summary_dict(res, curve)
    summary["options"] = {k: (list(v) if isinstance(v, tuple) else v)
                          for k, v in (options or {}).items()}
    summary["wall_time_s"] = wall_time
    if res.status == "fitted":
        save_params(pth("params.json"), res.params, note)
        stage.wrote("params.json")
        cols = {"eps1": curve.eps1, "q": curve.q, "q_fit": res.model_q}
        rcols = {"eps1": curve.eps1, "r_q": res.residuals_q,
                 "r_q_weighted": res.residuals_q * res.info["weight_q"]}
        if curve.eps_v is not None:
            cols.update(eps_v=curve.eps_v, eps_v_fit=res.model_eps_v)
            rcols.update(r_eps_v=res.residuals_eps_v,
                         r_eps_v_weighted=res.residuals_eps_v * res.info["weight_eps_v"])
        write_csv(pth("fit.csv"), cols)
        write_csv(pth("residuals.csv"), rcols)
        with atomic_open(pth("correlation.json")) as fh:
            json.dump(hfit.correlation_dict(res), fh, indent=2)
        stage.wrote("fit.csv", "residuals.csv", "correlation.json")
    with atomic_open(pth("summary.json")) as fh:
        json.dump(summary, fh, indent=2)
    stage.wrote("summary.json")
    hfit.plot_fit(curve, res, pth("fig_fit.png"))
    stage.wrote("fig_fit.png")
    return summary


def cmd_params(args, stage):
    P = params_from(args)
    opt.check_out_file(args.out)
    save_params(args.out, P, f"python -m hmodel params; {args.params_note}")
    stage.wrote(os.path.basename(args.out))
    print(args.params_note)
    print(f"wrote {args.out}")
