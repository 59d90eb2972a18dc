"""Benchmark of the H-model kernel and driver (issue #2). Prints figures, never asserts timings.

1. Hexagon updates per second of the Numba update kernel through update_full (stress +
   consistent tangent, the material contract; the kernel alone with its output buffers allocated
   once; and with the Lagrangian tangent and micro sums of the probes), one thread, on a batch
   of points in the isotropic state and at point A, against a plain NumPy version of the same
   update (stress only: it does less work) run in the same process.
2. Wall time of the default drained path: Table I, 360 orientations, d_eps1 = 1e-5 to eps1 = 5 %.
3. CPU time of the default bifurcation domain (``python -m hmodel domain``'s: Table I, 100, 200,
   400 kPa) in this process on one thread, by its route and by the general route it replaced
   (issue 19: full sweeps, the path step by step), interleaved, with the ratio and whether the
   results are the same bits; and the shares of the sign checks and, in them, of the update
   kernel with the extras.

Usage: python bench/bench_hmodel.py [--points 2000] [--repeat 5]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from hmodel import HParams, _kernels, broadcast_state, update_full
from hmodel.material import _material_args, kernel_args, to_voigt
from point.driver import drained_biaxial, isotropic_state, run_path


def numpy_update_stress(state, d_eps, params):
    """Plain NumPy version of the kernel's update for closed and staying-open hexagons (the
    closing branch is not needed for the benchmark increments); returns the Cauchy stress
    (2, 2, npts). Vectorized over points and orientations."""
    th = params.theta
    c, s = np.cos(th), np.sin(th)
    kn, kt, mu, two_r = params.kn, params.kt, params.mu, 2 * params.r_g
    e11, e22, e12 = d_eps[0, 0][:, None], d_eps[1, 1][:, None], d_eps[0, 1][:, None]
    en = c * c * e11 + s * s * e22 + 2 * c * s * e12
    et = s * s * e11 + c * c * e22 - 2 * c * s * e12
    dl1, dl2 = -state.l1 * en, -state.l2 * et
    d1, d2, a, N1, T1, N2 = state.d1, state.d2, state.alpha, state.N1, state.T1, state.N2
    ca, sa = np.cos(a), np.sin(a)
    A = np.empty(d1.shape + (3, 3))
    A[..., 0, 0], A[..., 0, 1], A[..., 0, 2] = 2 * ca, 1.0, -2 * d1 * sa
    A[..., 1, 0], A[..., 1, 1], A[..., 1, 2] = 2 * sa, 0.0, 2 * d1 * ca
    A[..., 2, 0], A[..., 2, 1], A[..., 2, 2] = ca, -1.0, (N1 * sa - T1 * ca - kt * d1 * sa) / kn
    b = np.stack([dl1, dl2, np.zeros_like(dl1)], axis=-1)
    x = np.linalg.solve(A, b[..., None])[..., 0]
    nN1 = N1 - kn * x[..., 0]
    Ttr = T1 + kt * d1 * x[..., 2]
    slide = np.abs(Ttr) >= mu * nN1
    xi = np.where(Ttr >= 0, 1.0, -1.0)
    A2 = A.copy()
    A2[..., 2, 0] = ca + xi * mu * sa
    A2[..., 2, 2] = (N1 * sa - T1 * ca) / kn
    b2 = b.copy()
    b2[..., 2] = sa * (xi * mu * N1 - T1) / kn
    x2 = np.linalg.solve(A2, b2[..., None])[..., 0]
    x = np.where(slide[..., None], x2, x)
    nN1 = N1 - kn * x[..., 0]
    nN2 = N2 - kn * x[..., 1]
    nT1 = np.where(slide, xi * mu * nN1, T1 + kt * d1 * x[..., 2])
    closed = ~state.is_open & (nN1 >= 0) & (nN2 >= 0)
    nN1, nN2, nT1 = (np.where(closed, v, 0.0) for v in (nN1, nN2, nT1))
    na = a + x[..., 2]
    nl1, nl2 = state.l1 + dl1, state.l2 + dl2
    f14 = np.where(nl1 < two_r, kn * (two_r - nl1), 0.0)
    f26 = np.where(nl2 < two_r, kn * (two_r - nl2), 0.0)
    S1 = (2 * nN2 + f14) * nl1
    S2 = (2 * (nN1 * np.sin(na) - nT1 * np.cos(na)) + 2 * f26) * nl2
    w = params.omega
    sig = np.empty((2, 2, d1.shape[0]))
    sig[0, 0] = (w * (S1 * c * c + S2 * s * s)).sum(-1)
    sig[1, 1] = (w * (S1 * s * s + S2 * c * c)).sum(-1)
    sig[0, 1] = sig[1, 0] = (w * (S1 - S2) * c * s).sum(-1)
    eps = state.eps + d_eps
    V = state.V0 * ((1 - eps[0, 0]) * (1 - eps[1, 1]) - eps[0, 1] * eps[1, 0])
    return sig / V


def best_of(f, repeat, clock=time.process_time):
    """Best time of ``repeat`` calls. Default: CPU time of the process, less sensitive to other
    processes on a shared machine than wall time (for single-threaded code); thread scaling
    needs wall time (``clock=time.perf_counter``)."""
    ts = []
    for _ in range(repeat):
        t = clock()
        f()
        ts.append(clock() - t)
    return min(ts)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
                                 allow_abbrev=False)
    ap.add_argument("--points", type=int, default=2000, help="material points in the kernel batch")
    ap.add_argument("--repeat", type=int, default=5, help="repetitions (best time is kept)")
    args = ap.parse_args(argv)

    P = HParams(n_dir=360)
    s0 = isotropic_state(P)
    rA = run_path(s0, P, drained_biaxial(1e-5), 5000,
                  until=lambda e, s: (s[0] - s[1]) >= 1.029 * 0.5 * (s[0] + s[1]))
    npts = args.points
    rng = np.random.default_rng(0)
    ang = rng.uniform(0, 2 * np.pi, npts)
    de = np.zeros((2, 2, npts))
    de[0, 0], de[1, 1] = 1e-6 * np.cos(ang), 1e-6 * np.sin(ang)
    hex_updates = npts * P.n_dir
    for label, state in (("isotropic state (all hexagons closed)", s0),
                         ("point A, eta = 1.029 (many hexagons open or sliding)", rA.state)):
        st = broadcast_state(state, (npts,))
        n_open = int(state.is_open.sum())
        update_full(st, de, P, parallel=False)                 # compile / load cache
        t_kernel = best_of(lambda: update_full(st, de, P, parallel=False, extras=False), args.repeat)
        # the kernel alone, output buffers allocated once: update_full also pays for the first
        # touch (page faults) of the ~60 MB of new state it returns at every call
        kargs, out = kernel_args(st, P)[:-1], _kernels.allocate_outputs(npts, P.n_dir)
        kcall = lambda: _kernels.update_serial(*kargs, to_voigt(de), *_material_args(P), True, False, *out)
        kcall()
        t_alone = best_of(kcall, args.repeat)
        t_extra = best_of(lambda: update_full(st, de, P, parallel=False), args.repeat)
        t_numpy = best_of(lambda: numpy_update_stress(st, de, P), max(1, args.repeat // 2))
        ref = update_full(st, de, P, parallel=False).stress
        diff = np.max(np.abs(numpy_update_stress(st, de, P) - ref)) / np.max(np.abs(ref))
        update_full(st, de, P, parallel=True, extras=False)
        wall = time.perf_counter
        t_par = best_of(lambda: update_full(st, de, P, parallel=True, extras=False), args.repeat, wall)
        t_ser_wall = best_of(lambda: update_full(st, de, P, parallel=False, extras=False), args.repeat, wall)
        print(f"\n{label}: {npts} points x {P.n_dir} orientations, {n_open} open")
        print(f"  NumPy baseline (stress only):      {hex_updates / t_numpy:12.4g} hexagon updates/s")
        print(f"  Numba kernel, 1 thread (+tangent): {hex_updates / t_kernel:12.4g} hexagon updates/s"
              f"   speed-up x{t_numpy / t_kernel:.1f}")
        print(f"    kernel alone, outputs allocated once: {hex_updates / t_alone:.4g} hexagon updates/s")
        print(f"    with Lagrangian tangent, T3, micro W2 (probes): {hex_updates / t_extra:.4g} hexagon updates/s")
        print(f"  Numba kernel, all threads (wall):  {hex_updates / t_par:12.4g} hexagon updates/s"
              f"   x{t_ser_wall / t_par:.2f} over 1 thread (wall)")
        print(f"  max relative stress difference NumPy vs kernel: {diff:.2e}")

    print()
    run_path(s0, P, drained_biaxial(1e-5), 10)
    t_path = best_of(lambda: run_path(s0, P, drained_biaxial(1e-5), 5000), max(1, args.repeat // 2))
    rr = run_path(s0, P, drained_biaxial(1e-5), 5000)
    n_upd = int(np.sum(rr.newton_iters)) + len(rr.newton_iters) - 1
    print(f"drained path, Table I, 360 orientations, 5000 steps of 1e-5: {t_path:.3f} s"
          f" ({n_upd} updates at least, {n_upd * P.n_dir / t_path:.3g} hexagon updates/s incl. driver)")

    # the default domain by its route (lean probes, the sign check that stops refining once both
    # signs are known, the Numba path with states kept only where a criterion fired) and by the
    # general route it replaced (every check a full directional_sweep, every block of the path
    # step by step with its states), interleaved in this process; one Numba thread, the CPU
    # time of the process; and where the time goes (both looked up at call time, so wrapped)
    import point.experiment as ex
    from point.probes import directional_sweep

    def general_signs(st, p, n):
        sw = directional_sweep(st, p, n=n)
        return bool(np.nanmin(sw.w2) <= 0.0), bool(np.nanmin(sw.w2_sigma) <= 0.0)

    def general_path(*a, **k):
        k["keep_states"] = True
        return run_path(*a, **k)

    spent = {"checks": 0.0, "kernel with the extras": 0.0}

    def timed(f, key, when=lambda *a: True):
        def g(*a, **k):
            t = time.process_time()
            try:
                return f(*a, **k)
            finally:
                if when(*a):
                    spent[key] += time.process_time() - t
        return g

    import numba
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    T = HParams()
    pressures = [100e3, 200e3, 400e3]
    route = ex.w2_vanishes, ex.run_path
    general = general_signs, general_path
    ex.bifurcation_domain(T, [200e3], workers=1)
    n_dom = max(1, args.repeat // 2)
    times = {"route": [], "general": []}
    points = {}
    try:
        for _ in range(n_dom):
            for name, (signs, path) in (("general", general), ("route", route)):
                ex.w2_vanishes, ex.run_path = signs, path
                t = time.process_time()
                points[name] = ex.bifurcation_domain(T, pressures, workers=1)
                times[name].append(time.process_time() - t)
        saved = ex.w2_vanishes, _kernels.update_serial, _kernels.update_parallel
        ex.w2_vanishes, ex.run_path = route
        ex.w2_vanishes = timed(saved[0], "checks")
        _kernels.update_serial, _kernels.update_parallel = (
            timed(k, "kernel with the extras", when=lambda *a: a[22]) for k in saved[1:])
        try:
            t = time.process_time()
            ex.bifurcation_domain(T, pressures, workers=1)
            t_one = time.process_time() - t
        finally:
            ex.w2_vanishes, _kernels.update_serial, _kernels.update_parallel = saved
    finally:
        ex.w2_vanishes, ex.run_path = route
        numba.set_num_threads(threads)
    same = [tuple(a) for a in points["route"]] == [tuple(b) for b in points["general"]]
    t_r, t_g = min(times["route"]), min(times["general"])
    print(f"bifurcation domain, Table I, 100, 200, 400 kPa, one process, one thread (CPU, best of "
          f"{n_dom}, interleaved): {t_r:.2f} s; the general route {t_g:.2f} s: x{t_g / t_r:.2f}; "
          f"the same DomainPoints to the bit: {same}")
    print(f"  one more run by the route, {t_one:.2f} s: the sign checks {spent['checks']:.2f} s and, "
          f"within them, the update kernel with the extras {spent['kernel with the extras']:.2f} s")

if __name__ == "__main__":
    main()
