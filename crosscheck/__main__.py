"""Command line: ``python -m crosscheck --out DIR [--full] ...``, the cross-check of the three
parts (``crosscheck.run.run_crosscheck``), with the options ``python -m dem crosscheck`` had, from
the vocabulary of ``common.options`` and checked by the same rules (one line, exit 2, before
anything runs). One command, no subcommands: the H-model fit to a DEM run is its own command,
``python -m crosscheck.fit``."""
from __future__ import annotations

import argparse
import os
import sys
import time

from common import options as opt

DESCRIPTION = """The cross-check of the three parts: the H-model material point, the FE biaxial
specimen and the DEM sample side by side, each conclusion of the paper's section 5 stated with
the run's numbers (report.md, conclusions.json, the figures), and the burst section (docs/burst.md).
python -m crosscheck --help lists the options, each with its unit and default. --out is required:
a folder that records the command that wrote it (command.json); another command refuses that
folder unless --force. The H-model fitted to a DEM run: python -m crosscheck.fit."""


def build_parser() -> opt.Parser:
    from dem.__main__ import parse_ratios
    add = opt.add
    x = opt.Parser(prog="python -m crosscheck", description=DESCRIPTION,
                   formatter_class=argparse.RawDescriptionHelpFormatter)
    opt.add_out(x)
    add(x, "--dem-params", metavar="FILE", default_text="the paper's stated set")
    add(x, "--hmodel-params", metavar="FILE", default_text="Table I; both at 200 kPa, the FE at "
        "72 orientations")
    add(x, "--full")
    add(x, "--n", default_text="1000, 12000 with --full", note="of the DEM sample")
    add(x, "--seed", 1, note="of the DEM sample")
    add(x, "--rate", default_text="0.05, 0.01 with --full", note="of the DEM's biaxial test")
    add(x, "--max-steps", default_text="the probes'", note="of each DEM probe run")
    add(x, "--workers", default_text="the cores",
        note="for the DEM's runs after its biaxial test: its relaxations, probes and burst, one "
             "pool")
    add(x, "--scheduler", default_text="none (local processes)",
        note="for the DEM's runs after its biaxial test (one task a run)")
    add(x, "--no-dem")
    add(x, "--no-domain")
    add(x, "--threads", default_text="auto (common.threads)",
        note="of the DEM compaction, biaxial test and relaxations")
    add(x, "--resume", note="the DEM work an interrupted run left in --out/dem")
    add(x, "--dem-domain", default_text="on, off with --full (use dem domain there)")
    add(x, "--no-burst")
    add(x, "--ratios", parse=parse_ratios, note="of the burst section", default_text="-2")
    add(x, "--start-fractions", note="of the burst section, of each part's drained peak eta, "
        "among the DEM's saved ones", default_text="0.9")
    opt.add_quiet(x)
    return x


def check(a):
    """Every option and input file, before anything runs (the order of ``python -m dem``'s
    checks): --out, the parameter files, --workers / --scheduler / --threads, the burst
    section's start fractions."""
    from dem.__main__ import check_run_options
    from dem.params import load_params
    from hmodel.params import load_params as load_hparams
    opt.check_out_dir(a.out)
    dem_set = load_params(a.dem_params, option="--dem-params") if a.dem_params else None
    if not a.no_dem:
        # the DEM sample of a set outside the granular regime is no packing to hold the theory
        # against: refused here, before the H-model's and the FE's parts run (no --allow-soft:
        # `python -m dem` runs such a set for its own study)
        from dem.params import DemParams
        from dem.regime import check_regime
        from .run import SIGMA2
        check_regime(dem_set or DemParams(), SIGMA2, False,
                     f"--dem-params {a.dem_params}" if a.dem_params else "the paper's set", "",
                     "the cross-check holds the theory against granular packings only "
                     "(python -m dem biaxial --allow-soft runs such a set for its own study)")
    if a.hmodel_params:
        load_hparams(a.hmodel_params, option="--hmodel-params")
    check_run_options(a)
    if not a.no_burst and not a.no_dem:
        from dem.experiment import SAVE_FRACTIONS
        bad = [f for f in a.start_fractions or () if f not in SAVE_FRACTIONS]
        if bad:
            raise opt.OptionError(f"--start-fractions {bad}: allowed fractions the DEM's "
                                  f"biaxial test saves, {list(SAVE_FRACTIONS)}")


def main(argv=None) -> int:
    """``python -m crosscheck ...``: 0 done, 1 a DEM run stopped on an unsound state (one line,
    its state kept in the DEM's folder), 2 bad option (one line), 130 / 143 interrupted."""
    def run(a, stage):
        check(a)
        from dem.regime import UnsoundState
        try:
            return _run(a, stage)
        except UnsoundState as e:     # a run's failure, not bad input: one line, exit 1
            from dem.io import save_unsound
            kept = save_unsound(e, os.path.join(a.out, "dem"))
            print(f"stopped: {e}" + (f"; the state is kept in {kept}" if kept else ""),
                  file=sys.stderr)
            return 1

    def _run(a, stage):
        stage.at("crosscheck (run it again with --resume to continue)")
        from dem.__main__ import compile_kernels_once
        compile_kernels_once()        # before the run's own timers start
        from .run import run_crosscheck
        t0 = time.time()
        run_crosscheck(a.out, full=a.full, n=a.n, seed=a.seed, rate=a.rate, workers=a.workers,
                       skip_dem=a.no_dem, domain=not a.no_domain, dem_max_steps=a.max_steps,
                       threads=a.threads, resume=a.resume, dem_domain=a.dem_domain,
                       dem_params=a.dem_params, scheduler=a.scheduler,
                       hmodel_params=a.hmodel_params, burst=not a.no_burst,
                       burst_ratios=a.ratios, burst_fractions=a.start_fractions,
                       verbose=not a.quiet)
        with open(os.path.join(a.out, "report.md")) as f:
            print(f.read().split("## The paper's conclusions")[1])
        print(f"crosscheck: report {os.path.join(a.out, 'report.md')}; "
              f"wall time {time.time() - t0:.1f} s")
        return 0

    return opt.run_cli(build_parser(), argv, run, errors=(ValueError, RuntimeError))


if __name__ == "__main__":
    sys.exit(main())
