"""Does a static solution exist under a mixed control? The decision a path makes when a step,
cut down to its floor, still does not converge (docs/hmodel.md, "Every path ends in an answer").

Controlled variables e' = A de (the strain-controlled ones prescribed) and their conjugate
stresses s' = A^-T sigma (the stress-controlled ones prescribed), ``mixed.MixedControl``. With
the tangent M of the increment, the stress-controlled (free) entries of a step solve

    M'_ff de'_f = ds'_f - M'_fp de'_p,     M' = A^-T M A^-1,

and the second-order work of an increment is ds'.W.de' (W = diag(1, 1, 2): tensor shear), the
same in either set of variables. At det M'_ff = 0 a null vector x gives the increment de' = (0, x):
every control parameter held (de'_p = 0, ds'_f = M'_ff x = 0), the material still deforming, and
W2 = ds'_f.W.x = 0: the loss of controllability of Nicot & Darve (the paper's section 2: W2 = 0
for the control parameters of the loading programme). Before it, the first zero of W2 over the
increments with de'_p = 0 is lam_min(sym(W M'_ff)) = 0.

The H-model's tangent is piecewise constant (each increment decides its sliding pattern), so the
test is made on the response itself, as ``hmodel.burst.static_check`` does for c: a one-parameter
scan of the conjugate stress s'_k over the free variable e'_k (the others held at the failed
step's values; with several free entries, the others are solved at each point of the scan and
e'_k is the entry of the near-null vector of M'_ff). Over the bracket |e'_k| <= scan_strain:

* ``uncontrollable``: s'_k never reaches its target and its closest approach is an interior
  extremum: the controlled block's determinant changes sign there (W2 for this control
  vanishes); or the response is flat (no stiffness left: det = 0).
* ``discontinuous``: s'_k passes its target by a jump (bisected to the last bit of e'_k): no
  strain reaches it, but no extremum either: the determinant keeps its sign (W2 > 0 on both sides).
  The H-model's response jumps where a hexagon loses its axial contact (N2 = 0) while its
  inclined contacts still carry N1 (possible only for alpha > 90 deg - phi_g): the spec's opening
  rule then drops N1 and T1 at once (docs/hmodel.md).
* ``exists``: s'_k reaches its target continuously: a static solution exists, the Newton failure
  was numerical (an error for the caller, with its residual).
* ``unresolved``: none of these within the largest bracket (the target is not reached and the
  closest approach is at its end); an error for the caller.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .contract import MaterialError, Rows, material_of
from .mixed import MixedControl, MixedControlError, mixed_step
from .tensors import to_voigt, voigt_tangent

__all__ = ["Verdict", "PathEnd", "decide", "control_scan", "describe_control", "stress_name",
           "verdict_text", "SCAN_STRAIN", "N_SCAN", "END_OUTCOMES"]

SCAN_STRAIN = 2e-3      # the bracket |e'_k| <= this of the scan (hmodel.burst.static_check's)
SCAN_STRAIN_MAX = 0.032  # widened x4 up to this while the closest approach is at the bracket's end
N_SCAN = 801            # points of the scan (odd: 0 is one of them)
W_SHEAR = np.array([1.0, 1.0, 2.0])     # ds:de = ds'.W.de' with tensor shear
END_OUTCOMES = ("complete", "uncontrollable", "discontinuous")
_NAMES = ("eps11", "eps22", "eps12")
_STRESS = ("s11", "s22", "s12")


class Verdict(NamedTuple):
    """What ``decide`` found (SI; angles not involved).

    outcome : 'uncontrollable', 'discontinuous', 'exists' or 'unresolved' (module docstring).
    variable : index k (0-2) of the scanned free variable e'_k.
    target : s'_k asked [Pa]; reached : the closest s'_k over the scan (uncontrollable: the
        extremum), or s'_k at the near side of the jump [Pa].
    at : e'_k of the extremum, the jump or the root [-] (increment from the state).
    jump : size of the jump of s'_k [Pa] (discontinuous), else 0.
    det, lam_min, w2 : the controlled block's determinant [Pa^nfree], smallest eigenvalue of its
        symmetric part [Pa] and the normalized second-order work of the control's free increment
        (x.W M'_ff x / (|x| |M' x|)), each as (before, after) the extremum or jump.
    bracket : the scan's |e'_k| bound; points : its number of points.
    hexagons : the orientations theta [deg] whose flags (open, sliding) differ across the jump or
        the extremum, their N1, N2 [N] and alpha [deg] on the side where they are closed, whether
        they open and by which contacts ('axial': N2 reaches 0, 'inclined': N1 does; the rule
        drops the other force).
    residual : |s'_k - target| at the root (exists) [Pa].
    """

    outcome: str
    variable: int
    target: float
    reached: float
    at: float
    jump: float
    det: tuple
    lam_min: tuple
    w2: tuple
    bracket: float
    points: int
    hexagons: dict
    residual: float


class PathEnd(NamedTuple):
    """How a path ended (``driver.run_path``'s ``PathResult.end``).

    outcome : 'complete' or, when a step cut to its floor had no static solution, the verdict
        ('uncontrollable', 'discontinuous'). step : the 1-based step without a static solution
        (0: complete); fraction : the part of it its substeps reached (0-1). eps, sigma : (3,)
        strain (from the start of the path) and stress [Pa] of the last state. control : the
        control in words. verdict : the ``Verdict`` (None when complete). stress : the name of
        the controlled stress the verdict is about (``stress_name``).
    """

    outcome: str
    step: int
    fraction: float
    eps: np.ndarray
    sigma: np.ndarray
    control: str
    verdict: Verdict | None
    stress: str = ""

    def line(self) -> str:
        """One line: 'complete', or 'uncontrollable at eps1 = 0.2040 % (eta 0.5729): ...'."""
        if self.outcome == "complete":
            return "complete"
        s = self.sigma
        p, q = 0.5 * (s[0] + s[1]), s[0] - s[1]
        head = (f"{self.outcome} at eps1 = {100 * self.eps[0]:.4f} % (eps2 = {100 * self.eps[1]:.4f} "
                f"%, eta = {q / p if p else math.nan:.4f}), step {self.step}: no static state under "
                f"{self.control}")
        why = verdict_text(self.verdict, self.stress)
        return f"{head}: {why}"

    def as_dict(self) -> dict:
        """JSON-ready (numbers and lists)."""
        d = {"outcome": self.outcome, "line": self.line(), "step": int(self.step),
             "fraction_of_step": float(self.fraction), "eps": [float(x) for x in self.eps],
             "sigma": [float(x) for x in self.sigma], "control": self.control}
        if self.verdict is not None:
            v = self.verdict
            d["verdict"] = {"outcome": v.outcome, "stress": self.stress,
                            "target": v.target, "reached": v.reached, "at": v.at, "jump": v.jump,
                            "det": list(v.det), "lam_min_sym": list(v.lam_min), "w2": list(v.w2),
                            "bracket": v.bracket, "points": v.points, "hexagons": v.hexagons}
        return d


def verdict_text(v: Verdict, name: str) -> str:
    """Why there is no static state, in words (``name``: the controlled stress, e.g. 's22')."""
    if v.outcome == "uncontrollable" and v.det == (0.0, 0.0):
        return (f"{name} comes no closer than {v.reached:.9g} Pa to the {v.target:.9g} asked, with "
                "no stiffness left there (the controlled block's determinant is 0"
                + (": every hexagon that could carry it open)" if v.hexagons else ")"))
    if v.outcome == "uncontrollable":
        return (f"{name} turns at {v.reached:.9g} Pa, {abs(v.target - v.reached):.3g} Pa short of "
                f"the {v.target:.9g} asked; the controlled block's determinant goes from "
                f"{v.det[0]:.4g} to {v.det[1]:.4g}, W2 for this control from {v.w2[0]:+.3g} to "
                f"{v.w2[1]:+.3g}")
    if v.outcome == "discontinuous":
        hx = v.hexagons
        op = [i for i, o in enumerate(hx.get("opens", [])) if o]
        what = ""
        if op:
            theta = ", ".join("%.0f" % hx["theta"][i] for i in op[:6])
            via = "/".join(sorted({hx["via"][i] for i in op}))
            n1, n2 = max(hx["N1"][i] for i in op), max(hx["N2"][i] for i in op)
            what = (f" (hexagons at theta = {theta} deg open by their {via} contacts, dropping N1 "
                    f"up to {n1:.3g} N and N2 up to {n2:.3g} N at once)")
        return (f"{name} jumps by {v.jump:.4g} Pa across the {v.target:.9g} asked, the determinant "
                f"keeping its sign ({v.det[0]:.4g}, {v.det[1]:.4g}; W2 {v.w2[0]:+.3g}, "
                f"{v.w2[1]:+.3g}): a discontinuity of the model's response{what}")
    return f"{v.outcome}: {name} = {v.reached:.9g} Pa at d e' = {v.at:.6g} (target {v.target:.9g})"


def describe_control(control) -> str:
    """The control in words: 'eps11, eps12 prescribed, s22 held' (drained), 'the tie d eps22 =
    -2 d eps11 (no shear strain), c = s11 + (-2) s22 prescribed', ..."""
    sc = control.strain_controlled
    if control.control_matrix is not None:
        A = np.asarray(control.control_matrix)
        R = -A[1, 0]
        if sc == (False, True, True) and A[0, 0] == 1 and A[0, 1] == 0 and A[1, 1] == 1 and R != 0:
            return f"the tie d eps22 = {R:g} d eps11 (no shear strain), c = s11 + ({R:g}) s22 prescribed"
        return (f"e' = A de (A = {A.tolist()}) with "
                + ", ".join(f"e'{i + 1}" if s else f"s'{i + 1}" for i, s in enumerate(sc)) + " prescribed")
    strain = [n for n, s in zip(_NAMES, sc) if s]
    stress = [n for n, s in zip(_STRESS, sc) if not s]
    return ", ".join(([", ".join(strain) + " prescribed"] if strain else [])
                     + ([", ".join(stress) + " held"] if stress else []))


def stress_name(control, k: int) -> str:
    """The name of the conjugate stress s'_k: 'c' for the tie, s11 / s22 / s12 without a
    control matrix, s'1 ... otherwise."""
    if control.control_matrix is None:
        return _STRESS[k]
    return "c" if k == 0 and "the tie" in describe_control(control) else f"s'{k + 1}"


def _block(tan, Ainv, free):
    """W M'_ff: the controlled block (rows (n, 3, 3) of d sigma / d de -> (n, nf, nf))."""
    Mp = np.einsum("ia,nij,jb->nab", Ainv, tan, Ainv)
    idx = np.asarray(free)
    return W_SHEAR[idx][None, :, None] * Mp[:, idx[:, None], idx[None, :]], Mp


def _indicators(tan, Ainv, free):
    """(det, lam_min of the symmetric part, normalized W2 of its eigenvector) of the controlled
    block of each tangent row (n, 3, 3). The eigenvector x (free entries, the others 0: every
    control parameter held) has W2 = ds'.W.x = x.W M' x = lam_min, normalized by |x|_W |M' x|_W
    (|v|_W^2 = v.W.v): within [-1, 1] by Cauchy-Schwarz."""
    B, Mp = _block(tan, Ainv, free)
    det = np.linalg.det(B)
    S = 0.5 * (B + np.swapaxes(B, 1, 2))
    lam, vec = np.linalg.eigh(S)
    x = np.zeros((len(tan), 3))
    x[:, free] = vec[:, :, 0]
    resp = np.einsum("nab,nb->na", Mp, x)
    norm_w = lambda v: np.sqrt(np.einsum("na,a,na->n", v, W_SHEAR, v))     # noqa: E731
    with np.errstate(invalid="ignore", divide="ignore"):
        w2 = lam[:, 0] / (norm_w(x) * norm_w(resp))
    return det, lam[:, 0], w2


def _rows(state, params, de, refusals=None):
    """``Material.update_rows`` of the increments ``de`` (n, 3); where the law refuses some of
    them (``MaterialError``: a state it does not describe, Drucker-Prager's apex), row by row,
    the refused ones NaN: they lie outside the law's domain, not in the scan's answer (the
    refusal appended to ``refusals``). Refusing them all, the law's own MaterialError (it cannot
    go on from ``state`` at all)."""
    law = material_of(params)
    try:
        return law.update_rows(state, de, params)
    except MaterialError as refused:
        n = de.shape[0]
        stress, tangent = np.full((n, 3), np.nan), np.full((n, 3, 3), np.nan)
        for i in range(n):
            try:
                r = law.update_rows(state, de[i:i + 1], params)
            except MaterialError:
                continue
            stress[i], tangent[i] = r.stress[0], r.tangent[0]
        if not np.any(np.isfinite(stress[:, 0])):
            raise refused
        if refusals is not None:
            refusals.append(refused)
        return Rows(stress, tangent, np.zeros(n, dtype=bool), {})


def control_scan(state, params, control, de_p, s_target, t, k: int, refusals=None):
    """The conjugate stresses s' (n, 3) [Pa], tangents (n, 3, 3) (d sigma / d de, the kernel's
    rows) and strain increments (n, 3) of the increments from ``state`` whose controlled
    variables are ``de_p`` (3,) with e'_k = each of ``t`` (n,). With other free entries than k,
    those are solved at each point so that their s' reach ``s_target`` (3,) (``mixed.mixed_step``
    with e'_k prescribed, from the previous point's solution; rows where it fails are NaN). Rows
    of increments the law refuses (``MaterialError``) are NaN too (``_rows``; the refusals
    appended to ``refusals``)."""
    _, A, Ainv = control.matrices()
    t = np.atleast_1d(np.asarray(t, float))
    n = t.size
    others = [i for i in range(3) if not control.strain_controlled[i] and i != k]
    ep = np.repeat(np.asarray(de_p, float)[None, :], n, axis=0)
    ep[:, k] = t
    if not others:
        de = ep @ Ainv.T
        rows = _rows(state, params, de, refusals)
        return rows.stress @ Ainv, rows.tangent, de
    sc = list(control.strain_controlled)
    sc[k] = True
    sig = np.full((n, 3), np.nan)
    tan = np.full((n, 3, 3), np.nan)
    de_all = np.full((n, 3), np.nan)
    guess = None
    for i in range(n):
        ctl = MixedControl(tuple(sc), tuple(ep[i]), (0.0, 0.0, 0.0), control.control_matrix)
        try:
            inc, de, _ = mixed_step(state, params, ctl, s_target, guess=guess)
        except MixedControlError:
            continue
        except MaterialError as refused:
            if refusals is not None:
                refusals.append(refused)
            continue
        sig[i] = to_voigt(inc.stress)[0] @ Ainv
        tan[i] = voigt_tangent(inc.tangent)[0]
        de_all[i] = guess = de
    return sig, tan, de_all


def _pattern_changes(state, params, de_a, de_b) -> dict:
    """What changes in the law's pattern between the increments de_a and de_b (3,) from
    ``state`` (the H-model: the hexagons that open or start / stop sliding,
    ``Material.pattern_changes``); {} for a law without patterns."""
    law = material_of(params)
    f = getattr(law, "pattern_changes", None)
    return {} if f is None else f(state, params, de_a, de_b)


def _no_change(params) -> dict:
    """The pattern record of an extremum where nothing changes (the law's empty one)."""
    f = getattr(material_of(params), "pattern_changes", None)
    return {} if f is None else f(None, params, None, None)


class _Scan:
    """One scan's fixed data: the state, the control, the step's controlled variables de_p (3,),
    the targets s_target (3,), the scanned entry k."""

    def __init__(self, state, params, control, de_p, s_target, k):
        self.state, self.params, self.control = state, params, control
        self.de_p, self.s_target, self.k = de_p, s_target, k
        self.T = float(s_target[k])
        _, _, self.Ainv = control.matrices()
        self.free = [i for i in range(3) if not control.strain_controlled[i]]
        self.refusals = []          # the law's refusals of increments of the scan (``_rows``)

    def rows(self, t):
        """(g = s'_k - target (n,), tangents (n, 3, 3), strain increments (n, 3)) at e'_k = t."""
        s, tan, de = control_scan(self.state, self.params, self.control, self.de_p,
                                  self.s_target, t, self.k, self.refusals)
        return s[:, self.k] - self.T, tan, de

    def g(self, x) -> float:
        return float(self.rows([x])[0][0])

    def sides(self, a, b):
        """(det, lam_min, w2) pairs and the hexagons that change, between e'_k = a and b."""
        _, tan, de = self.rows([a, b])
        det, lam, w2 = _indicators(tan, self.Ainv, self.free)
        pair = lambda v: (float(v[0]), float(v[1]))
        return pair(det), pair(lam), pair(w2), _pattern_changes(self.state, self.params, de[0], de[1])


def decide(state, params, control, s_target, de_p, tol: float,
           scan_strain: float = SCAN_STRAIN, n_scan: int = N_SCAN) -> Verdict:
    """Decide whether a static state exists next to ``state`` under ``control`` for the step
    whose controlled variables are ``de_p`` (3,) (its prescribed entries count; the free ones are
    the unknowns) and whose conjugate stresses must reach ``s_target`` (3,) [Pa] (its free entries
    count); ``tol`` the Newton tolerance [Pa] (a crossing is a continuous root when s' changes by
    less than 100 tol across its last bit). The bracket |e'_k| <= ``scan_strain`` is widened x4 up
    to ``SCAN_STRAIN_MAX`` while the closest approach lies at its end. See the module docstring.
    Increments the law refuses (``MaterialError``) are left out of the scans; if the target is
    reached nowhere else, the law's refusal is raised (a MaterialError: the path cannot go on
    within the law's domain) rather than an 'unresolved' verdict."""
    _, A, Ainv = control.matrices()
    free = [i for i in range(3) if not control.strain_controlled[i]]
    if not free:
        raise ValueError("a fully strain-controlled step has no stress target to decide")
    de_p = np.asarray(de_p, float).copy()
    de_p[free] = 0.0
    s_target = np.asarray(s_target, float)
    k = free[0]
    if len(free) > 1:
        # the free entry that dominates the near-null vector of the controlled block
        tan0 = material_of(params).update_rows(state, (de_p @ Ainv.T)[None, :], params).tangent
        B, _ = _block(tan0, Ainv, free)
        w, V = np.linalg.eig(B[0])
        k = free[int(np.argmax(np.abs(np.real(V[:, int(np.argmin(np.abs(w)))]))))]
    sc = _Scan(state, params, control, de_p, s_target, k)
    S = float(scan_strain)
    while True:
        t = np.linspace(-S, S, int(n_scan))
        g, tan, _ = sc.rows(t)
        ok = np.isfinite(g)
        v = _analyse(sc, t[ok], g[ok], tan[ok], tol)
        if v is not None:
            return v._replace(bracket=S, points=int(ok.sum()))
        if S >= SCAN_STRAIN_MAX:
            if sc.refusals:
                # not reached where the law answers, and the law refuses the rest: its refusal
                # (a MaterialError; the first met, in the narrowest bracket) is the end of the
                # path, not an unresolved step
                raise MaterialError(f"{sc.refusals[0]}; the step's static state, if any, lies "
                                    "among the increments it refuses (none among those it "
                                    f"accepts, |d e'| <= {S:g})")
            j = int(np.nanargmin(np.abs(g)))
            nan2 = (math.nan, math.nan)
            return Verdict("unresolved", k, sc.T, sc.T + float(g[j]), float(t[j]), 0.0, nan2, nan2,
                           nan2, S, int(ok.sum()), {}, math.nan)
        S *= 4.0


def _analyse(sc: _Scan, t, g, tan, tol):
    """The verdict from the scan g(t) = s'_k(t) - target, or None (widen the bracket)."""
    if t.size < 3:
        return None
    nan2 = (math.nan, math.nan)
    jumps = []
    for i in np.flatnonzero(np.sign(g[1:]) != np.sign(g[:-1])):
        a, b, ga, gb = float(t[i]), float(t[i + 1]), float(g[i]), float(g[i + 1])
        while True:                      # bisect to the last bit of e'_k
            m = 0.5 * (a + b)
            if not a < m < b:
                break
            gm = sc.g(m)
            if not np.isfinite(gm):
                break
            if np.sign(gm) == np.sign(ga):
                a, ga = m, gm
            else:
                b, gb = m, gm
        if abs(gb - ga) <= 100.0 * tol:
            x, gx = (a, ga) if abs(ga) <= abs(gb) else (b, gb)
            return Verdict("exists", sc.k, sc.T, sc.T + gx, x, 0.0, nan2, nan2, nan2, 0.0, 0, {},
                           abs(gx))
        jumps.append((a, b, ga, gb))
    if jumps:
        a, b, ga, gb = min(jumps, key=lambda j: abs(j[0]))      # the jump nearest the state
        det, lam, w2, hexa = sc.sides(a, b)
        return Verdict("discontinuous", sc.k, sc.T, sc.T + (ga if abs(ga) < abs(gb) else gb),
                       0.5 * (a + b), abs(gb - ga), det, lam, w2, 0.0, 0, hexa, math.nan)
    j = int(np.argmin(np.abs(g)))
    det = _indicators(tan, sc.Ainv, sc.free)[0]
    if np.ptp(g) <= 1e-12 * max(abs(sc.T), 1.0) or det[j] == 0.0:
        # no stiffness left where s'_k comes closest (e.g. every hexagon open: no tension)
        return Verdict("uncontrollable", sc.k, sc.T, sc.T + float(g[j]), float(t[j]), 0.0,
                       (0.0, 0.0), (0.0, 0.0), (0.0, 0.0), 0.0, 0,
                       _no_change(sc.params), math.nan)
    if j == 0 or j == t.size - 1:
        return None
    # the extremum of s'_k: golden section on |g| between the neighbours of the closest point
    lo, hi = float(t[j - 1]), float(t[j + 1])
    r = 0.5 * (math.sqrt(5.0) - 1.0)
    x1, x2 = hi - r * (hi - lo), lo + r * (hi - lo)
    f1, f2 = abs(sc.g(x1)), abs(sc.g(x2))
    while hi - lo > 4e-16 * max(abs(lo), abs(hi), 1e-300) and hi - lo > 1e-300:
        if f1 < f2:
            hi, x2, f2 = x2, x1, f1
            x1 = hi - r * (hi - lo)
            f1 = abs(sc.g(x1))
        else:
            lo, x1, f1 = x1, x2, f2
            x2 = lo + r * (hi - lo)
            f2 = abs(sc.g(x2))
        if not lo < x1 < x2 < hi:
            break
    x = x1 if f1 < f2 else x2
    gx = sc.g(x)
    if np.sign(gx) != np.sign(g[j]):
        # the refinement found a crossing the grid had missed: decide it as one
        xs = np.array([t[j - 1], x, t[j + 1]])
        gs = np.array([g[j - 1], gx, g[j + 1]])
        return _analyse(sc, xs, gs, sc.rows(xs)[1], tol)
    # the controlled block on either side of the extremum, as close to it as its sign change
    # shows (a smooth extremum is located only to about sqrt(ulp / curvature): closer, its sides
    # blur), out to the scan's neighbours of it
    spacing = float(t[1] - t[0])
    for d in spacing * 10.0 ** -np.arange(8.0, -1.0, -1.0):
        det, lam, w2, hexa = sc.sides(max(x - d, float(t[j - 1])), min(x + d, float(t[j + 1])))
        if det[0] * det[1] < 0 or (det[0] != 0.0) != (det[1] != 0.0):
            return Verdict("uncontrollable", sc.k, sc.T, sc.T + gx, x, 0.0, det, lam, w2, 0.0, 0,
                           hexa, math.nan)
    # s'_k turns back with its slope keeping its sign: by a jump, a discontinuity, not W2 = 0
    h = 1e-9 * (t[-1] - t[0])
    jump = abs(sc.g(x + h) - sc.g(x - h))
    if jump > 100.0 * tol:
        det, lam, w2, hexa = sc.sides(x - h, x + h)
        return Verdict("discontinuous", sc.k, sc.T, sc.T + gx, x, jump, det, lam, w2, 0.0, 0,
                       hexa, math.nan)
    return None
