"""Throughput benchmark: particle-steps/s on a dense sample confined at 200 kPa.

``bench`` measures, in one process and one sitting, the same sample stepped on one thread,
on the default choice (``auto``, see ``dem.threads``) and on every thread, optionally while a
busy-loop process keeps a core occupied (what a shared 2-core machine looks like).  The rounds
are interleaved so that a change of the machine's load hits every variant alike.
"""
from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import time

import numpy as np

from . import io
from .params import DemParams
from .sample import compact
from .threads import ThreadChooser, available_threads


def confined_sample(n=12000, seed=1, cache_dir=None, params=None):
    """Compacted sample of ``params`` (default: the paper's set with n disks and this seed),
    cached as npz in cache_dir if given."""
    params = params or DemParams(n=n, seed=seed)
    tag = f"bench_n{params.n}_s{params.seed}"
    if params != DemParams(n=params.n, seed=params.seed):
        import hashlib
        import json
        tag += "_" + hashlib.sha256(json.dumps(params.to_dict(), sort_keys=True).encode()).hexdigest()[:10]
    path = os.path.join(cache_dir, tag + ".npz") if cache_dir else None
    if path and os.path.exists(path):
        try:
            return io.load_state(path)[0]
        except ValueError:
            pass
    sim, _ = compact(params)
    st = sim.state()
    if path:
        io.save_state(path, st)
    return st


def _rate(state, steps, threads):
    """particle-steps/s of ``steps`` steps from ``state`` (wall time); threads None = auto."""
    from .simulation import Simulation
    sim = Simulation(state)
    sim.threads = ThreadChooser(sim.n, threads)
    sim.run(10)  # warm-up (compilation is cached)
    t = time.perf_counter()
    sim.run(steps)
    return sim.n * steps / (time.perf_counter() - t)


class busy_core:
    """Context manager: a process spinning on one core while the block runs."""

    def __enter__(self):
        self.p = subprocess.Popen([sys.executable, "-c", "while True: pass"])
        time.sleep(0.2)
        return self

    def __exit__(self, *exc):
        self.p.kill()
        self.p.wait()


def bench(n=12000, steps=2000, seed=1, cache_dir=None, busy=False, rounds=3, params=None):
    """Medians over ``rounds`` interleaved rounds of particle-steps/s on one thread, on the
    default (auto) and on all threads, and their ratios to one thread; ``busy``: with a
    busy-loop process beside the run; ``params``: DemParams in place of (n, seed)."""
    st = confined_sample(n, seed, cache_dir, params)
    n = st.params.n
    nt = available_threads()
    variants = {"1_thread": 1, "auto": None, f"{nt}_threads": nt}
    got = {k: [] for k in variants}
    with busy_core() if busy else contextlib.nullcontext():
        for _ in range(rounds):
            for k, th in variants.items():
                got[k].append(_rate(st, steps, th))
    med = {k: float(np.median(v)) for k, v in got.items()}
    out = {"n": n, "steps": steps, "busy_core": bool(busy), "threads_available": nt}
    for k, v in med.items():
        out[f"particle_steps_per_s_{k}"] = v
        out[f"ratio_{k}_to_1_thread"] = v / med["1_thread"]
    return out
