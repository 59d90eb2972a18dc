"""Throughput benchmark: particle-steps/s on a dense sample confined at 200 kPa."""
from __future__ import annotations

import os
import time

import numba
import numpy as np

from . import io
from .params import DemParams
from .sample import compact


def confined_sample(n=12000, seed=1, cache_dir=None):
    """Compacted sample (cached as npz in cache_dir if given)."""
    path = os.path.join(cache_dir, f"bench_n{n}_s{seed}.npz") if cache_dir else None
    if path and os.path.exists(path):
        try:
            return io.load_state(path)[0]
        except ValueError:
            pass
    sim, _ = compact(DemParams(n=n, seed=seed))
    st = sim.state()
    if path:
        io.save_state(path, st)
    return st


def _rate(state, steps, threads):
    from .simulation import Simulation
    numba.set_num_threads(threads)
    sim = Simulation(state)
    sim.run(10)  # warm-up (compilation is cached)
    t = time.perf_counter()
    sim.run(steps)
    return sim.n * steps / (time.perf_counter() - t)


def bench(n=12000, steps=2000, seed=1, cache_dir=None):
    """Returns a dict with particle-steps/s on one thread and on all threads (wall time, in
    the same process) and their ratio."""
    st = confined_sample(n, seed, cache_dir)
    nt = numba.config.NUMBA_NUM_THREADS
    one = _rate(st, steps, 1)
    allt = _rate(st, steps, nt)
    numba.set_num_threads(nt)
    return {"n": n, "steps": steps, "threads": nt, "particle_steps_per_s_1_thread": one,
            "particle_steps_per_s_all_threads": allt, "thread_speedup": allt / one}
