"""The paper's drained biaxial test (section 4, Figs. 13-14) and its figures.

Axis 1 = axial = y, axis 2 = lateral = x.  Compression positive; p = (s1+s2)/2, q = s1-s2,
eta = q/p, eps_v = eps1 + eps2 (engineering strains from the wall positions).
"""
from __future__ import annotations

import json
import math
import os
import shutil
import sys
import time
from typing import NamedTuple

import numpy as np

from common.io import atomic_write_bytes

from . import io
from .params import DemParams, record_params
from .regime import check_regime
from .sample import compact
from .ledger import Ledger
from .simulation import Simulation
from .walls import biaxial

# a record, then the energy ledger of the test since its start (dem.ledger; first order: the
# test's second-order terms are not the experiment's)
LEDGER_COLUMNS = ["ke", "w_ext", "w_int", "w_damp", "e_elastic", "d_slip", "d_roll",
                  "balance_residual", "split_residual"]
COLUMNS = ["step", "time", "eps1", "eps2", "eps_v", "s1", "s2", "p", "q", "eta",
           "s1_lw", "s2_lw", "unbalanced", "porosity", "coordination"] + LEDGER_COLUMNS


class BiaxialResult(NamedTuple):
    rows: list
    state_a_path: str | None
    eta_a_reached: bool
    compaction: dict
    wall_time: float
    stopped: object = None      # what ``stop`` returned where it stopped the run, else None


def record(sim: Simulation):
    """One row of the biaxial CSV (see COLUMNS)."""
    snap = sim.snapshot()
    s2, s1 = sim.wall_stress(snap)
    e2, e1 = sim.strain()
    lw = sim.love_weber(snap)
    p = 0.5 * (s1 + s2)
    q = s1 - s2
    coord = 2.0 * len(snap.ci) / sim.n
    led = sim.ledger.read() if sim.ledger is not None else None
    return [sim.step, sim.time, e1, e2, e1 + e2, s1, s2, p, q, q / p if p > 0 else 0.0,
            lw[1, 1], lw[0, 0], sim.unbalanced(snap), sim.porosity(), coord] + [
                getattr(led, c) if led else math.nan for c in LEDGER_COLUMNS]


def _progress(msg):
    print(msg, file=sys.stderr, flush=True)


SAVE_FRACTIONS = (0.80, 0.85, 0.90, 0.93, 0.95, 0.97)   # of the peak eta: states along the path
FALLBACK_FRACTION = 0.97   # A when eta never reaches eta_a: first state at 0.97 of the peak eta


def run_biaxial(params: DemParams, out_dir, rate=0.01, confining=200e3, eta_a=1.029,
                eps_max=0.10, post_peak_strain=0.02, record_strain=1e-4,
                compaction_friction_deg=0.0, checkpoint_every=50, resume=False,
                verbose=True, figures=True, vtk=True, save_fractions=SAVE_FRACTIONS,
                save_etas=(), params_note=None, allow_soft=False, stop=None) -> BiaxialResult:
    """Compact, then run the drained biaxial test past the peak.

    Writes out_dir/params.json first (``params``: ``--params out_dir/params.json`` repeats the
    run; ``params_note`` says where they came from, also in summary.json), out_dir/biaxial.csv,
    out_dir/stateA.npz (first eta >= eta_a; if never reached,
    the first state with eta >= 0.97 max(eta), flagged in out_dir/summary.json), figures fig13_q.png and
    fig14_epsv.png, VTK snapshots at A, out_dir/checkpoint.npz (+ rows) every
    `checkpoint_every` records so that `resume=True` continues an interrupted run.
    rate: axial strain rate [1/s]; confining: lateral stress [Pa]; record_strain: axial
    strain between CSV rows; the test stops at eps_max or post_peak_strain after the peak.

    States along the path (for ``dem domain``): out_dir/states/state_fF.FFF.npz, the first
    recorded state whose eta reaches F times the peak eta, for F in ``save_fractions``, and
    state_etaE.EEEE.npz, the first with eta >= E, for E in ``save_etas`` (absolute), listed in
    out_dir/states/states.csv.  While the test runs, every recorded state that raises the
    largest eta so far above ``min(save_fractions) - 0.02`` of it is written to
    out_dir/candidates/ (and is part of the checkpoint), so a resumed run picks the same
    states as an uninterrupted one; the folder is removed at the end.

    A set outside the granular regime at ``confining`` (``dem.regime.check_regime``) is refused
    before anything is written, unless ``allow_soft``; summary.json records the regime
    (``regime``). A run that reaches an unsound state (``dem.regime.UnsoundState``) stops there.

    ``stop``: None, or a function of the rows so far (lists in COLUMNS' order, the first the
    start of the test), called after each new one, that returns a true value to stop the test
    there (the calibration's in-run stop): the run then writes
    biaxial.csv and its checkpoint at that row and returns with ``stopped`` that value (no
    path states, summary or figures); ``resume=True`` without ``stop`` continues it to the
    rows, bit for bit, of a run never stopped.
    """
    for name, val, ok, rng in (("rate", rate, rate > 0, "rate > 0 [1/s]"),
                               ("confining", confining, confining > 0, "confining > 0 [Pa]"),
                               ("eta_a", eta_a, eta_a > 0, "eta_a > 0"),
                               ("eps_max", eps_max, 0 < eps_max < 0.5, "0 < eps_max < 0.5"),
                               ("record_strain", record_strain, 0 < record_strain < eps_max,
                                "0 < record_strain < eps_max"),
                               ("save_fractions", save_fractions,
                                all(0 < f <= 1 for f in save_fractions), "0 < fraction <= 1"),
                               ("save_etas", save_etas, all(e > 0 for e in save_etas),
                                "eta > 0")):
        if not ok:
            raise ValueError(f"{name}={val!r}; allowed range: {rng}")
    regime = check_regime(params, confining, allow_soft)
    t_start = time.time()
    os.makedirs(out_dir, exist_ok=True)
    record_params(out_dir, params, params_note or "dem.experiment.run_biaxial")
    ck_path = os.path.join(out_dir, "checkpoint.npz")
    a_path = os.path.join(out_dir, "stateA.npz")
    rows = []
    info = {}
    if resume and os.path.exists(ck_path):
        st, info = io.load_state(ck_path)
        sim = Simulation(st)
        rows = info.pop("rows")
        if "arrays" in info:
            Ledger.from_arrays(sim, info.pop("arrays"))
        elif verbose:       # a checkpoint of a version before the ledger: its columns stay NaN
            _progress(f"[biaxial] {ck_path} has no energy ledger (an older version's): the "
                      "ledger's columns of biaxial.csv stay empty (NaN)")
        if verbose:
            _progress(f"[biaxial] resumed from {ck_path} at step {sim.step}, {len(rows)} rows")
    else:
        t0 = time.time()
        sim, rep = compact(params, stress=confining, friction_deg=compaction_friction_deg,
                           verbose=verbose, allow_soft=allow_soft)
        info["compaction"] = {"porosity": float(rep.porosity), "stress": list(rep.stress),
                              "unbalanced": float(rep.unbalanced), "steps": int(rep.steps),
                              "converged": bool(rep.converged), "wall_time": time.time() - t0}
        io.save_state(os.path.join(out_dir, "compacted.npz"), sim.state(),
                      meta={"compaction": info["compaction"]})
        sim.ref_len = sim.size.copy()
        sim.set_control(biaxial(confining, rate, sim.ref_len))
        Ledger(sim)     # from the start of the drained test (the compaction grows the radii)
        info.update(eta_a_reached=False, q_max=-1e300, eps_peak=0.0, eta_max=-1e300)
        rows.append(record(sim))
    rec_steps = max(1, int(round(record_strain / (rate * sim.dt))))
    cdir = os.path.join(out_dir, "candidates")
    keep_from = min(tuple(save_fractions) + (FALLBACK_FRACTION,)) - 0.02
    cands = info.setdefault("candidates", [])     # [row dict, file name] of the kept states
    last_print = 0.0
    t_loop = time.time()
    step_loop = sim.step
    while True:
        sim.run(rec_steps)
        row = record(sim)
        rows.append(row)
        e1, q, eta = row[2], row[8], row[9]
        if q > info["q_max"]:
            info["q_max"], info["eps_peak"] = q, e1
        if not info["eta_a_reached"]:
            if eta >= eta_a:
                info["eta_a_reached"] = True
                info["A"] = dict(zip(COLUMNS, row))
                io.save_state(a_path, sim.state(), meta={"A": info["A"], "eta_a": eta_a})
                if vtk:
                    io.write_particles_vtk(os.path.join(out_dir, "particlesA.vtu"), sim)
                    io.write_contacts_vtk(os.path.join(out_dir, "contactsA.vtu"), sim)
                if verbose:
                    _progress(f"[biaxial] point A: eta={eta:.4f} eps1={e1:.5f} -> {a_path}")
        if eta > info["eta_max"]:
            # a new largest eta: the first state at this eta on the way up
            name = f"step_{sim.step:010d}.npz"
            io.save_state(os.path.join(cdir, name), sim.state(), meta={"row": dict(zip(COLUMNS, row))})
            cands.append([dict(zip(COLUMNS, row)), name])
        info["eta_max"] = max(info["eta_max"], eta)
        # states far below the largest eta so far can no longer be chosen
        for c in [c for c in cands if c[0]["eta"] < keep_from * info["eta_max"]
                  and not any(c[0]["eta"] >= e for e in save_etas)]:
            cands.remove(c)
            if os.path.exists(os.path.join(cdir, c[1])):
                os.unlink(os.path.join(cdir, c[1]))
        done = e1 >= eps_max or (e1 >= info["eps_peak"] + post_peak_strain and
                                 q < 0.98 * info["q_max"])
        now = time.time()
        if verbose and (now - last_print > 2.0 or done):
            last_print = now
            sps = (sim.step - step_loop) * sim.n / max(now - t_loop, 1e-9)
            _progress(f"[biaxial] step {sim.step} eps1={e1:.5f} q={q/1e3:.2f} kPa eta={eta:.4f} "
                      f"eps_v={row[4]:.5f} unbalanced={row[12]:.1e} ({sps:.2e} particle-steps/s)")
        stopped = None if (done or stop is None) else stop(rows)
        if stopped or (checkpoint_every and len(rows) % checkpoint_every == 0 and not done):
            # the wall time so far goes with the checkpoint, so a resumed run reports the total
            io.save_state(ck_path, sim.state(), meta=dict(
                info, rows=rows,
                wall_time_before=info.get("wall_time_before", 0.0) + time.time() - t_start),
                arrays=sim.ledger.to_arrays())
            io.write_csv(os.path.join(out_dir, "biaxial.csv"), COLUMNS, rows)
        if stopped:
            wall = time.time() - t_start + info.get("wall_time_before", 0.0)
            return BiaxialResult(rows, None, info["eta_a_reached"], info.get("compaction", {}),
                                 wall, stopped)
        if done:
            break
    first = lambda ok: min((c for c in cands if ok(c[0]["eta"])), key=lambda c: c[0]["step"],
                           default=None)
    info["states"] = _save_path_states(out_dir, cdir, cands, first, info["eta_max"],
                                       save_fractions, save_etas)
    if not info["eta_a_reached"]:
        # "just before the peak": the first state with eta >= 0.97 eta_max
        c = first(lambda e: e >= FALLBACK_FRACTION * info["eta_max"])
        if c is not None:
            st, _ = io.load_state(os.path.join(cdir, c[1]))
            io.save_state(a_path, st, meta={"A": c[0], "eta_a": eta_a, "eta_a_reached": False})
            info["A"] = c[0]
            if vtk:
                sa = Simulation(st)
                io.write_particles_vtk(os.path.join(out_dir, "particlesA.vtu"), sa)
                io.write_contacts_vtk(os.path.join(out_dir, "contactsA.vtu"), sa)
        if verbose:
            a_txt = (f"eta = {info['A']['eta']:.4f} at eps1 = {info['A']['eps1']:.5f}"
                     if info.get("A") else "none")
            _progress(f"[biaxial] WARNING: eta never reached {eta_a:g} (max "
                      f"{info['eta_max']:.4f}); stateA.npz holds the first state with eta >= "
                      f"{FALLBACK_FRACTION:g} max eta: {a_txt}")
    io.write_csv(os.path.join(out_dir, "biaxial.csv"), COLUMNS, rows)
    wall = time.time() - t_start + info.get("wall_time_before", 0.0)
    summary = {k: v for k, v in info.items() if k not in ("rows", "candidates")}
    summary.update(n=sim.n, rate=rate, confining=confining, eta_a=eta_a, dt=sim.dt,
                   wall_time=wall, params=params.to_dict(), parameters=params_note,
                   regime=regime)
    atomic_write_bytes(os.path.join(out_dir, "summary.json"),
                          json.dumps(summary, indent=1, default=float).encode())
    if figures:
        plot_biaxial(rows, info.get("A"), out_dir, n=sim.n, sigma2=confining, rate=rate)
    if os.path.exists(ck_path):
        os.unlink(ck_path)
    if os.path.isdir(cdir):
        shutil.rmtree(cdir)
    return BiaxialResult(rows, a_path if os.path.exists(a_path) else None,
                         info["eta_a_reached"], info.get("compaction", {}), wall)


STATE_COLUMNS = ["file", "target", "fraction_of_peak", "eta", "eps1", "p", "q", "step"]


def _save_path_states(out_dir, cdir, cands, first, eta_max, fractions, etas):
    """Copy the chosen candidates to out_dir/states/ and list them in states.csv."""
    sdir = os.path.join(out_dir, "states")
    listed = []
    for kind, vals in (("f", fractions), ("eta", etas)):
        for v in vals:
            goal = v * eta_max if kind == "f" else v
            c = first(lambda e: e >= goal)
            if c is None:
                continue
            name = f"state_{kind}{v:.3f}.npz" if kind == "f" else f"state_eta{v:.4f}.npz"
            st, _ = io.load_state(os.path.join(cdir, c[1]))
            row = c[0]
            io.save_state(os.path.join(sdir, name), st, meta={
                "row": row, "target": f"{v:g} of the peak eta" if kind == "f" else f"eta {v:g}",
                "fraction_of_peak": row["eta"] / eta_max, "eta_peak": eta_max})
            listed.append([name, f"{kind}={v:g}", row["eta"] / eta_max, row["eta"], row["eps1"],
                           row["p"], row["q"], row["step"]])
    if listed:
        io.write_csv(os.path.join(sdir, "states.csv"), STATE_COLUMNS, listed)
    return [dict(zip(STATE_COLUMNS, r)) for r in listed]


def plot_biaxial(rows, a_row, out_dir, n=None, sigma2=None, rate=None):
    """Figs. 13 (q vs eps1) and 14 (eps_v vs eps1) as PNG, point A marked and labelled off the
    curve (``common.plots.label_point``); the title names the sample (``n`` disks), the
    confining stress ``sigma2`` [Pa] and the axial strain rate ``rate`` [1/s] when given."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from common.io import save_figure
    from common.plots import label_point
    arr = np.array([[r[2], r[4], r[8]] for r in rows])
    run = ", ".join(x for x in (f"{n} disks" if n else "",
                                f"$\\sigma_2$ = {sigma2 / 1e3:g} kPa" if sigma2 else "",
                                f"rate {rate:g} /s" if rate else "") if x)
    for name, col, ylabel, scale, what in (
            ("fig13_q.png", 2, "q = s1 - s2 [kPa]", 1e-3, "deviatoric stress"),
            ("fig14_epsv.png", 1, "eps_v = eps1 + eps2 [%]", 100, "volumetric strain")):
        fig, ax = plt.subplots(figsize=(5, 4))
        ax.plot(arr[:, 0] * 100, arr[:, col] * scale, "-k", lw=1)
        ax.set_xlabel("axial strain eps1 [%]")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
        title = f"DEM drained biaxial test: {what}" + (f"\n{run}" if run else "")
        if col == 1:
            title += "\ncompression positive (eps_v < 0: dilation)"
        ax.set_title(title, fontsize=8)
        fig.tight_layout()
        if a_row is not None:
            yv = a_row["q"] if col == 2 else a_row["eps_v"]
            ax.plot([a_row["eps1"] * 100], [yv * scale], "o", color="C3")
            label_point(ax, a_row["eps1"] * 100, yv * scale, "A", color="C3")
        save_figure(fig, os.path.join(out_dir, name), dpi=120)


def redraw_figures(out_dir, summary="summary.json"):
    """Figs. 13 and 14 of a finished ``dem biaxial`` folder drawn again from its biaxial.csv and
    ``summary`` (point A, n, sigma2, rate), without a run: ``python -c "from dem.experiment
    import redraw_figures; redraw_figures('DIR')"``."""
    from . import io
    header, recs = io.read_csv(os.path.join(out_dir, "biaxial.csv"))
    rows = [[r[c] for c in header] for r in recs]
    with open(os.path.join(out_dir, summary)) as f:
        s = json.load(f)
    plot_biaxial(rows, s.get("A"), out_dir, n=s.get("n"), sigma2=s.get("confining"),
                 rate=s.get("rate"))
