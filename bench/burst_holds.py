"""The below and past holds of a `dem burst` folder rerun with other walls' masses and with the
servo (issue 24: the outcome and the c held must not depend on a factor 4 of the wall mass; the
dead load against the servo).

    python bench/burst_holds.py DIR [--factors 0.25,1,4] [--no-servo] [--workers N]

DIR is the output folder of `python -m dem burst` (its rest/ holds the states the switches
started from, burst.csv their targets). For every switch and variant: the outcome, the steps,
the c held at the end (equilibrium) or the largest backbone kinetic energy over the switch's
(failure), the strain since the switch, W2_int at the end; one CSV (DIR/holds_variants.csv) and
lines on stdout.
"""
from __future__ import annotations

import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from dem import io                                              # noqa: E402
from dem.burst import BurstOptions, H, hold, ke_growth, wall_mass_rule  # noqa: E402
from dem.simulation import Simulation                            # noqa: E402

COLUMNS = ["switch", "variant", "wall_mass", "outcome", "steps", "c_target", "c_end", "de1_end",
           "ke_growth", "w2_int_end", "eq1_bookkeeping", "wall_time"]


def _task(args):
    st, ratio, target, opts, name, sw = args
    t0 = time.time()
    r = hold(st, ratio, target, opts, threads=1)
    h = r.history
    return [sw, name, r.wall_mass, r.outcome, r.steps, target, h[-1, 4], h[-1, 2] - h[0, 2],
            ke_growth(h[:, 8]), h[-1, H["w2_int"]], float(h[:, H["eq1_bookkeeping"]].max()),
            time.time() - t0]


def main(argv=None):
    from common import options as opt
    ap = opt.Parser(prog="python bench/burst_holds.py", description=__doc__.split("\n\n")[0])
    ap.add_argument("dir", help="a dem burst output folder")
    ap.add_argument("--factors", type=opt.reals(0), default=[0.25, 1.0, 4.0],
                    help="multiples of the wall-mass rule's mass")
    ap.add_argument("--no-servo", action="store_true", help="skip the servo hold")
    ap.add_argument("--workers", type=opt.integer(1, 64), default=2)
    a = ap.parse_args(argv)
    _, rows = io.read_csv(os.path.join(a.dir, "burst.csv"))
    import json
    with open(os.path.join(a.dir, "summary.json")) as f:
        summ = json.load(f)
    base = BurstOptions(**{k: v for k, v in summ["options"].items()
                           if k in BurstOptions._fields})
    tasks = []
    for row in rows:
        sw, ratio = row["switch"], row["ratio"]
        path = os.path.join(a.dir, "rest", f"R{ratio:g}_f{row['start_fraction']:g}_{sw}.npz")
        st, _ = io.load_state(path)
        m0 = wall_mass_rule(Simulation(st), ratio, base.wall_period_steps)
        for fct in a.factors:
            tasks.append((st, ratio, row["c_target"], base._replace(
                hold="dead_load", wall_mass=m0 * fct), f"dead load, m_G x {fct:g}", sw))
        if not a.no_servo:
            tasks.append((st, ratio, row["c_target"], base._replace(hold="servo"), "servo", sw))
    from concurrent.futures import ProcessPoolExecutor
    import multiprocessing
    out = []
    with ProcessPoolExecutor(a.workers, mp_context=multiprocessing.get_context("spawn")) as ex:
        for res in ex.map(_task, tasks):
            out.append(res)
            print(", ".join(f"{k}={v:.6g}" if isinstance(v, float) else f"{k}={v}"
                            for k, v in zip(COLUMNS, res)), flush=True)
    io.write_csv(os.path.join(a.dir, "holds_variants.csv"), COLUMNS, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
