"""Directional analysis at a saved state (paper section 4, Figs. 15-17).

Each probe starts from the reference state R (state A relaxed under stress control at its
own wall stresses, so that both ends of a probe are equilibrium states as the paper's
Eq. 15 assumes), ramps the wall stresses to s_R + ds with |ds| = norm in direction
alpha_sigma (tan alpha_sigma = ds1/ds2, axis 1 = y = axial, axis 2 = x = lateral) and
relaxes to equilibrium.  Reported per probe (compression positive everywhere):
  w2       = ds . de / (|ds| |de|)                               (macro, section 4)
  w2_micro = sum_c df . dl / (V |ds| |de|)                       (Eq. 15, contacts at R,
             at the end or both; a missing end has f = 0; f on p by q, l = x_q - x_p)
  w2n, w2t = normal / tangential parts with n_c the branch unit vector at R
  w2_walls = same sum over the wall contacts (l = wall point - x_p), not in the paper's sum
  w2_unbalanced = sum_p df^p . dx^p / (V |ds| |de|)              (Eq. 14 second term)
Every probe is run twice: sliding allowed and sliding prevented (Coulomb cap off) to get
the elastic strain; plastic = |de - de_elastic| > plastic_tol |de_elastic|.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from typing import NamedTuple

import numpy as np

from .sample import equilibrate
from .simulation import Simulation, State
from .walls import stress_path


class ProbeOptions(NamedTuple):
    norm: float = 2500.0            # |ds| [Pa]
    ramp_steps: int = 5000          # stress ramp length [steps]
    unbalanced_tol: float = 1e-4    # equilibrium: unbalanced-force ratio below this
    stress_tol: float = 25.0        # and wall stresses within this of the target [Pa]
    max_steps: int = 400_000        # iteration cap (reported in the CSV, never silent)
    relax_max_steps: int = 2_000_000  # cap of the relaxation of A into the reference R
    check_every: int = 1000         # equilibrium check interval [steps]
    plastic_tol: float = 0.05       # plastic if |de_p| > plastic_tol * |de_elastic|

    def validate(self):
        checks = (("norm", self.norm > 0, "norm > 0 [Pa]"),
                  ("ramp_steps", self.ramp_steps >= 0, "ramp_steps >= 0"),
                  ("unbalanced_tol", 0 < self.unbalanced_tol < 1, "0 < unbalanced_tol < 1"),
                  ("stress_tol", 0 < self.stress_tol < self.norm, "0 < stress_tol < norm [Pa]"),
                  ("max_steps", self.max_steps > 0, "max_steps > 0"),
                  ("relax_max_steps", self.relax_max_steps > 0, "relax_max_steps > 0"),
                  ("check_every", self.check_every > 0, "check_every > 0"),
                  ("plastic_tol", self.plastic_tol > 0, "plastic_tol > 0"))
        for name, ok, rng in checks:
            if not ok:
                raise ValueError(f"{name}={getattr(self, name)!r}; allowed range: {rng}")
        return self


def directions(step_q3=5.0, step_other=10.0):
    """alpha_sigma [deg]: every step_q3 in the third quadrant [180, 270] (ds1<0, ds2<0),
    every step_other elsewhere.  Default: 45 directions."""
    if not (0 < step_q3 <= 90 and 0 < step_other <= 90):
        raise ValueError("direction steps must be in (0, 90] deg")
    a = list(np.arange(0.0, 180.0 - 1e-9, step_other))
    a += list(np.arange(180.0, 270.0 + 1e-9, step_q3))
    a += list(np.arange(270.0 + step_other, 360.0 - 1e-9, step_other))
    return [float(round(v, 9)) for v in a]


def _axes(sim):
    """Wall stresses and sizes in the (1, 2) = (y, x) order."""
    snap = sim.snapshot()
    sx, sy = sim.wall_stress(snap)
    return snap, np.array([sy, sx]), sim.size[::-1].copy()


def prepare_reference(state: State, opts: ProbeOptions = ProbeOptions(), verbose=False):
    """Relax `state` under stress control at its own wall stresses.  Returns
    (State R, converged, steps, unbalanced)."""
    sim = Simulation(state)
    sim.cap_on = True
    s = sim.wall_stress()
    sim.set_control(stress_path(s, s, sim.step, 0))
    last = [time.time()]

    def progress(steps, s_now, ub):
        if verbose and time.time() - last[0] > 5.0:
            last[0] = time.time()
            print(f"[probes] relaxing A: step {steps} unbalanced={ub:.2e} "
                  f"s=({s_now[0]:.6g}, {s_now[1]:.6g}) Pa", file=sys.stderr, flush=True)

    ok, steps, ub, _ = equilibrate(sim, s, opts.stress_tol, opts.unbalanced_tol,
                                   opts.relax_max_steps, opts.check_every, progress=progress)
    return sim.state(), ok, steps, ub


def _contacts(snap, x):
    d = {}
    for a in range(len(snap.ci)):
        d[(int(snap.ci[a]), int(snap.cj[a]))] = (snap.fx[a], snap.fy[a])
    return d


def run_probe(state: State, alpha_deg: float, sliding: bool, opts: ProbeOptions = ProbeOptions(),
              threads: int | None = 1) -> dict:
    """One stress probe from `state` (should be an equilibrium state).  See module doc."""
    if threads is not None:
        import numba
        numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    sim = Simulation(state)
    sim.cap_on = bool(sliding)
    snap0, s0, len0 = _axes(sim)
    x0 = sim.x.copy()
    walls0 = sim.walls.copy()
    vol0 = sim.volume
    from . import kernels
    fnet0 = kernels.net_forces(sim.n, sim.x, snap0.ci, snap0.cj, snap0.fx, snap0.fy,
                               snap0.wp, snap0.ww, snap0.wf)
    a = math.radians(alpha_deg)
    ds = opts.norm * np.array([math.sin(a), math.cos(a)])  # (ds1, ds2)
    target = s0 + ds
    # control is in (x, y) order
    sim.set_control(stress_path((s0[1], s0[0]), (target[1], target[0]), sim.step,
                                opts.ramp_steps))
    sim.run(opts.ramp_steps)
    ok, steps, ub, _ = equilibrate(sim, (target[1], target[0]), opts.stress_tol,
                                   opts.unbalanced_tol, opts.max_steps, opts.check_every)
    snap1, s1, len1 = _axes(sim)
    dsig = s1 - s0
    deps = (len0 - len1) / len0
    nds, nde = np.linalg.norm(dsig), np.linalg.norm(deps)
    norm = vol0 * nds * nde
    # contact sums over the union of the contact sets (missing end: f = 0)
    c0, c1 = _contacts(snap0, x0), _contacts(snap1, sim.x)
    keys = sorted(set(c0) | set(c1))
    ij = np.array(keys, dtype=np.int64).reshape(-1, 2)
    f0 = np.array([c0.get(k, (0.0, 0.0)) for k in keys]).reshape(-1, 2)
    f1 = np.array([c1.get(k, (0.0, 0.0)) for k in keys]).reshape(-1, 2)
    l0 = x0[ij[:, 1]] - x0[ij[:, 0]]
    l1 = sim.x[ij[:, 1]] - sim.x[ij[:, 0]]
    df, dl = f1 - f0, l1 - l0
    nc = l0 / np.linalg.norm(l0, axis=1)[:, None]
    tc = np.column_stack([-nc[:, 1], nc[:, 0]])
    w2n = np.sum(np.sum(df * nc, 1) * np.sum(dl * nc, 1))
    w2t = np.sum(np.sum(df * tc, 1) * np.sum(dl * tc, 1))
    w2c = np.sum(df * dl)
    # wall contacts: (particle, wall); l along the wall axis = wall position - x_p
    wc0 = {(int(p), int(w)): f for p, w, f in zip(snap0.wp, snap0.ww, snap0.wf)}
    wc1 = {(int(p), int(w)): f for p, w, f in zip(snap1.wp, snap1.ww, snap1.wf)}
    w2w = 0.0
    for (p, w) in set(wc0) | set(wc1):
        sgn = 1.0 if w % 2 == 0 else -1.0
        ax = w // 2
        dfw = sgn * (wc1.get((p, w), 0.0) - wc0.get((p, w), 0.0))
        dlw = (sim.walls[w] - sim.x[p, ax]) - (walls0[w] - x0[p, ax])
        w2w += dfw * dlw
    fnet1 = kernels.net_forces(sim.n, sim.x, snap1.ci, snap1.cj, snap1.fx, snap1.fy,
                               snap1.wp, snap1.ww, snap1.wf)
    w2u = np.sum((fnet1 - fnet0) * (sim.x - x0))
    res = dict(alpha_sigma=float(alpha_deg) % 360.0, sliding=bool(sliding),
               ds1=dsig[0], ds2=dsig[1], de1=deps[0], de2=deps[1],
               w2=float(dsig @ deps / (nds * nde)) if nds * nde > 0 else float("nan"),
               w2_micro=w2c / norm, w2n=w2n / norm, w2t=w2t / norm, w2_walls=w2w / norm,
               w2_unbalanced=w2u / norm, converged=bool(ok), steps=int(steps + opts.ramp_steps),
               unbalanced=float(ub), n_contacts_R=len(c0), n_contacts_end=len(c1),
               n_created=len(set(c1) - set(c0)), n_lost=len(set(c0) - set(c1)))
    return res


COLUMNS = ["alpha_sigma", "w2", "w2_micro", "w2n", "w2t", "w2_unbalanced", "w2_walls", "plastic",
           "ds1", "ds2", "de1", "de2", "de1_elastic", "de2_elastic", "de_plastic_ratio",
           "w2_elastic", "converged", "converged_elastic", "steps", "steps_elastic",
           "unbalanced", "n_contacts_R", "n_created", "n_lost"]


def _task(args):
    state, alpha, sliding, opts = args
    return run_probe(state, alpha, sliding, opts, threads=1)


def state_fingerprint(state: State) -> str:
    """SHA-256 (hex) of what a probe starts from: positions, velocities, spins, walls, the
    pair list with its history, the step and the parameters. Two states with the same
    fingerprint give the same probe results (the kernels are deterministic)."""
    h = hashlib.sha256()
    for a in (state.x, state.v, state.w, state.theta, state.r, state.walls, state.walls_ref,
              state.prev, state.x_ref, state.pi, state.pj, state.ft, state.ref_len):
        h.update(np.ascontiguousarray(a).tobytes())
    h.update(json.dumps([state.params.to_dict(), state.step, state.mu, state.cap_on,
                         list(state.control)], default=str).encode())
    return h.hexdigest()


def _checkpoint_header(state, opts):
    return {"fingerprint": state_fingerprint(state), "options": list(opts)}


def read_checkpoint(path, state: State, opts: ProbeOptions) -> dict:
    """Finished probe runs of a checkpoint file (JSON lines, see ``run_probes``) that belong to
    this state and these options: {(alpha_sigma, sliding): result}. A line cut short by an
    interrupted write is dropped; runs of another state or other options are refused with a
    ValueError rather than mixed in."""
    if not os.path.exists(path):
        return {}
    want = _checkpoint_header(state, opts)
    done = {}
    with open(path) as f:
        lines = f.read().split("\n")
    for k, line in enumerate(lines):
        try:
            rec = json.loads(line)
        except ValueError:
            continue  # a torn last line of an interrupted run
        if k == 0 and "fingerprint" in rec:
            if rec != want:
                raise ValueError(f"probe checkpoint {path} belongs to another state or other "
                                 "probe options; remove it or choose another output directory")
            continue
        if isinstance(rec, dict) and "alpha_sigma" in rec:
            done[(float(rec["alpha_sigma"]), bool(rec["sliding"]))] = rec
    return done


def run_probes(state: State, alphas, opts: ProbeOptions = ProbeOptions(), workers=None,
               scheduler=None, verbose=True, checkpoint=None):
    """Run every direction twice (sliding allowed / prevented); returns rows (dicts with
    COLUMNS).  Spread over local processes (ProcessPoolExecutor, `workers`) or over a
    dask.distributed cluster at address `scheduler`.  Each probe runs single-threaded and
    the kernels do not depend on the thread count, so results do not depend on placement.

    ``checkpoint``: path of a JSON-lines file; every finished run is appended to it (and
    flushed to disk) as it comes in, and runs already there for the same state and options
    are not run again, so an interrupted sweep resumes where it stopped.
    """
    opts.validate()
    tasks = [(state, a, s, opts) for a in alphas for s in (True, False)]
    t0 = time.time()
    out = []
    sink = None
    if checkpoint:
        done = read_checkpoint(checkpoint, state, opts)
        keep = [done[(float(a) % 360.0, s)] for _, a, s, _ in tasks
                if (float(a) % 360.0, s) in done]
        # rewrite the file whole (atomic), so that appends never follow a torn line
        from .io import atomic_write_bytes
        lines = [json.dumps(_checkpoint_header(state, opts))] + [json.dumps(r) for r in keep]
        atomic_write_bytes(checkpoint, ("\n".join(lines) + "\n").encode())
        out.extend(keep)
        tasks = [t for t in tasks if (float(t[1]) % 360.0, t[2]) not in done]
        if keep and verbose:
            print(f"[probes] {len(keep)} runs taken from {checkpoint}, {len(tasks)} to run",
                  file=sys.stderr, flush=True)
        sink = open(checkpoint, "a")
    total = len(out) + len(tasks)

    def collect(r):
        out.append(r)
        if sink is not None:
            sink.write(json.dumps(r) + "\n")
            sink.flush()
            os.fsync(sink.fileno())
        _report(out, total, t0, verbose)

    try:
        if not tasks:
            pass
        elif scheduler:
            try:
                from dask.distributed import Client, as_completed
            except ImportError as e:
                raise RuntimeError("--scheduler needs dask.distributed (pip install "
                                   "'granular-w2[distributed]')") from e
            with Client(scheduler) as client:
                futs = client.map(_task, tasks, pure=False)
                for fut in as_completed(futs):
                    collect(fut.result())
        elif workers == 1:
            for t in tasks:
                collect(_task(t))
        else:
            # spawn, not fork: numba's OpenMP threading layer must not be forked
            import multiprocessing
            with ProcessPoolExecutor(max_workers=workers or os.cpu_count(),
                                     mp_context=multiprocessing.get_context("spawn")) as ex:
                for r in ex.map(_task, tasks):
                    collect(r)
    finally:
        if sink is not None:
            sink.close()
    return combine(out, opts)


def _report(out, total, t0, verbose):
    if verbose:
        r = out[-1]
        print(f"[probes] {len(out)}/{total} alpha={r['alpha_sigma']:.0f} "
              f"sliding={r['sliding']} w2={r['w2']:.3f} micro={r['w2_micro']:.3f} "
              f"converged={r['converged']} steps={r['steps']} ({time.time() - t0:.0f} s)",
              file=sys.stderr, flush=True)


def combine(results, opts: ProbeOptions):
    """Pair the sliding / no-sliding runs of each direction into one row."""
    by = {}
    for r in results:
        by.setdefault(r["alpha_sigma"], {})[r["sliding"]] = r
    rows = []
    for a in sorted(by):
        t, e = by[a][True], by[a][False]
        de = np.array([t["de1"], t["de2"]])
        dee = np.array([e["de1"], e["de2"]])
        ratio = float(np.linalg.norm(de - dee) / np.linalg.norm(dee))
        row = {k: t[k] for k in ("alpha_sigma", "w2", "w2_micro", "w2n", "w2t", "w2_unbalanced",
                                 "w2_walls", "ds1", "ds2", "de1", "de2", "converged", "steps",
                                 "unbalanced", "n_contacts_R", "n_created", "n_lost")}
        row.update(plastic=int(ratio > opts.plastic_tol), de1_elastic=e["de1"],
                   de2_elastic=e["de2"], de_plastic_ratio=ratio, w2_elastic=e["w2"],
                   converged_elastic=e["converged"], steps_elastic=e["steps"])
        rows.append(row)
    return rows


def plot_probes(rows, out_dir):
    """Figs. 15 (W2 polar), 16 (macro vs micro), 17 (normal/tangential parts) as PNG.
    Polar radius 0.5 + W2 (the circle r = 0.5 is W2 = 0), angle alpha_sigma.  Probes that
    reached no equilibrium (iteration cap) have no meaningful W2 (both ends must be
    equilibrium states): they are left out of the curves and named under the figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    failed = [r["alpha_sigma"] for r in rows if not r["converged"]]
    figs = (("fig15_w2.png", [("w2", "W2 macro")], "Normalized second-order work W2"),
            ("fig16_w2_micro.png", [("w2", "W2 macro"), ("w2_micro", "sum df.dl / (V|ds||de|)")],
             "Macro vs micro second-order work"),
            ("fig17_w2_nt.png", [("w2n", "W2 normal part"), ("w2t", "W2 tangential part")],
             "Normal and tangential parts of the micro W2"))
    th = np.linspace(0, 2 * np.pi, 200)
    # closed loop over every direction; NaN where no equilibrium, so the curve breaks there
    loop = list(rows) + list(rows[:1])
    a = np.radians([r["alpha_sigma"] for r in loop])
    get = lambda k: np.array([float(r[k]) if r["converged"] else np.nan for r in loop])
    for name, series, title in figs:
        fig = plt.figure(figsize=(5.5, 5.5))
        ax = fig.add_subplot(projection="polar")
        ax.plot(th, np.full_like(th, 0.5), "--", color="gray", lw=0.8, label="W2 = 0")
        for k, lab in series:
            ax.plot(a, 0.5 + get(k), "o-", ms=3, lw=1, label=lab)
        pl = np.array([bool(r["plastic"]) and r["converged"] for r in rows], bool)
        if name == "fig15_w2.png" and pl.any():
            ax.plot(a[:-1][pl], 0.5 + get("w2")[:-1][pl], "x", color="C3", label="plastic")
        ax.set_title(f"{title}\nangle: alpha_sigma (tan = ds1/ds2), radius: 0.5 + W2 [-]",
                     fontsize=9)
        ax.legend(loc="lower left", fontsize=7, bbox_to_anchor=(-0.1, -0.15))
        if failed:
            fig.text(0.99, 0.01, f"no equilibrium (not drawn): {len(failed)} probes,\n"
                     f"alpha_sigma = {', '.join(f'{v:g}' for v in failed)} deg",
                     ha="right", va="bottom", fontsize=6, wrap=True)
        fig.tight_layout()
        tmp = os.path.join(out_dir, ".tmp-" + name)
        fig.savefig(tmp, dpi=120, format="png")
        plt.close(fig)
        os.replace(tmp, os.path.join(out_dir, name))
