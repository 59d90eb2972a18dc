"""The rule of the kinematic probe (``dem.burst.path_probe``): at the two switch states a
``dem burst`` run keeps (OUT/rest/R{R}_f{f}_below.npz: the below run's start, an equilibrium
half way up the staircase; ..._past.npz: the last equilibrium, where the holds of +dc failed),
k_path = dc / d eps1 measured with several probe rates and strains, and the noise of c at rest
(the change of c when the state is relaxed at fixed strain once more: a probe of d eps1 = 0).

    python bench/path_probe_rule.py OUT [--rates 0.01,0.003,0.001,0.0003]
                                        [--d-eps1 3e-6,1e-5,3e-5] [--threads 1]

Prints one line per probe (rate, d eps1, c before, dc, k_path, steps, wall time) and, per state,
the noise of c and the k_path noise of each d eps1 (sqrt 2 x the noise of c over d eps1). The
rule chosen (docs/burst.md): slow enough that k_path no longer moves with the rate, small against
the strain of the staircase's steps, large against the noise."""
import argparse
import math
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import numpy as np  # noqa: E402

from dem import io  # noqa: E402
from dem.burst import BurstOptions, path_probe, relax  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", help="a dem burst output folder (its rest/ states)")
    ap.add_argument("--ratio", type=float, default=-2.0)
    ap.add_argument("--fraction", type=float, default=0.9)
    ap.add_argument("--rates", default="0.01,0.003,0.001,0.0003")
    ap.add_argument("--d-eps1", default="3e-6,1e-5,3e-5")
    ap.add_argument("--threads", type=int, default=None, help="default: common.threads chooses")
    ap.add_argument("--switches", default="below,past", help="the states probed")
    a = ap.parse_args(argv)
    rates = [float(x) for x in a.rates.split(",")]
    strains = [float(x) for x in a.d_eps1.split(",")]
    opts = BurstOptions()
    print(f"{'state':6s} {'rate':>7s} {'d_eps1':>8s} {'c_before':>10s} {'dc':>9s} "
          f"{'k_path':>10s} {'steps':>7s} {'wall':>6s}")
    for sw in a.switches.split(","):
        path = os.path.join(a.out, "rest", f"R{a.ratio:g}_f{a.fraction:g}_{sw}.npz")
        st, _ = io.load_state(path)
        t0 = time.time()
        r0 = relax(st, a.ratio, opts, a.threads)
        r1 = relax(r0.state, a.ratio, opts, a.threads)
        # the noise of c at rest: the equilibrium relaxed at fixed strain, and once more
        dz = [r0.c_rest - r0.c_loaded, r1.c_rest - r1.c_loaded]
        sig = math.sqrt(float(np.mean(np.square(dz))))
        print(f"{sw:6s} zero probes: c {r0.c_loaded:.1f} -> {r0.c_rest:.1f} -> {r1.c_rest:.1f} Pa "
              f"(noise of c at rest {sig:.1f} Pa; {time.time() - t0:.0f} s)", flush=True)
        for d in strains:
            print(f"{sw:6s} k_path noise at d eps1 {d:g}: {math.sqrt(2) * sig / d:.3g} Pa")
        for rate in rates:
            for d in strains:
                p = path_probe(st, a.ratio, opts._replace(probe_rate=rate, probe_d_eps1=d),
                               a.threads, sw)
                print(f"{sw:6s} {rate:7.4f} {d:8.1e} {p.c_before:10.1f} "
                      f"{p.c_after - p.c_before:+9.1f} {p.k_path:+10.3e} {p.steps:7d} "
                      f"{p.wall_time:5.0f}s {p.outcome}", flush=True)


if __name__ == "__main__":
    main()
