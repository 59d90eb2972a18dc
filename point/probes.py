"""Directional analysis of second-order work at one saved state (section 3.3-3.4 of the paper),
for any material of the contract (``point.contract``).

All probes are run from the same saved state, batched as independent material points, so every
probe decides its own loading branch (the H-model: its own sliding pattern; no pattern is
inherited from the path).

W2 of a probe: for a law that provides the Lagrangian increment (the H-model), the paper's
W2 = V dPi:d_eps [J] (Eq. 10) and its Eulerian split (Eq. 38: w2 = w2_sigma + w2_V + w2_g) and
the micro sums; for any other law the small-strain W2 = d_sigma:d_eps [J/m^3] of the probe's
Cauchy stress increment, w2 = w2_sigma, and the H-model's own fields NaN (absent).

Sign conventions: compression positive; every W2 signed so that an elastic
spring gives W2 > 0. Angles in degrees. ``alpha_sigma`` as in the paper, tan(alpha_sigma) =
dsigma1 / dsigma2, i.e. alpha_sigma = atan2(ds1, ds2) in [0, 360), measured from the ds2 axis.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .contract import material_of
from .tensors import ddot as _ddot, to_voigt

__all__ = ["ProbeResult", "StressProbeResult", "strain_probes", "directional_sweep", "w2_vanishes",
           "stress_probes", "tangent_criteria", "min_w2", "arcs", "format_arcs", "cone_edges"]

DEFAULT_PROBE_NORM = 1e-6   # |d_eps| of a strain probe: a tenth of the default path step


class ProbeResult(NamedTuple):
    """Responses to strain probes d_eps = norm (cos a_e, sin a_e) on the axes (1, 2).

    Arrays of length n (one per probe) or (n, 3) in (11, 22, 12) order.
    alpha_eps, alpha_sigma : [deg]; d_eps [-]; d_sigma = T1 + T2 + T3 the Cauchy increment (Eq. 28),
    d_sigma_step = step(d_eps) - step(0) [Pa] (equal to d_sigma up to O(|d_eps|) terms);
    dPi = T1 (Eq. 32), T2 = -(dV/V) sigma, T3 transport term [Pa].
    W2 = V dPi:d_eps [J] (Lagrangian, Eq. 10); normalized by V |dPi| |d_eps|:
    w2, w2_sigma, w2_V, w2_g (Eq. 38 split, w2 = w2_sigma + w2_V + w2_g), w2_micro (contact sum,
    Eq. 15/36), w2n, w2t (its normal / tangential parts).
    plastic : some closed hexagon slides; n_sliding, n_open : counts of hexagons.
    """

    alpha_eps: np.ndarray
    d_eps: np.ndarray
    d_sigma: np.ndarray
    d_sigma_step: np.ndarray
    dPi: np.ndarray
    T2: np.ndarray
    T3: np.ndarray
    alpha_sigma: np.ndarray
    W2: np.ndarray
    w2: np.ndarray
    w2_sigma: np.ndarray
    w2_V: np.ndarray
    w2_g: np.ndarray
    w2_micro: np.ndarray
    w2n: np.ndarray
    w2t: np.ndarray
    w2_hex: np.ndarray
    plastic: np.ndarray
    n_sliding: np.ndarray
    n_open: np.ndarray

    def take(self, idx) -> "ProbeResult":
        return _take(self, idx)

    @staticmethod
    def concat(results) -> "ProbeResult":
        return _concat(results)


def _norm(a):
    return np.sqrt(_ddot(a, a))


def alpha_sigma_of(d_sigma):
    """Response angle [deg] in [0, 360): tan(alpha_sigma) = ds1/ds2 (paper, section 3.4)."""
    return np.degrees(np.arctan2(d_sigma[..., 0], d_sigma[..., 1])) % 360.0


def _check_state(state):
    if state.batch_shape != ():
        raise ValueError(f"probes start from a single-point state, got batch {state.batch_shape}")


class _Response(NamedTuple):
    """What every strain probe computes (``_responses``); rows as in ``ProbeResult``."""

    alpha_eps: np.ndarray
    d_eps: np.ndarray
    dPi: np.ndarray
    T2: np.ndarray
    T3: np.ndarray
    d_sigma: np.ndarray
    alpha_sigma: np.ndarray
    tr: np.ndarray
    W2: np.ndarray
    scale: np.ndarray
    w2: np.ndarray
    w2_sigma: np.ndarray


class _Signs(NamedTuple):
    """The part of a probe the sweep's refinement and the domain's check need."""

    alpha_eps: np.ndarray
    alpha_sigma: np.ndarray
    w2: np.ndarray
    w2_sigma: np.ndarray


def _take(rows, idx):
    """The rows ``idx`` of every field of a record of per-probe arrays."""
    return type(rows)(*(np.asarray(f)[idx] for f in rows))


def _concat(records):
    """The records' rows, one after the other, field by field."""
    return type(records[0])(*(np.concatenate([getattr(r, f) for r in records])
                              for f in records[0]._fields))


def _responses(state, params, a, norm: float, allow_sliding: bool,
               shear: float = 0.0):
    """The update kernel's response to the strain probes in the directions ``a`` [deg] (checked
    by the caller) from the single-point ``state``, each probe a point of its own, and the
    normalized second-order works (Eq. 10, 38). Returns (``_Response``, kernel outputs in
    ``_kernels.allocate_outputs`` order)."""
    n = a.size
    de = np.zeros((n, 3))
    de[:, 0] = norm * np.cos(np.radians(a))
    de[:, 1] = norm * np.sin(np.radians(a))
    de[:, 2] = shear * norm
    law = material_of(params)
    out = law.update_rows(state, de, params, elastic=not allow_sliding)
    sigma = to_voigt(state.stress)[0]
    if "lagrangian" in law.provides:
        dPi, T3 = out.extras["dPi"], out.extras["T3"]
        V = float(law.volume(state))
        # dV/V = -(I - eps)^-T : d_eps, the first-order change of V = V0 det(I - eps); it is
        # -tr(d_eps) up to O(|eps|) terms (2 % at A), which matter for T2 to be the exact
        # derivative
        Ainv = np.linalg.inv(np.eye(2) - state.eps)
        tr = Ainv[0, 0] * de[:, 0] + Ainv[1, 1] * de[:, 1] + (Ainv[0, 1] + Ainv[1, 0]) * de[:, 2]
        T2 = tr[:, None] * sigma[None, :]            # -(dV/V) sigma
        d_sigma = dPi + T2 + T3
    else:
        # small strain: the Cauchy increment of the probe is its Lagrangian one, per unit volume
        d_sigma = out.stress - sigma[None, :]
        dPi, T2, T3 = d_sigma, np.zeros_like(d_sigma), np.zeros_like(d_sigma)
        V = 1.0
        tr = np.full(n, np.nan)
    W2 = V * _ddot(dPi, de)
    scale = V * _norm(dPi) * _norm(de)
    with np.errstate(divide="ignore", invalid="ignore"):
        w2 = W2 / scale
        w2_sigma = V * _ddot(d_sigma, de) / scale
    return _Response(a, de, dPi, T2, T3, d_sigma, alpha_sigma_of(d_sigma), tr, W2, scale, w2,
                     w2_sigma), out


def _check_probe_args(state, a, norm):
    _check_state(state)
    if not (np.isfinite(norm) and norm > 0):
        raise ValueError(f"norm must be a finite |d_eps| > 0, got {norm!r}")
    a = np.atleast_1d(np.asarray(a, dtype=float))
    if not np.all(np.isfinite(a)):
        raise ValueError("alpha_eps_deg must be finite angles in degrees")
    return a


def strain_probes(state, params, alpha_eps_deg, norm: float = DEFAULT_PROBE_NORM,
                  allow_sliding: bool = True, shear: float = 0.0) -> ProbeResult:
    """Strain probes d_eps = norm (cos a, sin a) in the (d_eps1, d_eps2) plane from ``state``.

    ``shear`` adds d_eps12 = shear * norm to every probe (the paper's probes have none).
    """
    a = _check_probe_args(state, alpha_eps_deg, norm)
    r, out = _responses(state, params, a, norm, allow_sliding, shear)
    law = material_of(params)
    sig0 = law.update_rows(state, np.zeros((1, 3)), params, elastic=not allow_sliding).stress
    sigma = to_voigt(state.stress)[0]
    nan = np.full(a.size, np.nan)
    if "lagrangian" in law.provides:
        V = float(law.volume(state))
        with np.errstate(divide="ignore", invalid="ignore"):
            nrm = lambda x: x / r.scale                                   # noqa: E731
            w2_V = nrm(-V * r.tr * _ddot(sigma[None, :], r.d_eps))
            w2_g = nrm(-V * _ddot(r.T3, r.d_eps))
    else:
        w2_V = w2_g = nan
    if "micro" in law.provides:
        with np.errstate(divide="ignore", invalid="ignore"):
            w2n = out.extras["w2n"] / r.scale
            w2t = out.extras["w2t"] / r.scale
            w2_hex = out.extras["w2_hex"] / r.scale
    else:
        w2n = w2t = w2_hex = nan
    if "patterns" in law.provides:
        sliding, is_open = out.extras["sliding"], out.extras["is_open"]
        closed = ~is_open
        n_sliding, n_open = np.sum(sliding & closed, axis=-1), np.sum(is_open, axis=-1)
    else:
        n_sliding, n_open = out.plastic.astype(np.int64), np.zeros(a.size, dtype=np.int64)
    return ProbeResult(
        alpha_eps=a, d_eps=r.d_eps, d_sigma=r.d_sigma, d_sigma_step=out.stress - sig0[0][None, :],
        dPi=r.dPi, T2=r.T2, T3=r.T3, alpha_sigma=r.alpha_sigma, W2=r.W2,
        w2=r.w2, w2_sigma=r.w2_sigma, w2_V=w2_V, w2_g=w2_g, w2_micro=w2n + w2t, w2n=w2n, w2t=w2t,
        w2_hex=w2_hex, plastic=out.plastic, n_sliding=n_sliding, n_open=n_open)


def _signs(state, params, alpha_eps_deg, norm: float = DEFAULT_PROBE_NORM,
           allow_sliding: bool = True) -> _Signs:
    """``strain_probes`` reduced to alpha_sigma, w2 and w2_sigma: the same numbers, computed by
    the same ``_responses``, without the fields the sweep's refinement does not look at."""
    a = _check_probe_args(state, alpha_eps_deg, norm)
    r, _ = _responses(state, params, a, norm, allow_sliding)
    return _Signs(a, r.alpha_sigma, r.w2, r.w2_sigma)


def arcs(alpha_deg, mask) -> list:
    """Contiguous arcs [start, end] [deg] of the directions ``alpha_deg`` where ``mask`` holds,
    walking the directions in increasing angle (e.g. the plastic zone or the instability cone);
    an arc that runs through 360 deg is joined into one ending above 360."""
    o = np.argsort(alpha_deg)
    a, m = np.asarray(alpha_deg, float)[o], np.asarray(mask, bool)[o]
    out, start, prev = [], None, None
    for ak, mk in zip(a, m):
        if mk and start is None:
            start = ak
        if not mk and start is not None:
            out.append([float(start), float(prev)])
            start = None
        prev = ak
    if start is not None:
        out.append([float(start), float(a[-1])])
    if len(out) > 1 and m[0] and m[-1]:
        first = out.pop(0)
        out[-1] = [out[-1][0], first[1] + 360.0]
    return out


def format_arcs(arc_list) -> str:
    """'[a, b], [c, d]' [deg] for a list of arcs, or 'none'."""
    return ", ".join(f"[{a:.1f}, {b:.1f}]" for a, b in arc_list) if arc_list else "none"


def _wrap180(x):
    return (np.asarray(x) + 180.0) % 360.0 - 180.0


def directional_sweep(state, params, n: int = 360, norm: float = DEFAULT_PROBE_NORM,
                      max_gap_deg: float = 1.0, max_rounds: int = 30, allow_sliding: bool = True) -> ProbeResult:
    """Strain probes on a uniform grid of ``n`` directions, refined by bisection wherever the
    response direction alpha_sigma jumps by more than ``max_gap_deg`` between neighbours.

    Near the peak most of the plastic zone (and the instability cone) comes from a window of a few
    degrees of strain directions (docs/hmodel.md, the formulation), which a uniform sweep misses. Refinement stops
    after ``max_rounds`` bisections of an interval (an interval of 360/n/2**30 deg is a jump of
    the response, not a missed direction). Sorted by alpha_eps in [0, 360).
    """
    return _refine(lambda a: strain_probes(state, params, a, norm, allow_sliding), n, max_gap_deg,
                   max_rounds)


def w2_vanishes(state, params, n: int = 360, norm: float = DEFAULT_PROBE_NORM,
                max_gap_deg: float = 1.0, max_rounds: int = 30,
                allow_sliding: bool = True) -> tuple[bool, bool]:
    """Whether W2 (Eq. 10) and W2_sigma are <= 0 in some strain direction of
    ``directional_sweep``'s probes: the bifurcation domain's check (Fig. 10). The same answer
    as the minima of ``directional_sweep``, from the same probes: it computes only what its
    refinement and the two signs need, and stops refining once both are <= 0 (a refinement
    only adds probes, so it cannot undo that)."""
    def both(r):
        return bool(np.nanmin(r.w2) <= 0.0) and bool(np.nanmin(r.w2_sigma) <= 0.0)

    r = _refine(lambda a: _signs(state, params, a, norm, allow_sliding), n, max_gap_deg, max_rounds,
                enough=both)
    return bool(np.nanmin(r.w2) <= 0.0), bool(np.nanmin(r.w2_sigma) <= 0.0)


def _refine(probe, n, max_gap_deg, max_rounds, enough=None):
    """The adaptive sweep of ``directional_sweep``: ``probe(alpha_eps)`` (a record of per-probe
    arrays with ``alpha_eps`` and ``alpha_sigma``) on the grid of ``n`` directions, then at the
    middle of every interval where alpha_sigma jumps by more than ``max_gap_deg``, for at most
    ``max_rounds`` rounds or until ``enough(record)``. Sorted by alpha_eps."""
    if int(n) < 8:
        raise ValueError(f"n must be an integer >= 8 probe directions, got {n!r}")
    res = probe(360.0 * np.arange(int(n)) / int(n))
    min_width = 360.0 / int(n) / 2.0 ** max_rounds
    for _ in range(max_rounds):
        if enough is not None and enough(res):
            break
        a = res.alpha_eps
        a_next = np.roll(a, -1)
        width = (a_next - a) % 360.0
        gap = np.abs(_wrap180(np.roll(res.alpha_sigma, -1) - res.alpha_sigma))
        bad = (gap > max_gap_deg) & (width > min_width)
        if not np.any(bad):
            break
        mids = (a[bad] + 0.5 * width[bad]) % 360.0
        res = _concat([res, probe(mids)])
        res = _take(res, np.argsort(res.alpha_eps, kind="stable"))
    return res


class StressProbeResult(NamedTuple):
    """Stress probes: for each asked alpha_sigma, the strain directions that give it.

    alpha_sigma_target : (m,) [deg]; n_solutions : (m,) number of strain directions found (0: no
    strain direction gives that stress direction, the response jumps over it; > 1: several do);
    probe : ProbeResult of one solution per target (the first, by alpha_eps), rows of targets
    without a solution are NaN; status : (m,) 'unique' | 'multiple' | 'none'.
    """

    alpha_sigma_target: np.ndarray
    n_solutions: np.ndarray
    probe: ProbeResult
    status: np.ndarray
    all_alpha_eps: list


def stress_probes(state, params, alpha_sigma_deg, sigma_norm: float | None = None,
                  sweep: ProbeResult | None = None, tol_deg: float = 1e-6,
                  allow_sliding: bool = True) -> StressProbeResult:
    """Stress probes in the directions ``alpha_sigma_deg`` [deg] (paper's convention).

    The strain direction is found by bisection on the response angle along the adaptive sweep
    (the map is piecewise linear, continuous for a fixed pattern). These are rate (directional)
    probes: the direction is found at the sweep's small strain norm. With ``sigma_norm`` [Pa] the
    increments are scaled linearly to |d_sigma| = sigma_norm, which is what the rate response
    gives; a finite probe of that size near the peak would need strains far beyond the tangent
    regime (the plastic modulus vanishes there) and is a different, path-dependent question.
    """
    _check_state(state)
    if sigma_norm is not None and not (np.isfinite(sigma_norm) and sigma_norm > 0):
        raise ValueError(f"sigma_norm = {sigma_norm!r} is out of range: allowed a stress norm > 0 [Pa] "
                         "(or None: the rate probes unscaled)")
    targets = np.atleast_1d(np.asarray(alpha_sigma_deg, dtype=float)) % 360.0
    if sweep is None:
        sweep = directional_sweep(state, params, allow_sliding=allow_sliding)
    a = sweep.alpha_eps
    s = sweep.alpha_sigma
    width = (np.roll(a, -1) - a) % 360.0
    dgap = _wrap180(np.roll(s, -1) - s)
    norm = float(_norm(sweep.d_eps[0]))
    brackets = []   # (target index, lo alpha_eps, width, lo alpha_sigma, gap)
    for ti, t in enumerate(targets):
        off = _wrap180(t - s)
        hit = np.where(dgap >= 0, (off >= 0) & (off <= dgap), (off <= 0) & (off >= dgap))
        for k in np.flatnonzero(hit & (np.abs(dgap) < 180.0)):
            brackets.append((ti, a[k], width[k]))
    sols = [[] for _ in targets]
    if brackets:
        ti = np.array([b[0] for b in brackets])
        lo = np.array([b[1] for b in brackets])
        w = np.array([b[2] for b in brackets])
        t = targets[ti]
        s_lo = _signs(state, params, lo, norm, allow_sliding).alpha_sigma
        for _ in range(60):
            w = 0.5 * w
            mid = (lo + w) % 360.0
            s_mid = _signs(state, params, mid, norm, allow_sliding).alpha_sigma
            # keep the half whose start is still on the low side of the target
            go_up = _wrap180(t - s_lo) * _wrap180(t - s_mid) > 0
            lo = np.where(go_up, mid, lo)
            s_lo = np.where(go_up, s_mid, s_lo)
        fin = strain_probes(state, params, lo, norm, allow_sliding)
        ok = np.abs(_wrap180(fin.alpha_sigma - t)) <= max(tol_deg, 1e-9)
        for k in np.flatnonzero(ok):
            sols[ti[k]].append(lo[k])
    n_sol = np.array([len(v) for v in sols])
    first = np.array([min(v) if v else np.nan for v in sols])
    status = np.where(n_sol == 0, "none", np.where(n_sol == 1, "unique", "multiple"))
    have = np.isfinite(first)
    res = None
    if np.any(have):
        base = strain_probes(state, params, first[have], norm, allow_sliding)
        if sigma_norm is not None:
            # rate response, positively homogeneous: scale the small probe to the asked norm
            c = float(sigma_norm) / _norm(base.d_sigma)
            lin = {f: getattr(base, f) * c[:, None] for f in ("d_eps", "d_sigma", "d_sigma_step", "dPi", "T2", "T3")}
            base = base._replace(W2=base.W2 * c * c, **lin)
        full = [np.full((targets.size,) + np.shape(f)[1:], np.nan) for f in base]
        for f, b in zip(full, base):
            f[have] = b
        res = ProbeResult(*full)
    else:
        res = ProbeResult(*(np.full(targets.size, np.nan) for _ in ProbeResult._fields))
    return StressProbeResult(targets, n_sol, res, status, sols)


def min_w2(state, params, n: int = 360, which: str = "w2",
           sweep: ProbeResult | None = None) -> tuple[float, float]:
    """Minimum over all strain directions of the normalized ``which`` ('w2' or 'w2_sigma') and
    the response angle alpha_sigma [deg] where it occurs (adaptive sweep)."""
    sweep = directional_sweep(state, params, n=n) if sweep is None else sweep
    v = getattr(sweep, which)
    k = int(np.nanargmin(v))
    return float(v[k]), float(sweep.alpha_sigma[k])


def cone_edges(state, params, n: int = 360, norm: float = DEFAULT_PROBE_NORM,
               sweep: ProbeResult | None = None, tol_deg: float = 1e-10) -> list:
    """The edges of the cone of W2 < 0, located to ``tol_deg``: every change of sign of the
    normalized W2 between neighbours of the adaptive sweep (``directional_sweep``), bisected on
    the probe's own W2 (``strain_probes`` of norm ``norm``, each deciding its own branch). Each
    edge a dict: ``alpha_eps`` [deg] the strain direction, ``alpha_sigma`` [deg] its response's
    direction (the edge of the cone in the stress probe plane: W2 is the same scalar), ``enters``
    True where W2 turns negative with increasing alpha_eps. A finite probe sees the response
    of a step of its size: the edges move with ``norm`` (for a law whose tangent depends on the
    step, to first order in it)."""
    sw = directional_sweep(state, params, n=n, norm=norm) if sweep is None else sweep
    a, w = np.asarray(sw.alpha_eps), np.asarray(sw.w2)
    neg = w <= 0.0
    out = []
    for k in np.flatnonzero(neg != np.roll(neg, -1)):
        lo, hi = float(a[k]), float(a[k]) + float((a[(k + 1) % a.size] - a[k]) % 360.0)
        lo_neg = bool(neg[k])
        while hi - lo > tol_deg:
            mid = 0.5 * (lo + hi)
            if not lo < mid < hi:
                break
            m_neg = bool(strain_probes(state, params, [mid % 360.0], norm).w2[0] <= 0.0)
            lo, hi = (mid, hi) if m_neg == lo_neg else (lo, mid)
        x = (0.5 * (lo + hi)) % 360.0
        pr = strain_probes(state, params, [x], norm)
        out.append({"alpha_eps": x, "alpha_sigma": float(pr.alpha_sigma[0]), "enters": not lo_neg})
    return out


def tangent_criteria(state, params, d_eps_dir=(1.0, -1.0),
                     norm: float = DEFAULT_PROBE_NORM) -> dict:
    """det(M) and det(M_sym) of the 2x2 principal tangent (d sigma1, d sigma2 vs d eps1, d eps2)
    on the sliding pattern of the strain direction ``d_eps_dir`` (e.g. the path's loading
    direction), Cauchy and Lagrangian. M_sym = (M + M^T)/2; det(M_sym) <= 0 is the first loss of
    positive definiteness, det(M) = 0 the limit state (docs/hmodel.md)."""
    _check_state(state)
    d = np.asarray(d_eps_dir, dtype=float)
    d = norm * d / np.linalg.norm(d)
    law = material_of(params)
    if "lagrangian" in law.provides:
        inc = law.full_update(state, np.diag(d), params)
        tangents = (("cauchy", inc.tangent), ("lagrangian", inc.tangent_lagrangian))
    else:
        tangents = (("cauchy", law.rate_tangent(state, np.diag(d), params, norm)),)
    out = {}
    for name, C in tangents:
        M = np.array([[C[0, 0, 0, 0], C[0, 0, 1, 1]], [C[1, 1, 0, 0], C[1, 1, 1, 1]]])
        Ms = 0.5 * (M + M.T)
        out[f"det_M_{name}"] = float(np.linalg.det(M))
        out[f"det_Msym_{name}"] = float(np.linalg.det(Ms))
        out[f"lam_min_Msym_{name}"] = float(np.linalg.eigvalsh(Ms)[0])
    return out
