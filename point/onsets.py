"""The analysis's onsets stood beside their closed forms, for a law with a single mechanism
(``Material.mechanism`` not None: Drucker-Prager; ``point.closed_forms``): what the command lines
write in each summary as value, closed form and difference, and print one line each.

Along a path, every criterion of ``point.closed_forms`` fires where the hardening modulus h
falls to the criterion's own h_crit (h = 0 the limit state, h_sym the first W2 <= 0 over every
direction, h_loc Rice's localization, h_R the peak of c along a proportional path, h_c the loss
of control): ``first_root`` finds the first row of the path's own states (single points, as the
driver keeps them) where g = h - h_crit <= 0 on a loaded state, and interpolates every quantity
of the path to g = 0 through that row, the one before and a third beside them (a parabola in g),
so that it needs nothing of the law but its mechanism (for Drucker-Prager's drained path the
same root is a 1D root in kappa, tests/point/test_exact_analysis.py). The interpolation's error
is O(step^3) in a smooth quantity along the path, also where the quantity peaks at the root (q
at h = 0, c at h = h_R, where a line through two rows would miss the peak by O(step^2)): far
below one step of the path, which is what the analysis's own onsets (a row of the path) can
differ by.

A law without a mechanism (the H-model) has none of this: its summaries say ``NO_CLOSED_FORM``.
"""
from __future__ import annotations

import math

import numpy as np

from .closed_forms import (cone_edges, det_D, golden_section, h_control, h_path, h_rice, h_sym,
                           plane_operator)
from .contract import Material, material_of
from .tensors import mandel_tangent

__all__ = ["NO_CLOSED_FORM", "has_mechanism", "compare", "first_root", "biaxial_onsets",
           "probe_onsets", "domain_onsets", "path_onsets", "exact_min_w2", "line"]

NO_CLOSED_FORM = "no closed form for this law"
# rows between two evaluations of an expensive criterion (Rice's: a search over the normals)
# before the bisection of the block where it fires
RICE_STRIDE = 32


def has_mechanism(law) -> bool:
    """True if ``law`` gives a single mechanism (it implements ``Material.mechanism``): its
    onsets have closed forms."""
    return type(law).mechanism is not Material.mechanism


def _f(x):
    x = float(x)
    return x if math.isfinite(x) else None


def compare(value, closed) -> dict:
    """{"value", "closed_form", "difference" (value - closed form)} (None where not finite)."""
    v, c = _f(value), _f(closed)
    return {"value": v, "closed_form": c,
            "difference": None if v is None or c is None else v - c}


def first_root(states, params, h_crit, values: dict, stride: int = 1):
    """The first row j >= 1 of ``states`` whose state is loaded (``Material.plastic``) and has
    g = h - h_crit(mechanism) <= 0, and the root: {"row": j, "fraction": t in (0, 1] (the root
    between rows j - 1 and j, linear in g), name: each array of ``values`` at g = 0, by the
    parabola in g through rows j - 1, j and j + 1 (j - 2 at the path's end; the line through
    j - 1 and j where a third row has no finite g)}; None where no row has it. With ``stride``
    > 1 every stride-th row is tried, then the block where g first falls to 0 is bisected (the
    first row where g changes sign once in the block)."""
    law = material_of(params)

    def g(j):
        s = states[j]
        if not bool(np.all(law.plastic(s, ()))):
            return math.inf
        m = law.mechanism(s, params)
        return math.inf if m is None else float(m.h) - float(h_crit(m))

    n = len(states)
    found = None
    prev = 0
    for j in range(1, n, max(1, int(stride))):
        if g(j) <= 0:
            found = j
            break
        prev = j
    if found is None and stride > 1 and prev < n - 1 and g(n - 1) <= 0:
        found = n - 1
    if found is None:
        return None
    lo, hi = prev, found
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if g(mid) <= 0 else (mid, hi)
    j = hi
    def g_any(i):           # g of a row, loaded or not (the interpolation's nodes)
        m = law.mechanism(states[i], params)
        return math.inf if m is None else float(m.h) - float(h_crit(m))
    g0, g1 = g_any(j - 1), g(j)
    t = g0 / (g0 - g1) if math.isfinite(g0) and g0 > 0 and g0 != g1 else 1.0
    rows = [j - 1, j]
    third = j + 1 if j + 1 < n else j - 2
    if t < 1.0 and third >= 0:
        g2 = g_any(third)
        if math.isfinite(g2) and g2 not in (g0, g1):
            rows.append(third)
    gs = {j - 1: g0, j: g1, **({rows[2]: g2} if len(rows) == 3 else {})}
    out = {"row": int(j), "fraction": float(t)}
    for k, v in values.items():
        v = np.asarray(v, dtype=float)
        if t >= 1.0:
            out[k] = float(v[j])
            continue
        # Lagrange's polynomial through the rows, in g, at g = 0
        out[k] = float(sum(v[a] * np.prod([gs[b] / (gs[b] - gs[a]) for b in rows if b != a])
                           for a in rows))
    return out


def _path_values(r):
    p, q, eta = r.invariants()
    return {"eps1": r.eps[:, 0], "eta": eta, "p": p, "q": q}


def _onset(r, params, h_crit, criterion, value: dict):
    """One onset along the path ``r`` (states kept): the analysis's ``value`` (name -> number:
    eta, eps1, ...; NaN where it found none) against the closed-form root of h = h_crit."""
    root = first_root(r.states, params, h_crit, _path_values(r))
    out = {"criterion": criterion}
    for k, v in value.items():
        out[k] = compare(v, root[k] if root else math.nan)
    out["closed_form_row"] = None if root is None else root["row"]
    return out


H0 = "h = 0: det D = 0, the limit state under stress control (the drained peak)"
HSYM = "h = h_sym = (sqrt(P:E:P Q:E:Q) - P:E:Q)/2: the first W2 <= 0 in some direction"
HRICE = "h = h_loc, Rice's localization: det(n.D.n) = 0 for some normal n"


def biaxial_onsets(r, params) -> dict:
    """The drained peak of the path ``r`` (states kept): its largest q against h = 0."""
    v = _path_values(r)
    k = int(np.argmax(v["q"]))
    return {"peak": _onset(r, params, lambda m: 0.0, H0,
                           {"eta": v["eta"][k], "eps1": v["eps1"][k], "q": v["q"][k]})}


def domain_onsets(r, params, d) -> dict:
    """The domain point ``d`` (``experiment.DomainPoint``) of a drained path against the roots
    along ``r``, the same drained path with its states (to past the peak): the first W2 <= 0 and
    W2_sigma <= 0 against h_sym, Rice's onset (closed form only: the material point's analysis
    has no localization check), the peak against h = 0."""
    vals = _path_values(r)

    def at(p, q, eps1):
        with np.errstate(invalid="ignore", divide="ignore"):
            return {"eta": q / p, "eps1": eps1}
    out = {"sigma2": float(d.sigma2),
           "first_w2": _onset(r, params, h_sym, HSYM, at(d.p_w2, d.q_w2, d.eps1_w2)),
           "first_w2_sigma": _onset(r, params, h_sym, HSYM + " (W2_sigma = W2 at small strain)",
                                    at(d.p_w2sigma, d.q_w2sigma, d.eps1_w2sigma)),
           "peak": _onset(r, params, lambda m: 0.0, H0, at(d.p_peak, d.q_peak, d.eps1_peak))}
    rice = first_root(r.states, params, lambda m: h_rice(m, n_grid=90)[0], vals, RICE_STRIDE)
    out["rice"] = {"criterion": HRICE, "value": None,
                   "note": "the material point's analysis has no localization check (the FE's "
                           "local check has)",
                   "eta_closed_form": None if rice is None else rice["eta"],
                   "eps1_closed_form": None if rice is None else rice["eps1"]}
    return out


def path_onsets(r, params, ratio, c, k_peak, control, holds) -> dict:
    """A proportional path of the burst (``r`` with its states, from its start; ``c`` its
    conjugate stress, ``k_peak`` the row of its c peak or None): the c peak against h = h_R
    (u.D.u = 0, u = (1, R, 0)), and each run held at c (``holds``: [(switch, c_hold,
    static_verdict)]) against the closed form's verdict: a static state with c = c_hold exists
    iff c_hold lies below the c where h = h_c, the loss of control under ``control`` (the tie,
    c controlled: det of its controlled block = 0)."""
    u = (1.0, float(ratio), 0.0)
    vals = dict(_path_values(r), c=np.asarray(c, dtype=float)[:len(r.states)])
    peak = first_root(r.states, params, lambda m: h_path(m, u), vals)
    ctl = first_root(r.states, params,
                     lambda m: h_control(m, control.strain_controlled, control.control_matrix), vals)
    out = {"criterion": "h = h_R = (u.E.Q)(P.E.u)/(u.E.u) - P:E:Q, u = (1, R, 0): the peak of c"}
    for k in ("eta", "eps1", "c"):
        v = vals[k][k_peak] if k_peak is not None else math.nan
        out[k] = compare(v, peak[k] if peak else math.nan)
    c_c = ctl["c"] if ctl else math.nan
    out["c_at_h_control"] = _f(c_c)
    out["runs"] = []
    for switch, c_hold, verdict in holds:
        exact = "exists" if not c_c < c_hold else "uncontrollable"
        out["runs"].append({"switch": switch, "c_hold": float(c_hold),
                            "verdict": {"value": verdict, "closed_form": exact,
                                        "agree": verdict == exact}})
    return out


# -- at one state: the cone, min W2, the tangent's determinants --------------------------------
def _mandel_dir(t_deg):
    t = math.radians(t_deg)
    return np.array([math.cos(t), math.sin(t), 0.0])


def exact_cone(m) -> tuple:
    """(strain-plane edges alpha_eps, stress-plane edges alpha_sigma) [deg] of the cone W2 < 0
    of the mechanism ``m`` on its loading side (P:E:d eps > 0; P:d sigma > 0)."""
    D = m.tangent()
    strain = [e for e in cone_edges(plane_operator(D, "strain"))
              if m.P @ m.E @ _mandel_dir(e) > 0]
    stress = [(90.0 - t) % 360.0 for t in cone_edges(plane_operator(D, "stress"))
              if m.P @ _mandel_dir(t) > 0]
    return strain, stress


def exact_min_w2(m, n: int = 7200) -> tuple:
    """The minimum over strain directions d eps = (cos t, sin t) of the normalized W2 =
    d eps:D:d eps / (|D:d eps| |d eps|) of the exact rate tangent (D on the loading side
    P:E:d eps > 0, E elsewhere), and its t [deg]: a grid of ``n`` directions, then golden
    section around the lowest (to the last bits of t)."""
    D = m.tangent()
    PE = m.P @ m.E

    def w(t):
        x = _mandel_dir(t)
        M = D if PE @ x > 0 else m.E
        y = M @ x
        return float(x @ y / np.linalg.norm(y))
    grid = 360.0 * np.arange(n) / n
    k = int(np.argmin([w(t) for t in grid]))
    t, least = golden_section(w, grid[k] - 360.0 / n, grid[k] + 360.0 / n, 1e-12)
    return least, t % 360.0


def _nearest(got, exact):
    """Each of ``got`` [deg] beside the nearest of ``exact`` (mod 360) and their difference."""
    out = []
    for e in got:
        if not exact:
            out.append((e, None, None))
            continue
        x = min(exact, key=lambda v: abs((v - e + 180.0) % 360.0 - 180.0))
        out.append((e, x, (e - x + 180.0) % 360.0 - 180.0))
    return out


def probe_onsets(state, params, sweep, edges, tangent, loading_dir=(1.0, -1.0)) -> dict:
    """The directional analysis at A against the closed forms of the mechanism there: the
    cone's edges (``edges``: ``probes.cone_edges``'s, each with alpha_eps and alpha_sigma) in
    the strain and the stress plane, min W2 of the sweep against ``exact_min_w2``, and the
    tangent's criteria (``tangent``: ``probes.tangent_criteria`` on the branch of the strain
    direction ``loading_dir``) against the mechanism's tangent on the same branch: lam_min and
    det of the symmetric principal block and of the block, det D (``closed_forms.det_D``)
    against the determinant of the law's rate tangent."""
    law = material_of(params)
    m = law.mechanism(state, params)
    strain, stress = exact_cone(m)
    d = np.array([loading_dir[0], loading_dir[1], 0.0])
    loading = float(m.P @ m.E @ d) > 0
    D = m.tangent() if loading else m.E
    M = D[:2, :2]
    Ms = 0.5 * (M + M.T)
    C = law.rate_tangent(state, np.diag(np.asarray(loading_dir, dtype=float)), params)
    k = int(np.nanargmin(sweep.w2))
    w_exact, t_exact = exact_min_w2(m)
    pair = lambda got, ex: {"value": [g for g, _, _ in _nearest(got, ex)],      # noqa: E731
                            "closed_form": [x for _, x, _ in _nearest(got, ex)],
                            "difference": [e for _, _, e in _nearest(got, ex)],
                            "closed_form_all": ex}
    return {
        "cone_edges_strain_plane": dict(pair([e["alpha_eps"] for e in edges], strain),
                                        criterion="alpha_eps [deg] where W2 = 0 on the loading "
                                        "side: the roots of the strain plane's sym(D_12)"),
        "cone_edges_stress_plane": dict(pair([e["alpha_sigma"] for e in edges], stress),
                                        criterion="alpha_sigma [deg] where W2 = 0 on the loading "
                                        "side: the roots of the stress plane's sym(D^-1_12), "
                                        "alpha_sigma = 90 - t"),
        "min_w2": dict(compare(sweep.w2[k], w_exact),
                       criterion="min over strain directions of the normalized W2 of the exact "
                       "rate tangent (D loading, E unloading)",
                       alpha_eps=compare(sweep.alpha_eps[k], t_exact)),
        "lam_min_Msym": dict(compare(tangent["lam_min_Msym_cauchy"], np.linalg.eigvalsh(Ms)[0]),
                             criterion="lowest eigenvalue of the symmetric principal block of "
                             "D [Pa]: W2 <= 0 in the strain plane where it is <= 0"),
        "det_M": dict(compare(tangent["det_M_cauchy"], np.linalg.det(M)),
                      criterion="det of the principal block of D [Pa^2]"),
        "det_D": dict(compare(np.linalg.det(mandel_tangent(C)), det_D(m) if loading
                              else np.linalg.det(m.E)),
                      criterion="det D = det E h / (h + P:E:Q) [Pa^3] (Mandel)"),
        "h": _f(m.h), "h_sym": _f(h_sym(m)),
    }


def line(name, entry, key=None, fmt=".7g") -> str:
    """One printed line of a comparison: 'name: key = value (closed form x, difference d)', of
    ``entry[key]`` (an onset's eta, eps1, ...) or, without ``key``, of ``entry`` itself."""
    c = entry[key] if key else entry
    v, x, d = c["value"], c["closed_form"], c["difference"]
    show = lambda y: "none" if y is None else format(y, fmt)         # noqa: E731
    return (f"{name}: {key + ' = ' if key else ''}{show(v)} (closed form {show(x)}, difference "
            f"{'none' if d is None else format(d, '.3g')})")
