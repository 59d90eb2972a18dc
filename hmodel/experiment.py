"""The paper's H-model experiments: drained biaxial test, directional analysis at point A,
bifurcation domain (sections 3.3-3.4, Figs. 3-11). Functions here are what the CLI and the tests
call; they return arrays and write nothing (see ``hmodel.cli`` for files and figures)."""
from __future__ import annotations

import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor
from typing import NamedTuple

import numpy as np

from .driver import PathResult, drained_biaxial, isotropic_state, run_path, stress_invariants
from .material import HState
from .params import HParams
from .probes import ProbeResult, directional_sweep

__all__ = ["biaxial_test", "state_at_eta", "biaxial_columns", "probe_columns", "DomainPoint",
           "domain_point", "bifurcation_domain"]


def _check_sigma2(sigma2):
    if not (np.isfinite(sigma2) and sigma2 > 0):
        raise ValueError(f"sigma2 must be a confining stress > 0 [Pa], got {sigma2!r}")


def biaxial_test(params: HParams, sigma2: float | None = None, d_eps1: float = 1e-5,
                 eps1_max: float = 0.05, progress: bool = False) -> PathResult:
    """Drained biaxial test from the isotropic state at ``sigma2`` [Pa] (default params.p0):
    axial strain steps ``d_eps1`` up to ``eps1_max``, lateral stress held (Figs. 4-5)."""
    sigma2 = params.p0 if sigma2 is None else float(sigma2)
    _check_sigma2(sigma2)
    if not (np.isfinite(eps1_max) and eps1_max > 0):
        raise ValueError(f"eps1_max must be > 0, got {eps1_max!r}")
    if not (np.isfinite(d_eps1) and 0 < d_eps1 <= eps1_max):
        raise ValueError(f"d_eps1 must be in (0, eps1_max = {eps1_max}], got {d_eps1!r}")
    p = params.replace(p0=sigma2)
    n = int(round(eps1_max / d_eps1))
    return run_path(isotropic_state(p), p, drained_biaxial(d_eps1), n, progress=progress,
                    label="drained biaxial")


def state_at_eta(params: HParams, eta: float, sigma2: float | None = None, d_eps1: float = 1e-5,
                 eps1_max: float = 0.2) -> tuple[PathResult, HState]:
    """Run the drained path to the first state with eta >= ``eta`` (point A for eta = 1.029).
    Raises ValueError if the path peaks below ``eta``."""
    sigma2 = params.p0 if sigma2 is None else float(sigma2)
    _check_sigma2(sigma2)
    p = params.replace(p0=sigma2)
    n = int(round(eps1_max / d_eps1))
    r = run_path(isotropic_state(p), p, drained_biaxial(d_eps1), n,
                 until=lambda e, s: (s[0] - s[1]) >= eta * 0.5 * (s[0] + s[1]))
    _, _, e = r.invariants()
    if e[-1] < eta:
        raise ValueError(f"eta = {eta} is never reached on the drained path (max eta {e.max():.4f})")
    return r, r.state


def biaxial_columns(r: PathResult) -> dict:
    """CSV columns of a path: eps1, eps2, eps_v, s1, s2, p, q, eta (SI, compression positive)."""
    p, q, eta = r.invariants()
    return {"eps1": r.eps[:, 0], "eps2": r.eps[:, 1], "eps_v": r.eps[:, 0] + r.eps[:, 1],
            "s1": r.sigma[:, 0], "s2": r.sigma[:, 1], "p": p, "q": q, "eta": eta,
            "s12": r.sigma[:, 2], "n_sliding": r.n_sliding, "n_open": r.n_open,
            "newton_iters": r.newton_iters}


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
    NaN where the criterion never fires before the peak."""

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


def domain_point(params: HParams, sigma2: float, d_eps1: float = 1e-5, check_every: int = 25,
                 n_dir_probe: int = 180, eps1_max: float = 0.2) -> DomainPoint:
    """Scan the drained path at ``sigma2`` [Pa]: every ``check_every`` steps the minimum over
    directions of W2 and W2_sigma (adaptive strain-probe sweep); once one is <= 0 the last
    ``check_every`` steps are replayed one by one to find the first state where it is."""
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
        sw = directional_sweep(st, p, n=n_dir_probe)
        return {"w2": bool(np.nanmin(sw.w2) <= 0.0), "w2_sigma": bool(np.nanmin(sw.w2_sigma) <= 0.0)}

    while steps < n_max and (peak is None or any(v is None for v in found.values())):
        r = run_path(state, p, ctl, check_every, keep_states=any(v is None for v in found.values()))
        pp, qq, _ = r.invariants()
        # the peak: first row where q stops increasing
        for j in range(1, len(qq)):
            if peak is None and qq[j] < q_prev:
                peak = (pp[j - 1], qq[j - 1], eps1 + r.eps[j - 1, 0])
            q_prev = qq[j]
        if any(v is None for v in found.values()):
            f_end = fires(r.state)
            for key in found:
                if found[key] is None and f_end[key]:
                    for j in range(1, len(r.states)):
                        if fires(r.states[j])[key]:
                            found[key] = (pp[j], qq[j], eps1 + r.eps[j, 0])
                            break
        eps1 += r.eps[-1, 0]
        steps += check_every
        state = r.state
        if peak is not None and all(v is not None for v in found.values()):
            break
    nan3 = (np.nan, np.nan, np.nan)
    w, ws, pk = found["w2"] or nan3, found["w2_sigma"] or nan3, peak or nan3
    # a criterion that fires only after the peak is outside the pre-peak domain: keep it anyway
    return DomainPoint(float(sigma2), w[0], w[1], ws[0], ws[1], pk[0], pk[1], w[2], ws[2], pk[2])


def _domain_job(args):
    params, s2, kw = args
    return domain_point(params, s2, **kw)


def bifurcation_domain(params: HParams, sigma2_list, workers: int | None = None, **kw) -> list[DomainPoint]:
    """``domain_point`` for every confining pressure, in parallel processes (``workers``,
    default min(len, cpu count); 1 runs in this process). Results in the input order."""
    sig = [float(s) for s in sigma2_list]
    for s in sig:
        _check_sigma2(s)
    workers = min(len(sig), os.cpu_count() or 1) if workers is None else int(workers)
    jobs = [(params, s, kw) for s in sig]
    if workers <= 1 or len(sig) == 1:
        return [_domain_job(j) for j in jobs]
    # spawn, not fork: a fork after Numba's parallel kernel has started its threads can crash
    with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn")) as ex:
        return list(ex.map(_domain_job, jobs))
