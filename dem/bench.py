"""Throughput benchmark: particle-steps/s on a dense sample confined at 200 kPa.

``bench`` measures, in one process and one sitting, the same sample stepped on one thread,
on the default choice (``auto``, see ``common.threads``) and on every thread, optionally while a
busy-loop process keeps a core occupied (what a shared 2-core machine looks like).  The rounds
are interleaved so that a change of the machine's load hits every variant alike.  Then the
energy ledger's cost, ``ledger_cost``: a step's time with it over without it.
"""
from __future__ import annotations

import contextlib
import math
import os
import subprocess
import sys
import time

import numpy as np

from common.threads import ThreadChooser, available_threads

from . import io
from .params import DemParams
from .sample import compact


def confined_sample(n=12000, seed=1, cache_dir=None, params=None, allow_soft=False):
    """Compacted sample of ``params`` (default: the paper's set with n disks and this seed),
    cached as npz in cache_dir if given; ``allow_soft``: ``dem.sample.compact``'s."""
    params = params or DemParams(n=n, seed=seed)
    tag = f"bench_n{params.n}_s{params.seed}"
    if params != DemParams(n=params.n, seed=params.seed):
        import hashlib
        import json
        from .params import hashed_dict     # friction_deg, as before phi_g: the cache stays
        tag += "_" + hashlib.sha256(json.dumps(hashed_dict(params), sort_keys=True).encode()).hexdigest()[:10]
    path = os.path.join(cache_dir, tag + ".npz") if cache_dir else None
    if path and os.path.exists(path):
        try:
            return io.load_state(path)[0]
        except ValueError:
            pass
    sim, _ = compact(params, allow_soft=allow_soft)
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


def ledger_cost(state, steps, chunk=100):
    """The energy ledger's cost (``dem.ledger``): one simulation of ``state`` on one thread runs
    ``steps`` steps in chunks of ``chunk``, the ledger attached to every other chunk (in the
    order on-off, off-on, ... so that neither is always first); the CPU time of the thread
    (``time.thread_time``: what another process takes of the core does not count) of each
    chunk with it over the one without it, the median of the pairs. Measured so, in one
    process and one sitting, it was stable to 0.01 on the shared machine where separate runs
    scattered by 0.1."""
    from .ledger import Ledger
    from .simulation import Simulation
    sim = Simulation(state)
    sim.threads = ThreadChooser(sim.n, 1)
    led = Ledger(sim)
    sim.run(10)           # the first step of the ledger and the compilation out of the timing
    pairs = []
    for k in range(max(1, steps // (2 * chunk))):
        t = {}
        for on in ((True, False) if k % 2 == 0 else (False, True)):
            sim.ledger = led if on else None
            t0 = time.thread_time()
            sim.run(chunk)
            t[on] = time.thread_time() - t0
        pairs.append(t[True] / t[False])
    return float(np.median(pairs))


def bench(n=12000, steps=2000, seed=1, cache_dir=None, busy=False, rounds=3, params=None,
          allow_soft=False):
    """Medians over ``rounds`` interleaved rounds of particle-steps/s on one thread, on the
    default (auto) and on all threads, and their ratios to one thread; ``busy``: with a
    busy-loop process beside the run; ``params``: DemParams in place of (n, seed);
    ``allow_soft``: a set outside the granular regime compacted anyway (``dem.regime``)."""
    st = confined_sample(n, seed, cache_dir, params, allow_soft)
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
    with busy_core() if busy else contextlib.nullcontext():
        out["ledger_cost"] = ledger_cost(st, max(steps, 2000))
    return out


# --------------------------------------------------------------------------------------
# The same sample in LAMMPS (issue 11): the code a user would pick instead
# --------------------------------------------------------------------------------------
def lammps_executable():
    """Path of the LAMMPS binary (``lmp``, as the Debian package installs it), or None."""
    import shutil
    for name in ("lmp", "lmp_serial"):
        path = shutil.which(name)
        if path:
            return path
    return None


def write_lammps(state, out_dir, steps):
    """Write ``out_dir/sample.data`` and ``out_dir/in.bench``: this project's sample in LAMMPS
    with the same contact law and numerics.

    Same radii and positions, atom_style sphere in 2D (``set density/disc`` to density *
    thickness per unit area, so the masses are this project's and ``fix nve/sphere disc``
    gives the disk inertia m r^2 / 2), pair_style gran/hooke/history with Kn, Kt (force/distance: LAMMPS'
    hooke is the linear spring kn * overlap), no viscous damping (gamma_n = gamma_t = 0),
    xmu = tan(friction), the same time step and neighbour skin, four frictionless hooke walls
    (fix wall/gran, same kn) at the walls of the state, rebuild checked every step.  What
    LAMMPS lacks: Cundall's non-viscous damping and the servo of the walls (a few per cent of
    this project's step), so the comparison slightly favours LAMMPS.  Returns the input path.
    """
    p = state.params
    g = lambda v: repr(float(v))   # full precision, plain text
    x, r, walls = state.x, state.r, state.walls
    n = len(r)
    lo, hi = x.min(0) - 2 * r.max(), x.max(0) + 2 * r.max()
    lo = np.minimum(lo, walls[[0, 2]]) - p.skin
    hi = np.maximum(hi, walls[[1, 3]]) + p.skin
    rho_area = p.density * p.thickness
    lines = ["LAMMPS data file: dem bench sample (granular-w2)", "",
             f"{n} atoms", "1 atom types", "",
             f"{g(lo[0])} {g(hi[0])} xlo xhi", f"{g(lo[1])} {g(hi[1])} ylo yhi",
             "-0.5 0.5 zlo zhi", "", "Atoms # sphere", ""]
    lines += [f"{k + 1} 1 {g(2 * r[k])} {g(rho_area)} {g(x[k, 0])} {g(x[k, 1])} 0.0"
              for k in range(n)]
    os.makedirs(out_dir, exist_ok=True)
    with open(os.path.join(out_dir, "sample.data"), "w") as f:
        f.write("\n".join(lines) + "\n")
    mu = math.tan(math.radians(p.phi_g))
    inp = f"""# dem bench sample in LAMMPS: same contact law, masses, inertia, dt and skin
units si
dimension 2
boundary f f p
atom_style sphere
comm_modify vel yes
read_data sample.data
# this LAMMPS reads the data file's density as mass/volume even in 2D: set the disks' mass/area
set type 1 density/disc {g(rho_area)}
pair_style gran/hooke/history {g(p.kn)} {g(p.kt)} 0.0 0.0 {g(mu)} 0
pair_coeff * *
neighbor {g(p.skin)} bin
neigh_modify delay 0 every 1 check yes
fix walls_x all wall/gran hooke {g(p.kn)} 0.0 0.0 0.0 0.0 0 xplane {g(walls[0])} {g(walls[1])}
fix walls_y all wall/gran hooke {g(p.kn)} 0.0 0.0 0.0 0.0 0 yplane {g(walls[2])} {g(walls[3])}
fix integrate all nve/sphere disc
fix plane all enforce2d
timestep {g(p.dt)}
thermo {max(1, steps)}
run 10
run {int(steps)}
"""
    path = os.path.join(out_dir, "in.bench")
    with open(path, "w") as f:
        f.write(inp)
    return path


def lammps_rate(state, steps, work_dir, exe=None):
    """Atom-steps/s of LAMMPS (serial, one OpenMP thread) on ``state`` over ``steps`` steps,
    from its own 'Loop time' line of the timed run (the 10-step warm-up run excluded).
    RuntimeError if LAMMPS fails or prints no loop time."""
    import re
    exe = exe or lammps_executable()
    inp = write_lammps(state, work_dir, steps)
    env = dict(os.environ, OMP_NUM_THREADS="1")
    res = subprocess.run([exe, "-in", os.path.basename(inp), "-log", "log.lammps", "-screen",
                          "none", "-nocite"], cwd=work_dir, env=env, capture_output=True,
                         text=True)
    try:
        with open(os.path.join(work_dir, "log.lammps")) as f:
            log = f.read()
    except OSError:
        log = res.stdout + res.stderr
    loops = re.findall(r"Loop time of ([0-9.eE+-]+) on (\d+) procs for (\d+) steps with (\d+) atoms",
                       log)
    if res.returncode != 0 or len(loops) < 2:
        tail = (log + res.stderr).strip().splitlines()[-3:]
        raise RuntimeError(f"LAMMPS ({exe}) failed: {' | '.join(tail)}")
    t, _, nsteps, natoms = loops[-1]
    return int(natoms) * int(nsteps) / float(t)


def bench_lammps(n=12000, steps=2000, seed=1, cache_dir=None, rounds=3, params=None,
                 work_dir=None):
    """This project on one thread against LAMMPS serial on the same sample, ``rounds``
    interleaved rounds; medians and the ratio (None if LAMMPS is not on the PATH)."""
    import tempfile
    exe = lammps_executable()
    if exe is None:
        return None
    st = confined_sample(n, seed, cache_dir, params)
    ours, theirs = [], []
    with tempfile.TemporaryDirectory() as tmp:
        wd = work_dir or tmp
        for _ in range(rounds):
            ours.append(_rate(st, steps, 1))
            theirs.append(lammps_rate(st, steps, wd, exe))
    one, lmp = float(np.median(ours)), float(np.median(theirs))
    return {"n": st.params.n, "steps": steps, "lammps": exe,
            "particle_steps_per_s_1_thread": one, "lammps_atom_steps_per_s": lmp,
            "ratio_1_thread_to_lammps": one / lmp}
