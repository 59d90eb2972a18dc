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

from common.io import atomic_open
from common.threads import ThreadChooser

from .ledger import Ledger, max_eq1_bookkeeping
from .pool import NEEDS_DASK
from .settle import HISTORY_COLUMNS, SettleRule, settle, voigt_strain
from .simulation import Simulation, State
from .walls import DEAD, TIED, stress_path


RELAX_FAIL_STRAIN = 0.01   # a relaxation that moves the walls by 1 % strain has run away


class ProbeOptions(NamedTuple):
    norm: float = 2500.0            # |ds| [Pa]
    ramp_steps: int = 5000          # stress ramp length [steps]
    unbalanced_tol: float = 1e-4    # equilibrium (dem.settle): unbalanced-force ratio below this
    stress_tol: float = 25.0        # and wall stresses within this of the target [Pa]
    max_steps: int = 400_000        # cap of a probe run: undecided when reached
    relax_max_steps: int = 2_000_000  # cap of the relaxation of A into the reference R
    check_every: int = 1000         # check interval [steps]
    plastic_tol: float = 0.05       # plastic if |de_p| > plastic_tol * |de_elastic|
    strain_tol: float = 0.01        # equilibrium: strain drift over the window / |de|
    ke_tol: float = 1e-10           # equilibrium: backbone kinetic energy per disk [J]
    window: int = 20_000            # equilibrium window at 1000 disks [steps] (scaled with sqrt n)
    runaway_ratio: float = 100.0    # failure: |de|/|de_el| beyond this with the stresses lost
    fail_ratio: float = 1000.0      # failure: |de|/|de_el| beyond this

    def validate(self):
        checks = (("norm", self.norm > 0, "norm > 0 [Pa]"),
                  ("ramp_steps", self.ramp_steps >= 0, "ramp_steps >= 0"),
                  ("stress_tol", 0 < self.stress_tol < self.norm, "0 < stress_tol < norm [Pa]"),
                  ("relax_max_steps", self.relax_max_steps > 0, "relax_max_steps > 0"),
                  ("plastic_tol", self.plastic_tol > 0, "plastic_tol > 0"))
        for name, ok, rng in checks:
            val = getattr(self, name)
            if not ok or (isinstance(val, float) and not math.isfinite(val)):
                raise ValueError(f"{name}={val!r}; allowed range: {rng}")
        self.rule().validate()
        return self

    def rule(self, max_steps=None) -> SettleRule:
        """The equilibrium / failure rule of a probe run (or, with ``max_steps``, of the
        relaxation)."""
        return SettleRule(self.unbalanced_tol, self.stress_tol, self.strain_tol, self.ke_tol,
                          self.window, self.check_every, self.runaway_ratio, self.fail_ratio,
                          self.max_steps if max_steps is None else max_steps)


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


def prepare_reference(state: State, opts: ProbeOptions = ProbeOptions(), verbose=False,
                      threads=None):
    """Relax `state` under stress control at its own wall stresses, by the probes' own rule
    (``dem.settle``: the drift over the window measured against the elastic strain of a
    probe, ``voigt_strain``), capped at ``opts.relax_max_steps``.  Returns (State R,
    Settled): ``Settled.outcome`` is ``failure`` when the state cannot be held at constant
    stress (above the sample's eta_lim).  ``threads``: None = the default choice."""
    sim = Simulation(state)
    if threads is not None:
        sim.threads = ThreadChooser(sim.n, threads)
    sim.cap_on = True
    Ledger(sim)
    s = sim.wall_stress()
    sim.set_control(stress_path(s, s, sim.step, 0))
    last = [time.time()]

    def progress(steps, row):
        if verbose and time.time() - last[0] > 5.0:
            last[0] = time.time()
            print(f"[probes] relaxing the reference: step {steps} unbalanced={row[3]:.2e} "
                  f"drift ratio={row[9]:.3g} backbone KE={row[2]:.2e} J",
                  file=sys.stderr, flush=True)

    # A state taken from a strain-controlled test creeps before it settles, with slips that
    # keep the servo off target for long stretches (12,000 disks: 0.27 % of axial strain at
    # eta 0.90, kPa of stress error), so the probes' runaway rules, scaled on a probe's elastic
    # strain, do not apply.  A relaxation fails when it has moved by RELAX_FAIL_STRAIN: states
    # above the limit reach tens of percent (60-70 % after 2M steps at 1000 disks).
    rule = opts.rule(opts.relax_max_steps)._replace(fail_ratio=math.inf, runaway_ratio=math.inf,
                                                    fail_strain=RELAX_FAIL_STRAIN)
    res = settle(sim, s, rule, strain_scale=voigt_strain(sim, opts.norm), progress=progress)
    sim.ledger.detach()
    return sim.state(), res


def reference_state(state: State, out_dir, opts: ProbeOptions = ProbeOptions(), relax=True,
                    resume=False, verbose=True, threads=None):
    """The probes' reference R in ``out_dir/stateR.npz``: ``state`` relaxed by
    ``prepare_reference`` (or, ``relax=False``, as it is), kept on ``resume`` when it belongs
    to ``state`` (same fingerprint of the relaxed state's origin) and was decided, relaxed
    further when its earlier relaxation hit the cap.  Returns (State R, outcome)."""
    from . import io
    path = os.path.join(out_dir, "stateR.npz")
    origin = state_fingerprint(state)
    if not relax:
        return state, "not relaxed"
    start = state
    if resume and os.path.exists(path):
        R, meta = io.load_state(path)
        if meta.get("origin") != origin:
            raise ValueError(f"{path} was relaxed from another state; remove it or choose "
                             "another output directory")
        if meta.get("outcome") in ("equilibrium", "failure"):
            if verbose:
                print(f"[probes] reference taken from {path} ({meta.get('outcome')})",
                      file=sys.stderr, flush=True)
            return R, meta["outcome"]
        start = R           # an earlier relaxation hit its cap: go on from where it stopped
    R, res = prepare_reference(start, opts, verbose=verbose, threads=threads)
    if verbose:
        print(f"[probes] reference: {res.outcome} after {res.steps} steps (unbalanced "
              f"{res.unbalanced:.2e}, drift ratio {res.strain_ratio:.3g})", file=sys.stderr,
              flush=True)
    io.write_csv(os.path.join(out_dir, "reference_history.csv"), HISTORY_COLUMNS, res.history)
    io.save_state(path, R, meta={"origin": origin, "outcome": res.outcome, "steps": res.steps,
                                 "unbalanced": res.unbalanced, "creep_rate": res.creep_rate,
                                 "converged": res.outcome == "equilibrium"})
    return R, res.outcome


def _contacts(snap, x):
    d = {}
    for a in range(len(snap.ci)):
        d[(int(snap.ci[a]), int(snap.cj[a]))] = (snap.fx[a], snap.fy[a])
    return d


def run_probe(state: State, alpha_deg: float, sliding: bool, opts: ProbeOptions = ProbeOptions(),
              threads: int | None = 1, de_elastic: float | None = None, ledger=True) -> dict:
    """One stress probe from `state` (an equilibrium state), decided by ``dem.settle``.
    ``de_elastic``: |de| of the elastic probe of this direction (its failure rules use it;
    without it the strain ratio is taken against ``voigt_strain``).  ``ledger``: keep the
    energy ledger from the probe's start (``dem.ledger``; its columns in the history, NaN
    without it; it does not change the run's bits).  See the module doc."""
    sim = Simulation(state)
    if threads is not None:
        sim.threads = ThreadChooser(sim.n, threads)
    sim.cap_on = bool(sliding)
    if ledger:
        Ledger(sim)
    from .anatomy import contact_state
    contacts0 = contact_state(sim)      # the anatomy's t = 0 (dem.anatomy)
    snap0, s0, len0 = _axes(sim)
    x0 = sim.x.copy()
    walls0 = sim.walls.copy()
    vol0 = sim.volume
    ke0 = sim.kinetic_energy()
    from . import kernels
    fnet0 = kernels.net_forces(sim.n, sim.x, snap0.ci, snap0.cj, snap0.fx, snap0.fy,
                               snap0.wp, snap0.ww, snap0.wf)
    a = math.radians(alpha_deg)
    ds = opts.norm * np.array([math.sin(a), math.cos(a)])  # (ds1, ds2)
    target = s0 + ds
    eps0 = sim.strain()[::-1].copy()
    scale = voigt_strain(sim, opts.norm)
    # control is in (x, y) order
    sim.set_control(stress_path((s0[1], s0[0]), (target[1], target[0]), sim.step,
                                opts.ramp_steps))
    sim.run(opts.ramp_steps)
    st = settle(sim, (target[1], target[0]), opts.rule(), eps0=eps0, de_elastic=de_elastic,
                strain_scale=scale, contacts0=contacts0)
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
               w2_unbalanced=w2u / norm, outcome=st.outcome,
               converged=st.outcome == "equilibrium", steps=int(st.steps + opts.ramp_steps),
               unbalanced=float(st.unbalanced), ke_peak=st.ke_peak_backbone,
               strain_ratio=st.strain_ratio, creep_rate=st.creep_rate,
               # Eq. 1 over the probe: the external second-order work V ds.de [J] against
               # the change of kinetic energy [J] (a failure turns the first into the second)
               d2_work=float(vol0 * (dsig @ deps)), d_kinetic_energy=sim.kinetic_energy() - ke0,
               eq1_bookkeeping=max_eq1_bookkeeping(st.history, HISTORY_COLUMNS),
               n_contacts_R=len(c0), n_contacts_end=len(c1),
               n_created=len(set(c1) - set(c0)), n_lost=len(set(c0) - set(c1)),
               history=st.history.tolist())
    return res


COLUMNS = ["alpha_sigma", "outcome", "w2", "w2_micro", "w2n", "w2t", "w2_unbalanced", "w2_walls",
           "plastic", "ds1", "ds2", "de1", "de2", "de1_elastic", "de2_elastic", "de_plastic_ratio",
           "w2_elastic", "strain_ratio", "ke_peak", "creep_rate", "d2_work", "d_kinetic_energy",
           "outcome_elastic", "converged", "converged_elastic", "steps", "steps_elastic",
           "unbalanced", "n_contacts_R", "n_created", "n_lost", "eq1_bookkeeping"]
HISTORY_FILE_COLUMNS = ["alpha_sigma", "sliding"] + HISTORY_COLUMNS


def _task(args):
    state, alpha, sliding, opts, de_el = args
    return run_probe(state, alpha, sliding, opts, threads=1, de_elastic=de_el)


def state_fingerprint(state: State) -> str:
    """SHA-256 (hex) of what a probe starts from: positions, velocities, spins, walls, the
    pair list with its history, the step and the parameters. Two states with the same
    fingerprint give the same probe results (the kernels are deterministic).  Without rolling
    resistance (mu_r = 0 and no moment history: the run is then the same to the bit whatever
    ``rolling_stiffness``) the rolling fields are left out, so the fingerprint is the one of
    the code before rolling resistance existed and earlier checkpoints stay valid; so is the
    tie's ratio of a control that is not tied.  A dead load's control hashes as before its held
    force had a field of its own (state format 4: in the y axis's stress targets)."""
    rolling = bool(state.params.rolling_friction != 0 or state.mu_r != 0 or np.any(state.mr))
    h = hashlib.sha256()
    for a in (state.x, state.v, state.w, state.theta, state.r, state.walls, state.walls_ref,
              state.prev, state.x_ref, state.pi, state.pj, state.ft) + (
                  (state.mr,) if rolling else ()) + (state.ref_len,):
        h.update(np.ascontiguousarray(a).tobytes())
    from .params import hashed_dict
    params = hashed_dict(state.params)       # friction_deg, as before phi_g: resumes stay valid
    if not rolling:
        params = {k: v for k, v in params.items()
                  if k not in ("rolling_friction", "rolling_stiffness")}
    # the tie's ratio only under the tied controls, the wall mass and the held force only under
    # the dead load (a control of the other modes hashes as before the fields existed)
    c = state.control
    if DEAD in c.mode:
        control = list(c._replace(s_from=(c.s_from[0], c.g_held), s_to=(c.s_to[0], c.g_held)))[:9]
    else:
        control = list(c)[:8] if TIED in c.mode else list(c)[:7]
    h.update(json.dumps([params, state.step, state.mu] + ([state.mu_r] if rolling else [])
                        + [state.cap_on, control], default=str).encode())
    return h.hexdigest()


def _checkpoint_header(state, opts):
    return {"fingerprint": state_fingerprint(state), "options": list(opts)}


def read_checkpoint(path, state: State, opts: ProbeOptions) -> dict:
    """Finished probe runs of a checkpoint file (JSON lines, see ``run_probes``) that belong to
    this state and these options: {(alpha_sigma, sliding): result}. A line cut short by an
    interrupted write is dropped; runs of another state or other options are refused with a
    ValueError rather than mixed in.  Only the cap may differ: a run is deterministic and the
    cap only truncates it, so a run decided (equilibrium or failure) within the new cap is kept
    and one left undecided at a smaller cap runs again."""
    if not os.path.exists(path):
        return {}
    want = _checkpoint_header(state, opts)
    i_cap = ProbeOptions._fields.index("max_steps")
    strip = lambda h: {**h, "options": [v for k, v in enumerate(h["options"]) if k != i_cap]}
    done = {}
    old_cap = opts.max_steps
    with open(path) as f:
        lines = f.read().split("\n")
    for k, line in enumerate(lines):
        try:
            rec = json.loads(line)
        except ValueError:
            continue  # a torn last line of an interrupted run
        if k == 0 and "fingerprint" in rec:
            if strip(rec) != strip(want):
                raise ValueError(f"probe checkpoint {path} belongs to another state or other "
                                 "probe options; remove it or choose another output directory")
            old_cap = rec["options"][i_cap]
            continue
        if isinstance(rec, dict) and "alpha_sigma" in rec:
            decided = rec["outcome"] != "undecided"
            if (decided and rec["steps"] <= opts.ramp_steps + opts.max_steps) or (
                    not decided and old_cap == opts.max_steps):
                done[(float(rec["alpha_sigma"]), bool(rec["sliding"]))] = rec
    return done


def run_probes(state: State, alphas, opts: ProbeOptions = ProbeOptions(), workers=None,
               scheduler=None, verbose=True, checkpoint=None):
    """Run every direction twice, sliding prevented first (its strain is the elastic scale
    of the sliding run's failure rules, ``dem.settle``), then sliding allowed; returns rows
    (dicts with COLUMNS, and the check histories under ``history`` / ``history_elastic``).
    Spread over local processes (ProcessPoolExecutor, `workers`) or over a dask.distributed
    cluster at address `scheduler`.  Each probe runs single-threaded and the kernels do not
    depend on the thread count, so results do not depend on placement.

    ``checkpoint``: path of a JSON-lines file; every finished run is appended to it (and
    flushed to disk) as it comes in, and runs already there for the same state and options
    are not run again, so an interrupted sweep resumes where it stopped.
    """
    return run_probe_sets([(state, alphas, checkpoint)], opts, workers, scheduler, verbose)[0]


def run_probe_sets(sets, opts: ProbeOptions = ProbeOptions(), workers=None, scheduler=None,
                   verbose=True):
    """``run_probes`` of several states as one pool of independent runs: ``sets`` is a list of
    (state, alphas, checkpoint or None); returns one list of rows per set. The runs are
    ``probe_sets_runs``'s, on ``workers`` local processes or the dask cluster at ``scheduler``
    (``dem.pool``; on one worker in this process)."""
    from .pool import run_jobs
    return run_jobs([("probes", lambda tasks: probe_sets_runs(sets, opts, verbose, tasks))],
                    workers, scheduler)["probes"]


def _probe_task(state, alpha, sliding, opts, de_el, threads=None):
    """One probe run, a task of ``dem.pool``: on one thread whatever the pool offers (a probe
    is short; many run side by side)."""
    return _task((state, alpha, sliding, opts, de_el))


def probe_sets_runs(sets, opts: ProbeOptions, verbose, tasks):
    """``run_probe_sets``'s runs as a generator of ``dem.pool`` (``tasks.start`` a run,
    ``yield WAIT`` for them): every elastic run (sliding prevented), then every sliding run
    with its elastic strain. Every finished run is appended to its set's checkpoint as it comes
    in; the rows do not depend on the order the runs finish in. Returns one list of rows per
    set."""
    from .pool import WAIT
    opts.validate()
    key = lambda a, s: (float(a) % 360.0, bool(s))
    t0 = time.time()
    outs, sinks, alist = [], [], []
    total = 0
    for state, alphas, checkpoint in sets:
        alphas = [float(a) for a in alphas]
        alist.append(alphas)
        total += 2 * len(alphas)
        out = {}
        if checkpoint:
            done = read_checkpoint(checkpoint, state, opts)
            keep = {key(a, s): done[key(a, s)] for a in alphas for s in (False, True)
                    if key(a, s) in done}
            # rewrite the file whole (atomic), so that appends never follow a torn line
            from common.io import atomic_write_bytes
            lines = [json.dumps(_checkpoint_header(state, opts))] + [json.dumps(r) for r in keep.values()]
            atomic_write_bytes(checkpoint, ("\n".join(lines) + "\n").encode())
            out.update(keep)
            if keep and verbose:
                print(f"[probes] {len(keep)} runs taken from {checkpoint}, "
                      f"{2 * len(alphas) - len(keep)} to run", file=sys.stderr, flush=True)
        outs.append(out)
        sinks.append(open(checkpoint, "a") if checkpoint else None)
    count = [sum(len(o) for o in outs)]

    def collect(k):
        def done(r):
            outs[k][key(r["alpha_sigma"], r["sliding"])] = r
            if sinks[k] is not None:
                sinks[k].write(json.dumps(r) + "\n")
                sinks[k].flush()
                os.fsync(sinks[k].fileno())
            count[0] += 1
            _report(r, count[0], total, t0, verbose)
        return done

    try:
        # phase 1: elastic runs; phase 2: sliding runs with their elastic strain
        for k, (st, _, _) in enumerate(sets):
            for a in alist[k]:
                if key(a, False) not in outs[k]:
                    tasks.start(_probe_task, (st, a, False, opts, None), {}, collect(k))
        yield WAIT
        for k, (st, _, _) in enumerate(sets):
            for a in alist[k]:
                if key(a, True) not in outs[k]:
                    de_el = float(np.hypot(outs[k][key(a, False)]["de1"],
                                           outs[k][key(a, False)]["de2"]))
                    tasks.start(_probe_task, (st, a, True, opts, de_el), {}, collect(k))
        yield WAIT
    finally:
        for f in sinks:
            if f is not None:
                f.close()
    return [combine(list(o.values()), opts) for o in outs]


def check_scheduler(address: str, timeout: float = 5.0) -> None:
    """Refuse, before any computation, a ``--scheduler`` address that is malformed, needs a
    missing dask.distributed, or where nothing listens (a TCP connection within ``timeout``
    seconds): ValueError with one line naming the option. (A dask Client that fails to connect
    also prints a traceback from its finalizer, hence the plain socket.)"""
    import socket
    try:
        from distributed.comm.addressing import parse_address, parse_host_port
    except ImportError as e:
        raise ValueError(NEEDS_DASK) from e
    try:
        scheme, loc = parse_address(address)
        if scheme != "tcp":
            return          # inproc://, ucx://...: nothing to check with a socket
        host, port = parse_host_port(loc)
    except (ValueError, TypeError) as e:
        raise ValueError(f"--scheduler {address!r}: not an address (allowed: "
                         f"tcp://HOST:PORT or HOST:PORT): {e}") from e
    try:
        socket.create_connection((host, int(port)), timeout=timeout).close()
    except OSError as e:
        raise ValueError(f"--scheduler {address!r}: nothing answers there within {timeout:g} s "
                         f"({e.strerror or type(e).__name__})") from e


def _map(tasks, collect, workers, scheduler, fn=None):
    """Run ``fn`` (default ``_task``) over the (tag, args) ``tasks`` locally or on dask;
    ``collect(tag, result)`` each result as it comes."""
    fn = fn or _task
    if not tasks:
        return
    tags = [t for t, _ in tasks]
    args = [a for _, a in tasks]
    if scheduler:
        try:
            from dask.distributed import Client, as_completed
        except ImportError as e:
            raise RuntimeError(NEEDS_DASK) from e
        with Client(scheduler) as client:
            futs = client.map(fn, args, pure=False)
            where = {f.key: tag for f, tag in zip(futs, tags)}
            for fut in as_completed(futs):
                collect(where[fut.key], fut.result())
    elif workers == 1 or len(tasks) == 1:
        for tag, a in tasks:
            collect(tag, fn(a))
    else:
        # spawn, not fork: numba's OpenMP threading layer must not be forked
        import multiprocessing
        ex = ProcessPoolExecutor(max_workers=min(workers or os.cpu_count(), len(tasks)),
                                 mp_context=multiprocessing.get_context("spawn"))
        try:
            for tag, r in zip(tags, ex.map(fn, args)):
                collect(tag, r)
        except BaseException:
            # Ctrl-C / SIGTERM (or a failed run): stop the workers now rather than wait for
            # their runs to end (the executor's exit would); what finished is already collected
            for proc in list((getattr(ex, "_processes", None) or {}).values()):
                proc.terminate()
            ex.shutdown(wait=False, cancel_futures=True)
            raise
        ex.shutdown()


def _report(r, k, total, t0, verbose):
    if verbose:
        print(f"[probes] {k}/{total} alpha={r['alpha_sigma']:.0f} "
              f"sliding={r['sliding']} {r['outcome']} w2={r['w2']:.3f} micro={r['w2_micro']:.3f} "
              f"|de|/|de_el|={r['strain_ratio']:.3g} steps={r['steps']} ({time.time() - t0:.0f} s)",
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
        row = {k: t[k] for k in ("alpha_sigma", "outcome", "w2", "w2_micro", "w2n", "w2t",
                                 "w2_unbalanced", "w2_walls", "ds1", "ds2", "de1", "de2",
                                 "strain_ratio", "ke_peak", "creep_rate", "d2_work",
                                 "d_kinetic_energy", "converged", "steps", "unbalanced",
                                 "n_contacts_R", "n_created", "n_lost", "history")}
        # the largest Eq. 1 residual of the direction's two runs (NaN for runs of a checkpoint
        # written before the ledger)
        got = [v for v in (t.get("eq1_bookkeeping"), e.get("eq1_bookkeeping"))
               if v is not None and not math.isnan(v)]
        row["eq1_bookkeeping"] = max(got) if got else math.nan
        row.update(plastic=int(ratio > opts.plastic_tol), de1_elastic=e["de1"],
                   de2_elastic=e["de2"], de_plastic_ratio=ratio, w2_elastic=e["w2"],
                   outcome_elastic=e["outcome"], converged_elastic=e["converged"],
                   steps_elastic=e["steps"], history_elastic=e["history"])
        rows.append(row)
    return rows


def csv_rows(rows):
    """``rows`` as lists in COLUMNS order (booleans as 0/1) for ``io.write_csv``."""
    return [[int(r[c]) if isinstance(r[c], bool) else r[c] for c in COLUMNS] for r in rows]


def history_rows(rows):
    """Every check of every run, for ``probe_histories.csv`` (HISTORY_FILE_COLUMNS)."""
    out = []
    width = len(HISTORY_COLUMNS)
    for r in rows:
        for sliding, key in ((1, "history"), (0, "history_elastic")):
            # a run of a checkpoint from before the ledger has only the rule's columns
            out += [[r["alpha_sigma"], sliding] + list(h) + [math.nan] * (width - len(h))
                    for h in r[key]]
    return out


def write_probe_files(rows, out_dir, note=""):
    """probes.csv, probe_histories.csv, Figs. 15-17 of ``rows`` and fig_ledger.png
    (``plot_probe_ledger``) in ``out_dir``."""
    from . import io
    io.write_csv(os.path.join(out_dir, "probes.csv"), COLUMNS, csv_rows(rows))
    io.write_csv(os.path.join(out_dir, "probe_histories.csv"), HISTORY_FILE_COLUMNS,
                 history_rows(rows))
    plot_probes(rows, out_dir, note)
    plot_probe_ledger(rows, os.path.join(out_dir, "fig_ledger.png"), note)


def plot_probe_ledger(rows, path, note=""):
    """Eq. 1's terms against time (``dem.ledger.plot_ledger``) of two probes: the settled one
    of the smallest W2 (the nearest to the boundary) and the failure of the largest backbone
    kinetic energy; one panel when only one kind is there, none without a ledger. The title
    quotes the settled probe's W2 as normalized (W2 / (|d sigma| |d eps|), Eq. 15, [-]): the
    axis below it is in J; ``note`` goes on a second line."""
    from .ledger import plot_ledger
    k = HISTORY_COLUMNS.index("eq1_bookkeeping")
    led = [r for r in rows if r["history"] and len(r["history"][0]) > k
           and not math.isnan(r["history"][-1][k])]
    eq = [r for r in led if r["outcome"] == "equilibrium"]
    fail = [r for r in led if r["outcome"] == "failure"]
    panels = []
    if eq:
        r = min(eq, key=lambda r: r["w2"])
        panels.append((f"settled probe {r['alpha_sigma']:g} deg, normalized W2 = {r['w2']:.3f} "
                       "[-]", r["history"], HISTORY_COLUMNS))
    if fail:
        r = max(fail, key=lambda r: r["ke_peak"])
        panels.append((f"failed probe {r['alpha_sigma']:g} deg (runaway)", r["history"],
                       HISTORY_COLUMNS))
    if panels:
        plot_ledger(path, [(t + ("\n" + note if note else ""), h, c) for t, h, c in panels])


RMAX = 2.0   # polar radius of the outer ring: 0.5 + W2 is drawn in [0, RMAX]


def polar_radius(w2):
    """Radius 0.5 + W2 of the polar diagrams, clipped to [0, RMAX] (so matplotlib never moves
    the origin); returns (radius, clipped mask).  Clipped points get their own marker."""
    r = 0.5 + np.asarray(w2, float)
    clipped = np.isfinite(r) & ((r < 0) | (r > RMAX))
    return np.clip(r, 0.0, RMAX), clipped


def plot_probes(rows, out_dir, note=""):
    """Figs. 15 (W2 polar), 16 (macro vs micro), 17 (normal/tangential parts) as PNG.
    Polar radius 0.5 + W2 (the dashed circle is W2 = 0), angle alpha_sigma, clipped to
    [0, RMAX] with clipped points marked.  Only equilibrium probes have a W2 (Eq. 15 needs
    equilibrium at both ends) and are joined by the curves; failures (the sample ran away:
    W2 <= 0 in the limit, Eq. 1) are red triangles on the W2 = 0 circle; undecided probes are
    grey dots at their last W2.  Fig. 15 shades the cone (the probed directions that failed or
    settled with W2 <= 0) with its angles, marks the plastic zone at the rim and, where the cone
    is narrow, adds W2 against alpha_sigma around it (``hmodel.plots``).  ``note``: sample,
    pressure and rate for the title."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from common.plots import cone_zoom, mark_cone, mark_plastic, needs_zoom, polar_axes
    from point.probes import arcs
    figs = (("fig15_w2.png", [("w2", r"$W_2$ macro")], r"Normalized second-order work $W_2$"),
            ("fig16_w2_micro.png", [("w2", r"$W_2$ macro"),
                                    ("w2_micro", r"micro $\sum d\mathbf{f}\cdot d\mathbf{l}\,/\,(V|d\sigma||d\varepsilon|)$")],
             "Macro vs micro second-order work"),
            ("fig17_w2_nt.png", [("w2n", r"$W_2^n$ (normal)"), ("w2t", r"$W_2^t$ (tangential)")],
             "Normal and tangential parts of the micro $W_2$"))
    outc = np.array([r["outcome"] for r in rows])
    alpha = np.array([float(r["alpha_sigma"]) for r in rows])
    a_all = np.radians(alpha)
    eq = outc == "equilibrium"
    fail = outc == "failure"
    w2_eq = np.array([float(r["w2"]) if e else np.nan for r, e in zip(rows, eq)])
    # the cone: the probed directions that ran away or settled with W2 <= 0; the plastic zone
    cone = arcs(alpha, fail | (eq & (np.nan_to_num(w2_eq, nan=1.0) <= 0)))
    plastic = arcs(alpha, np.array([bool(r["plastic"]) for r in rows], bool) & eq)
    # closed loop over every direction; NaN where no equilibrium, so the curve breaks there
    loop = np.append(np.arange(len(rows)), 0) if rows else np.array([], int)
    for name, series, title in figs:
        zoom = name == "fig15_w2.png" and needs_zoom(cone)
        fig = plt.figure(figsize=(12, 6.4) if zoom else (6, 6.4))
        ax = fig.add_subplot(1, 2 if zoom else 1, 1, projection="polar")
        polar_axes(ax, RMAX)
        if name == "fig15_w2.png":
            mark_plastic(ax, plastic, RMAX)
            mark_cone(ax, cone, RMAX, label=r"failure or $W_2 \leq 0$")
        for j, (k, lab) in enumerate(series):
            w = np.array([float(r[k]) for r in rows])
            rad, clip = polar_radius(np.where(eq, w, np.nan))
            ax.plot(a_all[loop], rad[loop], "o-", ms=3, lw=1, color=f"C{j}", label=lab)
            if clip.any():
                ax.plot(a_all[clip], rad[clip], "D", mfc="none", color=f"C{j}", ms=6,
                        label=f"clipped to [{-0.5:g}, {RMAX - 0.5:g}]" if j == 0 else None)
            und = outc == "undecided"
            if und.any():
                ax.plot(a_all[und], polar_radius(w[und])[0], "o", color="0.6", ms=4,
                        label="undecided (at the cap)" if j == 0 else None)
        if fail.any():
            ax.plot(a_all[fail], np.full(fail.sum(), 0.5), "^", color="C3", ms=7,
                    label=r"failure (runaway: $W_2 \leq 0$)")
        fig.suptitle(f"{title}{' - ' + note if note else ''}", fontsize=10)
        ax.set_title(r"angle: $\alpha_\sigma$ ($\tan\alpha_\sigma = d\sigma_1/d\sigma_2$), "
                     r"radius: $0.5 + W_2$", fontsize=8, pad=24)
        if zoom:
            cone_zoom(fig.add_subplot(1, 2, 2),
                      [(r"$W_2$ macro (equilibrium)", alpha, w2_eq, "o-"),
                       (r"failure (no $W_2$: drawn at 0)", alpha[fail], np.zeros(fail.sum()), "C3^")],
                      cone, plastic, pad_deg=20.0, label=r"failure or $W_2 \leq 0$")
        fig.legend(*ax.get_legend_handles_labels(), loc="lower center", ncol=3, fontsize=7,
                   frameon=False)
        fig.tight_layout(rect=(0, 0.1, 1, 0.97))
        with atomic_open(os.path.join(out_dir, name), "wb") as f:
            fig.savefig(f, dpi=120, format="png")
        plt.close(fig)
