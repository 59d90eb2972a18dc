"""Command line: ``python -m hmodel {biaxial,probes,domain,params} ...`` (thin layer over
``hmodel.experiment`` and ``hmodel.plots``). The model parameters of every command: ``--params
FILE`` and the options of ``options.add_param_options``, read by ``options.params_from``; every
output folder records them in params.json (docs/parameters.md)."""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

from . import options as opt
from . import plots
from .driver import MixedControlError
from .experiment import (DOMAIN_EPS1_MAX, biaxial_columns, biaxial_test, bifurcation_domain,
                         compile_kernels, probe_columns, state_at_eta)
from .io import atomic_open, write_csv
from .options import add_param_options, params_from, record_params
from .params import save_params
from .probes import arcs, directional_sweep, format_arcs, stress_probes, tangent_criteria

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
    n = 2 * args.n     # the refinement typically doubles the uniform grid near the peak
    opt.check_memory(n * P.n_dir * PROBE_BYTES_PER_DIR, f"{args.n} strain probes of {P.n_dir} "
                     "orientations", "--n / --n-dir", "fewer directions or orientations")


def _start(args, stage, text):
    """Validated: check the output folder, compile the kernels if this is the first run (apart
    from the timings), and say what starts. Returns the start time of the timings."""
    opt.check_out_dir(args.out)
    compile_kernels()
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
    if args.eps1_max >= 1.0:
        raise opt.OptionError(f"--eps1-max {args.eps1_max:g} is out of range: allowed 0 < value < 1 "
                              "(the volume V0 det(I - eps) vanishes at eps1 = 1)")
    stage.quiet = args.quiet
    t0 = _start(args, stage, f"drained biaxial test, sigma2 = {sigma2:g} Pa, to eps1 = {args.eps1_max:g}")
    r = biaxial_test(P, sigma2, args.d_eps1, args.eps1_max, progress=not args.quiet)
    cols = biaxial_columns(r)
    t_run = time.time() - t0
    _say(stage, "writing biaxial.csv and Figs. 4-5")
    os.makedirs(args.out, exist_ok=True)
    write_csv(os.path.join(args.out, "biaxial.csv"), cols)
    stage.wrote("biaxial.csv", record_params(args.out, P, f"python -m hmodel biaxial; {args.params_note}"))
    k_pk = int(np.argmax(cols["q"]))
    hit = np.flatnonzero(cols["eta"] >= args.eta_a)
    a = (cols["eps1"][hit[0]], cols["q"][hit[0]], cols["eps_v"][hit[0]]) if hit.size else None
    plots.fig_q_eps1([("H-model", cols["eps1"], cols["q"])], os.path.join(args.out, "fig4_q_eps1.png"),
                     point_a=a[:2] if a else None,
                     peak=(cols["eps1"][k_pk], cols["q"][k_pk]) if 0 < k_pk < len(cols["q"]) - 1 else None,
                     title=f"H-model drained biaxial test, $\\sigma_2$ = {sigma2 / 1e3:g} kPa (Fig. 4)")
    stage.wrote("fig4_q_eps1.png")
    plots.fig_epsv_eps1([("H-model", cols["eps1"], cols["eps_v"])], os.path.join(args.out, "fig5_epsv_eps1.png"),
                        point_a=(a[0], a[2]) if a else None,
                        title=f"H-model drained biaxial test, $\\sigma_2$ = {sigma2 / 1e3:g} kPa (Fig. 5)")
    stage.wrote("fig5_epsv_eps1.png")
    print(args.params_note)
    print(f"drained biaxial, sigma2 = {sigma2:g} Pa, {len(cols['eps1']) - 1} steps in {t_run:.2f} s")
    print(f"peak: q = {cols['q'][k_pk]:.6g} Pa, eta = {cols['eta'][k_pk]:.4f} at eps1 = {cols['eps1'][k_pk]:.4%}")
    if a:
        print(f"point A (eta >= {args.eta_a}): eps1 = {a[0]:.4%}, q = {a[1]:.6g} Pa"
              f" ({'before' if hit[0] < k_pk else 'after'} the peak)")
    print(f"wrote {args.out}/biaxial.csv, params.json, fig4_q_eps1.png, fig5_epsv_eps1.png")


def cmd_probes(args, stage):
    P = params_from(args)
    _check_path(args, DOMAIN_EPS1_MAX)
    _check_probes(args, P)
    t0 = _start(args, stage, f"drained path to point A (eta = {args.eta:g}), sigma2 = {P.p0:g} Pa")
    r, sA = state_at_eta(P, args.eta, P.p0, args.d_eps1)
    _say(stage, f"strain probes at A: {args.n} directions, refined where the response jumps")
    sw = directional_sweep(sA, P, n=args.n, norm=args.norm)
    _say(stage, f"stress probes every {args.stress_step:g} deg ({len(sw.alpha_eps)} strain probes done)")
    targets = np.arange(0.0, 360.0, args.stress_step)
    sp = stress_probes(sA, P, targets, sigma_norm=args.sigma_norm, sweep=sw)
    tc = tangent_criteria(sA, P)
    t_run = time.time() - t0
    _say(stage, "writing probes.csv, stress_probes.csv, Figs. 3, 6-9, 11 and summary.json")
    os.makedirs(args.out, exist_ok=True)
    write_csv(os.path.join(args.out, "probes.csv"), probe_columns(sw))
    stage.wrote("probes.csv", record_params(args.out, P, f"python -m hmodel probes; {args.params_note}"))
    cols = {"alpha_sigma_target": targets, "n_solutions": sp.n_solutions}
    cols.update({k: v for k, v in probe_columns(sp.probe).items()})
    write_csv(os.path.join(args.out, "stress_probes.csv"), cols)
    stage.wrote("stress_probes.csv")
    pth = lambda n: os.path.join(args.out, n)
    plots.fig_probes(sw, pth("fig3_probes.png"))
    plots.fig_stress_components(sw, 0, pth("fig6_axial_components.png"))
    plots.fig_stress_components(sw, 1, pth("fig7_lateral_components.png"))
    plots.fig_polar_w2([("H-model W2", sw.alpha_sigma, sw.w2, "C3-")], pth("fig8_polar_w2.png"),
                       title=f"Normalized second-order work at A ($\\eta$ = {args.eta}) (Fig. 8)")
    plots.fig_w2_split(sw, pth("fig9_w2_split.png"))
    plots.fig_w2_normal_tangential(sw, pth("fig11_w2_normal_tangential.png"),
                                   title="H-model: normal and tangential parts of W2 (Fig. 11)")
    stage.wrote("Figs. 3, 6-9, 11")
    p, q, eta = r.invariants()
    summary = {
        "parameters": args.params_note, "sigma2": P.p0, "eta_A": float(eta[-1]), "eps1_A": float(r.eps[-1, 0]),
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


def build_parser() -> argparse.ArgumentParser:
    R = opt.real
    ap = opt.Parser(prog="python -m hmodel",
                                 description="H-microdirectional model: biaxial test, directional "
                                             "analysis of second-order work, bifurcation domain")
    sub = ap.add_subparsers(dest="command", required=True)

    b = sub.add_parser("biaxial", help="drained biaxial test (Figs. 4-5)")
    b.add_argument("--sigma2", type=R(0, unit="Pa"), default=None,
                   help="confining stress [Pa] (default: p0 of --params FILE, or 200e3)")
    b.add_argument("--eps1-max", type=R(0), default=0.05, help="final axial strain [-], < 1")
    b.add_argument("--d-eps1", type=R(0), default=1e-5, help="axial strain step [-]")
    b.add_argument("--eta-a", type=R(0, 2), default=1.029, help="stress ratio of point A (marked)")
    b.add_argument("--out", default="out/hmodel", help="output folder")
    b.add_argument("--quiet", action="store_true", help="no progress bar")
    add_param_options(b)
    b.set_defaults(func=cmd_biaxial)

    p = sub.add_parser("probes", help="directional analysis at point A (Figs. 3, 6-9, 11)")
    p.add_argument("--eta", type=R(0, 2), default=1.029,
                   help="stress ratio q/p of point A (0 < eta < 2: q/p < 2 while sigma2 > 0)")
    p.add_argument("--sigma2", type=R(0, unit="Pa"), default=None,
                   help="confining stress [Pa] (default: p0 of --params FILE, or 200e3)")
    p.add_argument("--n", type=opt.integer(8), default=360, help="uniform strain directions before refinement")
    p.add_argument("--norm", type=R(0, 1e-2, hi_open=False), default=1e-6,
                   help="strain probe norm |d eps| [-] (a rate probe: small)")
    p.add_argument("--d-eps1", type=R(0), default=1e-5, help="axial strain step of the path [-]")
    p.add_argument("--stress-step", type=R(0, 360, hi_open=False, unit="deg"), default=5.0,
                   help="stress-probe spacing [deg]")
    p.add_argument("--sigma-norm", type=R(0, unit="Pa"), default=2.5e3, help="stress probe norm [Pa]")
    p.add_argument("--out", default="out/hmodel", help="output folder")
    add_param_options(p)
    p.set_defaults(func=cmd_probes)

    d = sub.add_parser("domain", help="bifurcation domain over confining pressures (Fig. 10)")
    d.add_argument("--sigma2", type=opt.reals(0, unit="Pa"), default=None,
                   help="comma-separated confining stresses [Pa] (default: p0/2, p0, 2 p0 with p0 "
                        "of --params FILE: 100e3,200e3,400e3 for Table I)")
    d.add_argument("--d-eps1", type=R(0), default=1e-5, help="axial strain step [-]")
    d.add_argument("--n", type=opt.integer(8), default=180, help="strain directions of each check")
    d.add_argument("--workers", type=opt.integer(1), default=None,
                   help="parallel processes, >= 1 (default: min(pressures, cores))")
    d.add_argument("--out", default="out/hmodel", help="output folder")
    add_param_options(d)
    d.set_defaults(func=cmd_domain)

    w = sub.add_parser("params", help="write a parameter file: Table I, or --params FILE, with "
                                      "the options given on top (docs/parameters.md)")
    w.add_argument("--out", required=True, help="the JSON file to write")
    w.add_argument("--sigma2", type=R(0, unit="Pa"), default=None,
                   help="p0: the confining stress of the initial state [Pa]")
    add_param_options(w)
    w.set_defaults(func=cmd_params)
    return ap


def main(argv=None) -> int:
    """``python -m hmodel ...``: 0 done, 2 bad option (one line), 130 / 143 interrupted."""
    def run(args, stage):
        args.func(args, stage)
        return 0
    return opt.run_cli(build_parser(), argv, run, errors=(ValueError, MixedControlError))


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
    pts = bifurcation_domain(P, pressures, workers=args.workers, d_eps1=args.d_eps1,
                             n_dir_probe=args.n, progress=lambda m: _say(stage, m))
    t_run = time.time() - t0
    os.makedirs(args.out, exist_ok=True)
    cols = {k: np.array([getattr(d, k) for d in pts]) for k in pts[0]._fields}
    write_csv(os.path.join(args.out, "domain.csv"), cols)
    stage.wrote("domain.csv", record_params(args.out, P, f"python -m hmodel domain; {note}"))
    plots.fig_domain(pts, os.path.join(args.out, "fig10_domain.png"))
    print(note)
    for d in pts:
        print(f"sigma2 = {d.sigma2:g} Pa: first W2<=0 at (p, q) = ({d.p_w2:.4g}, {d.q_w2:.4g}), "
              f"W2_sigma<=0 at ({d.p_w2sigma:.4g}, {d.q_w2sigma:.4g}), peak ({d.p_peak:.4g}, {d.q_peak:.4g}) Pa")
    print(f"wrote {args.out}/domain.csv, params.json, fig10_domain.png ({t_run:.1f} s)")


def cmd_params(args, stage):
    P = params_from(args)
    opt.check_out_file(args.out)
    save_params(args.out, P, f"python -m hmodel params; {args.params_note}")
    stage.wrote(os.path.basename(args.out))
    print(args.params_note)
    print(f"wrote {args.out}")
