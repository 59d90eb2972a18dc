"""Benchmark of the FE biaxial test (fem): time per Newton iteration split into constitutive
update, assembly and linear solve; indicators + output per step; total to the end of the test.
Ratios against baselines measured in the same process: the hmodel update of a single point
(hexagon-updates/s, the per-call rate) and of one large batch.

    python bench/bench_fem.py                      # 20 x 40 quads, 4 points each, n_dir 180
    python bench/bench_fem.py --nx 10 --ny 20      # the CLI default problem

Goals: (issue #4) 20 x 40 quads, 180 orientations, from the isotropic state past the peak in under
two minutes on 2 cores; (issue #11) the run's total at most 2 x its constitutive update time, with
the FE's constitutive rate at least 0.8 x the batch baseline. Every indicator at every step.

OpenBLAS runs on one thread here (OPENBLAS_NUM_THREADS=1, set before numpy is imported): SuperLU and
ARPACK on ~10^3 dofs are too small for BLAS threads, which on a shared 2-core machine fight the
material kernel's threads for the cores (the global check also sets it itself, fem.indicators).
The global check runs in a process of its own (fem.indicators.GlobalCheckProcess) and Numba's
OpenMP threads sleep when idle (OMP_WAIT_POLICY=passive, set by fem.__main__ when imported here,
before any kernel runs). The machine's load average is printed before and after the run.
Kernels missing from Numba's cache are compiled before the timed run (as the CLI does), so that a
first run after an edit does not count their compilation.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

os.environ["OPENBLAS_NUM_THREADS"] = "1"      # before numpy: see the docstring

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from hmodel import HParams, update, broadcast_state          # noqa: E402
from point.driver import isotropic_state                    # noqa: E402
from fem.biaxial import BiaxialConfig, run_biaxial, format_summary   # noqa: E402
from fem.__main__ import _fem_kernels, _warm_indicators             # noqa: E402
from point.experiment import compile_kernels                       # noqa: E402


def baseline_rates(params: HParams, npts: int, reps: int = 200, batch_reps: int = 20):
    """(single-point, batch of npts) hexagon updates per second of hmodel.update, measured before
    and after the run (the load of a shared machine drifts: the ratios use the single-point mean
    and the interleaved batch baseline, ``InterleavedBatch``)."""
    s0 = isotropic_state(params)
    de = np.array([[1e-4, 0.0], [0.0, -3e-5]])
    update(s0, de, params)
    t = time.perf_counter()
    for _ in range(reps):
        update(s0, de, params)
    single = reps * params.n_dir / (time.perf_counter() - t)
    sb = broadcast_state(s0, (npts,))
    deb = np.repeat(de[..., None], npts, axis=-1)
    update(sb, deb, params)
    t = time.perf_counter()
    for _ in range(batch_reps):
        update(sb, deb, params)
    batch = batch_reps * npts * params.n_dir / (time.perf_counter() - t)
    return single, batch


class InterleavedBatch:
    """The batch baseline (hmodel.update of all the run's points at once) measured in chunks of
    ``reps`` calls between the run's steps, every ``every`` rows (from run_biaxial's progress
    callback), so that it sees the same load as the FE's constitutive updates; the seconds spent
    in it (``spent``) are taken out of the run's total."""

    def __init__(self, params: HParams, npts: int, every: int = 25, reps: int = 3):
        s0 = isotropic_state(params)
        self.sb = broadcast_state(s0, (npts,))
        self.deb = np.repeat(np.array([[1e-4, 0.0], [0.0, -3e-5]])[..., None], npts, axis=-1)
        self.params, self.every, self.reps = params, every, reps
        self.work, self.seconds, self.spent, self.rows = 0, 0.0, 0.0, 0
        update(self.sb, self.deb, params)
        self.chunk()

    def chunk(self):
        t = time.perf_counter()
        for _ in range(self.reps):
            update(self.sb, self.deb, self.params)
        self.seconds += time.perf_counter() - t
        self.work += self.reps * self.deb.shape[-1] * self.params.n_dir

    def progress(self, line: str):
        if line.startswith("step "):
            self.rows += 1
            if self.rows % self.every == 0:
                t = time.perf_counter()
                self.chunk()
                self.spent += time.perf_counter() - t

    @property
    def rate(self) -> float:
        return self.work / self.seconds


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
                                 allow_abbrev=False)
    ap.add_argument("--nx", type=int, default=20)
    ap.add_argument("--ny", type=int, default=40)
    ap.add_argument("--n-dir", type=int, default=180)
    ap.add_argument("--d-eps1", type=float, default=BiaxialConfig.d_eps1)
    ap.add_argument("--eps1-max", type=float, default=BiaxialConfig.eps1_max)
    ap.add_argument("--no-fields", action="store_true", help="skip the XDMF output")
    ap.add_argument("--out", default=None, help="output directory (default: a temporary one)")
    a = ap.parse_args(argv)
    cfg = BiaxialConfig(nx=a.nx, ny=a.ny, n_dir=a.n_dir, d_eps1=a.d_eps1, eps1_max=a.eps1_max,
                        fields=not a.no_fields)
    params = cfg.params()
    npts = a.nx * a.ny * 4
    # kernels not in Numba's cache (a first run, an edited module) compile here, not in the run
    compile_kernels(extra=_fem_kernels(), warm=_warm_indicators)
    single, batch = baseline_rates(params, npts)
    print("load average (1, 5, 15 min) before: %.2f %.2f %.2f" % os.getloadavg())
    print(f"cores: {os.cpu_count()}, problem: {a.nx} x {a.ny} quads, {npts} points, n_dir {a.n_dir}, "
          f"d_eps1 {a.d_eps1:g} to eps1 {a.eps1_max:g}")
    print(f"baseline hmodel.update: single point {single:.3e} hexagon-updates/s, "
          f"batch of {npts} points {batch:.3e} hexagon-updates/s")
    out = a.out or tempfile.mkdtemp(prefix="bench_fem_")
    inter = InterleavedBatch(params, npts)
    t0 = time.perf_counter()
    res = run_biaxial(cfg, out, progress=inter.progress)
    total = time.perf_counter() - t0 - inter.spent
    inter.chunk()
    single2, batch2 = baseline_rates(params, npts)
    batch = inter.rate
    print(f"baseline hmodel.update after the run: single point {single2:.3e}, batch {batch2:.3e} "
          f"hexagon-updates/s; interleaved with the run ({inter.work // (npts * a.n_dir)} calls): "
          f"batch {batch:.3e} (the ratios below use it and the single-point mean; "
          f"{inter.spent:.1f} s of it taken out of the total)")
    single = 0.5 * (single + single2)
    t = res.timings
    it = max(t["iterations"], 1)
    n_upd = it + t["steps"]     # material calls: one per iterate (iterations + the final check)
    rate_fe = n_upd * npts * a.n_dir / t["update"]
    print(format_summary(res.summary))
    print(f"steps {t['steps']}, Newton iterations {t['iterations']} ({t['iterations'] / max(t['steps'], 1):.2f} per step)")
    print(f"per Newton iteration: update {1e3 * t['update'] / it:.1f} ms, assembly "
          f"{1e3 * t['assembly'] / it:.1f} ms, linear solve {1e3 * t['solve'] / it:.1f} ms")
    rows = max(t["steps"] + 1, 1)            # indicators at every converged step and at row 0
    out_s = t["indicators_output"] - t["global_indicators"] - t["local_indicators"]
    print(f"per row ({rows}): indicators + output {1e3 * t['indicators_output'] / rows:.1f} ms = global "
          f"(K, det K, inertia, lam_min, modes) {1e3 * t['global_indicators'] / rows:.1f} + local "
          f"{1e3 * t['local_indicators'] / rows:.1f} + CSV/XDMF/rest {1e3 * out_s / rows:.1f}")
    print(f"total {total:.1f} s = update {t['update']:.1f} + assembly {t['assembly']:.1f} + solve "
          f"{t['solve']:.1f} + indicators/output {t['indicators_output']:.1f} (global "
          f"{t['global_indicators']:.1f}, local {t['local_indicators']:.1f}, output {out_s:.1f}) + rest "
          f"{total - t['update'] - t['assembly'] - t['solve'] - t['indicators_output']:.1f}")
    print(f"FE constitutive rate {rate_fe:.3e} hexagon-updates/s = {rate_fe / single:.1f} x single-point "
          f"baseline, {rate_fe / batch:.2f} x batch baseline")
    ratio = total / t["update"]
    print(f"ratios: total / update = {ratio:.2f} (goal <= 2: {'met' if ratio <= 2 else 'NOT met'}), "
          f"FE rate / batch baseline = {rate_fe / batch:.2f} (goal >= 0.8: "
          f"{'met' if rate_fe / batch >= 0.8 else 'NOT met'}), indicators + output / update = "
          f"{t['indicators_output'] / t['update']:.2f}")
    print(f"goal (< 120 s to the end of the test): {'met' if total < 120 else 'NOT met'} ({total:.1f} s); outputs in {out}")
    print("load average (1, 5, 15 min) after: %.2f %.2f %.2f" % os.getloadavg())


if __name__ == "__main__":
    main()
