"""Benchmark of the FE dynamics (fem.dynamics, ``python -m fem burst``): time steps per second of
the tied specimen held at a generalized force, beside the static steps of the same specimen,
measured in the same process; the peak memory.

    python bench/bench_fem_dynamics.py                      # 20 x 40 quads, n_dir 180, perfect
    python bench/bench_fem_dynamics.py --imperfection band  # a weak band: Newton does work
    python bench/bench_fem_dynamics.py --nx 10 --ny 20      # the CLI's default specimen

What runs: the drained path (LoadStepper, d_eps1 1e-4) to the start state f = 0.90, the tied
proportional path (R = -2, steps 1e-5) for ``--path-steps`` steps, then ``--steps`` time steps of
``fem.dynamics.hold`` from there at G + dG (dc = 1e-4 sigma2, 20 steps a period). Each phase is
timed per step and per Newton iteration, with the share of the constitutive update (the
material's ``trial`` calls, timed by a wrapper); no assertion: figures and ratios are printed.
The perfect specimen's static steps need no Newton iteration (the extrapolated homogeneous
predictor is its solution), so its static step is one material call; the band makes Newton
iterate on both sides. Kernels missing from Numba's cache are compiled first (not timed).
"""
from __future__ import annotations

import argparse
import math
import os
import resource
import sys
import time

os.environ["OPENBLAS_NUM_THREADS"] = "1"      # as bench_fem.py: SuperLU on ~10^3 dofs

import numpy as np  # noqa: E402

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from fem.__main__ import _fem_kernels, _warm_specimen            # noqa: E402
from fem.biaxial import BiaxialConfig, build_problem              # noqa: E402
from fem.burst import _averages                                   # noqa: E402
from fem.dynamics import Tie, TiedStatic, hold, lowest_mode, mass_matrix   # noqa: E402
from fem.reference import material_point_curve                    # noqa: E402
from fem.solver import LoadStepper                                # noqa: E402
from point.experiment import compile_kernels                     # noqa: E402
from point.burst_rule import check_columns                        # noqa: E402


class Timed:
    """Wraps the material's ``trial``: calls and seconds."""

    def __init__(self, f):
        self.f, self.calls, self.seconds = f, 0, 0.0

    def __call__(self, *a, **k):
        t0 = time.perf_counter()
        try:
            return self.f(*a, **k)
        finally:
            self.seconds += time.perf_counter() - t0
            self.calls += 1

    def reset(self):
        self.calls, self.seconds = 0, 0.0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], allow_abbrev=False)
    ap.add_argument("--nx", type=int, default=20)
    ap.add_argument("--ny", type=int, default=40)
    ap.add_argument("--n-dir", type=int, default=180)
    ap.add_argument("--imperfection", choices=["none", "band"], default="none")
    ap.add_argument("--steps", type=int, default=200, help="time steps timed")
    ap.add_argument("--path-steps", type=int, default=40, help="tied static steps timed")
    a = ap.parse_args(argv)
    compile_kernels(extra=_fem_kernels(indicators=False), warm=_warm_specimen)
    load0 = os.getloadavg()
    cfg = BiaxialConfig(nx=a.nx, ny=a.ny, n_dir=a.n_dir,
                        imperfection=None if a.imperfection == "none" else "band", imp_phi_g=15.0,
                        imp_size=0.08)
    prob = build_problem(cfg)
    timed = Timed(prob.material.trial)
    prob.material.trial = timed
    M = mass_matrix(prob)
    eta0 = 0.9 * material_point_curve(prob.params, 0.05)["eta_peak"]
    print(f"{a.nx} x {a.ny} quads, {prob.npts} points, n_dir {a.n_dir}, {prob.ndofs} dofs, "
          f"{a.imperfection}; load average {load0[0]:.2f}")

    # the drained path to the start state
    st = LoadStepper(prob, cfg.d_eps1)
    reached = []
    t0 = time.perf_counter()
    st.run(0.05, lambda res, info: reached.append(_averages(prob, res.trial.sigma, st.u)["eta"]
                                                  >= eta0), until=lambda: reached[-1])
    t_dr = time.perf_counter() - t0
    dr = (st.step, st.times["iterations"], t_dr, timed.calls, timed.seconds)
    timed.reset()

    # the tied static path
    tie = Tie(prob, -2.0)
    sp = LoadStepper(TiedStatic(tie, st.u), 1e-5, u0=st.u, du0=tie.a)
    t0 = time.perf_counter()
    sp.run(a.path_steps * 1e-5 * (1 - 1e-9))
    t_sp = time.perf_counter() - t0
    ps = (sp.step, sp.times["iterations"], t_sp, timed.calls, timed.seconds)
    timed.reset()

    # the dynamic steps from there
    el = prob.material.trial(np.zeros((2, 2, prob.npts)), elastic=True)
    t0 = time.perf_counter()
    omega, _ = lowest_mode(tie.reduce_matrix(prob.stiffness(el.D)), tie.reduce_matrix(M))
    t_eig = time.perf_counter() - t0
    timed.reset()
    t0 = time.perf_counter()
    r = hold(tie, M, sp.u, 1e-4 * cfg.sigma2 * prob.width, 2 * math.pi / omega, 20, 0.05,
             max_steps=a.steps)
    t_dy = time.perf_counter() - t0
    n_dy = int(r.history["step"][-1])
    it_dy = int(r.history["newton_iters"].sum())
    dy = (n_dy, it_dy, t_dy, timed.calls, timed.seconds)
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    load1 = os.getloadavg()

    print(f"{'phase':<28s} {'steps':>6s} {'iters':>6s} {'s':>7s} {'ms/step':>8s} {'steps/s':>8s} "
          f"{'ms/iter':>8s} {'update share':>12s}")
    for name, (n, it, t, calls, tu) in (("drained (static, d_eps1 1e-4)", dr),
                                        ("tied path (static, 1e-5)", ps),
                                        ("dynamics (Newmark, T1/20)", dy)):
        per_it = 1e3 * t / max(calls, 1)
        print(f"{name:<28s} {n:6d} {it:6d} {t:7.2f} {1e3 * t / n:8.2f} {n / t:8.1f} {per_it:8.2f} "
              f"{tu / t:12.2f}")
    print(f"lowest elastic mode (shift-invert ARPACK, {tie.size} unknowns): {t_eig:.3f} s, "
          f"T1 = {1e3 * 2 * math.pi / omega:.4f} ms")
    print(f"dynamic step / tied static step: {(t_dy / n_dy) / (t_sp / ps[0]):.2f} per step, "
          f"{(t_dy / max(dy[3], 1)) / (t_sp / max(ps[3], 1)):.2f} per material call "
          f"({dy[3] / n_dy:.2f} against {ps[3] / ps[0]:.2f} material calls a step)")
    print(f"dynamic step / drained static step: {(t_dy / n_dy) / (t_dr / dr[0]):.2f}; "
          f"outcome after {n_dy} steps: {r.outcome}; Newmark's balance (the Newton residual's "
          f"work) at most {r.history['newton_work'].max():.2e}, energy check "
          f"{check_columns(r.history)['energy_check']:.2e}")
    print(f"peak memory (max RSS) {rss:.0f} MB; load average {load1[0]:.2f} at the end")


if __name__ == "__main__":
    main()
