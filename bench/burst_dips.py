"""The dips of k_path measured (docs/burst.md, "The dips of k_path and the overshoot"): the
clearly negative equilibria of a `dem burst` staircase, what they do under other probes and
under +dc, and the overshoot past the crossing per size.

    python bench/burst_dips.py scan OUT FOLDER [FOLDER ...]
    python bench/burst_dips.py measure OUT --biaxial B --burst U [--keys auto|K1,K2]
                                            [--controls] [--d-eps1 3e-6,1e-5,3e-5] [--dc 100]
    python bench/burst_dips.py report OUT --scan S --dips D

``scan`` reads finished `dem burst` folders (stairs.csv, probes.csv, rest.csv, summary.json; the
verdict drawn again by ``dem.burst.verdict_of_folder``) and writes OUT/equilibria.csv (every
equilibrium of every staircase: its k_path over the rule's k_noise, whether it is clearly
negative, k_path < -k_noise, and the holds the staircase started from it) and
OUT/overshoot.csv (per folder: the verdict, the crossing and the overshoot). A *dip* is a clearly
negative equilibrium that is not the staircase's last: the staircase later settled a larger
held force from it.

``measure`` rebuilds the dips of one folder U (or the equilibria ``--keys``) from its biaxial
test B by the staircase's own rule, without the staircase's search: the start state relaxed at
fixed strain (``dem.burst.relax``), then the holds of the chain that led to the state replayed
from stairs.csv (``dem.burst.hold``, their recorded targets, the folder's options); each rebuilt
equilibrium's c must equal stairs.csv's to the bit (the kernels are deterministic on one
thread), or the script stops. At each state:

* k_path at every ``--d-eps1`` (``dem.burst.path_probe``, the rate by the rule: the move lasts
  one equilibrium window whatever its size); the 1e-5 one must give back probes.csv's k_path;
* the stress-controlled probe: the state's c raised by ``--dc`` under the walls' servo on c
  (``hold`` with hold="servo", the tie d eps2 = R d eps1 kept) and the same state under the
  servo at its own c (dc = 0, the drift of the switch of control alone); its strain response
  d eps1 (end of the run less the state's), and k_servo = dc / (d eps1(dc) - d eps1(0));
* the dead load's +dc hold (``hold``, the staircase's rule: G raised by W t dc from the state,
  the walls one dynamic degree of freedom): settles or fails.

``--controls`` adds the equilibria just before each dip (the state its hold started from) and
the last equilibrium (the c peak at rest, whose +dc fails by the staircase's definition).
Appends to OUT/dips.csv, one row per state; the rebuilt states are kept in OUT/states/ (not a
result: a resume of the script skips the rows already in dips.csv).

``report`` gathers a scan's S/equilibria.csv and S/overshoot.csv and the measured D/dips.csv into
OUT (the gallery's docs/gallery/burst/dips/): the three CSVs with each run folder named by its
sample (``sample`` = disks-seed, ``source`` = gallery or campaign), holds.csv (every hold of the
staircases and of ``measure`` started from a clearly negative equilibrium: its step and outcome),
fig_dips.png (k_path against the probe's d eps1 at every measured state; the overshoot against
the size, each seed a point) and prints the counts: the holds of +dc from clearly negative
states that failed, before and after the crossing, and the overshoot per size (mean, standard
deviation, range over the seeds with a crossing).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import numpy as np  # noqa: E402

from dem import io  # noqa: E402
from dem.burst import (BurstOptions, growth, hold, path_probe, relax,  # noqa: E402
                       verdict_of_folder)
from dem.simulation import Simulation  # noqa: E402

EQ_COLUMNS = ["folder", "n_disks", "seed", "key", "index", "c", "eps1", "k_path", "k_noise",
              "k_over_noise", "clearly_negative", "clearly_positive", "last", "c_cross",
              "after_cross", "next_steps", "next_outcomes", "next_settled_higher"]
OVERSHOOT_COLUMNS = ["folder", "n_disks", "seed", "verdict", "why", "n_clearly_positive",
                     "k_noise", "k_noise_relax", "n_equilibria", "n_dips", "c_peak_rest",
                     "c_cross", "overshoot_c", "overshoot_eps1", "holds", "avalanches",
                     "relax_collapses", "k_noise_wo_collapses", "verdict_wo_collapses",
                     "c_cross_wo_collapses", "overshoot_c_wo_collapses",
                     "overshoot_eps1_wo_collapses"]
DIP_COLUMNS = ["folder", "n_disks", "seed", "key", "kind", "c", "eps1", "k_path_run",
               "k_noise", "rebuilt_c_equal", "rebuild_steps",
               "k_3e-6", "k_1e-5", "k_3e-5", "c_before", "dc_3e-6", "dc_1e-5", "dc_3e-5",
               "probe_outcomes", "probe_rate_1e-5",
               "servo_dc", "servo_outcome", "servo_steps", "servo_de1", "servo0_outcome",
               "servo0_steps", "servo0_de1", "k_servo",
               "dead_dc", "dead_outcome", "dead_steps", "dead_de1", "dead_ke_w2ext_max",
               "dead_c_end", "dead_source", "wall_time"]


def _read(folder):
    with open(os.path.join(folder, "summary.json")) as f:
        s = json.load(f)
    _, stairs = io.read_csv(os.path.join(folder, "stairs.csv"))
    _, probes = io.read_csv(os.path.join(folder, "probes.csv"))
    _, rest = io.read_csv(os.path.join(folder, "rest.csv"))
    return s, stairs, probes, rest


def equilibria(folder):
    """(rows of EQ_COLUMNS, the verdict of the folder's first path) of one burst folder."""
    s, stairs, probes, rest = _read(folder)
    v = verdict_of_folder(folder)[0]
    p = s["paths"][0]
    mine = lambda rows: [r for r in rows if (r["ratio"], r["start_fraction"])
                         == (p["ratio"], p["start_fraction"])]
    start = next(r for r in mine(rest) if r["state"] == "start")
    eq = [("relaxed_start", start["c_rest"], start["eps1"])]
    holds = sorted(mine(stairs), key=lambda r: r["hold"])
    for r in holds:
        if r["role"] == "stair" and r["outcome"] == "equilibrium":
            eq.append((f"h{int(r['hold'])}_end", r["c_end"], r["eps1_end"]))
    k = {r["key"]: r["k_path"] for r in mine(probes)}
    noise = v["k_noise"]
    rows = []
    for i, (key, c, e1) in enumerate(eq):
        nxt = [r for r in holds if r["role"] == "stair" and r["from"] == key]
        kp = k.get(key, math.nan)
        rows.append({"folder": folder, "n_disks": s["n_disks"], "seed": s["params"]["seed"],
                     "key": key, "index": i, "c": c, "eps1": e1, "k_path": kp, "k_noise": noise,
                     "k_over_noise": kp / noise, "clearly_negative": int(kp < -noise),
                     "clearly_positive": int(kp > 2.0 * noise), "last": int(i == len(eq) - 1),
                     "c_cross": v["c_cross"],
                     "after_cross": int(math.isfinite(v["c_cross"]) and i > 0 and
                                        _after_cross(eq, k, noise, i)),
                     "next_steps": ";".join(f"{r['c_target'] - r['c_from']:.6g}" for r in nxt),
                     "next_outcomes": ";".join(r["outcome"] for r in nxt),
                     "next_settled_higher": int(i < len(eq) - 1)})
    return rows, v, s, len(holds)


def _after_cross(eq, k, noise, i):
    """Whether equilibrium ``i`` lies after the crossing (theory_verdict's: after the last
    clearly positive equilibrium)."""
    pos = [j for j, e in enumerate(eq) if k.get(e[0], math.nan) > 2.0 * noise]
    return bool(pos) and i > pos[-1]


def without_collapses(folder, v):
    """The verdict with the relaxations that collapsed left out of the relaxations' noise: a
    dead-load equilibrium whose relaxation at fixed strain moved c by more than the path's
    stiffest response moves it over the probe's whole d eps1 (|c_before - c_state| > k_max
    d_eps1: the state slid with its walls still, as an avalanche of a probe) is its own
    response, not noise about k_path's sign. Written before the package's rule
    (``dem.burst.k_noise``) left such relaxations out too; it gives the same verdict now, and
    stays as the check of that rule on every folder. Returns (collapsed keys, the noise,
    theory_verdict's dict)."""
    from dem.burst import theory_verdict
    s, stairs, probes, rest = _read(folder)
    d = s["options"]["probe_d_eps1"]
    kmax = v["k_max"]
    dz = {p["key"]: p["c_before"] - p["c_state"] for p in probes if p["key"].startswith("h")}
    gone = [k for k, z in dz.items() if abs(z) > kmax * d]
    keep = [z for k, z in dz.items() if k not in gone]
    relax_noise = math.sqrt(2.0) * math.sqrt(float(np.mean(np.square(keep)))) / d
    rep = v["k_noise_repeat"]
    noise = max(x for x in (relax_noise, rep) if math.isfinite(x))
    rows, _, _, _ = equilibria(folder)
    eqk = [(r["key"], r["c"], r["eps1"], r["k_path"]) for r in rows]
    fails = [(r["from"], r["c_target"] - r["c_from"]) for r in stairs
             if r["role"] == "stair" and r["outcome"] == "failure"]
    return gone, noise, theory_verdict(eqk, fails, noise, s["options"]["dc"])


def scan(out, folders):
    os.makedirs(out, exist_ok=True)
    eq_rows, ov_rows = [], []
    for folder in folders:
        rows, v, s, nh = equilibria(folder)
        eq_rows += rows
        ov_rows.append({"folder": folder, "n_disks": s["n_disks"], "seed": s["params"]["seed"],
                        "verdict": v["verdict"], "why": v["why"],
                        "n_clearly_positive": v["n_clearly_positive"], "k_noise": v["k_noise"],
                        "k_noise_relax": v["k_noise_relax"], "n_equilibria": len(rows),
                        "n_dips": sum(r["clearly_negative"] and not r["last"] for r in rows),
                        "c_peak_rest": v["c_peak_rest"], "c_cross": v["c_cross"],
                        "overshoot_c": v["overshoot_c"], "overshoot_eps1": v["overshoot_eps1"],
                        "holds": nh, "avalanches": ";".join(a["key"] for a in v["avalanches"])})
        gone, n2, v2 = without_collapses(folder, v)
        ov_rows[-1].update(relax_collapses=";".join(gone), k_noise_wo_collapses=n2,
                           verdict_wo_collapses=v2["verdict"], c_cross_wo_collapses=v2["c_cross"],
                           overshoot_c_wo_collapses=v2["overshoot_c"],
                           overshoot_eps1_wo_collapses=v2["overshoot_eps1"])
        if gone:
            print(f"{folder}: relaxations that collapsed {gone}: without them k_noise "
                  f"{n2 / 1e6:.2f} MPa, {v2['verdict']}, crossing {v2['c_cross'] / 1e3:.3f} kPa, "
                  f"overshoot {v2['overshoot_c']:.0f} Pa")
        for r in rows:
            if r["clearly_negative"]:
                print(f"{folder}: {r['key']} c {r['c'] / 1e3:.2f} kPa k_path "
                      f"{r['k_path'] / 1e6:+.1f} MPa ({r['k_over_noise']:+.1f} k_noise)"
                      f"{' (last)' if r['last'] else ''}; next holds "
                      f"{r['next_steps']} -> {r['next_outcomes']}")
        print(f"{folder}: {s['n_disks']} disks seed {s['params']['seed']}: {v['verdict']}, "
              f"crossing {v['c_cross'] / 1e3:.3f} kPa, overshoot {v['overshoot_c']:.0f} Pa "
              f"(eps1 {v['overshoot_eps1']:.2g}), k_noise {v['k_noise'] / 1e6:.2f} MPa",
              flush=True)
    io.write_csv(os.path.join(out, "equilibria.csv"), EQ_COLUMNS,
                 [[r[c] for c in EQ_COLUMNS] for r in eq_rows])
    io.write_csv(os.path.join(out, "overshoot.csv"), OVERSHOOT_COLUMNS,
                 [[r[c] for c in OVERSHOOT_COLUMNS] for r in ov_rows])


def _chain(holds, key):
    """The stair holds that led from the relaxed start to equilibrium ``key``, in order."""
    by = {f"h{int(r['hold'])}_end": r for r in holds}
    out = []
    while key != "relaxed_start":
        r = by[key]
        out.append(r)
        key = r["from"]
    return out[::-1]


class Rebuilder:
    """The states of one staircase rebuilt by its rule (``measure``), each once, kept on disk."""

    def __init__(self, biaxial, folder, cache):
        from dem.burst import load_starts
        from dem.probes import state_fingerprint
        self.s, stairs, self.probes, rest = _read(folder)
        p = self.s["paths"][0]
        self.ratio, self.frac = p["ratio"], p["start_fraction"]
        self.opts = BurstOptions(**{k: v for k, v in self.s["options"].items()
                                    if k in BurstOptions._fields})
        self.holds = [r for r in stairs if (r["ratio"], r["start_fraction"])
                      == (self.ratio, self.frac)]
        self.rest = next(r for r in rest if r["state"] == "start"
                         and (r["ratio"], r["start_fraction"]) == (self.ratio, self.frac))
        st = load_starts(biaxial, [self.frac])[0][0][1]
        fp = state_fingerprint(st)
        if fp != self.s["fingerprints"][f"{self.frac:g}"]:
            raise SystemExit(f"{biaxial}: its f={self.frac:g} state is not the one {folder} "
                             "started from (fingerprint differs)")
        self.start = st
        self.cache = cache
        os.makedirs(cache, exist_ok=True)
        self.steps = 0

    def _file(self, key):
        return os.path.join(self.cache, f"{key}.npz")

    def state(self, key):
        if os.path.exists(self._file(key)):
            return io.load_state(self._file(key))[0]
        if key == "relaxed_start":
            # the path's first state, as ``proportional_path`` keeps it (its control set)
            from dem.ledger import Ledger
            from dem.walls import strain_rate
            sim = Simulation(self.start)
            sim.set_control(strain_rate(self.ratio * self.opts.rate, self.opts.rate,
                                        sim.ref_len))
            Ledger(sim)
            r = relax(sim.state(), self.ratio, self.opts, 1)
            self._check(key, r.c_rest, self.rest["c_rest"])
            self.steps += r.steps
            st = r.state
        else:
            h = _chain(self.holds, key)[-1]
            prev = self.state(h["from"])
            r = hold(prev, self.ratio, h["c_target"], self.opts, 1)
            self._check(key, r.history[-1, 4], h["c_end"])
            if r.outcome != h["outcome"]:
                raise SystemExit(f"{key}: rebuilt hold {r.outcome}, stairs.csv {h['outcome']}")
            self.steps += r.steps
            st = r.end_state
        io.save_state(self._file(key), st)
        return st

    @staticmethod
    def _check(key, got, want):
        if got != want:
            raise SystemExit(f"{key}: rebuilt c {got!r} Pa, stairs.csv {want!r} Pa: not the "
                             "same state (the code or the thread count differs)")
        print(f"  rebuilt {key}: c {got / 1e3:.3f} kPa equal to the run's to the bit",
              flush=True)


def c_of(state, ratio):
    s2, s1 = Simulation(state).wall_stress()
    return s1 + ratio * s2


def measure_state(rb, key, kind, strains, dc, k_noise):
    t0 = time.time()
    steps0 = rb.steps
    st = rb.state(key)
    ratio, opts = rb.ratio, rb.opts
    c = c_of(st, ratio)
    e1 = Simulation(st).strain()[1]
    row = {"folder": "", "n_disks": len(st.r), "seed": st.params.seed, "key": key,
           "kind": kind, "c": c, "eps1": e1,
           "k_path_run": next((p["k_path"] for p in rb.probes if p["key"] == key), math.nan),
           "k_noise": k_noise, "rebuilt_c_equal": 1, "rebuild_steps": rb.steps - steps0}
    outs = []
    for d in strains:
        pr = path_probe(st, ratio, opts._replace(probe_d_eps1=d), 1, key)
        tag = f"{d:.0e}".replace("e-0", "e-")
        row[f"k_{tag}"] = pr.k_path
        row[f"dc_{tag}"] = pr.c_after - pr.c_before
        row["c_before"] = pr.c_before
        if d == 1e-5:
            row["probe_rate_1e-5"] = pr.rate
        outs.append(pr.outcome)
        print(f"  {key} probe d eps1 {d:g}: c {pr.c_before:.1f} -> {pr.c_after:.1f} Pa, k_path "
              f"{pr.k_path / 1e6:+.2f} MPa, {pr.outcome}, {pr.steps} steps", flush=True)
    row["probe_outcomes"] = ";".join(outs)
    servo = opts._replace(hold="servo")
    des = {}
    for name, d in (("servo", dc), ("servo0", 0.0)):
        h = hold(st, ratio, c + d, servo, 1)
        des[name] = h.history[-1, 2] - e1
        row[f"{name}_outcome"], row[f"{name}_steps"], row[f"{name}_de1"] = (
            h.outcome, h.steps, des[name])
        print(f"  {key} servo c + {d:g} Pa: {h.outcome} after {h.steps} steps, d eps1 "
              f"{des[name]:.3g}", flush=True)
    row["servo_dc"] = dc
    ok = row["servo_outcome"] == row["servo0_outcome"] == "equilibrium"
    row["k_servo"] = dc / (des["servo"] - des["servo0"]) if ok else math.nan
    same = [r for r in rb.holds if r["role"] == "stair" and r["from"] == key
            and abs(r["c_target"] - r["c_from"] - dc) <= 1e-9 * dc]
    if same:        # the staircase held this very +dc (deterministic: the same run again)
        r = same[0]
        row.update(dead_dc=dc, dead_outcome=r["outcome"], dead_steps=r["steps"],
                   dead_de1=r["eps1_end"] - r["eps1_start"],
                   dead_ke_w2ext_max=r["ke_w2ext_max"], dead_c_end=r["c_end"],
                   dead_source="staircase", wall_time=time.time() - t0)
        print(f"  {key} dead load c + {dc:g} Pa: the staircase's hold {int(r['hold'])}, "
              f"{r['outcome']}", flush=True)
        return row
    h = hold(st, ratio, c + dc, opts, 1)
    g = growth(h.history, len(st.r), opts.ke_tol)
    row.update(dead_dc=dc, dead_outcome=h.outcome, dead_steps=h.steps,
               dead_de1=h.history[-1, 2] - e1, dead_ke_w2ext_max=g["ke_w2ext_max"],
               dead_c_end=h.history[-1, 4], dead_source="this script",
               wall_time=time.time() - t0)
    print(f"  {key} dead load c + {dc:g} Pa: {h.outcome} after {h.steps} steps "
          f"(largest (E_c - E_c(0)) / W2_ext {g['ke_w2ext_max']:.3g}); {row['wall_time']:.0f} s",
          flush=True)
    return row


def measure(out, biaxial, folder, keys, controls, strains, dc):
    os.makedirs(out, exist_ok=True)
    rows, v, s, _ = equilibria(folder)
    rb = Rebuilder(biaxial, folder, os.path.join(out, "states",
                                                 os.path.basename(os.path.normpath(folder))))
    if keys == "auto":
        dips = [r for r in rows if r["clearly_negative"] and not r["last"]]
    else:
        want = keys.split(",")
        dips = [r for r in rows if r["key"] in want]
    todo = []
    for r in dips:
        if controls and r["index"] > 0:
            todo.append((rows[r["index"] - 1]["key"], "before_dip"))
        todo.append((r["key"], "dip" if r["clearly_negative"] and not r["last"] else "chosen"))
    if controls:
        todo.append((rows[-1]["key"], "last"))
    path = os.path.join(out, "dips.csv")
    done = []
    if os.path.exists(path):
        _, done = io.read_csv(path)
    have = {(d["folder"], d["key"]) for d in done}
    seen = set()
    for key, kind in todo:
        if (folder, key) in have or key in seen:
            continue
        seen.add(key)
        print(f"{folder}: {key} ({kind})", flush=True)
        row = measure_state(rb, key, kind, strains, dc, v["k_noise"])
        row["folder"] = folder
        if not math.isnan(row["k_path_run"]) and "k_1e-5" in row \
                and row["k_1e-5"] != row["k_path_run"]:
            print(f"  note: k_path at 1e-5 {row['k_1e-5']!r} differs from the run's "
                  f"{row['k_path_run']!r}", flush=True)
        done.append(row)
        io.write_csv(path, DIP_COLUMNS, [[d.get(c, math.nan) for c in DIP_COLUMNS]
                                         for d in done])


def _label(folder):
    return "gallery" if "gallery" in folder.replace("\\", "/").split("/") else "campaign"


def _relabel(rows):
    """The rows with the run folder replaced by the sample's name (a folder of the machine that
    ran them means nothing to a reader): ``sample`` = disks-seed, ``source``."""
    out = []
    for r in rows:
        d = {"sample": f"{int(float(r['n_disks']))}-{int(float(r['seed']))}",
             "source": _label(r["folder"])}
        d.update({k: v for k, v in r.items() if k != "folder"})
        out.append(d)
    return out


INT_COLUMNS = {"n_disks", "seed", "index", "clearly_negative", "clearly_positive", "last",
               "after_cross", "next_settled_higher", "n_clearly_positive", "n_equilibria",
               "n_dips", "holds", "rebuilt_c_equal", "rebuild_steps", "servo_steps",
               "servo0_steps", "dead_steps"}


def _write(path, rows):
    cols = list(rows[0])
    fix = lambda c, v: (int(v) if c in INT_COLUMNS and isinstance(v, float) and math.isfinite(v)
                        else v)
    io.write_csv(path, cols, [[fix(c, r[c]) for c in cols] for r in rows])


def report(out, scan_dir, dips_dir):
    os.makedirs(out, exist_ok=True)
    _, eq = io.read_csv(os.path.join(scan_dir, "equilibria.csv"))
    _, ov = io.read_csv(os.path.join(scan_dir, "overshoot.csv"))
    _, dp = io.read_csv(os.path.join(dips_dir, "dips.csv"))
    eq, ov, dp = _relabel(eq), _relabel(ov), _relabel(dp)
    # one row per sample: a campaign's folder measured twice under two names is one sample
    dp = list({(r["sample"], r["key"]): r for r in dp}.values())
    neg = {(r["sample"], r["key"]): r for r in eq if int(r["clearly_negative"])}
    holds = []
    for (sample, key), r in neg.items():
        steps = [float(x) for x in str(r["next_steps"]).split(";") if x != ""]
        outs = [x for x in str(r["next_outcomes"]).split(";") if x != ""]
        for st, o in zip(steps, outs):
            holds.append({"sample": sample, "key": key, "c": r["c"], "k_path": r["k_path"],
                          "k_over_noise": r["k_over_noise"], "after_cross": r["after_cross"],
                          "last": r["last"], "step": st, "outcome": o, "source": "staircase"})
    for d in dp:
        if (d["sample"], d["key"]) in neg and d["dead_source"] == "this script":
            r = neg[(d["sample"], d["key"])]
            holds.append({"sample": d["sample"], "key": d["key"], "c": r["c"],
                          "k_path": r["k_path"], "k_over_noise": r["k_over_noise"],
                          "after_cross": r["after_cross"], "last": r["last"],
                          "step": d["dead_dc"], "outcome": d["dead_outcome"],
                          "source": "measure"})
    holds.sort(key=lambda h: (h["sample"], float(h["c"]), -h["step"]))
    for name, rows in (("equilibria.csv", eq), ("overshoot.csv", ov), ("dips.csv", dp),
                       ("holds.csv", holds)):
        if rows:
            _write(os.path.join(out, name), rows)
    dc = min(h["step"] for h in holds) if holds else math.nan
    print(f"holds from clearly negative equilibria ({len(neg)} states in "
          f"{len({s for s, _ in neg})} samples):")
    for what, sel in (("every step", lambda h: True),
                      (f"+dc = {dc:g} Pa", lambda h: abs(h["step"] - dc) < 1e-9 * dc)):
        for part, keep in (("all", lambda h: True),
                           ("before the crossing", lambda h: not int(h["after_cross"])),
                           ("after the crossing", lambda h: int(h["after_cross"])),
                           ("not the last equilibrium", lambda h: not int(h["last"])),
                           ("the last equilibrium", lambda h: int(h["last"]))):
            hs = [h for h in holds if sel(h) and keep(h)]
            nf = sum(h["outcome"] == "failure" for h in hs)
            print(f"  {what}, {part}: {nf} of {len(hs)} failed")
    states = {}
    for h in holds:
        if abs(h["step"] - dc) < 1e-9 * dc:
            states.setdefault((h["sample"], h["key"]), []).append(h["outcome"])
    miss = sorted(set(neg) - set(states))
    print(f"  clearly negative states with no +dc hold: {miss}")
    print("overshoot past the crossing per size (the seeds with a crossing):")
    by = {}
    for r in ov:
        by.setdefault(int(float(r["n_disks"])), []).append(r)
    for n in sorted(by):
        rs = sorted(by[n], key=lambda r: int(float(r["seed"])))
        x = np.array([float(r["overshoot_c"]) for r in rs if math.isfinite(float(r["overshoot_c"]))])
        e = np.array([float(r["overshoot_eps1"]) for r in rs
                      if math.isfinite(float(r["overshoot_eps1"]))])
        each = ", ".join(f"seed {int(float(r['seed']))} {float(r['overshoot_c']):.0f}"
                         if math.isfinite(float(r["overshoot_c"]))
                         else f"seed {int(float(r['seed']))} none ({r['verdict']})" for r in rs)
        if len(x):
            print(f"  {n} disks: {len(x)} of {len(rs)} with a crossing, overshoot mean "
                  f"{x.mean():.0f} Pa, sd {x.std(ddof=1) if len(x) > 1 else math.nan:.0f} Pa, "
                  f"range {x.min():.0f}-{x.max():.0f} Pa; eps1 {e.min():.2g}-{e.max():.2g} "
                  f"[{each}]")
        else:
            print(f"  {n} disks: no crossing [{each}]")
    _figure(out, dp, ov)


def _figure(out, dp, ov):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.5), constrained_layout=True)
    kinds = {"before_dip": ("C2", "the equilibrium before a dip"),
             "dip": ("C3", "a dip (clearly negative, not the last)"),
             "last": ("k", "the last equilibrium"), "chosen": ("C0", "chosen")}
    seen = set()
    marks = "osD^v<>ph*"
    samples = sorted({d["sample"] for d in dp})
    for d in dp:
        xs, ys = [], []
        for tag, x in (("3e-6", 3e-6), ("1e-5", 1e-5), ("3e-5", 3e-5)):
            v = d.get(f"k_{tag}", math.nan)
            if v != "" and math.isfinite(float(v)):
                xs.append(x)
                ys.append(float(v) / 1e6)
        col, lab = kinds.get(d["kind"], ("0.5", d["kind"]))
        a1.plot(xs, ys, "-", color=col, lw=0.8, alpha=0.8,
                marker=marks[samples.index(d["sample"]) % len(marks)], ms=4,
                label=lab if lab not in seen else None)
        seen.add(lab)
    a1.set_xscale("log")
    a1.set_xticks([3e-6, 1e-5, 3e-5])
    a1.set_xticklabels(["3e-6", "1e-5", "3e-5"])
    a1.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    a1.set_yscale("symlog", linthresh=10.0)
    a1.axhline(0, color="0.5", lw=0.5)
    a1.set_xlabel("the probe's d eps1 [-]")
    a1.set_ylabel("k_path = dc / d eps1 [MPa]")
    a1.set_title("k_path of one state against the probe's size\n(markers: " +
                 ", ".join(f"{marks[i % len(marks)]} {s}" for i, s in enumerate(samples)) + ")",
                 fontsize=8)
    a1.legend(fontsize=7, loc="upper right")
    lab = {"gallery": "the gallery's run (seed 1)", "campaign": "another seed"}
    none = {}
    for r in ov:
        n, x = int(float(r["n_disks"])), float(r["overshoot_c"])
        if math.isfinite(x):
            a2.plot(n, x, "o", color="C1" if r["source"] == "gallery" else "C0", ms=6,
                    label=lab.pop(r["source"], None))
            a2.annotate(f"{int(float(r['seed']))}", (n, x), textcoords="offset points",
                        xytext=(5, -3 if int(float(r["seed"])) % 2 else 3), fontsize=7)
        else:
            none.setdefault(n, []).append(str(int(float(r["seed"]))))
    for n, seeds in none.items():
        a2.plot(n, 20.0, "x", color="0.4", ms=6)
        a2.annotate(f"no verdict: seed {', '.join(seeds)}", (n, 20.0),
                    textcoords="offset points", xytext=(5, -3), fontsize=7)
    a2.legend(fontsize=7, loc="upper right")
    a2.set_xscale("log")
    a2.set_yscale("log")
    a2.set_xlabel("disks")
    a2.set_ylabel("overshoot: c peak at rest - c_cross [Pa]")
    a2.set_title("the overshoot past the crossing per sample (its seed beside it)", fontsize=8)
    a2.set_xticks([2000, 4000, 12000])
    a2.set_xticklabels(["2000", "4000", "12,000"])
    a2.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    a2.set_xlim(1600, 16000)
    from common.io import save_figure
    save_figure(fig, os.path.join(out, "fig_dips.png"))
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    a1 = sub.add_parser("scan")
    a1.add_argument("out")
    a1.add_argument("folders", nargs="+")
    a2 = sub.add_parser("measure")
    a2.add_argument("out")
    a2.add_argument("--biaxial", required=True)
    a2.add_argument("--burst", required=True)
    a2.add_argument("--keys", default="auto")
    a2.add_argument("--controls", action="store_true")
    a2.add_argument("--d-eps1", default="3e-6,1e-5,3e-5")
    a2.add_argument("--dc", type=float, default=100.0)
    a3 = sub.add_parser("report")
    a3.add_argument("out")
    a3.add_argument("--scan", required=True)
    a3.add_argument("--dips", required=True)
    a = ap.parse_args(argv)
    if a.cmd == "report":
        report(a.out, a.scan, a.dips)
    elif a.cmd == "scan":
        scan(a.out, a.folders)
    else:
        measure(a.out, a.biaxial, a.burst, a.keys, a.controls,
                [float(x) for x in a.d_eps1.split(",")], a.dc)
    return 0


if __name__ == "__main__":
    sys.exit(main())
