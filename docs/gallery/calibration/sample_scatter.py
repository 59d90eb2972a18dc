"""A sample's scatter: one DEM parameter set's drained biaxial test on many seeds (issue 34).

Runs the set of a parameter file (``calibrated.json``) on each seed with the calibration's own
run (``dem.calibrate`` evaluation: compaction, then the test at 0.01/s under 200 kPa, stopped
1 % past the peak or at eps1 = 3.5 %; one thread per run), reads the calibration's four figures
of each run and prints, for each figure, the mean over the seeds against the H-model's target,
one run's relative standard deviation, the standard error of a mean of 2 and of 4 seeds, and
how many seeds alone meet every target.  Writes OUT/sample_scatter.csv (a row per seed: its
figures and their errors) and keeps each run's curve in OUT/curve_SEED.json (a rerun takes
them instead of running again).

    python docs/gallery/calibration/sample_scatter.py docs/gallery/calibration/calibrated.json \
        --seeds 1-10 --out DIR [--workers 2]
"""
import argparse
import json
import math
import os
import sys
from multiprocessing import Pool

import numpy as np

from dem.calibrate import TOLERANCES, compare, curve_figures, hmodel_curve, params_key
from dem.calibrate.evaluation import _evaluate_task
from dem.params import load_params


def _run(a):
    path = os.path.join(a["out"], f"curve_{a['seed']}.json")
    if os.path.exists(path):
        with open(path) as f:
            return json.load(f)
    wd = os.path.join(a["out"], f"work_{a['seed']}")
    os.makedirs(wd, exist_ok=True)
    res = _evaluate_task({"key": params_key(a["params"]), "params": a["params"], "work_dir": wd,
                          "rate": 0.01, "confining": 200e3, "eps_max": a["eps_max"],
                          "post_peak_strain": a["post_peak_strain"], "resume": True})
    with open(path + ".part", "w") as f:
        json.dump(res, f)
    os.replace(path + ".part", path)
    os.remove(os.path.join(wd, "result.json"))
    os.rmdir(wd)
    print(f"seed {a['seed']}: {res['wall_time']:.0f} s", file=sys.stderr, flush=True)
    return res


def _seeds(text):
    lo, _, hi = text.partition("-")
    try:
        out = list(range(int(lo), int(hi) + 1)) if hi else [int(s) for s in text.split(",")]
    except ValueError:
        out = []
    if len(out) < 2 or min(out) < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: allowed A-B or a comma-separated list of "
                                         "two or more integers >= 0")
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("params", help="a DEM parameter file (e.g. calibrated.json)")
    ap.add_argument("--seeds", type=_seeds, default=_seeds("1-10"))
    ap.add_argument("--out", required=True)
    ap.add_argument("--workers", type=int, default=2, choices=range(1, 65), metavar="1..64")
    ap.add_argument("--eps1-max", type=float, default=0.035)
    ap.add_argument("--post-peak-strain", type=float, default=0.01)
    a = ap.parse_args(argv)
    base = load_params(a.params)
    os.makedirs(a.out, exist_ok=True)
    tasks = [{"seed": s, "out": a.out, "params": base.replace(seed=s).to_dict(),
              "eps_max": a.eps1_max, "post_peak_strain": a.post_peak_strain} for s in a.seeds]
    with Pool(a.workers) as pool:
        runs = pool.map(_run, tasks, chunksize=1)
    h = hmodel_curve(200e3, a.eps1_max)
    target = curve_figures(h["eps1"], h["q"], 0.0, eps_v=h["eps_v"])
    per = []
    for s, r in zip(a.seeds, runs):
        c = r["curve"]
        fig = curve_figures(c["eps1"], c["q"], 0.001, eps_v=c["eps_v"])
        per.append({"seed": s, **fig, **compare(fig, target)})
    cols = ["seed"] + list(TOLERANCES) + ["err_" + k for k in TOLERANCES] + ["met"]
    with open(os.path.join(a.out, "sample_scatter.csv"), "w") as f:
        f.write(",".join(cols) + "\n")
        for p in per:
            f.write(",".join(str(int(p[k]) if isinstance(p[k], bool) else p[k]) for k in cols)
                    + "\n")
    n = len(per)
    print(f"{a.params}: {n} seeds ({a.seeds[0]}..{a.seeds[-1]}); seeds alone meeting every "
          f"target: {sum(p['met'] for p in per)}")
    print("| figure | mean of the seeds vs target | one run sd/mean | s.e. of 2 | s.e. of 4 | "
          "tolerance | seeds alone within it |")
    print("|---|---|---|---|---|---|---|")
    for k, tol in TOLERANCES.items():
        v = np.array([p[k] for p in per])
        sd = np.std(v, ddof=1) / np.mean(v)
        print(f"| {k} | {np.mean(v) / target[k] - 1:+.1%} | {sd:.1%} | {sd / math.sqrt(2):.1%} | "
              f"{sd / 2:.1%} | {tol:.0%} | {sum(p['met_' + k] for p in per)}/{n} |")


if __name__ == "__main__":
    main()
