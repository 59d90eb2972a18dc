"""The burst's files (``dem.burst``): the rows of burst.csv (``burst_row``), and burst.csv,
history.csv, paths.csv, rest.csv, stairs.csv, probes.csv, summary.json and the figures
(``write_burst_files``); the columns of those that are not a run's own records."""
from __future__ import annotations

import json
import math
import os

import numpy as np

from common.io import atomic_write_bytes

from .figures import plot_burst
from .options import SWITCHES
from .runs import H, HISTORY_COLUMNS, PATH_COLUMNS, HoldResult, PathResult, growth, ke_growth
from .stairs import StairResult

BURST_COLUMNS = ["ratio", "start_fraction", "eta_start", "eta_peak_c", "fraction_peak_c",
                 "eps1_peak_c", "c_start", "c_peak", "peak_confirmed_by", "switch",
                 "eta_switch", "eps1_switch", "c_switch", "dc", "c_target", "outcome",
                 "ke_growth", "ke_max", "ke_backbone_max", "w2_ext_end", "w2_walls_end",
                 "w2_int_end", "t_end", "steps", "de1_end", "de2_end", "creep_rate",
                 "unbalanced_end", "path_steps", "n_disks", "w2_ext_held_end",
                 "w2_int_secant_end", "w_damp_end", "u0_end", "eq1_bookkeeping", "ke_switch",
                 "c_rest", "c_loaded", "hold", "c_peak_loaded", "eta_peak_loaded", "wall_mass",
                 "g_held", "holds", "rest_search",
                 # the growth against the held step's work and the equilibrium bound (``growth``)
                 "ke_w2ext_max", "t_release", "released", "ke_end_over_bound",
                 # the kinematic probe at the switch's start, the path's verdict (``staircase``)
                 "k_path_switch", "k_noise", "c_cross", "overshoot_c", "overshoot_eps1",
                 "verdict",
                 # the anatomy: unstable contacts of the increment, against the baseline run
                 # (the switch's state held with no change of load), and at the burst's onset
                 "n_unstable_max", "unstable_noise_mean", "unstable_noise_max",
                 "n_unstable_excess", "largest_cluster_max", "largest_cluster_noise_max",
                 "t_onset", "n_unstable_onset", "largest_cluster_onset", "sliding_share_onset",
                 "sliding_share_switch", "n_unstable_raw_max", "unstable_raw_noise_max"]


REST_COLUMNS = ["ratio", "start_fraction", "state", "eps1", "c_loaded", "c_rest", "drop",
                "eta_rest", "outcome", "steps", "ke_end", "unbalanced_end", "k_path"]
STAIR_COLUMNS = ["ratio", "start_fraction", "hold", "role", "c_from", "c_target", "dc",
                 "outcome", "steps", "eps1_start", "eps1_end", "c_end", "ke_switch",
                 "ke_backbone_max", "w2_int_end", "eq1_bookkeeping", "from", "k_path_from",
                 "k_path", "ke_w2ext_max", "ke_end_over_bound"]
# rest.csv's probe columns, and probes.csv's (every kinematic probe of the path: ``path_probe``)
PROBE_COLUMNS = ["ratio", "start_fraction", "key", "c_state", "c_before", "c_after", "eps1_before",
                 "d_eps1", "k_path", "w2", "outcome", "steps", "wall_time", "rate"]


def burst_row(ratio, fraction, switch, path: PathResult, res: StairResult, i, opts, eta_peak, n):
    """One row of burst.csv (BURST_COLUMNS) as a dict: the path (its loaded peak), the rest
    search (the c peak at rest, the switch's hold ``i``: its start at rest, its target)."""
    pr = path.rows
    role, c_from, c_target, run = res.holds[i]
    h = run.history
    nan = math.nan
    lpk = path.peak
    rs = res.relaxed["start"]
    eps_sw = h[0, 2]
    c_loaded = float(np.interp(eps_sw, pr[:, 1], pr[:, 8])) if eps_sw <= pr[-1, 1] else nan
    peak = res.end == "past found"
    eta_sw = (h[0, 10] - h[0, 11]) / (0.5 * (h[0, 10] + h[0, 11]))
    return {"ratio": ratio, "start_fraction": fraction, "eta_start": rs.eta_rest,
            "eta_peak_c": res.eta_peak if peak else nan,
            "fraction_peak_c": res.eta_peak / eta_peak if peak else nan,
            "eps1_peak_c": res.eps1_peak - pr[0, 1] if peak else nan,
            "c_start": rs.c_rest, "c_peak": res.c_peak if peak else nan,
            "peak_confirmed_by": path.confirmed_by, "switch": switch,
            "eta_switch": eta_sw, "eps1_switch": eps_sw, "c_switch": h[0, 4],
            "dc": c_target - c_from, "c_target": c_target, "outcome": run.outcome,
            "ke_growth": ke_growth(h[:, 8]), "ke_max": float(h[:, 7].max()),
            "ke_backbone_max": float(h[:, 8].max()), "w2_ext_end": h[-1, H["w2_ext"]],
            "w2_walls_end": h[-1, H["w2_walls"]], "w2_int_end": h[-1, H["w2_int"]],
            "t_end": h[-1, 1], "steps": run.steps,
            "de1_end": h[-1, 2] - h[0, 2], "de2_end": h[-1, 3] - h[0, 3],
            "creep_rate": run.creep_rate, "unbalanced_end": h[-1, 9],
            "path_steps": path.steps, "n_disks": n,
            "w2_ext_held_end": h[-1, H["w2_ext_held"]],
            "w2_int_secant_end": h[-1, H["w2_int_secant"]], "w_damp_end": h[-1, H["w_damp"]],
            "u0_end": h[-1, H["u0"]], "eq1_bookkeeping": float(np.max(h[:, H["eq1_bookkeeping"]])),
            "ke_switch": run.ke_switch, "c_rest": h[0, 4], "c_loaded": c_loaded,
            "hold": run.hold, "c_peak_loaded": pr[lpk, 8] if lpk is not None else nan,
            "eta_peak_loaded": pr[lpk, 7] if lpk is not None else nan,
            "wall_mass": run.wall_mass, "g_held": run.g_held,
            "holds": len(res.holds), "rest_search": res.end,
            **growth(h, n, opts.ke_tol),
            "k_path_switch": _k(res, res.starts[i]), "k_noise": res.verdict.get("k_noise", nan),
            "c_cross": res.verdict.get("c_cross", nan),
            "overshoot_c": res.verdict.get("overshoot_c", nan),
            "overshoot_eps1": res.verdict.get("overshoot_eps1", nan),
            "verdict": res.verdict.get("verdict", "no probes"),
            **_anatomy_figures(run, res.holds[res.baselines[switch]][3]
                               if switch in res.baselines else None)}


def _k(res: StairResult, key):
    """k_path of the state ``key`` [Pa] (NaN if not probed or its probe did not settle)."""
    p = res.probes.get(key)
    return p.k_path if p is not None and p.outcome == "equilibrium" else math.nan


def _anatomy_figures(run: HoldResult, base: HoldResult | None) -> dict:
    """The anatomy of a switch's run against its baseline run (``staircase``: the switch's
    start held with no change of load, the same window and threshold): the largest count of
    unstable contacts over the run (below -UNSTABLE_TAU x the energy scale, ``dem.anatomy``),
    the baseline's mean and largest, the excess of the first over the baseline's largest; the
    largest cluster of each; the raw counts (threshold 0) of both; at the burst's onset
    (``ONSET``) the time, the count, the largest cluster and the sliding share."""
    h = run.history
    nan = math.nan
    out = {"n_unstable_max": float(np.max(h[:, H["n_unstable"]])),
           "largest_cluster_max": float(np.max(h[:, H["largest_cluster"]])),
           "sliding_share_switch": float(h[0, H["sliding_share"]])}
    b = base.history if base is not None else None
    out["unstable_noise_mean"] = float(np.mean(b[1:, H["n_unstable"]])) if b is not None and len(b) > 1 else nan
    out["unstable_noise_max"] = float(np.max(b[1:, H["n_unstable"]])) if b is not None and len(b) > 1 else nan
    out["largest_cluster_noise_max"] = (float(np.max(b[1:, H["largest_cluster"]]))
                                        if b is not None and len(b) > 1 else nan)
    out["n_unstable_excess"] = out["n_unstable_max"] - out["unstable_noise_max"]
    out["n_unstable_raw_max"] = float(np.max(h[:, H["n_unstable_raw"]]))
    out["unstable_raw_noise_max"] = (float(np.max(b[1:, H["n_unstable_raw"]]))
                                     if b is not None and len(b) > 1 else nan)
    k = np.flatnonzero(h[:, 0] == run.onset_step) if run.onset_step >= 0 else []
    if len(k):
        r = h[k[0]]
        out.update(t_onset=r[1], n_unstable_onset=r[H["n_unstable"]],
                   largest_cluster_onset=r[H["largest_cluster"]],
                   sliding_share_onset=r[H["sliding_share"]])
    else:
        out.update(t_onset=nan, n_unstable_onset=nan, largest_cluster_onset=nan,
                   sliding_share_onset=nan)
    return out


def write_burst_files(out_dir, combos, paths, stairs, rows, summary):
    """burst.csv, history.csv (the below and past runs and their baselines), paths.csv, rest.csv
    (the relaxations), stairs.csv (every hold of every staircase), probes.csv (every kinematic
    probe), summary.json and the figures."""
    from .. import io
    io.write_csv(os.path.join(out_dir, "burst.csv"), BURST_COLUMNS,
                 [[r[c] for c in BURST_COLUMNS] for r in rows])
    runs = {(r, f, sw): stairs[(r, f)].holds[i][3] for (r, f), res in stairs.items()
            for sw, i in res.switches.items()}
    bases = {(r, f, f"baseline_{sw}"): stairs[(r, f)].holds[i][3] for (r, f), res in stairs.items()
             for sw, i in res.baselines.items()}
    io.write_csv(os.path.join(out_dir, "history.csv"), HISTORY_COLUMNS,
                 [[r, f, sw] + list(h) for (r, f, sw), run in {**runs, **bases}.items()
                  for h in run.history])
    io.write_csv(os.path.join(out_dir, "paths.csv"), PATH_COLUMNS,
                 [[r, f] + list(x) for r, f, _ in combos for x in paths[(r, f)].rows])
    rest = []
    for (r, f), res in stairs.items():
        for name, x in res.relaxed.items():
            row = paths[(r, f)].grid[0 if name == "start" else 1][0]
            rest.append([r, f, name, paths[(r, f)].rows[row, 1], x.c_loaded, x.c_rest,
                         x.c_loaded - x.c_rest, x.eta_rest, x.outcome, x.steps, x.ke_end,
                         x.unbalanced_end, _k(res, "relaxed_" + name)])
    io.write_csv(os.path.join(out_dir, "rest.csv"), REST_COLUMNS, rest)
    n = summary["n_disks"]
    tol = summary["options"]["ke_tol"]
    stair_rows = []
    for (r, f), res in stairs.items():
        for k, (role, a, b, h) in enumerate(res.holds):
            g = growth(h.history, n, tol)
            stair_rows.append([r, f, k, role, a, b, b - a, h.outcome, h.steps, h.history[0, 2],
                               h.history[-1, 2], h.history[-1, 4], h.ke_switch,
                               float(h.history[:, 8].max()), h.history[-1, H["w2_int"]],
                               float(np.max(h.history[:, H["eq1_bookkeeping"]])), res.starts[k],
                               _k(res, res.starts[k]),
                               _k(res, f"h{k}_end") if h.outcome == "equilibrium" else math.nan,
                               g["ke_w2ext_max"], g["ke_end_over_bound"]])
    io.write_csv(os.path.join(out_dir, "stairs.csv"), STAIR_COLUMNS, stair_rows)
    io.write_csv(os.path.join(out_dir, "probes.csv"), PROBE_COLUMNS,
                 [[r, f] + [getattr(p, c) for c in PROBE_COLUMNS[2:]]
                  for (r, f), res in stairs.items() for p in res.probes.values()])
    atomic_write_bytes(os.path.join(out_dir, "summary.json"),
                          json.dumps(summary, indent=1, default=float).encode())
    plot_burst(out_dir, combos, paths, stairs, runs, summary)
    from ..ledger import plot_ledger
    for r, f, _ in combos[:1]:          # Eq. 1's terms of the first path's holds
        panels = [(f"R = {r:g}, f = {f:g}, {sw}: {runs[(r, f, sw)].outcome} "
                   f"({summary['n_disks']} disks)", runs[(r, f, sw)].history, HISTORY_COLUMNS[3:])
                  for sw in SWITCHES if (r, f, sw) in runs]
        if panels:
            plot_ledger(os.path.join(out_dir, "fig_burst_ledger.png"), panels)
