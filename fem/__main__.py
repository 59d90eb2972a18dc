"""Command line: ``python -m fem biaxial --nx 10 --ny 20 --out DIR`` (thin argparse over
fem.biaxial.run_biaxial)."""
from __future__ import annotations

import argparse
import os
import sys

import numpy as np

from hmodel import options as opt
from hmodel.experiment import compile_kernels
from hmodel.params import ParamError

from .biaxial import MATERIAL, BiaxialConfig, run_biaxial, format_summary

# Numba's OpenMP threads spin-wait after each parallel region of the material update (libgomp's
# default, ~5 ms with this CPU's slow `pause`), on the core where the run's global check then
# runs in its own process (fem.indicators.GlobalCheckProcess): measured, its checks took 13-16
# ms instead of 7-10 and the run 13.3 s instead of 10.8 (20 x 40 quads). Passive: idle threads
# sleep at once (the update itself measured no slower). libgomp reads this when the first
# parallel region starts, after these imports (they run none); a value set by the user is kept.
os.environ.setdefault("OMP_WAIT_POLICY", "passive")

# memory of one quadrature point per hexagon orientation [bytes]: committed and trial states and
# the update's outputs (10 floats + 2 flags each, about 4 copies alive during a Newton iteration)
POINT_BYTES_PER_DIR = 4 * (10 * 8 + 2)
# the rest of one quadrature point [bytes]: stresses, tangents, B-matrices, its share of the
# sparse stiffness and its factorizations. Together: 66 kB a point at 180 orientations, as
# measured (peak RSS of 20 x 40 quads 160 MB above that of 10 x 20)
POINT_BYTES = 7_000


def _opt_float(s):
    return None if s.lower() == "none" else opt.real()(s)


def build_parser() -> argparse.ArgumentParser:
    d = BiaxialConfig()
    R = opt.real
    ap = opt.Parser(prog="python -m fem", description=__doc__)
    sub = ap.add_subparsers(dest="cmd", required=True)
    b = sub.add_parser("biaxial", help="plane-strain FE biaxial test with bifurcation checks")
    b.add_argument("--out", required=True, help="output directory")
    g = b.add_argument_group("mesh")
    g.add_argument("--nx", type=opt.integer(1), default=d.nx, help="cells across the width (default %(default)s)")
    g.add_argument("--ny", type=opt.integer(1), default=d.ny, help="cells along the height (default %(default)s)")
    g.add_argument("--width", type=R(0, unit="m"), default=d.width, help="B [m] (default %(default)s)")
    g.add_argument("--height", type=R(0, unit="m"), default=d.height, help="H [m] (default %(default)s)")
    g.add_argument("--mesh", dest="mesh_kind", choices=["quad", "tri"], default=d.mesh_kind)
    g.add_argument("--mesh-file", default=None, help="meshio-readable triangle/quad mesh (overrides --nx ...)")
    g = b.add_argument_group("loading")
    g.add_argument("--eps1-max", type=R(0, 0.5), default=d.eps1_max, help="final axial strain (default %(default)s)")
    g.add_argument("--d-eps1", type=R(0, 0.05), default=d.d_eps1, help="axial strain step (default %(default)s)")
    g.add_argument("--sigma2", type=R(0, unit="Pa"), default=None,
                   help="confining pressure = p0 [Pa] (default: p0 of --params FILE, or 200e3)")
    opt.add_param_options(b)
    g = b.add_argument_group("imperfection")
    g.add_argument("--imperfection", choices=["none", "spot", "band"], default="none")
    g.add_argument("--imp-size", type=R(0, 1, hi_open=False), default=d.imp_size,
                   help="fraction of the width, 0 < size <= 1 (spot radius, band half-width)")
    g.add_argument("--imp-phi-g", type=_opt_float, default=d.imp_phi_g, help="weak phi_g [deg] or none")
    g.add_argument("--imp-alpha0", type=_opt_float, default=d.imp_alpha0, help="weak alpha0 [deg] or none")
    g.add_argument("--imp-angle", type=R(unit="deg"), default=d.imp_angle, help="band angle [deg]")
    g = b.add_argument_group("solver and output")
    g.add_argument("--rtol", type=R(0, 1), default=d.rtol)
    g.add_argument("--max-iter", type=opt.integer(1), default=d.max_iter)
    g.add_argument("--max-cutbacks", type=opt.integer(0), default=d.max_cutbacks)
    g.add_argument("--no-fields", dest="fields", action="store_false", help="skip fields.xdmf")
    g.add_argument("--n-sphere", type=opt.integer(1), default=d.n_sphere,
                   help="strain directions sampled for the local min of W2 (default %(default)s)")
    g.add_argument("--quiet", action="store_true")
    return ap


def check_config(cfg: BiaxialConfig) -> None:
    """Everything ``run_biaxial`` would refuse, refused here first as an OptionError naming the
    command-line option: the material (--sigma2 for p0) and weak-zone parameters, the mesh file
    (missing, unreadable, no cells, bad elements) and the memory the run would need."""
    from .mesh import from_file
    from .problem import Imperfection
    try:
        base = cfg.params()
    except ParamError as e:
        raise opt.param_option_error(e) from None
    if cfg.imperfection is not None:
        try:
            Imperfection(kind=cfg.imperfection, size=cfg.imp_size, phi_g=cfg.imp_phi_g,
                         alpha0=cfg.imp_alpha0, angle=cfg.imp_angle).params(base)
        except ParamError as e:
            raise opt.param_option_error(e, {"phi_g": "--imp-phi-g", "alpha0": "--imp-alpha0"}) from None
        except ValueError as e:
            raise opt.OptionError(f"--imperfection {cfg.imperfection}: {e}") from None
    if cfg.mesh_file:
        try:
            mesh = from_file(cfg.mesh_file)
        except ValueError as e:
            raise opt.OptionError(f"--mesh-file {cfg.mesh_file}: {e}") from None
        npts, options = mesh.t.shape[1] * (4 if mesh.t.shape[0] == 4 else 1), "--mesh-file / --n-dir"
    else:
        npts, options = cfg.nx * cfg.ny * (4 if cfg.mesh_kind == "quad" else 2), "--nx / --ny / --n-dir"
    opt.check_memory(npts * (base.n_dir * POINT_BYTES_PER_DIR + POINT_BYTES),
                     f"{npts:.3g} quadrature points of {base.n_dir} orientations", options,
                     f"fewer cells or orientations ({options})")


def _warm_indicators():
    """Compile fem's own kernels on tiny cases: the local indicators on one elastic point, the
    adapter's flag counts (and hmodel's update kernel through it, both drivers) on 70 and 4
    points of 8 orientations, the stiffness on one element, the global check's banded kernels
    on 2 x 4 elements."""
    from hmodel import HParams
    from .adapter import MaterialField
    from .indicators import GlobalCheck, local_indicators
    from .mesh import rectangle
    from .problem import Biaxial
    I = np.eye(2)
    D = (np.einsum("ij,kl->ijkl", I, I) + np.einsum("ik,jl->ijkl", I, I)
         + np.einsum("il,jk->ijkl", I, I))[..., None] * 1e6
    local_indicators(D, n_sphere=8)
    p = HParams(n_dir=8)
    for n in (70, 4):
        mf = MaterialField(n, [(p, np.arange(n))])
        t = mf.trial(np.zeros((2, 2, n)))
        mf.pattern_changes(t, t)
    Biaxial(rectangle(1.0, 1.0, 1, 1), p).stiffness(D[..., [0] * 4])
    b = Biaxial(rectangle(1.0, 2.0, 2, 4), p)
    GlobalCheck(b)(b.stiffness(D[..., [0] * b.npts]))


def _fem_kernels():
    import numba

    from . import adapter, indicators, problem
    return [v for m in (indicators, adapter, problem) for v in vars(m).values()
            if isinstance(v, numba.core.registry.CPUDispatcher)]


def main(argv=None) -> int:
    """``python -m fem biaxial ...``: 0 done, 1 a step failed (converged steps kept), 2 bad
    option (one line, nothing written), 130 / 143 interrupted."""
    return opt.run_cli(build_parser(), argv, _run)


def _run(args, stage) -> int:
    P = opt.params_from(args)
    kw = {k: v for k, v in vars(args).items()
          if k in BiaxialConfig.__dataclass_fields__ and k not in MATERIAL}
    if kw["imperfection"] == "none":
        kw["imperfection"] = None
    cfg = BiaxialConfig(**kw).with_params(P)
    check_config(cfg)
    opt.check_out_dir(args.out)
    compile_kernels(extra=_fem_kernels(), warm=_warm_indicators)

    def progress(line):
        if line.startswith("step"):
            if not stage.written:      # row 0 is on disk: from now on every converged step is
                stage.wrote("curve.csv, fields.xdmf and newton.log up to the last converged step")
            stage.at("load " + " ".join(line.split(" q =")[0].split()))
        if not args.quiet:
            print(line, file=sys.stderr, flush=True)

    stage.at("set-up of the specimen")
    try:
        res = run_biaxial(cfg, args.out, progress=progress, params_note=args.params_note)
    except RuntimeError as e:
        print(f"error: {e}", file=sys.stderr)
        r = getattr(e, "result", None)
        if r is not None:
            print(f"{r.timings['steps']} converged steps are in {args.out}", file=sys.stderr)
            print(format_summary(r.summary))
        return 1
    print(args.params_note)
    print(format_summary(res.summary))
    t = res.timings
    print(f"{t['steps']} steps, {t['iterations']} Newton iterations, {t['total']:.1f} s total "
          f"(update {t['update']:.1f} s, assembly {t['assembly']:.1f} s, solve {t['solve']:.1f} s, "
          f"indicators + output {t['indicators_output']:.1f} s); outputs in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
