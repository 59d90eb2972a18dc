"""Benchmark of the FE biaxial test (fem): time per Newton iteration split into constitutive
update, assembly and linear solve; indicators + output per step; total to the end of the test.
Ratios against baselines measured in the same process: the hmodel update of a single point
(hexagon-updates/s, the per-call rate) and of one large batch.

    python bench/bench_fem.py                      # 20 x 40 quads, 4 points each, n_dir 180
    python bench/bench_fem.py --nx 10 --ny 20      # the CLI default problem

Goal (issue #4): 20 x 40 quads, 180 orientations, from the isotropic state past the peak in under
two minutes on 2 cores.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from hmodel import HParams, update, broadcast_state          # noqa: E402
from hmodel.driver import isotropic_state                    # noqa: E402
from fem.biaxial import BiaxialConfig, run_biaxial, format_summary   # noqa: E402


def baseline_rates(params: HParams, npts: int, reps: int = 200):
    """(single-point, batch of npts) hexagon updates per second of hmodel.update."""
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
    for _ in range(5):
        update(sb, deb, params)
    batch = 5 * npts * params.n_dir / (time.perf_counter() - t)
    return single, batch


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
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
    single, batch = baseline_rates(params, npts)
    print(f"cores: {os.cpu_count()}, problem: {a.nx} x {a.ny} quads, {npts} points, n_dir {a.n_dir}, "
          f"d_eps1 {a.d_eps1:g} to eps1 {a.eps1_max:g}")
    print(f"baseline hmodel.update: single point {single:.3e} hexagon-updates/s, "
          f"batch of {npts} points {batch:.3e} hexagon-updates/s")
    out = a.out or tempfile.mkdtemp(prefix="bench_fem_")
    t0 = time.perf_counter()
    res = run_biaxial(cfg, out)
    total = time.perf_counter() - t0
    t = res.timings
    it = max(t["iterations"], 1)
    n_upd = it + t["steps"]     # material calls: one per iterate (iterations + the final check)
    rate_fe = n_upd * npts * a.n_dir / t["update"]
    print(format_summary(res.summary))
    print(f"steps {t['steps']}, Newton iterations {t['iterations']} ({t['iterations'] / max(t['steps'], 1):.2f} per step)")
    print(f"per Newton iteration: update {1e3 * t['update'] / it:.1f} ms, assembly "
          f"{1e3 * t['assembly'] / it:.1f} ms, linear solve {1e3 * t['solve'] / it:.1f} ms")
    print(f"per step: indicators + output {1e3 * t['indicators_output'] / max(t['steps'], 1):.1f} ms")
    print(f"total {total:.1f} s = update {t['update']:.1f} + assembly {t['assembly']:.1f} + solve "
          f"{t['solve']:.1f} + indicators/output {t['indicators_output']:.1f} + rest "
          f"{total - t['update'] - t['assembly'] - t['solve'] - t['indicators_output']:.1f}")
    print(f"FE constitutive rate {rate_fe:.3e} hexagon-updates/s = {rate_fe / single:.1f} x single-point "
          f"baseline, {rate_fe / batch:.2f} x batch baseline")
    print(f"goal (< 120 s to the end of the test): {'met' if total < 120 else 'NOT met'} ({total:.1f} s); outputs in {out}")


if __name__ == "__main__":
    main()
