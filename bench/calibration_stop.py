"""What an in-run stop would have saved a finished `python -m dem calibrate` run, and what it
would have cost its search.

The calibration runs every set on its first seed, and on its other seeds only where that run
does not decide a target missed by the seeds' mean (`dem.calibrate.first_run_decides`). A first
run could stop earlier still: as soon as the records so far decide a target missed
(`dem.calibrate.decided_in_run`: the secant modulus is exact from 0.25 % axial strain on; peak q
and eps1_95 are known from below). This replays each set's first run of a finished calibration
with that rule, looking at no later record than the one it stops at, and prints per set the
strain it would have stopped at and the share of its test's strain it would have saved (the
run's wall time times that share: an upper bound, its compaction is not saved), then, for each
figure, on how many of the sets of the start and the design (what the model of the figures is
first fitted on) that figure would still be known: a run stopped at 0.25 % knows its secant
only. The model needs `model_sets_min` sets of each figure (the number of --vary fields + 2).
(`python -m dem calibrate --stop-decided-runs` runs a calibration with that stop, its model
taking such figures and running on the stopped sets it lacks: docs/performance.md.)

    python bench/calibration_stop.py DIR        # DIR: a `python -m dem calibrate` --out folder
"""
import argparse
import csv
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from dem.calibrate import (SECANT_STRAIN, TOLERANCES, decided_in_run,  # noqa: E402
                           model_sets_min)


def read(folder):
    """(header, target figures, sets, runs) of a calibration folder: the checkpoint's header,
    the target's row of calibration.csv, its dem rows (dicts of strings) and every run of
    evaluations.jsonl. ValueError of one line when the folder is not a finished calibration."""
    ck, table = (os.path.join(folder, n) for n in ("evaluations.jsonl", "calibration.csv"))
    if not (os.path.isfile(ck) and os.path.isfile(table)):
        raise ValueError(f"DIR {folder}: allowed a finished `python -m dem calibrate` folder "
                         "(evaluations.jsonl and calibration.csv)")
    with open(ck) as f:
        lines = [json.loads(x) for x in f.read().splitlines() if x.strip()]
    with open(table, newline="") as f:
        rows = list(csv.DictReader(f))
    if not lines or "header" not in lines[0]:
        raise ValueError(f"DIR {folder}: allowed a finished `python -m dem calibrate` folder "
                         "(its evaluations.jsonl has no header)")
    target = next(r for r in rows if r["kind"] != "dem")
    return (lines[0]["header"], {k: float(target[k]) for k in TOLERANCES},
            [r for r in rows if r["kind"] == "dem"], lines[1:])


def replay(folder):
    """Per set of the folder (calibration.csv's order): its index, stage, the figures its full
    first run decided (``decided_by``), the in-run stop (``decided_in_run`` on that run's curve,
    or None), the test's strain it ran and would have run, its wall time, and the figures the
    set would still know. Returns (header, list of dicts)."""
    head, target, sets, runs = read(folder)
    head = {**head, "all_runs_wall": sum(r["wall_time"] for r in runs), "all_runs": len(runs)}
    first = head["seeds"][0]
    names = head["vary"]
    out = []
    for s in sets:
        values = [float(s[n]) for n in names]
        run = next(r for r in runs if r["params"]["seed"] == first
                   and [r["params"][n] for n in names] == values)
        c = run["curve"]
        e0, e1 = c["eps1"][0], c["eps1"][-1]
        stop = decided_in_run(c["eps1"], c["q"], target, len(head["seeds"]), head["n"],
                              head["smooth"])
        e_stop = e1 if stop is None else stop["eps1"]
        known = (list(TOLERANCES) if stop is None else
                 ["secant"] if e_stop >= SECANT_STRAIN else [])
        out.append({"index": int(s["index"]), "stage": s["stage"],
                    "decided_by": s.get("decided_by", ""), "stop": stop, "eps1_end": e1,
                    "eps1_stop": e_stop, "share_saved": (e1 - e_stop) / (e1 - e0),
                    "wall_time": run["wall_time"], "known": known,
                    "runs": int(s["runs"]) if s.get("runs") else len(head["seeds"])})
    return head, out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, allow_abbrev=False,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dir", metavar="DIR", help="a `python -m dem calibrate` --out folder")
    a = ap.parse_args(argv)
    try:
        head, sets = replay(a.dir)
    except (ValueError, OSError, KeyError, StopIteration) as e:
        msg = str(e) if isinstance(e, ValueError) else (
            f"DIR {a.dir}: allowed a finished `python -m dem calibrate` folder ({e!r} missing)")
        ap.error(msg)
    print(f"{a.dir}: {len(sets)} sets, n = {head['n']}, seeds {head['seeds']}, "
          f"{head['initial']} design sets; first runs replayed with the in-run stop")
    print(f"{'set':>4} {'stage':<8} {'runs':>4} {'decided (full run)':<28} {'stops at':>9} "
          f"{'on':<16} {'ran to':>7} {'saved':>6} {'~s saved':>8}")
    for s in sets:
        on = "-" if s["stop"] is None else "+".join(s["stop"]["figures"])
        print(f"{s['index']:>4} {s['stage']:<8} {s['runs']:>4} {s['decided_by'] or '-':<28} "
              f"{100 * s['eps1_stop']:>8.3f}% {on:<16} {100 * s['eps1_end']:>6.3f}% "
              f"{s['share_saved']:>6.1%} {s['wall_time'] * s['share_saved']:>8.0f}")
    wall = sum(s["wall_time"] for s in sets)
    saved = sum(s["wall_time"] * s["share_saved"] for s in sets)
    stopped = sum(s["stop"] is not None for s in sets)
    print(f"first runs: {stopped} of {len(sets)} would stop early; {saved:.0f} s of their "
          f"{wall:.0f} s ({saved / wall:.1%}; at most: the compaction is not saved), "
          f"{saved / head['all_runs_wall']:.1%} of all {head['all_runs']} runs' "
          f"{head['all_runs_wall']:.0f} s")
    first = [s for s in sets if s["index"] <= head["initial"]]
    need = model_sets_min(len(head["vary"]))
    for k in TOLERANCES:
        n = sum(k in s["known"] for s in first)
        print(f"  {k}: known on {n} of the {len(first)} sets of the start and the design "
              f"(the model needs {need}){'' if n >= need else ': TOO FEW'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
