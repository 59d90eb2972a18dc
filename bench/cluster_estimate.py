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
"""
from __future__ import annotations

import argparse
import json
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from dem.domain import makespan, stage_steps     # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter, allow_abbrev=False)
    ap.add_argument("dir", help="a crosscheck output folder (or a dem domain folder with --seconds)")
    ap.add_argument("--workers", default="1,2,4,8,16,32,64", help="worker counts to estimate")
    ap.add_argument("--measured-workers", type=int, default=2,
                    help="workers the run had (default 2: this 2-core machine)")
    ap.add_argument("--seconds", type=float, default=None,
                    help="measured wall time of the relaxations and probes [s] (default: from "
                         "DIR/conclusions.json)")
    a = ap.parse_args(argv)
    counts = [int(w) for w in a.workers.split(",")]
    if a.measured_workers < 1 or min(counts) < 1:
        ap.error("--workers and --measured-workers: allowed integers >= 1")
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
