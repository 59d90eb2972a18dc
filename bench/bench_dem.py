"""Benchmark of the dem kernel: particle-steps/s on a dense sample confined at 200 kPa.

Calls dem.bench.bench (the same function as `python -m dem bench`) and compares with
  * LAMMPS serial on this project's exact sample (same radii and positions, contact law,
    masses, inertia, dt and skin; `dem.bench.write_lammps` writes its data file and input),
    when `lmp` is on the PATH (Debian: apt-get install lammps), interleaved over --rounds;
    goal (issue 11): one thread >= 4x LAMMPS serial at 12,000 disks;
  * a plain NumPy implementation of the same step (same sample, same contact law,
    vectorized over the pair list, np.add.at gather), measured in this process;
  * the YADE figure quoted in issue #3: 4e5 particle-steps/s (one core).
Usage: python bench/bench_dem.py [--sizes 300,2000,12000] [--steps 2000] [--rounds 3]
"""
import argparse
import os
import time

import numpy as np

from dem.bench import bench, bench_lammps, confined_sample
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
    ap = argparse.ArgumentParser(allow_abbrev=False)
    ap.add_argument("--sizes", default="300,2000,12000", help="sample sizes [disks]")
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--rounds", type=int, default=3, help="interleaved rounds (medians)")
    ap.add_argument("--baseline-n", type=int, default=12000, help="sample of the NumPy baseline")
    ap.add_argument("--cache", default=os.path.join(os.path.expanduser("~"), ".cache", "dem"))
    a = ap.parse_args()
    print(f"machine load before: {os.getloadavg()[0]:.2f} (1-min average), "
          f"{os.cpu_count()} cores")
    print(f"{'n':>6} {'busy core':>9} {'1 thread':>11} {'auto':>11} {'all threads':>11} "
          f"{'auto/1':>7} {'all/1':>7} {'ledger':>7}  [particle-steps/s, medians of {a.rounds}; "
          "ledger: a step's time with the energy ledger over without it]")
    worst = 1e9
    for n in (int(v) for v in a.sizes.split(",")):
        for busy in (False, True):
            r = bench(n, a.steps, cache_dir=a.cache, busy=busy, rounds=a.rounds)
            k = f"{r['threads_available']}_threads"
            one, auto, allt = (r["particle_steps_per_s_1_thread"], r["particle_steps_per_s_auto"],
                               r[f"particle_steps_per_s_{k}"])
            worst = min(worst, auto / one)
            print(f"{n:>6} {'yes' if busy else 'no':>9} {one:11.3e} {auto:11.3e} {allt:11.3e} "
                  f"{auto / one:7.2f} {allt / one:7.2f} {r['ledger_cost']:7.3f}", flush=True)
    print(f"worst auto / 1 thread: {worst:.2f} (goal: >= 1/1.2 = 0.83)")
    lmp = bench_lammps(a.baseline_n, a.steps, cache_dir=a.cache, rounds=a.rounds)
    if lmp is None:
        print("LAMMPS: lmp not on the PATH (apt-get install lammps): comparison skipped")
    else:
        print(f"LAMMPS serial ({lmp['lammps']}, n={lmp['n']}, {lmp['steps']} steps, "
              f"medians of {a.rounds} interleaved rounds): {lmp['lammps_atom_steps_per_s']:.3e} "
              f"atom-steps/s; this project on 1 thread {lmp['particle_steps_per_s_1_thread']:.3e}: "
              f"{lmp['ratio_1_thread_to_lammps']:.2f}x (goal >= 4x); "
              f"load {os.getloadavg()[0]:.2f}", flush=True)
    st = confined_sample(a.baseline_n, 1, a.cache)
    base = numpy_baseline(st, max(20, a.steps // 20))
    one = bench(a.baseline_n, a.steps, cache_dir=a.cache, rounds=1)["particle_steps_per_s_1_thread"]
    print(f"numpy baseline (n={a.baseline_n}): {base:.3e} particle-steps/s (numba 1 thread is "
          f"{one / base:.1f}x); YADE reference {YADE_REFERENCE:.1e} (numba 1 thread is "
          f"{one / YADE_REFERENCE:.1f}x)")
    print(f"particle-steps/s: {one:.4g}")


if __name__ == "__main__":
    main()
