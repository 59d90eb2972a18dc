"""The calibration's search (``dem.calibrate``), pure numerics: no DEM run. The search space
(``Space``, ``make_space``: u in [0, 1]^d <-> the varied fields' values), the model of the four
figures (``FigureModel``, a thin-plate-spline RBF per figure), what it says of the box
(``analyse``, ``identifiability``) and the deterministic search (``surrogate_search``), which
calls an ``evaluate`` function once per batch."""
from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np

from ..params import DemParams
from .targets import TOLERANCES, rank

# default search range (lo, hi, logarithmic) of the usual fields
# (friction from 10 deg: the one set known to meet the targets before issue 27 had 15 deg with
# rolling resistance 0.2, which raises the strength as friction would)
DEFAULT_BOUNDS = {"kn_over_d": (2e9, 32e9, True), "phi_g": (10.0, 50.0, False),
                  "kt_over_kn": (0.2, 1.0, False), "rolling_friction": (0.0, 0.3, False),
                  "rolling_stiffness": (0.25, 4.0, True)}
LOG_FIELDS = ("kn_over_d", "rolling_stiffness", "r_min", "r_max", "density")


def _round(v):
    return float(f"{v:.4g}")


@dataclasses.dataclass(frozen=True)
class Space:
    """The varied fields, their ranges [lo, hi] and scales; u in [0, 1]^d <-> values."""
    names: tuple
    lo: tuple
    hi: tuple
    log: tuple

    def values(self, u):
        out = []
        for j, x in enumerate(u):
            a, b = self.lo[j], self.hi[j]
            x = min(max(float(x), 0.0), 1.0)
            v = a * (b / a) ** x if self.log[j] else a + (b - a) * x
            out.append(min(max(_round(v), a), b))
        return tuple(out)

    def values_of_axis(self, j, x):
        """The value of parameter j at u_j = x (not rounded)."""
        a, b = self.lo[j], self.hi[j]
        return float(a * (b / a) ** x if self.log[j] else a + (b - a) * x)

    def u_of_axis(self, j, v):
        """u_j of the value v of parameter j (not clipped)."""
        a, b = self.lo[j], self.hi[j]
        return float(math.log(v / a) / math.log(b / a) if self.log[j] else (v - a) / (b - a))

    def u_of(self, values):
        """u of values inside the ranges, or None."""
        u = []
        for j, v in enumerate(values):
            a, b = self.lo[j], self.hi[j]
            if not a <= v <= b:
                return None
            u.append(math.log(v / a) / math.log(b / a) if self.log[j] else (v - a) / (b - a))
        return tuple(u)

    def params(self, base: DemParams, values) -> DemParams:
        return base.replace(**dict(zip(self.names, values)))


def make_space(vary, base: DemParams, bounds=None) -> Space:
    """The search space of the fields ``vary`` (ValueError naming --bounds when a range is
    missing, or gives parameters DemParams refuses)."""
    bounds = dict(bounds or {})
    extra = sorted(set(bounds) - set(vary))
    if extra:
        raise ValueError(f"--bounds {', '.join(extra)}: not in --vary {','.join(vary)}; allowed "
                         "ranges of the varied parameters only")
    lo, hi, log = [], [], []
    for f in vary:
        if f in bounds:
            a, b = bounds[f]
            lg = f in LOG_FIELDS and a > 0
        elif f in DEFAULT_BOUNDS:
            a, b, lg = DEFAULT_BOUNDS[f]
        else:
            v = getattr(base, f)
            if not v > 0:
                raise ValueError(f"--bounds: {f} has no default range (its start value is {v}); "
                                 f"allowed: give one, e.g. --bounds {f}=LO:HI")
            a, b, lg = 0.5 * v, 2.0 * v, True
        for x in (a, b):
            try:
                base.replace(**{f: x})
            except ValueError as e:
                raise ValueError(f"--bounds {f}={a:g}:{b:g}: {e}") from None
        lo.append(float(a)); hi.append(float(b)); log.append(bool(lg))
    return Space(tuple(vary), tuple(lo), tuple(hi), tuple(log))


# -- the search ---------------------------------------------------------------------------------
# A surrogate of the four figures (not of the score): each figure is a smooth function of the
# parameters, the score a sum of squares of them; a model of each figure also says which target
# can be met where, so the search can show that two targets conflict.
SMOOTHINGS = (0.0, 1e-4, 1e-3, 1e-2, 1e-1, 1.0, 10.0)   # candidates of the RBF smoothing (LOO)
MARGIN_SIGMAS = 2.0      # the model's error bar: 2 LOO errors at an evaluated set, growing
                         # away from it with the figure's slope between neighbouring sets
MIN_DISTANCE = 0.03      # a new candidate keeps this distance (in u) from every evaluated one
DENSE_POINTS = 2 ** 13   # the Sobol set on which the model is minimised (then polished)


def _band(k):
    """The target band of figure k in y = log(figure / target): [log(1 - tol), log(1 + tol)]."""
    t = TOLERANCES[k]
    return math.log(1.0 - t), math.log(1.0 + t)


CENSORED = ("at least", "unknown")   # how a stopped run knows a figure: from below, or not


def _loo_smoothing(U, Y):
    """The smoothing of each column of Y among SMOOTHINGS of least leave-one-out error (the
    first of equal ones) and that error: (indices, RMS errors), one per column."""
    from scipy.interpolate import RBFInterpolator
    n = len(U)
    loo = np.full((len(SMOOTHINGS), Y.shape[1]), np.inf)
    for i, s in enumerate(SMOOTHINGS):
        err = np.empty_like(Y)
        for j in range(n):
            keep = np.arange(n) != j
            try:
                f = RBFInterpolator(U[keep], Y[keep], smoothing=s,
                                    kernel="thin_plate_spline", degree=1)
                err[j] = f(U[j:j + 1])[0] - Y[j]
            except (np.linalg.LinAlgError, ValueError):
                err[j] = np.inf
        loo[i] = np.sqrt(np.mean(err ** 2, axis=0))
    best = np.argmin(loo, axis=0)
    return best, loo[best, np.arange(Y.shape[1])]


def _slope(U, y):
    """The largest over the rows of |dy| / |du| to the nearest other row."""
    D = np.linalg.norm(U[:, None, :] - U[None], axis=2)
    np.fill_diagonal(D, np.inf)
    j = np.argmin(D, axis=1)
    return float(np.max(np.abs(y - y[j]) / D[np.arange(len(U)), j]))


class FigureModel:
    """Radial-basis-function model (thin-plate spline with a linear tail, scipy's
    ``RBFInterpolator``) of y_k = log(figure_k / target_k), k in TOLERANCES, over u in [0, 1]^d.

    The smoothing of each figure is chosen among SMOOTHINGS by leave-one-out (LOO) error: 0
    (interpolation) for an exact model, larger where the DEM's sample-to-sample scatter is;
    ``loo[k]`` (the RMS LOO error of y_k, i.e. a relative error) is the model's own error bar.
    U: (n, d) array, Y: (n, k) array (columns in the order of TOLERANCES, or of ``names``).

    ``censored``: None (every value exact) or an (n, k) array of how each value is known, 0
    exact, 1 from below (Y the bound: a run stopped before its peak, ``InRunDecision``), 2 not
    at all (Y ignored). A figure's model is then fitted on its exact values (the smoothing and
    LOO error from them alone) and its bounds: a bound the exact values' model predicts
    exceeded is that prediction (it says nothing more), one it predicts not reached is the
    value (the least the set's figure can be); ``Y`` holds the values so taken (NaN where
    unknown). Each figure needs d + 2 exact values (``model_sets_min``)."""

    def __init__(self, U, Y, names=None, censored=None):
        from scipy.interpolate import RBFInterpolator
        self.U = np.asarray(U, float)
        self.Y = np.array(Y, float)
        n, d = self.U.shape
        if n < d + 2:
            raise ValueError(f"FigureModel: {n} points in {d} dimensions; needs at least {d + 2}")
        self.names = tuple(TOLERANCES) if names is None else tuple(names)   # Y's columns
        if self.Y.ndim != 2 or self.Y.shape[1] != len(self.names):
            raise ValueError(f"FigureModel: Y has {self.Y.shape[-1]} columns for the figures "
                             f"{', '.join(self.names)}")
        C = np.zeros(self.Y.shape, int) if censored is None else np.asarray(censored, int)
        tps = dict(kernel="thin_plate_spline", degree=1)
        if not C.any():
            best, loo = _loo_smoothing(self.U, self.Y)
            self.smoothing = tuple(SMOOTHINGS[i] for i in best)
            self.loo = {k: float(e) for k, e in zip(self.names, loo)}
            self._f = [RBFInterpolator(self.U, self.Y[:, c], smoothing=self.smoothing[c], **tps)
                       for c in range(self.Y.shape[1])]
            self.slope = {k: _slope(self.U, self.Y[:, c]) for c, k in enumerate(self.names)}
            return
        smoothing, self.loo, self._f, self.slope = [], {}, [], {}
        for c, k in enumerate(self.names):
            exact, below = C[:, c] == 0, C[:, c] == 1
            if exact.sum() < d + 2:
                raise ValueError(f"FigureModel: {k} known exactly on {exact.sum()} points in "
                                 f"{d} dimensions; needs at least {d + 2}")
            best, loo = _loo_smoothing(self.U[exact], self.Y[exact][:, [c]])
            s = SMOOTHINGS[best[0]]
            if below.any():
                f = RBFInterpolator(self.U[exact], self.Y[exact, c], smoothing=s, **tps)
                self.Y[below, c] = np.maximum(self.Y[below, c], f(self.U[below]))
            self.Y[C[:, c] == 2, c] = np.nan
            rows = exact | below
            smoothing.append(s)
            self.loo[k] = float(loo[0])
            self._f.append(RBFInterpolator(self.U[rows], self.Y[rows, c], smoothing=s, **tps))
            self.slope[k] = _slope(self.U[rows], self.Y[rows, c])
        self.smoothing = tuple(smoothing)

    def distance(self, U):
        """Distance (in u) of each row of U to the nearest set the model was fitted on."""
        return nearest_distance(U, self.U)

    def __call__(self, U):
        """Predicted y (m, k) at u (m, d)."""
        U = np.atleast_2d(np.asarray(U, float))
        return np.stack([f(U) for f in self._f], axis=1)

    def score(self, U):
        """Predicted score sum_k ((exp(y_k) - 1) / tol_k)^2 at u (m, d)."""
        tol = np.array([TOLERANCES[k] for k in self.names])
        return np.sum(((np.exp(self(U)) - 1.0) / tol) ** 2, axis=1)

    def miss(self, U, which=None, error_bar=False):
        """max over the targets ``which`` (default all) of the distance of predicted y_k to its
        band, in units of the band's half-width: 0 where every one of them is predicted met.
        ``error_bar``: each band widened by the model's error bar there, MARGIN_SIGMAS * loo[k]
        + slope[k] * (distance to the nearest set evaluated): 0 where the model cannot rule out
        that every one of them is met."""
        Y = self(U)
        out = np.zeros(len(Y))
        dist = self.distance(U) if error_bar else None
        for c, k in enumerate(self.names):
            if which is not None and k not in which:
                continue
            lo, hi = _band(k)
            w = (MARGIN_SIGMAS * self.loo[k] + self.slope[k] * dist) if error_bar else 0.0
            d = np.maximum(lo - w - Y[:, c], 0.0) + np.maximum(Y[:, c] - hi - w, 0.0)
            out = np.maximum(out, d / (0.5 * (hi - lo)))
        return out


def _polish(fun, u0, method):
    from scipy.optimize import minimize
    d = len(u0)
    r = minimize(lambda u: float(fun(np.clip(u, 0.0, 1.0)[None, :])[0]), u0, method=method,
                 bounds=[(0.0, 1.0)] * d,
                 options={"maxiter": 200 * d} if method == "Nelder-Mead" else {"maxiter": 200})
    u = np.clip(r.x, 0.0, 1.0)
    return u, float(fun(u[None, :])[0])


def _minimise(fun, dense, method="L-BFGS-B", starts=3):
    """Minimum of fun over the box: the best of ``dense`` points, polished from the ``starts``
    best of them (L-BFGS-B for the smooth score, Nelder-Mead for a max of distances)."""
    v = fun(dense)
    order = np.argsort(v, kind="stable")
    best_u, best_v = dense[order[0]].copy(), float(v[order[0]])
    for i in order[:starts]:
        u, f = _polish(fun, dense[i], method)
        if f < best_v - 1e-15:
            best_u, best_v = u, f
    return best_u, best_v


def analyse(model: FigureModel, dense):
    """What the model says of the box: the minimum of the predicted score (and where), whether
    it predicts a set meeting every target (``predicted_met``), whether it can rule out that
    any does within its error bar (``reachable`` False: the proof), which targets no set can
    meet and which pairs no set can meet together (within the error bar)."""
    u_best, s_best = _minimise(model.score, dense)
    names = model.names
    out = {"u_best": u_best.tolist(), "predicted_score": s_best,
           "predicted_errors": {k: float(np.expm1(y)) for k, y in zip(names, model(u_best)[0])},
           "loo": dict(model.loo), "smoothing": dict(zip(names, model.smoothing))}

    def least(which):
        u, v = _minimise(lambda U: model.miss(U, which, True), dense, "Nelder-Mead")
        return u, v

    out["predicted_met"] = bool(_minimise(model.miss, dense, "Nelder-Mead")[1] <= 0.0)
    u_all, m_all = least(None)
    out["reachable"] = bool(m_all <= 0.0)
    out["slope"] = dict(model.slope)
    out["least_miss"] = m_all                 # in band half-widths, beyond the error bar
    out["least_miss_at"] = u_all.tolist()
    out["unreachable_targets"] = [k for k in names if least((k,))[1] > 0.0]
    out["conflicts"] = [f"{a}+{b}" for a, b in itertools.combinations(names, 2)
                        if least((a, b))[1] > 0.0]
    return out


def identifiability(model: FigureModel, space, u, dense):
    """Which parameters the targets fix at u: the sensitivities d y_k / d u_j (central
    differences of the model, in band half-widths per unit of u), their singular values, and
    the extent of the region the model predicts to meet every target (no margin) along each
    parameter (values; None when that region is empty)."""
    u = np.asarray(u, float)
    d = len(u)
    h = 0.02
    J = np.zeros((len(model.names), d))
    for j in range(d):
        a, b = u.copy(), u.copy()
        a[j], b[j] = max(u[j] - h, 0.0), min(u[j] + h, 1.0)
        J[:, j] = (model(b[None, :])[0] - model(a[None, :])[0]) / (b[j] - a[j])
    half = np.array([0.5 * (_band(k)[1] - _band(k)[0]) for k in model.names])
    G = J / half[:, None]
    sv = np.linalg.svd(G, compute_uv=False)
    inside = dense[model.miss(dense) <= 0.0]
    region = None
    if len(inside):
        region = {n: [space.values_of_axis(j, inside[:, j].min()),
                      space.values_of_axis(j, inside[:, j].max())]
                  for j, n in enumerate(space.names)}
    return {"sensitivity": {k: dict(zip(space.names, map(float, G[c])))
                            for c, k in enumerate(model.names)},
            "singular_values": [float(s) for s in sv],
            "met_region": region, "met_region_share": float(len(inside) / len(dense))}


def dense_points(d, seed):
    """DENSE_POINTS scrambled Sobol points in [0, 1]^d (seeded)."""
    from scipy.stats import qmc
    return qmc.Sobol(d, scramble=True, seed=seed).random_base2(int(math.log2(DENSE_POINTS)))


def initial_design(d, n, seed):
    """n scrambled Sobol points in [0, 1]^d (seeded; the first n of a 2^m set, so a larger n
    starts the same way)."""
    from scipy.stats import qmc
    m = max(int(math.ceil(math.log2(max(n, 2)))), 1)
    return qmc.Sobol(d, scramble=True, seed=seed).random_base2(m)[:n]


def model_of(space: Space, sets, target, names=None):
    """The ``FigureModel`` of the sets inside the box: y_k = log(figure_k / target_k) over
    (values, record) pairs ``sets``, censored where the record says (its "censored": {figure:
    one of CENSORED}, a first run stopped by ``InRunDecision``), or None while a figure is known
    exactly on fewer than ``model_sets_min`` of them (``short_figures``)."""
    names = tuple(TOLERANCES) if names is None else tuple(names)
    inside = [(space.u_of(tuple(v)), r) for v, r in sets]
    inside = [(u, r) for u, r in inside if u is not None]
    if short_figures(space, [r for _, r in inside], names):
        return None
    code = lambda r, f: 1 + CENSORED.index(r["censored"][f]) if f in (r.get("censored") or {}) \
        else 0
    C = np.array([[code(r, f) for f in names] for _, r in inside], int)
    Y = [[math.log(r[f] / target[f]) if c < 2 else math.nan for f, c in zip(names, row)]
         for (_, r), row in zip(inside, C)]
    return FigureModel([u for u, _ in inside], Y, names, C if C.any() else None)


def short_figures(space: Space, records, names=None):
    """The figures known exactly on fewer than ``model_sets_min`` of ``records`` (those inside
    the box): what the model lacks."""
    have = _exact_counts(records, names)
    return [f for f, n in have.items() if n < space_dim_min(space)]


def _exact_counts(records, names=None):
    """{figure: on how many of ``records`` it is known exactly (not in their "censored")}."""
    return {f: sum(f not in (r.get("censored") or {}) for r in records)
            for f in (tuple(TOLERANCES) if names is None else names)}


def to_complete(space: Space, sets):
    """The stopped sets (values) to run to the end so that every figure is known exactly on
    ``model_sets_min`` sets inside the box: in the order of ``rank`` (the score so far, a bound
    from below: the sets nearest the targets first), each one taken when it lacks a figure
    still short."""
    inside = [(v, r) for v, r in sets if space.u_of(tuple(v)) is not None]
    need = space_dim_min(space)
    have = _exact_counts([r for _, r in inside])
    out = []
    for v, r in sorted((p for p in inside if p[1].get("censored")), key=lambda p: rank(p[1])):
        if any(have[f] < need for f in r["censored"]):
            out.append(tuple(v))
            for f in r["censored"]:
                have[f] += 1
    return out


def surrogate_search(space: Space, evaluate, target, start=None, initial=16, max_evals=32, batch=1,
                     design_seed=0, complete=None):
    """Global search of the parameter sets (module docstring): the start set, a space-filling
    design of ``initial`` Sobol points, then rounds of ``batch`` sets where the model of the
    four figures (``FigureModel``, refitted on every evaluation inside the box) predicts the
    lowest score, each at least MIN_DISTANCE from those evaluated.  Stops when an evaluated set
    meets every target, when the model shows that none within the box can (``analyse``: no
    point meets them all even with every target widened by the model's error bar there), or at
    ``max_evals`` sets.  While the model predicts no set meeting every target, the rounds
    explore instead (``_explore``): where its error bar leaves the most room for one.

    ``target``: the target figures (dict of TOLERANCES' keys).  ``evaluate(list of value
    tuples, stage) -> list of records`` (dicts with at least met, score, index and the figures
    of TOLERANCES), called once per batch with the sets not evaluated yet.  Returns (best
    record, {values: record}, trace, why it stopped, the model's last analysis or None).

    A record may know some figures only from below or not at all (its "censored": a first run
    stopped once it decided, ``InRunDecision``); ``complete(list of value tuples, stage) ->
    list of records`` then runs such sets to the end, the fewest that give the model every
    figure exactly on ``model_sets_min`` sets (``to_complete``), before the model is fitted."""
    if initial < space_dim_min(space):
        raise ValueError(f"initial={initial!r}; allowed an integer >= {space_dim_min(space)}")
    seen = {}
    trace = []
    state = {"full": False}
    dense = dense_points(len(space.names), design_seed + 1)

    def run(points, stage):
        todo = []
        for v in points:
            if v not in seen and v not in todo:
                todo.append(v)
        room = max_evals - len(seen)
        if len(todo) > room:
            todo, state["full"] = todo[:max(room, 0)], True
        recs = evaluate(todo, stage) if todo else []
        seen.update(zip(todo, recs))
        trace.append({"stage": stage, "points": len(points), "evaluated": len(todo)})

    def best():
        return min(seen.values(), key=rank)

    if start is not None:
        run([tuple(start)], "start")
    if not state["full"]:
        run([space.values(u) for u in initial_design(len(space.names), initial, design_seed)],
            "design")
    k = 0
    why, info = None, None
    while True:
        if best()["met"]:
            why = "targets met"
            break
        if complete is not None:
            todo = to_complete(space, seen.items())
            if todo:
                seen.update(zip(todo, complete(todo, f"complete{k + 1}")))
                trace.append({"stage": f"complete{k + 1}", "points": len(todo),
                              "evaluated": len(todo)})
        model = model_of(space, seen.items(), target)
        if model is not None:
            info = analyse(model, dense)
            info["round"] = k
            trace[-1]["model"] = {key: info[key] for key in (
                "predicted_score", "predicted_met", "reachable", "least_miss", "conflicts", "loo")}
            if not info["reachable"]:
                why = "no set within the bounds meets the targets"
                break
        if state["full"] or len(seen) >= max_evals:
            why = "max_evals reached"
            break
        if model is None:
            why = "too few evaluations inside the bounds for a model"
            break
        k += 1
        U_seen = np.array([space.u_of(v) or [np.nan] * len(space.names) for v in seen])
        chosen = []
        explore = not info["predicted_met"]
        for _ in range(batch):
            ref = np.vstack([U_seen] + [np.atleast_2d(c) for c in chosen])
            # the model predicts no set that meets every target but cannot rule one out: look
            # where its error bar leaves the most room
            u = _explore(model, dense, ref) if explore else _candidate(model, dense, ref)
            if u is None:
                break
            chosen.append(u)
        if not chosen:
            why = "every point the model suggests is within MIN_DISTANCE of an evaluated one"
            break
        run([space.values(u) for u in chosen], f"{'explore' if explore else 'model'}{k}")
    return best(), seen, trace, why, info


def model_sets_min(d):
    """The fewest evaluations inside the box the model needs in ``d`` dimensions (thin-plate
    spline with a linear tail: d + 2, so that one can be left out); the least --initial
    (``CalibrationOptions``)."""
    return d + 2


def space_dim_min(space):
    """``model_sets_min`` of the space's dimension."""
    return model_sets_min(len(space.names))


def nearest_distance(P, ref):
    """Distance (in u) of each row of P to the nearest row of ref (rows of nan, sets outside
    the box, are ignored)."""
    P = np.atleast_2d(np.asarray(P, float))
    return np.nanmin(np.linalg.norm(P[:, None, :] - np.asarray(ref, float)[None], axis=2), axis=1)


def _explore(model, dense, ref):
    """Among the dense points at least MIN_DISTANCE from every row of ref, those of least miss
    within the model's error bar, and of them the one of least predicted miss (the model's
    best guess of where the targets may be met)."""
    far = nearest_distance(dense, ref) >= MIN_DISTANCE
    if not far.any():
        return None
    P = dense[far]
    bar = model.miss(P, error_bar=True)
    P = P[bar <= bar.min() + 1e-12]
    return P[int(np.argmin(model.miss(P)))]


def _candidate(model, dense, ref):
    """The point of least predicted score at least MIN_DISTANCE from every row of ref: the
    polished minimum when it keeps the distance, else the best dense point that does."""
    ok = lambda U: nearest_distance(U, ref) >= MIN_DISTANCE
    u, _ = _minimise(model.score, dense)
    if ok(u)[0]:
        return u
    far = ok(dense)
    if not far.any():
        return None
    s = model.score(dense[far])
    return dense[far][int(np.argmin(s))]
