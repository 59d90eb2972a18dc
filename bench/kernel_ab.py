"""This checkout's DEM kernel against another checkout's, in one process and one sitting.

The other kernel package (a checkout's `dem/kernels` folder, e.g. of a `git worktree add` of the
commit before a change) is copied into a temporary folder under another name and imported beside
this one; `dem.simulation` steps a simulation with either (its module reference swapped before
each chunk), from the bench's compacted sample (`dem.bench.confined_sample`). Two measures:
  * --pairs pairs of --chunk steps, alternately (base then this, this then base, ...), each
    timed by the thread's CPU time on one thread (what other processes take of the core does
    not count), by wall time on more: the median over the pairs of base's time over this one's
    (above 1: this kernel is faster) and its quartiles. Then whether the two simulations have
    the same positions, velocities and spins to the bit (a change that keeps the bits keeps them);
  * --rounds rounds of the bench's own measure (`dem.bench._rate`: a fresh simulation, 10
    warm-up steps, --steps steps, wall time) for base and this, and LAMMPS serial on the same
    sample (`dem.bench.lammps_rate`) when `lmp` is on the PATH, interleaved: each round's figures
    and ratios, then the medians.
Prints particle-steps/s. Usage:
  python bench/kernel_ab.py --base DIR [--n 12000] [--seed 1] [--pairs 40] [--chunk 200]
                            [--rounds 5] [--steps 2000] [--threads 1] [--cache DIR]
"""
import argparse
import os
import shutil
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def load_base(src, tmp):
    """The kernel package at ``src`` imported as ``kernels_base`` (a copy in ``tmp``, without its
    Numba cache: it compiles once in ``tmp``)."""
    dst = os.path.join(tmp, "kernels_base")
    shutil.copytree(src, dst, ignore=shutil.ignore_patterns("__pycache__"))
    sys.path.insert(0, tmp)
    import kernels_base
    return kernels_base


def alternate(state, kernels, pairs, chunk, threads):
    """Medians of the pairs' time ratios (see the module doc) and whether the bits agree.
    ``kernels``: {"base": module, "this": module}."""
    from common.threads import ThreadChooser
    import dem.simulation as S
    own = S.kernels
    sims = {}
    try:
        for name, K in kernels.items():
            S.kernels = K
            sim = S.Simulation(state)
            sim.threads = ThreadChooser(sim.n, threads)
            sim.run(20)         # compiles, and the first rebuild out of the timing
            sims[name] = sim
        clock = time.thread_time if threads == 1 else time.perf_counter
        t = {name: [] for name in kernels}
        for k in range(pairs):
            for name in (("base", "this") if k % 2 == 0 else ("this", "base")):
                S.kernels = kernels[name]
                t0 = clock()
                sims[name].run(chunk)
                t[name].append(clock() - t0)
    finally:
        S.kernels = own
    q = np.array(t["base"]) / np.array(t["this"])
    same = all(np.array_equal(getattr(sims["base"], f), getattr(sims["this"], f))
               for f in ("x", "v", "w"))
    n = sims["this"].n
    return {"base": n * chunk / float(np.median(t["base"])),
            "this": n * chunk / float(np.median(t["this"])),
            "speedup": float(np.median(q)), "q25": float(np.quantile(q, 0.25)),
            "q75": float(np.quantile(q, 0.75)), "same_bits": bool(same)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 allow_abbrev=False)
    ap.add_argument("--base", required=True,
                    help="the other checkout's kernel package, its dem/kernels folder")
    ap.add_argument("--n", type=int, default=12000, help="disks of the bench sample")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--pairs", type=int, default=40, help="alternated pairs of chunks")
    ap.add_argument("--chunk", type=int, default=200, help="steps of a chunk")
    ap.add_argument("--rounds", type=int, default=5,
                    help="interleaved rounds of the bench's measure and LAMMPS (0: none)")
    ap.add_argument("--steps", type=int, default=2000, help="steps of a round's run")
    ap.add_argument("--threads", type=int, default=1, help="threads of both kernels")
    ap.add_argument("--cache", default=os.path.join(os.path.expanduser("~"), ".cache", "dem"),
                    help="where the compacted sample is cached")
    a = ap.parse_args(argv)
    base = os.path.abspath(a.base)
    if not (os.path.isfile(os.path.join(base, "__init__.py"))
            and os.path.isfile(os.path.join(base, "step.py"))):
        ap.error(f"--base: allowed a checkout's dem/kernels folder (with __init__.py and "
                 f"step.py), got {a.base}")
    for name, v, lo in (("--n", a.n, 2), ("--pairs", a.pairs, 1), ("--chunk", a.chunk, 1),
                        ("--rounds", a.rounds, 0), ("--steps", a.steps, 1),
                        ("--threads", a.threads, 1)):
        if v < lo:
            ap.error(f"{name}: allowed integers >= {lo}, got {v}")
    from dem import bench as B
    from dem import kernels
    print(f"load {os.getloadavg()[0]:.2f} (1-min average); base {base}; this "
          f"{os.path.dirname(kernels.__file__)}", flush=True)
    st = B.confined_sample(a.n, a.seed, a.cache)
    with tempfile.TemporaryDirectory() as tmp:
        ks = {"base": load_base(base, tmp), "this": kernels}
        r = alternate(st, ks, a.pairs, a.chunk, a.threads)
        print(f"{a.pairs} pairs of {a.chunk} steps, {a.threads} thread(s): base {r['base']:.4g}, "
              f"this {r['this']:.4g} particle-steps/s; this / base {r['speedup']:.4f} "
              f"(quartiles {r['q25']:.4f} - {r['q75']:.4f}); the same bits: {r['same_bits']}",
              flush=True)
        if a.rounds:
            import dem.simulation as S
            lmp = B.lammps_executable()
            got = {"base": [], "this": [], "lammps": []}
            for k in range(a.rounds):
                for name in ("base", "this"):
                    S.kernels = ks[name]
                    try:
                        got[name].append(B._rate(st, a.steps, a.threads))
                    finally:
                        S.kernels = kernels
                line = f"round {k}: base {got['base'][-1]:.4g}, this {got['this'][-1]:.4g}"
                if lmp:
                    got["lammps"].append(B.lammps_rate(st, a.steps, os.path.join(tmp, "lmp"),
                                                       lmp))
                    line += (f", LAMMPS {got['lammps'][-1]:.4g}: base / LAMMPS "
                             f"{got['base'][-1] / got['lammps'][-1]:.2f}, this / LAMMPS "
                             f"{got['this'][-1] / got['lammps'][-1]:.2f}")
                print(line + f"; load {os.getloadavg()[0]:.2f}", flush=True)
            med = {k: float(np.median(v)) for k, v in got.items() if v}
            line = (f"medians of {a.rounds}: base {med['base']:.4g}, this {med['this']:.4g} "
                    f"(this / base {med['this'] / med['base']:.3f})")
            if "lammps" in med:
                line += (f", LAMMPS {med['lammps']:.4g}: base / LAMMPS "
                         f"{med['base'] / med['lammps']:.2f}x, this / LAMMPS "
                         f"{med['this'] / med['lammps']:.2f}x")
            else:
                line += "; LAMMPS not on the PATH (Debian: apt-get install lammps)"
            print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
