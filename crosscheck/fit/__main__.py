"""Command line: ``python -m crosscheck.fit [--dem docs/gallery/full] [--out
docs/gallery/fit_dem12000] ...`` (formerly ``python -m dem.crosscheck_fit``, the same options):
``run_fit`` with the options given. Exit 0 done, 1 the DEM's curve not fittable, 2 bad option
(one line), 130 / 143 interrupted."""
from __future__ import annotations

import os
import sys

from common import options as opt

PROG = "python -m crosscheck.fit"


def _log(msg):
    print(f"[fit_dem] {msg}", file=sys.stderr, flush=True)


def build_parser() -> opt.Parser:
    ap = opt.Parser(prog=PROG, description="fit the H-model to the DEM's drained curve and compare "
                    "the bifurcation domains")
    ap.add_argument("--dem", default="docs/gallery/full",
                    help="folder of the DEM run: biaxial.csv and domain12000/{domain.csv,boundaries.json}")
    ap.add_argument("--out", default="docs/gallery/fit_dem12000", help="output folder")
    ap.add_argument("--starts", type=opt.integer(1), default=8, help="starts of the fit")
    ap.add_argument("--seed", type=opt.integer(0), default=0, help="seed of the starts")
    ap.add_argument("--n-dir", type=opt.integer(8), default=180, help="hexagon orientations of the H-model")
    ap.add_argument("--n-probes", type=opt.integer(8), default=360,
                    help="strain directions of each sweep [-] (default 360)")
    opt.add_quiet(ap)
    return ap


def main(argv=None) -> int:
    ap = build_parser()

    def run(args, stage):
        from .run import DEM_FILES, NotFittable, run_fit
        for f in DEM_FILES:
            if not os.path.isfile(os.path.join(args.dem, f)):
                raise opt.OptionError(f"--dem {args.dem}: no {f}: allowed the folder of a DEM run with "
                                      "its domain (docs/gallery/full)")
        opt.check_out_dir(args.out)
        regenerate = PROG + "".join(f" --{k.replace('_', '-')} {v}" for k, v in vars(args).items()
                                    if v != ap.get_default(k))
        try:
            c = run_fit(args.dem, args.out, args.starts, args.seed, args.n_dir, args.n_probes,
                        options=dict(vars(args)), regenerate=regenerate,
                        progress=None if args.quiet else _log, stage=stage)
        except NotFittable as e:
            print(f"not fittable: {e}", file=sys.stderr)
            print(f"wrote {args.out}/summary.json, fig_fit.png")
            return 1
        print("\n".join(c["verdicts"]))
        print(f"wrote {args.out}/comparison.md and the rest ({c['wall_time_s']:.0f} s)")
        return 0

    return opt.run_cli(ap, argv, run, errors=(ValueError,))


if __name__ == "__main__":
    sys.exit(main())
