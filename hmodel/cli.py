"""Command line: ``python -m hmodel {biaxial,probes,domain} ...`` (thin layer over
``hmodel.experiment`` and ``hmodel.plots``)."""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

from . import plots
from .driver import MixedControlError
from .experiment import (biaxial_columns, biaxial_test, bifurcation_domain, probe_columns,
                         state_at_eta)
from .io import atomic_open, write_csv
from .params import HParams
from .probes import arcs, directional_sweep, format_arcs, stress_probes, tangent_criteria


def add_param_options(ap: argparse.ArgumentParser):
    d = HParams()
    g = ap.add_argument_group("model parameters (Table I defaults)")
    g.add_argument("--kn", type=float, default=d.kn, help="normal contact stiffness [N/m]")
    g.add_argument("--kt", type=float, default=d.kt, help="tangential contact stiffness [N/m]")
    g.add_argument("--phi-g", type=float, default=d.phi_g, help="contact friction angle [deg]")
    g.add_argument("--r-g", type=float, default=d.r_g, help="grain radius [m]")
    g.add_argument("--alpha0", type=float, default=d.alpha0, help="initial hexagon opening angle [deg]")
    g.add_argument("--n-dir", type=int, default=d.n_dir, help="number of hexagon orientations")
    g.add_argument("--thickness", type=float, default=None, help="slab thickness h [m] (default 2 r_g)")
    g.add_argument("--fabric-a", type=float, default=0.0, help="fabric anisotropy a, |a| < 1")
    g.add_argument("--fabric-b", type=float, default=0.0, help="fabric direction b [deg]")


def params_from(args, p0=None) -> HParams:
    return HParams(kn=args.kn, kt=args.kt, phi_g=args.phi_g, r_g=args.r_g, alpha0=args.alpha0,
                   n_dir=args.n_dir, thickness=args.thickness, fabric_a=args.fabric_a,
                   fabric_b=args.fabric_b, p0=args.sigma2 if p0 is None else p0)


def _floats(text):
    try:
        return [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}") from None


def cmd_biaxial(args):
    P = params_from(args)
    t0 = time.time()
    r = biaxial_test(P, args.sigma2, args.d_eps1, args.eps1_max, progress=not args.quiet)
    cols = biaxial_columns(r)
    os.makedirs(args.out, exist_ok=True)
    write_csv(os.path.join(args.out, "biaxial.csv"), cols)
    k_pk = int(np.argmax(cols["q"]))
    hit = np.flatnonzero(cols["eta"] >= args.eta_a)
    a = (cols["eps1"][hit[0]], cols["q"][hit[0]], cols["eps_v"][hit[0]]) if hit.size else None
    plots.fig_q_eps1([("H-model", cols["eps1"], cols["q"])], os.path.join(args.out, "fig4_q_eps1.png"),
                     point_a=a[:2] if a else None,
                     title=f"H-model drained biaxial test, $\\sigma_2$ = {args.sigma2 / 1e3:g} kPa (Fig. 4)")
    plots.fig_epsv_eps1([("H-model", cols["eps1"], cols["eps_v"])], os.path.join(args.out, "fig5_epsv_eps1.png"),
                        point_a=(a[0], a[2]) if a else None,
                        title=f"H-model drained biaxial test, $\\sigma_2$ = {args.sigma2 / 1e3:g} kPa (Fig. 5)")
    print(f"drained biaxial, sigma2 = {args.sigma2:g} Pa, {len(cols['eps1']) - 1} steps in {time.time() - t0:.2f} s")
    print(f"peak: q = {cols['q'][k_pk]:.6g} Pa, eta = {cols['eta'][k_pk]:.4f} at eps1 = {cols['eps1'][k_pk]:.4%}")
    if a:
        print(f"point A (eta >= {args.eta_a}): eps1 = {a[0]:.4%}, q = {a[1]:.6g} Pa"
              f" ({'before' if hit[0] < k_pk else 'after'} the peak)")
    print(f"wrote {args.out}/biaxial.csv, fig4_q_eps1.png, fig5_epsv_eps1.png")


def directional_analysis(P, args):
    """Path to point A, adaptive strain-probe sweep there, stress probes and tangent criteria."""
    r, sA = state_at_eta(P, args.eta, args.sigma2, args.d_eps1)
    sw = directional_sweep(sA, P, n=args.n, norm=args.norm)
    return r, sA, sw


def cmd_probes(args):
    P = params_from(args)
    t0 = time.time()
    r, sA, sw = directional_analysis(P, args)
    os.makedirs(args.out, exist_ok=True)
    write_csv(os.path.join(args.out, "probes.csv"), probe_columns(sw))
    targets = np.arange(0.0, 360.0, args.stress_step)
    sp = stress_probes(sA, P, targets, sigma_norm=args.sigma_norm, sweep=sw)
    cols = {"alpha_sigma_target": targets, "n_solutions": sp.n_solutions}
    cols.update({k: v for k, v in probe_columns(sp.probe).items()})
    write_csv(os.path.join(args.out, "stress_probes.csv"), cols)
    pth = lambda n: os.path.join(args.out, n)
    plots.fig_probes(sw, pth("fig3_probes.png"))
    plots.fig_stress_components(sw, 0, pth("fig6_axial_components.png"))
    plots.fig_stress_components(sw, 1, pth("fig7_lateral_components.png"))
    plots.fig_polar_w2([("H-model W2", sw.alpha_sigma, sw.w2, "C3-")], pth("fig8_polar_w2.png"),
                       title=f"Normalized second-order work at A ($\\eta$ = {args.eta}) (Fig. 8)")
    plots.fig_w2_split(sw, pth("fig9_w2_split.png"))
    plots.fig_w2_normal_tangential(sw, pth("fig11_w2_normal_tangential.png"),
                                   title="H-model: normal and tangential parts of W2 (Fig. 11)")
    p, q, eta = r.invariants()
    tc = tangent_criteria(sA, P)
    summary = {
        "sigma2": args.sigma2, "eta_A": float(eta[-1]), "eps1_A": float(r.eps[-1, 0]),
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
    print(f"point A: eta = {summary['eta_A']:.4f} at eps1 = {summary['eps1_A']:.4%} "
          f"({summary['n_probes']} strain probes, {time.time() - t0:.2f} s)")
    print(f"plastic tensorial zone (alpha_sigma, deg): {format_arcs(summary['plastic_zone_alpha_sigma'])}")
    print(f"instability cone W2 <= 0: {format_arcs(summary['cone_w2_alpha_sigma'])}; "
          f"W2_sigma <= 0: {format_arcs(summary['cone_w2sigma_alpha_sigma'])}")
    print(f"min W2 = {summary['min_w2']:.4f} at alpha_sigma = {summary['alpha_sigma_min_w2']:.2f} deg; "
          f"min W2n = {summary['min_w2n']:.4f}")
    print(f"det(M) = {tc['det_M_cauchy']:.4g}, det(M_sym) = {tc['det_Msym_cauchy']:.4g} (Cauchy, loading pattern)")
    print(f"wrote {args.out}/probes.csv, stress_probes.csv, summary.json and Figs. 3, 6-9, 11")


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m hmodel",
                                 description="H-microdirectional model: biaxial test, directional "
                                             "analysis of second-order work, bifurcation domain")
    sub = ap.add_subparsers(dest="command", required=True)

    b = sub.add_parser("biaxial", help="drained biaxial test (Figs. 4-5)")
    b.add_argument("--sigma2", type=float, default=200e3, help="confining stress [Pa]")
    b.add_argument("--eps1-max", type=float, default=0.05, help="final axial strain [-]")
    b.add_argument("--d-eps1", type=float, default=1e-5, help="axial strain step [-]")
    b.add_argument("--eta-a", type=float, default=1.029, help="stress ratio of point A (marked)")
    b.add_argument("--out", default="out/hmodel", help="output folder")
    b.add_argument("--quiet", action="store_true", help="no progress bar")
    add_param_options(b)
    b.set_defaults(func=cmd_biaxial)

    p = sub.add_parser("probes", help="directional analysis at point A (Figs. 3, 6-9, 11)")
    p.add_argument("--eta", type=float, default=1.029, help="stress ratio q/p of point A")
    p.add_argument("--sigma2", type=float, default=200e3, help="confining stress [Pa]")
    p.add_argument("--n", type=int, default=360, help="uniform strain directions before refinement")
    p.add_argument("--norm", type=float, default=1e-6, help="strain probe norm |d eps| [-]")
    p.add_argument("--d-eps1", type=float, default=1e-5, help="axial strain step of the path [-]")
    p.add_argument("--stress-step", type=float, default=5.0, help="stress-probe spacing [deg]")
    p.add_argument("--sigma-norm", type=float, default=2.5e3, help="stress probe norm [Pa]")
    p.add_argument("--out", default="out/hmodel", help="output folder")
    add_param_options(p)
    p.set_defaults(func=cmd_probes)

    d = sub.add_parser("domain", help="bifurcation domain over confining pressures (Fig. 10)")
    d.add_argument("--sigma2", type=_floats, default=[100e3, 200e3, 400e3],
                   help="comma-separated confining stresses [Pa]")
    d.add_argument("--d-eps1", type=float, default=1e-5, help="axial strain step [-]")
    d.add_argument("--n", type=int, default=180, help="strain directions of each check")
    d.add_argument("--workers", type=int, default=None, help="parallel processes (default: cores)")
    d.add_argument("--out", default="out/hmodel", help="output folder")
    add_param_options(d)
    d.set_defaults(func=cmd_domain)
    return ap


def main(argv=None) -> int:
    ap = build_parser()
    args = ap.parse_args(argv)
    try:
        args.func(args)
    except (ValueError, MixedControlError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


def cmd_domain(args):
    if not args.sigma2:
        raise ValueError("--sigma2 needs at least one confining stress [Pa]")
    P = params_from(args, p0=args.sigma2[0])
    t0 = time.time()
    pts = bifurcation_domain(P, args.sigma2, workers=args.workers, d_eps1=args.d_eps1,
                             n_dir_probe=args.n)
    os.makedirs(args.out, exist_ok=True)
    cols = {k: np.array([getattr(d, k) for d in pts]) for k in pts[0]._fields}
    write_csv(os.path.join(args.out, "domain.csv"), cols)
    plots.fig_domain(pts, os.path.join(args.out, "fig10_domain.png"))
    for d in pts:
        print(f"sigma2 = {d.sigma2:g} Pa: first W2<=0 at (p, q) = ({d.p_w2:.4g}, {d.q_w2:.4g}), "
              f"W2_sigma<=0 at ({d.p_w2sigma:.4g}, {d.q_w2sigma:.4g}), peak ({d.p_peak:.4g}, {d.q_peak:.4g}) Pa")
    print(f"wrote {args.out}/domain.csv, fig10_domain.png ({time.time() - t0:.1f} s)")
