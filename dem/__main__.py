"""Command line: python -m dem {biaxial, probes, bench} ... (thin layer over the library)."""
from __future__ import annotations

import argparse
import os
import sys
import time


def _params(a):
    from .params import DemParams
    return DemParams(n=a.n, seed=a.seed, damping=a.damping, dt_safety=a.dt_safety,
                     friction_deg=a.friction)


def _threads(a):
    if getattr(a, "threads", None):
        import numba
        numba.set_num_threads(min(a.threads, numba.config.NUMBA_NUM_THREADS))


def cmd_biaxial(a):
    from .experiment import run_biaxial
    _threads(a)
    t0 = time.time()
    res = run_biaxial(_params(a), a.out, rate=a.rate, confining=a.confining, eta_a=a.eta_a,
                      eps_max=a.eps_max, compaction_friction_deg=a.compaction_friction,
                      resume=a.resume, vtk=not a.no_vtk)
    print(f"biaxial: {len(res.rows)} rows -> {os.path.join(a.out, 'biaxial.csv')}; "
          f"stateA={res.state_a_path} (eta_a reached: {res.eta_a_reached}); "
          f"porosity after compaction={res.compaction.get('porosity')}; "
          f"wall time {time.time() - t0:.1f} s")


def cmd_probes(a):
    from . import io
    from .probes import (COLUMNS, ProbeOptions, directions, plot_probes, prepare_reference,
                         run_probes)
    opts = ProbeOptions(norm=a.norm, ramp_steps=a.ramp_steps, unbalanced_tol=a.unbalanced_tol,
                        stress_tol=a.stress_tol, max_steps=a.max_steps,
                        relax_max_steps=a.relax_max_steps,
                        plastic_tol=a.plastic_tol).validate()
    t0 = time.time()
    state, meta = io.load_state(a.state)
    if a.damping is not None:
        state = state._replace(params=state.params.replace(damping=a.damping))
    os.makedirs(a.out, exist_ok=True)
    ck = os.path.join(a.out, "probe_runs.jsonl")
    ref_path = os.path.join(a.out, "stateR.npz")
    if not a.resume and os.path.exists(ck):
        os.remove(ck)
    if a.no_relax:
        pass
    elif a.resume and os.path.exists(ref_path):
        state, meta = io.load_state(ref_path)
        print(f"[probes] resumed: reference state {ref_path} ({meta})", file=sys.stderr)
    else:
        state, ok, steps, ub = prepare_reference(state, opts, verbose=True)
        print(f"[probes] reference relaxed at the A stresses: converged={ok} steps={steps} "
              f"unbalanced={ub:.2e}", file=sys.stderr)
        io.save_state(ref_path, state, meta={"converged": ok, "steps": steps, "unbalanced": ub})
    alphas = directions(a.step_q3, a.step_other)
    rows = run_probes(state, alphas, opts, workers=a.workers, scheduler=a.scheduler,
                      checkpoint=ck)
    io.write_csv(os.path.join(a.out, "probes.csv"), COLUMNS,
                 [[r[c] if not isinstance(r[c], bool) else int(r[c]) for c in COLUMNS]
                  for r in rows])
    plot_probes(rows, a.out)
    nc = sum(1 for r in rows if not (r["converged"] and r["converged_elastic"]))
    print(f"probes: {len(rows)} directions -> {os.path.join(a.out, 'probes.csv')}; "
          f"{nc} hit the iteration cap; wall time {time.time() - t0:.1f} s")


def cmd_bench(a):
    from .bench import bench
    res = bench(n=a.n, steps=a.steps, seed=a.seed, cache_dir=a.cache)
    for k, v in res.items():
        print(f"{k}: {v}")
    print(f"particle-steps/s: {res['particle_steps_per_s_all_threads']:.4g}")


def cmd_crosscheck(a):
    from .crosscheck import run_crosscheck
    t0 = time.time()
    c, timings = run_crosscheck(a.out, full=a.full, n=a.n, seed=a.seed, rate=a.rate,
                                workers=a.workers, skip_dem=a.skip_dem, domain=not a.no_domain,
                                dem_max_steps=a.max_steps, threads=a.threads, resume=a.resume)
    print(open(os.path.join(a.out, "report.md")).read().split("## The paper's conclusions")[1])
    print(f"crosscheck: report {os.path.join(a.out, 'report.md')}; wall time {time.time() - t0:.1f} s")


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m dem", description=__doc__)
    sub = ap.add_subparsers(dest="cmd", required=True)

    b = sub.add_parser("biaxial", help="compact and run the drained biaxial test")
    b.add_argument("--n", type=int, default=12000)
    b.add_argument("--seed", type=int, default=1)
    b.add_argument("--out", required=True)
    b.add_argument("--rate", type=float, default=0.01, help="axial strain rate [1/s]")
    b.add_argument("--confining", type=float, default=200e3, help="[Pa]")
    b.add_argument("--eta-a", type=float, default=1.029)
    b.add_argument("--eps-max", type=float, default=0.10)
    b.add_argument("--damping", type=float, default=0.15)
    b.add_argument("--dt-safety", type=float, default=0.2)
    b.add_argument("--friction", type=float, default=35.0, help="[deg]")
    b.add_argument("--compaction-friction", type=float, default=0.0, help="[deg]")
    b.add_argument("--resume", action="store_true", help="continue from DIR/checkpoint.npz")
    b.add_argument("--no-vtk", action="store_true")
    b.add_argument("--threads", type=int, default=None,
                   help="numba threads (results do not depend on it; default: all)")
    b.set_defaults(func=cmd_biaxial)

    p = sub.add_parser("probes", help="directional analysis from a saved state")
    p.add_argument("--state", required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--norm", type=float, default=2500.0, help="|dsigma| [Pa]")
    p.add_argument("--step-q3", type=float, default=5.0, help="[deg] in the third quadrant")
    p.add_argument("--step-other", type=float, default=10.0, help="[deg] elsewhere")
    p.add_argument("--ramp-steps", type=int, default=5000)
    p.add_argument("--unbalanced-tol", type=float, default=1e-4)
    p.add_argument("--stress-tol", type=float, default=25.0, help="[Pa]")
    p.add_argument("--max-steps", type=int, default=400_000)
    p.add_argument("--plastic-tol", type=float, default=0.05)
    p.add_argument("--relax-max-steps", type=int, default=2_000_000,
                   help="cap of the relaxation of the state into the reference [steps]")
    p.add_argument("--no-relax", action="store_true",
                   help="probe from the saved state as is (no stress-controlled relaxation)")
    p.add_argument("--damping", type=float, default=None,
                   help="override the Cundall damping of the state (sensitivity check)")
    p.add_argument("--workers", type=int, default=None, help="local processes")
    p.add_argument("--scheduler", default=None, help="dask.distributed scheduler address")
    p.add_argument("--resume", action="store_true",
                   help="keep the runs already in DIR/probe_runs.jsonl (and DIR/stateR.npz) "
                        "and run only the missing ones")
    p.set_defaults(func=cmd_probes)

    c = sub.add_parser("bench", help="particle-steps/s on a dense confined sample")
    c.add_argument("--n", type=int, default=12000)
    c.add_argument("--steps", type=int, default=2000)
    c.add_argument("--seed", type=int, default=1)
    c.add_argument("--cache", default=os.path.join(os.path.expanduser("~"), ".cache", "dem"))
    c.set_defaults(func=cmd_bench)

    x = sub.add_parser("crosscheck", help="H-model, FE and DEM side by side (report.md + figures)")
    x.add_argument("--out", required=True)
    x.add_argument("--full", action="store_true", help="the paper's 12,000 disks at 0.01/s (about 1.5 h)")
    x.add_argument("--n", type=int, default=None, help="DEM disks (default 1000, 12000 with --full)")
    x.add_argument("--seed", type=int, default=1)
    x.add_argument("--rate", type=float, default=None, help="DEM axial strain rate [1/s] (0.05, 0.01 with --full)")
    x.add_argument("--max-steps", type=int, default=None, help="cap of each DEM probe run [steps]")
    x.add_argument("--workers", type=int, default=None, help="local processes for the probes")
    x.add_argument("--skip-dem", action="store_true", help="H-model and FE only")
    x.add_argument("--no-domain", action="store_true", help="skip the H-model bifurcation domain")
    x.add_argument("--threads", type=int, default=None,
                   help="numba threads of the DEM compaction and biaxial test (default: all)")
    x.add_argument("--resume", action="store_true",
                   help="keep the DEM work an interrupted run left in DIR/dem and do the rest")
    x.set_defaults(func=cmd_crosscheck)

    a = ap.parse_args(argv)
    try:
        a.func(a)
    except ValueError as e:
        ap.exit(2, f"error: {e}\n")


if __name__ == "__main__":
    main()
