"""Cost of the anatomy of a burst (``dem.anatomy``) against the run it watches.

At every check of a hold or a probe (1000 steps) the run calls ``contact_state`` and
``anatomy``; the goal (issue 24) is less than 10 % of a check interval on one thread.  The
bench sample (``dem.bench.confined_sample``: the paper's set, 200 kPa, cached in ``--cache``) is
sheared at a constant strain rate on one thread (the proportional path's axial rate, 0.01/s,
R = -2: contacts open, close and slide); after each interval of ``--steps`` steps the state of
the contacts and the anatomy since the start are computed.  Timed in this process: the wall
time and the CPU time of each (``time.process_time``: another process's load on the shared
machine does not count), medians over ``--rounds`` intervals; then, once, the VTU files and a
one-panel figure (written at the onset of a burst and at its end only).
Usage: python bench/bench_anatomy.py [--n 12000] [--steps 1000] [--rounds 7] [--cache DIR]
"""
import argparse
import os
import tempfile
import time

import numpy as np

from dem.anatomy import anatomy, contact_state, plot_anatomy, write_anatomy_vtk
from dem.bench import confined_sample
from dem.simulation import Simulation
from common.threads import ThreadChooser
from dem.walls import strain_rate


def _timed(fn, *args):
    w, c = time.perf_counter(), time.process_time()
    out = fn(*args)
    return out, time.perf_counter() - w, time.process_time() - c


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=12000)
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--cache", default=os.path.expanduser("~/.cache/dem"))
    a = ap.parse_args()
    st = confined_sample(a.n, 1, a.cache)
    sim = Simulation(st)
    sim.threads = ThreadChooser(sim.n, 1)
    sim.set_control(strain_rate(-2 * 0.01, 0.01, sim.ref_len))
    sim.run(10)                       # compilation (cached) out of the timings
    s0 = contact_state(sim)
    anatomy(s0, s0, sim.n)
    rows = []
    for _ in range(a.rounds):
        _, w_run, c_run = _timed(sim.run, a.steps)
        s, w_cs, c_cs = _timed(contact_state, sim)
        an, w_an, c_an = _timed(anatomy, s0, s, sim.n)
        rows.append((w_run, c_run, w_cs, c_cs, w_an, c_an))
    m = np.median(np.array(rows), axis=0)
    print(f"n={sim.n} contacts={len(s.keys)} steps={a.steps} rounds={a.rounds} "
          f"(median wall / CPU time [s])")
    print(f"run of {a.steps} steps, one thread: {m[0]:.3f} / {m[1]:.3f}")
    print(f"contact_state:                      {m[2] * 1e3:.1f} / {m[3] * 1e3:.1f} ms")
    print(f"anatomy:                            {m[4] * 1e3:.1f} / {m[5] * 1e3:.1f} ms")
    print(f"anatomy_cost (contact_state + anatomy over the run): wall "
          f"{(m[2] + m[4]) / m[0]:.4f}, CPU {(m[3] + m[5]) / m[1]:.4f} (goal < 0.10)")
    print(f"last check: {an}")
    with tempfile.TemporaryDirectory() as d:
        _, w_vtk, _ = _timed(write_anatomy_vtk, d, "bench", sim, s0)
        _, w_fig, _ = _timed(plot_anatomy, os.path.join(d, "anatomy.png"), [("bench", sim, s0)])
    print(f"once per burst: write_anatomy_vtk {w_vtk:.2f} s, plot_anatomy (one panel) "
          f"{w_fig:.2f} s")


if __name__ == "__main__":
    main()
