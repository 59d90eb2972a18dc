"""The paper's experiments on a material point of any law: drained biaxial test, directional
analysis at point A, bifurcation domain (sections 3.3-3.4, Figs. 3-11). Functions here are what
the command lines and the tests call; they return arrays and write nothing (the command lines
write the files and figures)."""
from __future__ import annotations

import multiprocessing
import os
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import NamedTuple

import numpy as np

from .contract import material_named, material_of
from .driver import PathResult, drained_biaxial, isotropic_state, run_path
from .probes import (DEFAULT_PROBE_NORM, ProbeResult, StressProbeResult, directional_sweep,
                     stress_probes, tangent_criteria, w2_vanishes)

__all__ = ["biaxial_test", "state_at_eta", "directional_analysis", "DirectionalAnalysis",
           "biaxial_columns", "probe_columns", "DomainPoint", "DOMAIN_COLUMNS",
           "domain_point", "bifurcation_domain", "compile_kernels", "DOMAIN_EPS1_MAX",
           "OPTIONAL_OUTPUTS", "absent_outputs", "present"]

# the axial strain where the searches for point A and for the domain boundaries give up [-]
DOMAIN_EPS1_MAX = 0.2


def compile_kernels(extra=(), warm=None, stream=None, material=None) -> float:
    """The first run after an install compiles the Numba kernels of a law (the H-model's: a
    minute or more): if they are not in Numba's cache, say so once (options.COMPILE_NOTICE:
    "compiling kernels, once: one to two minutes"), compile them on a tiny case
    (``Material.warm_up``) and say how long it took, so that the timings a command reports
    leave it out. ``material``: the law (default the H-model); a law without kernels compiles
    nothing. ``extra``: more Numba functions to check, ``warm()``: compiles them. Returns the
    compilation time [s] (0.0 when everything was cached)."""
    import sys

    from common.options import announce_compilation
    law = material_named("hmodel") if material is None else material
    stream = sys.stderr if stream is None else stream
    kernels = tuple(getattr(law, "kernels", lambda: ())()) + tuple(extra)
    if not kernels or not announce_compilation(kernels, stream):
        return 0.0
    t0 = time.perf_counter()
    if hasattr(law, "warm_up"):
        law.warm_up()
    if warm is not None:
        warm()
    dt = time.perf_counter() - t0
    print(f"compiled in {dt:.1f} s (cached now; not counted in the timings below)", file=stream,
          flush=True)
    return dt


def _check_sigma2(sigma2):
    if not (np.isfinite(sigma2) and sigma2 > 0):
        raise ValueError(f"sigma2 must be a confining stress > 0 [Pa], got {sigma2!r}")


def biaxial_test(params, sigma2: float | None = None, d_eps1: float = 1e-5,
                 eps1_max: float = 0.05, progress: bool = False,
                 keep_states: bool = False) -> PathResult:
    """Drained biaxial test from the isotropic state at ``sigma2`` [Pa] (default params.p0):
    axial strain steps ``d_eps1`` up to ``eps1_max``, lateral stress held (Figs. 4-5);
    ``keep_states``: every state of the path kept (``run_path``)."""
    sigma2 = params.p0 if sigma2 is None else float(sigma2)
    _check_sigma2(sigma2)
    if not (np.isfinite(eps1_max) and eps1_max > 0):
        raise ValueError(f"eps1_max must be > 0, got {eps1_max!r}")
    if not (np.isfinite(d_eps1) and 0 < d_eps1 <= eps1_max):
        raise ValueError(f"d_eps1 must be in (0, eps1_max = {eps1_max}], got {d_eps1!r}")
    p = params.replace(p0=sigma2)
    n = int(round(eps1_max / d_eps1))
    try:
        s0 = isotropic_state(p)
    except BaseException as e:
        e.partial = None          # the compression's rows are not the test's (interrupted there)
        raise
    return run_path(s0, p, drained_biaxial(d_eps1), n, progress=progress, label="drained biaxial",
                    keep_states=keep_states)


def state_at_eta(params, eta: float, sigma2: float | None = None, d_eps1: float = 1e-5,
                 eps1_max: float = DOMAIN_EPS1_MAX) -> tuple:
    """Run the drained path to the first state with eta >= ``eta`` (point A for eta = 1.029).
    Raises ValueError if the path peaks below ``eta``."""
    sigma2 = params.p0 if sigma2 is None else float(sigma2)
    _check_sigma2(sigma2)
    if not (np.isfinite(eta) and 0 < eta < 2):
        # nan never stops the path, eta <= 0 stops it at its first step: both silently wrong
        raise ValueError(f"eta = {eta!r} is out of range: allowed 0 < eta < 2 (q/p < 2 while sigma2 > 0)")
    p = params.replace(p0=sigma2)
    n = int(round(eps1_max / d_eps1))
    r = run_path(isotropic_state(p), p, drained_biaxial(d_eps1), n,
                 until=lambda e, s: (s[0] - s[1]) >= eta * 0.5 * (s[0] + s[1]))
    _, _, e = r.invariants()
    if e[-1] < eta:
        why = "" if r.end.outcome == "complete" else f"; the path ends {r.end.line()}"
        raise ValueError(f"eta = {eta} is never reached on the drained path (max eta {e.max():.4f}{why})")
    return r, r.state


class DirectionalAnalysis(NamedTuple):
    """The directional analysis at point A (``directional_analysis``)."""
    path: PathResult              # the drained path to A (its last state is A)
    sweep: ProbeResult            # the adaptive strain-probe sweep at A
    targets: np.ndarray           # the stress probes' directions alpha_sigma [deg]
    stress: StressProbeResult     # the stress probes in those directions
    tangent: dict                 # ``probes.tangent_criteria`` at A


def directional_analysis(params, eta_a: float, d_eps1: float = 1e-5, n_probes: int = 360,
                         strain_norm: float = DEFAULT_PROBE_NORM, stress_step: float = 5.0,
                         stress_norm: float | None = 2.5e3, progress=None) -> DirectionalAnalysis:
    """The directional analysis at point A (Figs. 3, 6-9, 11) of the material ``params`` at its
    confining stress p0: the drained path to the first state with eta >= ``eta_a``, there an
    adaptive sweep of ``n_probes`` strain probes of norm ``strain_norm``, stress probes every
    ``stress_step`` [deg] scaled to ``stress_norm`` [Pa], and the tangent's criteria.
    ``progress``: None or a callable taking one line of text before each stage."""
    say = progress or (lambda m: None)
    r, s_a = state_at_eta(params, eta_a, params.p0, d_eps1)
    say(f"strain probes at A: {n_probes} directions, refined where the response jumps")
    sw = directional_sweep(s_a, params, n=n_probes, norm=strain_norm)
    say(f"stress probes every {stress_step:g} deg ({len(sw.alpha_eps)} strain probes done)")
    targets = np.arange(0.0, 360.0, stress_step)
    sp = stress_probes(s_a, params, targets, sigma_norm=stress_norm, sweep=sw)
    return DirectionalAnalysis(r, sw, targets, sp, tangent_criteria(s_a, params))


def biaxial_columns(r: PathResult) -> dict:
    """CSV columns of a path: eps1, eps2, eps_v, s1, s2, p, q, eta (SI, compression positive)."""
    p, q, eta = r.invariants()
    return {"eps1": r.eps[:, 0], "eps2": r.eps[:, 1], "eps_v": r.eps[:, 0] + r.eps[:, 1],
            "s1": r.sigma[:, 0], "s2": r.sigma[:, 1], "p": p, "q": q, "eta": eta,
            "s12": r.sigma[:, 2], "n_sliding": r.n_sliding, "n_open": r.n_open,
            "newton_iters": r.newton_iters}


# the outputs a law provides only with an optional kind of ``Material.provides``: columns of
# biaxial.csv and probes.csv, keys of the probes' summary, figures. A law without the kind leaves
# them out (the CSV columns too: ``present``) and names them in its summaries ("absent").
OPTIONAL_OUTPUTS = {
    "lagrangian": ("w2_V", "w2_g", "dPi1", "dPi2", "T2_1", "T2_2", "T3_1", "T3_2",
                   "det_M_lagrangian", "det_Msym_lagrangian", "lam_min_Msym_lagrangian",
                   "fig9_w2_split.png"),
    "micro": ("w2_micro", "w2n", "w2t", "min_w2n", "max_w2t_in_cone", "max_abs_w2_minus_micro",
              "fig11_w2_normal_tangential.png"),
    "patterns": ("n_sliding", "n_open"),
}


def absent_outputs(law) -> frozenset:
    """The names of ``OPTIONAL_OUTPUTS`` that ``law`` does not provide."""
    return frozenset(n for kind, names in OPTIONAL_OUTPUTS.items() if kind not in law.provides
                     for n in names)


def present(cols: dict, law) -> dict:
    """The columns of ``cols`` that ``law`` provides (``absent_outputs`` left out)."""
    gone = absent_outputs(law)
    return {k: v for k, v in cols.items() if k not in gone}


def probe_columns(pr: ProbeResult) -> dict:
    """CSV columns of a directional analysis (angles in degrees, W2 normalized)."""
    return {"alpha_eps": pr.alpha_eps, "alpha_sigma": pr.alpha_sigma, "w2": pr.w2,
            "w2_sigma": pr.w2_sigma, "w2_V": pr.w2_V, "w2_g": pr.w2_g, "w2_micro": pr.w2_micro,
            "w2n": pr.w2n, "w2t": pr.w2t, "plastic": pr.plastic,
            "d_eps1": pr.d_eps[:, 0], "d_eps2": pr.d_eps[:, 1],
            "d_sigma1": pr.d_sigma[:, 0], "d_sigma2": pr.d_sigma[:, 1],
            "dPi1": pr.dPi[:, 0], "dPi2": pr.dPi[:, 1],
            "T2_1": pr.T2[:, 0], "T2_2": pr.T2[:, 1], "T3_1": pr.T3[:, 0], "T3_2": pr.T3[:, 1],
            "n_sliding": pr.n_sliding, "n_open": pr.n_open}


class DomainPoint(NamedTuple):
    """Bifurcation domain at one confining pressure (Fig. 10): (p, q) [Pa] of the first state of
    the drained path with W2 <= 0 in some direction, the same for W2_sigma, and the peak.
    NaN where the criterion never fires before the peak (or before the path ends). ``outcome``:
    'complete', or how the drained path ended before the domain was found (``PathResult.end``:
    'uncontrollable', 'discontinuous'), ``end`` its line, (p_end, q_end) [Pa] its last state."""

    sigma2: float
    p_w2: float
    q_w2: float
    p_w2sigma: float
    q_w2sigma: float
    p_peak: float
    q_peak: float
    eps1_w2: float
    eps1_w2sigma: float
    eps1_peak: float
    outcome: str = "complete"
    end: str = ""
    p_end: float = np.nan
    q_end: float = np.nan


# the columns of domain.csv (``outcome`` and ``end`` say how each drained path ended: summary.json)
DOMAIN_COLUMNS = DomainPoint._fields[:10]


def domain_point(params, sigma2: float, d_eps1: float = 1e-5, check_every: int = 25,
                 n_dir_probe: int = 180, eps1_max: float = DOMAIN_EPS1_MAX) -> DomainPoint:
    """Scan the drained path at ``sigma2`` [Pa]: every ``check_every`` steps the minimum over
    directions of W2 and W2_sigma (adaptive strain-probe sweep); once one is <= 0 the states of
    the last ``check_every`` steps are bisected to find the first state where it is."""
    _check_sigma2(sigma2)
    p = params.replace(p0=float(sigma2))
    ctl = drained_biaxial(d_eps1)
    state = isotropic_state(p)
    found = {"w2": None, "w2_sigma": None}
    eps1 = 0.0
    q_prev = -np.inf
    peak = None
    n_max = int(round(eps1_max / d_eps1))
    steps = 0

    def fires(st):
        w2, w2_sigma = w2_vanishes(st, p, n=n_dir_probe)
        return {"w2": w2, "w2_sigma": w2_sigma}

    def first_firing(states, f_end, keys):
        """Row of ``states`` (1..m) of the first state where each of ``keys`` fires, knowing that
        it fires at row m (``f_end``) and not at row 0 (the previous check). Bisection, which
        finds the first row if a criterion that fires keeps firing within the block (the cone
        widens as eta grows towards the peak; tests/hmodel/test_bad_input.py checks it against a
        sweep at every step); one sweep per tried row serves both criteria."""
        seen = {len(states) - 1: f_end}
        out = {}
        for key in keys:
            lo, hi = 0, len(states) - 1
            while hi - lo > 1:
                mid = (lo + hi) // 2
                if mid not in seen:
                    seen[mid] = fires(states[mid])
                lo, hi = (lo, mid) if seen[mid][key] else (mid, hi)
            out[key] = hi
        return out

    ended = None
    while steps < n_max and (peak is None or any(v is None for v in found.values())):
        r = run_path(state, p, ctl, check_every)
        if r.end.outcome != "complete":
            ended = r.end          # no static state beyond this block's last row
        pp, qq, _ = r.invariants()
        # the peak: first row where q stops increasing
        for j in range(1, len(qq)):
            if peak is None and qq[j] < q_prev:
                peak = (pp[j - 1], qq[j - 1], eps1 + r.eps[j - 1, 0])
            q_prev = qq[j]
        if any(v is None for v in found.values()):
            f_end = fires(r.state)
            keys = [key for key in found if found[key] is None and f_end[key]]
            # the block's states only where a criterion fired in it: run again keeping them (the
            # Numba loop and the step-by-step loop give the same bits: tests/hmodel/test_domain_route.py)
            if keys:
                states = run_path(state, p, ctl, check_every, keep_states=True).states
                for key, j in first_firing(states, f_end, keys).items():
                    found[key] = (pp[j], qq[j], eps1 + r.eps[j, 0])
        eps1 += r.eps[-1, 0]
        steps += check_every
        state = r.state
        if ended is not None or (peak is not None and all(v is not None for v in found.values())):
            break
    nan3 = (np.nan, np.nan, np.nan)
    w, ws, pk = found["w2"] or nan3, found["w2_sigma"] or nan3, peak or nan3
    end = (("complete", "") if ended is None else
           (ended.outcome, ended.line(), 0.5 * (ended.sigma[0] + ended.sigma[1]),
            ended.sigma[0] - ended.sigma[1]))
    # a criterion that fires only after the peak is outside the pre-peak domain: keep it anyway
    return DomainPoint(float(sigma2), w[0], w[1], ws[0], ws[1], pk[0], pk[1], w[2], ws[2], pk[2],
                       *end)


def _domain_job(args):
    params, s2, kw = args
    return domain_point(params, s2, **kw)


def _domain_worker_init():
    """A worker process of ``bifurcation_domain``: one Numba thread (the processes are the
    parallelism: a parallel kernel in each of them oversubscribes the cores; the default domain
    took 28 s instead of 8 s on 2 cores beside another job), and Ctrl-C left to the parent,
    which stops the workers itself."""
    import signal

    import numba
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    numba.set_num_threads(1)


def bifurcation_domain(params, sigma2_list, workers: int | None = None,
                       progress=None, **kw) -> list[DomainPoint]:
    """``domain_point`` for every confining pressure, in parallel processes (``workers`` >= 1,
    default min(len, cpu count); 1 runs in this process). Results in the input order.
    ``progress``: None or a callable taking one line of text, called as each pressure is done.
    Interrupted (or failed), the exception carries the pressures finished as ``.partial``."""
    sig = [float(s) for s in sigma2_list]
    for s in sig:
        _check_sigma2(s)
    if workers is not None and not (float(workers) == int(workers) and int(workers) >= 1):
        raise ValueError(f"workers = {workers!r} is out of range: allowed an integer >= 1 (or None)")
    workers = min(len(sig), os.cpu_count() or 1) if workers is None else int(workers)
    jobs = [(params, s, kw) for s in sig]
    t0 = time.perf_counter()
    out = [None] * len(jobs)

    def done(k, point):
        out[k] = point
        if progress is not None:
            n = sum(o is not None for o in out)
            progress(f"domain: sigma2 = {sig[k]:g} Pa done ({n}/{len(sig)}, "
                     f"{time.perf_counter() - t0:.1f} s)")

    if workers <= 1 or len(sig) == 1:
        try:
            for k, j in enumerate(jobs):
                done(k, _domain_job(j))
        except BaseException as e:
            e.partial = [o for o in out if o is not None]     # the pressures finished, in order
            raise
        return out
    # spawn, not fork: a fork after Numba's parallel kernel has started its threads can crash
    ex = ProcessPoolExecutor(max_workers=min(workers, len(jobs)), initializer=_domain_worker_init,
                             mp_context=multiprocessing.get_context("spawn"))
    try:
        futures = {ex.submit(_domain_job, j): k for k, j in enumerate(jobs)}
        for f in as_completed(futures):
            done(futures[f], f.result())
    except BaseException as e:
        # interrupted or failed: stop the workers now rather than after their current pressure
        for proc in list((getattr(ex, "_processes", None) or {}).values()):
            proc.terminate()
        e.partial = [o for o in out if o is not None]
        raise
    finally:
        ex.shutdown(wait=True, cancel_futures=True)
    return out
