"""What a finished DEM directional analysis would take on N workers (a dask cluster, or more
local processes), from that run's own step counts and wall time.

The relaxations and probe runs of `python -m crosscheck` and `python -m dem domain` are
independent one-thread runs handed out in three waves (the relaxations, then the elastic runs,
then the sliding runs, which need their elastic strain), each run to the first worker free
(`dem.domain.makespan`). The steps per second of one worker are calibrated on the run itself:
the simulated wall time of its waves on the workers it ran with, in steps, against its measured
wall time. The biaxial test (one sample, its own threads) and the H-model and FE parts do not
spread and are added as measured. A worker is taken as fast as one of this run's workers, and
dask's own overhead (seconds a task) is left out. The run must have done its relaxations and
probes in one go: a run completed by `--resume` measured only what was left.

    python bench/cluster_estimate.py DIR                 # DIR: a `crosscheck` output folder
    python bench/cluster_estimate.py DIR --workers 2,8,16,45 --measured-workers 2
    python bench/cluster_estimate.py DIR2 --seconds 6000 # DIR2: a `dem domain` output folder
    python bench/cluster_estimate.py DIR3 --workers 1,2,8 [--rate 4400]   # DIR3: a `dem burst` folder

A `dem burst` folder (its stairs.csv) is replayed as `run_burst` hands its runs out
(`dem.pool`): each path's chain (the path, the start's relaxation and the holds of the
staircase, one after another, always on a worker of its own), and beside it, on the workers the
chains leave, the runs as their states come: the loaded peak's relaxation once the path has
ended, the probe of each equilibrium when its hold or relaxation ends, the below run and the
baselines when the staircase ends and the probes of their ends after them; the runs that start
others before the probes, then first asked, first run. Every run's length is its step count
(rest.csv, stairs.csv, probes.csv, summary.json's paths) at one rate, ``--rate`` steps a second a
worker (default: the run's own probes', probes.csv's steps over wall_time); one worker runs
everything one after another. The figures are those of the files' runs (a run's steps do not
depend on the workers), a worker as fast as the rate says, dask's overhead (seconds a task) left
out.

With ``--graph``, a `crosscheck` folder's two pooled DEM stages, its domain's waves and its burst
section's runs (`DIR/dem/domain`, `DIR/burst/dem`), are replayed one after the other (the order
of `run_crosscheck(..., graph=False)`) and as one pool (the graph: the domain's runs first asked,
the burst's chain on a worker of its own), at the burst's probes' rate.

    python bench/cluster_estimate.py DIR --graph --workers 1,2,8
"""
from __future__ import annotations

import argparse
import json
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from dem.domain import makespan, stage_steps     # noqa: E402


def _csv(path):
    import csv
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def burst_runs(bdir):
    """The runs of a finished `dem burst` folder, one dict a path (in summary.json's order):
    ``path`` (its steps), ``chain`` ([(name, steps)]: the start's relaxation, then the
    staircase's holds, and the loaded peak's relaxation where the path has no loaded peak),
    ``peak`` (the loaded peak's relaxation beside the staircase: its steps, or None), ``holds``
    ({k: (role, outcome, steps)}), ``probes`` ({key: steps})."""
    with open(os.path.join(bdir, "summary.json")) as f:
        summ = json.load(f)
    rest, stairs, probes = (_csv(os.path.join(bdir, n)) for n in ("rest.csv", "stairs.csv",
                                                                  "probes.csv"))
    out = []
    for p in summ["paths"]:
        mine = lambda rows: [x for x in rows if float(x["ratio"]) == p["ratio"]
                             and float(x["start_fraction"]) == p["start_fraction"]]
        relax = {x["state"]: int(float(x["steps"])) for x in mine(rest)}
        holds = {int(x["hold"]): (x["role"], x["outcome"], int(float(x["steps"])))
                 for x in mine(stairs)}
        stair = [(f"h{k}", holds[k][2]) for k in sorted(holds) if holds[k][0] == "stair"]
        peaked = p["end"] in ("drop", "strain")
        chain = ([("relax_start", relax["start"])] if "start" in relax else []) + stair
        if not peaked and "peak" in relax:
            chain.append(("relax_peak", relax["peak"]))
        out.append({"path": p["steps"], "chain": chain,
                    "peak": relax.get("peak") if peaked else None, "holds": holds,
                    "probes": {x["key"]: int(float(x["steps"])) for x in mine(probes)}})
    return out


def replay_pool(runs, waves, workers):
    """The wall time, in steps of one worker, of ``burst_runs``'s runs and the directional
    analysis's ``waves`` (relaxations, elastic runs, sliding runs, or None) on ``workers``
    workers of one pool, as ``dem.pool`` hands them out (the module doc): each path's chain (its
    path, its start's relaxation, its holds) always on a worker of its own; beside the chains, on
    the workers they leave, the runs as they are asked for: the domain's waves (each once the
    one before has ended) and the burst's side runs, those that start others first, then first
    asked, first run. One worker runs everything one after another."""
    import heapq
    waves = [list(w) for w in (waves or ()) if w]
    if workers == 1:
        return float(sum(r["path"] + sum(s for _, s in r["chain"]) + (r["peak"] or 0)
                         + sum(h[2] for k, h in r["holds"].items() if h[0] != "stair")
                         + sum(r["probes"].values()) for r in runs) + sum(map(sum, waves)))
    t, seq = 0.0, [0]
    queue, running = [], []          # (rank, order, (owner, name, steps)); (end, order, ...)
    chains = {}                      # path -> index of its running chain run
    wave = {"k": -1, "left": 0}      # the domain's wave under way, its runs not yet ended

    def ask(i, name, steps, first=False):
        seq[0] += 1
        heapq.heappush(queue, (0 if first else 1, seq[0], (i, name, steps)))

    def probe(i, key):
        if key in runs[i]["probes"]:
            ask(i, "probe " + key, runs[i]["probes"][key])

    def run(i, name, steps, chain):
        seq[0] += 1
        heapq.heappush(running, (t + steps, seq[0], (i, name, chain)))

    def next_chain(i):
        r, k = runs[i], chains.get(i, -1) + 1
        links = [("path", r["path"])] + r["chain"]
        if k < len(links):
            chains[i] = k
            run(i, links[k][0], links[k][1], True)
            return
        chains.pop(i, None)
        for k, (role, _, steps) in sorted(r["holds"].items()):
            if role != "stair":
                ask(i, f"h{k}", steps, first=True)

    def next_wave():
        while wave["left"] == 0 and wave["k"] + 1 < len(waves):
            wave["k"] += 1
            wave["left"] = len(waves[wave["k"]])
            for steps in waves[wave["k"]]:
                ask(-1, "domain", steps)

    next_wave()                      # the domain's job is the first of the pool's
    for i, r in enumerate(runs):
        next_chain(i)

    def fill():
        busy = len(running) - len(chains)
        while queue and busy < workers - len(chains):
            _, _, (i, name, steps) = heapq.heappop(queue)
            run(i, name, steps, False)
            busy += 1

    fill()
    while running:
        t, _, (i, name, chain) = heapq.heappop(running)
        if i < 0:
            wave["left"] -= 1
            next_wave()
        elif name == "path":
            if runs[i]["peak"] is not None:
                ask(i, "relax_peak", runs[i]["peak"], first=True)
        elif name.startswith("relax_"):
            probe(i, "relaxed_" + name[len("relax_"):])
        elif name.startswith("h") and runs[i]["holds"][int(name[1:])][1] == "equilibrium":
            probe(i, name + "_end")
        if chain:
            next_chain(i)
        fill()
    return t


def _probe_rate(bdir):
    """Steps a second of one worker: the burst's probes' (probes.csv's steps over wall_time)."""
    rows = _csv(os.path.join(bdir, "probes.csv"))
    steps, wall = sum(int(float(x["steps"])) for x in rows), sum(float(x["wall_time"]) for x in rows)
    return steps / wall if steps and wall else None


def main_burst(a, counts):
    runs = burst_runs(a.dir)
    steps = sum(sum(r["probes"].values()) for r in runs)
    if a.rate is None:
        a.rate = _probe_rate(a.dir)
        if a.rate is None:
            sys.exit("no probes to take the rate from: give --rate")
    chain = sum(sum(s for _, s in r["chain"]) for r in runs)
    total = replay_pool(runs, None, 1)
    print(f"{a.dir}: {len(runs)} path(s), {total / 1e6:.2f} million steps of runs (the paths "
          f"{sum(r['path'] for r in runs) / 1e6:.2f}, the staircases' chains {chain / 1e6:.2f}, "
          f"the probes {steps / 1e6:.2f}); {a.rate:.0f} steps/s a worker")
    print(f"{'workers':>8} {'minutes':>8}   of one worker")
    for n in counts:
        s = replay_pool(runs, None, n)
        print(f"{n:>8} {s / a.rate / 60:>8.1f}   {s / total:>14.3f}")
    floor = max(r["path"] + sum(s for _, s in r["chain"]) + max(
        [h[2] + r["probes"].get(f"h{k}_end", 0) for k, h in r["holds"].items()
         if h[0] != "stair"] + [0]) for r in runs)
    print(f"floor (a path, its staircase, then its longest hold beside it and that hold's probe):"
          f" {floor / a.rate / 60:.1f} min, {floor / total:.3f} of one worker")


def main_graph(a, counts):
    """A crosscheck folder with its burst section: the DEM's pooled stages (its domain's waves
    and the burst's runs) one after the other and as one pool, on N workers."""
    ddir, bdir = os.path.join(a.dir, "dem", "domain"), os.path.join(a.dir, "burst", "dem")
    runs, waves = burst_runs(bdir), stage_steps(ddir)
    rate = a.rate or _probe_rate(bdir)
    if rate is None:
        sys.exit("no probes to take the rate from: give --rate")
    dom, bur = sum(map(sum, waves)), replay_pool(runs, None, 1)
    print(f"{a.dir}: the domain {len(waves[0])} relaxations and {len(waves[1]) + len(waves[2])} "
          f"probe runs, {dom / 1e6:.2f} million steps; the burst {bur / 1e6:.2f} million steps; "
          f"{rate:.0f} steps/s a worker (the burst's probes')")
    print(f"{'workers':>8} {'domain':>8} {'burst':>8} {'one after':>10} {'one pool':>9} "
          f"{'ratio':>6}   (minutes of the DEM's pooled stages)")
    for n in counts:
        d = sum(makespan(w, n) for w in waves if w)
        b = replay_pool(runs, None, n)
        g = replay_pool(runs, waves, n)
        print(f"{n:>8} {d / rate / 60:>8.1f} {b / rate / 60:>8.1f} {(d + b) / rate / 60:>10.1f} "
              f"{g / rate / 60:>9.1f} {g / (d + b):>6.3f}")
    chain = max(r["path"] + sum(s for _, s in r["chain"]) for r in runs)
    print(f"floor: the longest chain (a path and its staircase) {chain / rate / 60:.1f} min; "
          f"all the steps over N workers {(dom + bur) / rate / 60:.1f} / N min")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter, allow_abbrev=False)
    ap.add_argument("dir", help="a crosscheck output folder (or a dem domain folder with --seconds, "
                                "or a dem burst folder)")
    ap.add_argument("--workers", default="1,2,4,8,16,32,64", help="worker counts to estimate")
    ap.add_argument("--measured-workers", type=int, default=2,
                    help="workers the run had (default 2: this 2-core machine)")
    ap.add_argument("--seconds", type=float, default=None,
                    help="measured wall time of the relaxations and probes [s] (default: from "
                         "DIR/conclusions.json)")
    ap.add_argument("--rate", type=float, default=None,
                    help="a dem burst folder: steps a second of one worker (default: its probes')")
    ap.add_argument("--graph", action="store_true",
                    help="a crosscheck folder: its domain and its burst one after the other "
                         "against one pool (crosscheck.run's graph)")
    a = ap.parse_args(argv)
    counts = [int(w) for w in a.workers.split(",")]
    if a.measured_workers < 1 or min(counts) < 1:
        ap.error("--workers and --measured-workers: allowed integers >= 1")
    if os.path.exists(os.path.join(a.dir, "stairs.csv")):
        return main_burst(a, counts)
    if a.graph:
        return main_graph(a, counts)
    ddir = os.path.join(a.dir, "dem", "domain")
    fixed, seconds = {}, a.seconds
    if os.path.isdir(ddir):
        with open(os.path.join(a.dir, "conclusions.json")) as f:
            timings = json.load(f)["timings"]
        for k, v in timings.items():
            if k.strip().startswith("DEM relaxations and probes"):
                seconds = v if seconds is None else seconds
            elif k.strip().startswith("DEM compaction + biaxial"):
                fixed["DEM compaction + biaxial test"] = v
            elif not k.startswith("DEM") and not k.startswith(" "):
                fixed[k] = v
    else:
        ddir = a.dir
    if seconds is None:
        ap.error("no measured wall time: give --seconds")
    waves = stage_steps(ddir)
    n_runs = sum(len(w) for w in waves)

    def steps_on(n):
        return [makespan(w, n) for w in waves]

    rate = sum(steps_on(a.measured_workers)) / seconds
    print(f"{ddir}: {len(waves[0])} relaxations, {len(waves[1])} elastic and {len(waves[2])} "
          f"sliding runs, {sum(map(sum, waves)) / 1e6:.1f} million steps; measured "
          f"{seconds:.0f} s on {a.measured_workers} workers: {rate:.0f} steps/s a worker")
    print("not spread: " + ", ".join(f"{k} {v:.0f} s" for k, v in fixed.items()) if fixed else
          "not spread: (none given)")
    print(f"{'workers':>8} {'relaxations':>12} {'elastic':>9} {'sliding':>9} {'DEM runs':>9} "
          f"{'total':>9}   (minutes)")
    for n in counts:
        r, e, s = (x / rate / 60 for x in steps_on(n))
        total = r + e + s + sum(fixed.values()) / 60
        tag = "  (the run, calibrates)" if n == a.measured_workers else ""
        print(f"{n:>8} {r:>12.1f} {e:>9.1f} {s:>9.1f} {r + e + s:>9.1f} {total:>9.1f}{tag}")
    longest = max(max(w) for w in waves if w)
    print(f"floor (the longest single run, {longest / 1e3:.0f}k steps, in each wave): "
          f"{sum(max(w) for w in waves if w) / rate / 60:.1f} min of DEM runs from "
          f"{max(len(w) for w in waves)} workers on; {n_runs} runs in all")


if __name__ == "__main__":
    main()
