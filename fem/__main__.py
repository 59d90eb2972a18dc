"""Command line: ``python -m fem biaxial --nx 10 --ny 20 --out DIR`` (thin argparse over
fem.biaxial.run_biaxial)."""
from __future__ import annotations

import argparse
import sys

from .biaxial import BiaxialConfig, run_biaxial, format_summary


def _opt_float(s):
    return None if s.lower() == "none" else float(s)


def build_parser() -> argparse.ArgumentParser:
    d = BiaxialConfig()
    ap = argparse.ArgumentParser(prog="python -m fem", description=__doc__)
    sub = ap.add_subparsers(dest="cmd", required=True)
    b = sub.add_parser("biaxial", help="plane-strain FE biaxial test with bifurcation checks")
    b.add_argument("--out", required=True, help="output directory")
    g = b.add_argument_group("mesh")
    g.add_argument("--nx", type=int, default=d.nx, help="cells across the width (default %(default)s)")
    g.add_argument("--ny", type=int, default=d.ny, help="cells along the height (default %(default)s)")
    g.add_argument("--width", type=float, default=d.width, help="B [m] (default %(default)s)")
    g.add_argument("--height", type=float, default=d.height, help="H [m] (default %(default)s)")
    g.add_argument("--mesh", dest="mesh_kind", choices=["quad", "tri"], default=d.mesh_kind)
    g.add_argument("--mesh-file", default=None, help="meshio-readable triangle/quad mesh (overrides --nx ...)")
    g = b.add_argument_group("loading")
    g.add_argument("--eps1-max", type=float, default=d.eps1_max, help="final axial strain (default %(default)s)")
    g.add_argument("--d-eps1", type=float, default=d.d_eps1, help="axial strain step (default %(default)s)")
    g.add_argument("--sigma2", type=float, default=d.sigma2, help="confining pressure = p0 [Pa] (default %(default)s)")
    g = b.add_argument_group("material (Table I defaults)")
    g.add_argument("--kn", type=float, default=d.kn)
    g.add_argument("--kt", type=float, default=d.kt)
    g.add_argument("--phi-g", type=float, default=d.phi_g)
    g.add_argument("--alpha0", type=float, default=d.alpha0)
    g.add_argument("--r-g", type=float, default=d.r_g)
    g.add_argument("--thickness", type=float, default=None,
                   help="hexagon slab thickness h [m] of the material (default 2 r_g)")
    g.add_argument("--n-dir", type=int, default=d.n_dir)
    g = b.add_argument_group("imperfection")
    g.add_argument("--imperfection", choices=["none", "spot", "band"], default="none")
    g.add_argument("--imp-size", type=float, default=d.imp_size, help="fraction of the width")
    g.add_argument("--imp-phi-g", type=_opt_float, default=d.imp_phi_g, help="weak phi_g [deg] or none")
    g.add_argument("--imp-alpha0", type=_opt_float, default=d.imp_alpha0, help="weak alpha0 [deg] or none")
    g.add_argument("--imp-angle", type=float, default=d.imp_angle, help="band angle [deg]")
    g = b.add_argument_group("solver and output")
    g.add_argument("--rtol", type=float, default=d.rtol)
    g.add_argument("--max-iter", type=int, default=d.max_iter)
    g.add_argument("--max-cutbacks", type=int, default=d.max_cutbacks)
    g.add_argument("--no-fields", dest="fields", action="store_false", help="skip fields.xdmf")
    g.add_argument("--n-sphere", type=int, default=d.n_sphere,
                   help="strain directions sampled for the local min of W2 (default %(default)s)")
    g.add_argument("--quiet", action="store_true")
    return ap


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    kw = {k: v for k, v in vars(args).items() if k not in ("cmd", "out", "quiet")}
    if kw["imperfection"] == "none":
        kw["imperfection"] = None
    progress = None if args.quiet else (lambda s: print(s, file=sys.stderr, flush=True))
    try:
        cfg = BiaxialConfig(**kw)
        res = run_biaxial(cfg, args.out, progress=progress)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except RuntimeError as e:
        print(f"error: {e}", file=sys.stderr)
        r = getattr(e, "result", None)
        if r is not None:
            print(f"{r.timings['steps']} converged steps are in {args.out}", file=sys.stderr)
            print(format_summary(r.summary))
        return 1
    print(format_summary(res.summary))
    t = res.timings
    print(f"{t['steps']} steps, {t['iterations']} Newton iterations, {t['total']:.1f} s total "
          f"(update {t['update']:.1f} s, assembly {t['assembly']:.1f} s, solve {t['solve']:.1f} s, "
          f"indicators + output {t['indicators_output']:.1f} s); outputs in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
