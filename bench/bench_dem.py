"""Benchmark of the dem kernel: particle-steps/s on a dense sample confined at 200 kPa.

Calls dem.bench.bench (the same function as `python -m dem bench`) and compares with
  * a plain NumPy implementation of the same step (same sample, same contact law,
    vectorized over the pair list, np.add.at gather), measured in this process;
  * the YADE figure quoted in issue #3: 4e5 particle-steps/s (one core).
Usage: python bench/bench_dem.py [--n 12000] [--steps 2000]
"""
import argparse
import math
import os
import time

import numpy as np

from dem.bench import bench, confined_sample
from dem.simulation import Simulation

YADE_REFERENCE = 4e5  # particle-steps/s, quoted in issue #3


def numpy_baseline(state, steps):
    """Same physics as the kernel step (pair forces, walls, Cundall damping, leapfrog),
    written with NumPy array operations over the (fixed) pair list."""
    sim = Simulation(state)
    p = sim.params
    x, v, w, r, m, I = sim.x, sim.v, sim.w, sim.r, sim.m, sim.inertia
    pi, pj, ft = sim.pairs.pi.astype(np.int64), sim.pairs.pj.astype(np.int64), sim.pairs.ft.copy()
    walls = sim.walls
    dt, kn, kt, mu, lam = sim.dt, p.kn, p.kt, sim.mu, p.damping
    t0 = time.perf_counter()
    for _ in range(steps):
        d = x[pj] - x[pi]
        dist = np.sqrt((d ** 2).sum(1))
        ov = r[pi] + r[pj] - dist
        on = ov > 0
        n = d / dist[:, None]
        t = np.column_stack([-n[:, 1], n[:, 0]])
        dv = v[pj] - v[pi]
        vt = (dv * t).sum(1) - (w[pi] * r[pi] + w[pj] * r[pj])
        fn = np.where(on, kn * ov, 0.0)
        ft = np.where(on, np.clip(ft + kt * vt * dt, -mu * fn, mu * fn), 0.0)
        f = -fn[:, None] * n + ft[:, None] * t
        F = np.zeros_like(x)
        np.add.at(F, pi, f)
        np.add.at(F, pj, -f)
        tq = np.zeros(len(r))
        np.add.at(tq, pi, ft * r[pi])
        np.add.at(tq, pj, ft * r[pj])
        for wi in range(4):
            ax, s = wi // 2, (1.0 if wi % 2 == 0 else -1.0)
            o = r - s * (x[:, ax] - walls[wi])
            F[:, ax] += s * kn * np.clip(o, 0, None)
        F -= lam * np.abs(F) * np.sign(v)
        tq -= lam * np.abs(tq) * np.sign(w)
        v += F / m[:, None] * dt
        w += tq / I * dt
        x += v * dt
    return len(r) * steps / (time.perf_counter() - t0)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=12000)
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--cache", default=os.path.join(os.path.expanduser("~"), ".cache", "dem"))
    a = ap.parse_args()
    res = bench(a.n, a.steps, cache_dir=a.cache)
    st = confined_sample(a.n, 1, a.cache)
    base = numpy_baseline(st, max(20, a.steps // 20))
    one, allt = res["particle_steps_per_s_1_thread"], res["particle_steps_per_s_all_threads"]
    print(f"n={a.n} steps={a.steps} threads={res['threads']}")
    print(f"numba 1 thread      : {one:.3e} particle-steps/s")
    print(f"numba {res['threads']} threads     : {allt:.3e} particle-steps/s")
    print(f"numpy baseline      : {base:.3e} particle-steps/s  (numba 1 thread is {one / base:.1f}x)")
    print(f"YADE reference      : {YADE_REFERENCE:.1e} particle-steps/s (numba 1 thread is "
          f"{one / YADE_REFERENCE:.1f}x, all threads {allt / YADE_REFERENCE:.1f}x)")
    print(f"goal 2e7 on one thread: {'met' if one >= 2e7 else 'NOT met'}")
    print(f"particle-steps/s: {allt:.4g}")


if __name__ == "__main__":
    main()
