"""The calibration's targets (``dem.calibrate``): the four figures of a drained biaxial curve
(peak q, eps1 at PEAK_FRACTION of it, the secant modulus, the dilatancy ratio after eps1_95;
``curve_figures``), their tolerances and relative errors (``compare``, ``rank``), what one run
decides of a set's mean (``first_run_decides``; and from part of its curve,
``decided_in_run``), and the H-model's curve they are read from (``hmodel_curve``)."""
from __future__ import annotations

import math

import numpy as np

TOLERANCES = {"peak_q": 0.05, "eps1_95": 0.25, "secant": 0.20, "dilatancy": 0.05}
PEAK_FRACTION = 0.95     # eps1_95: the first strain where q reaches this fraction of its peak
DILATANCY_STRAIN = 0.01  # dilatancy: the slope of eps_v over eps1 in [eps1_95, eps1_95 + this]
FIGURE_TEXT = {"peak_q": "peak q", "eps1_95": "eps1 at 95 % of the peak",
               "secant": "secant modulus q/eps1 at eps1 = 0.25 %",
               "dilatancy": "dilatancy ratio 1 - d eps_v/d eps1 over 1 % after eps1_95"}
SECANT_STRAIN = 0.0025
TARGETS = ("hmodel",)


# -- a set decided on its first run ---------------------------------------------------------------
# One 2000-disk run's scatter about its set's mean: the relative standard deviation (sd / mean,
# ddof 1) of each figure over 16 seeds of the calibrated set (the calibration gallery's
# sample_scatter.csv: peak q 4.87 %, eps1_95 48.2 %, secant 3.24 %, dilatancy ratio 3.08 %).
ONE_RUN_SCATTER = {"peak_q": 0.0487, "eps1_95": 0.482, "secant": 0.0324, "dilatancy": 0.0308}
SCATTER_DISKS = 2000     # the sample size it was measured at
DECIDE_Z = 3.0           # a first run decides beyond this many predictive standard deviations


def one_run_scatter(n_disks: int) -> dict:
    """A run's relative scatter of each figure for a sample of ``n_disks``: the measured
    ``ONE_RUN_SCATTER`` at 2000 disks, scaled as the mean over the sample's grains,
    sqrt(2000 / n), for a smaller sample, and never below the 2000-disk figure for a larger one
    (no measurement says it shrinks so: the rule stays on the side of running the seeds)."""
    f = math.sqrt(max(SCATTER_DISKS / float(n_disks), 1.0))
    return {k: v * f for k, v in ONE_RUN_SCATTER.items()}


def first_run_decides(err: dict, n_seeds: int, n_disks: int) -> list:
    """The figures a set's first run alone decides as missed by the mean over its ``n_seeds``
    seeds (the set's figures by definition), from that run's relative errors ``err``
    ({figure: fig/target - 1}, ``compare``'s err_X): those with

        |err| > tol + DECIDE_Z * sigma * (1 + max(err, 0)) * sqrt((n_seeds - 1) / n_seeds),

    sigma the run's relative scatter (``one_run_scatter``). Why: given one run x1 of a set whose
    mean mu is unknown (flat prior), mu ~ N(x1, s^2) and the mean of the other n - 1 runs ~
    N(mu, s^2 / (n - 1)), so the n-seed mean ~ N(x1, s^2 (n - 1) / n): beyond the bound the
    n-seed mean meets the figure's tolerance with probability below Phi(-3) = 0.13 %. (And a set
    whose own mean lies within the tolerance has its first run beyond the bound with probability
    at most Phi(-3 sqrt((n - 1) / n)): 0.47 % at four seeds.) s = sigma x1 / target: the scatter
    is relative to the set's own figure, (1 + err) of the target's, counted where err > 0.
    [] for one seed (nothing to save) or where no figure is decided."""
    if n_seeds < 2:
        return []
    sig = one_run_scatter(n_disks)
    shrink = math.sqrt((n_seeds - 1) / n_seeds)
    return [k for k, tol in TOLERANCES.items()
            if abs(err[k]) > tol + DECIDE_Z * sig[k] * (1.0 + max(err[k], 0.0)) * shrink]


class InRunDecision:
    """The in-run stop of a set's first run, one record at a time (``add``): what the records
    so far fix of the run's figures (``known``) and whether they already decide a target missed
    by the mean over ``n_seeds`` (``first_run_decides``' bound), looking at no later record.
    ``target``: the target's figures (``curve_figures``); ``smooth``: the strain window of q's
    moving average (``smoothed``). What the records up to strain e fix:

    - the secant modulus, exactly, once e >= SECANT_STRAIN (it interpolates between the two
      records about that strain);
    - peak q from below: the largest smoothed q over the records whose averaging window lies
      whole before e (``smoothed``: their values cannot change), and eps1_95 from below: the
      first strain where those reach PEAK_FRACTION of that bound (a higher final peak is
      reached later, ``_first_reach``). A figure known from below decides only above its
      target, where the bound grows with the set's own scale (1 + err): err - tol - c (1 + err)
      increases with err for c = DECIDE_Z sigma sqrt((n - 1) / n) < 1 (peak q, 0.127 at four
      seeds), so a bound decided stays decided at the end of the run, and for c >= 1 (eps1_95,
      1.25) nothing above the target decides;
    - nothing of the dilatancy ratio (it is read after the final eps1_95) nor of peak q or
      eps1_95 from above (the peak may still come).

    ``add(eps1, q)`` returns None, or {"index": i, "eps1": eps1, "figures": [...]} (the figures
    decided there) at the first record that decides; the figures a full run's
    ``first_run_decides`` gives include them."""

    def __init__(self, target: dict, n_seeds: int, n_disks: int, smooth=0.001):
        self.target, self.n_seeds, self.n_disks, self.smooth = target, n_seeds, n_disks, smooth
        self.e, self.q = [], []
        self.k_done = 0            # records whose smoothed q is final
        self.best = -math.inf      # the largest of those
        self.sec = None            # the secant modulus, once past SECANT_STRAIN
        self._qs = None            # the final smoothed values (the first k_done)
        self.decided = None

    def add(self, eps1, q):
        """The next record (eps1 increasing); the decision, or None while undecided."""
        if self.decided is not None:
            return self.decided
        self.e.append(float(eps1))
        self.q.append(float(q))
        e, qq = np.asarray(self.e), np.asarray(self.q)
        i = len(e) - 1
        if self.sec is None and e[i] >= SECANT_STRAIN:
            self.sec = _secant(e, qq)       # fixed from the first record past the secant strain
        # the smoothed values are those of the whole curve where their window lies whole
        # before e[i] (``smoothed`` switches to the raw q below 3 records: here 3 are needed)
        half = _half(self.smooth) if self.smooth > 0 else 0.0
        k = int(np.searchsorted(e, e[i] - half, side="right"))
        if k > self.k_done and (self.smooth <= 0 or len(e) >= 3):
            qs = smoothed(e, qq, self.smooth)
            self.best = max(self.best, float(np.max(qs[self.k_done:k])))
            self.k_done = k
            self._qs = qs[:k]
        err = {}
        for f, v in self.known().items():
            if f in ("peak_q", "eps1_95"):
                v = v[1]
                if not v > self.target[f]:      # a bound from below decides above the target
                    continue
            err[f] = v / self.target[f] - 1.0
        zero = {f: 0.0 for f in TOLERANCES}
        figs = [f for f in first_run_decides({**zero, **err}, self.n_seeds, self.n_disks)
                if f in err]
        if figs:
            self.decided = {"index": i, "eps1": float(e[i]), "figures": figs}
        return self.decided

    def known(self) -> dict:
        """What the records so far fix: {"secant": value} once past SECANT_STRAIN, and
        {"peak_q": ("at least", bound), "eps1_95": ("at least", bound)} once a smoothed value is
        final; the dilatancy ratio never (``stopped_figures``)."""
        out = {}
        if self.sec is not None:
            out["secant"] = self.sec
        if self.k_done:
            e = np.asarray(self.e[:self.k_done])
            out["peak_q"] = ("at least", self.best)
            out["eps1_95"] = ("at least", _first_reach(e, self._qs, PEAK_FRACTION * self.best))
        return out


def stopped_figures(curve, known) -> tuple:
    """The figures of a run stopped by its ``InRunDecision`` (``known``: what its records fixed,
    ``InRunDecision.known``; ``curve``: its records) as ``curve_figures`` gives a whole run's,
    and how each is known: (figures, {figure: "at least" | "unknown"} for those not exact).
    A bound from below is its value; an unknown figure is NaN; eps1_peak is unknown,
    peak_q_raw the largest q so far (a bound from below)."""
    fig = {"peak_q": math.nan, "eps1_peak": math.nan, "eps1_95": math.nan, "secant": math.nan,
           "peak_q_raw": float(np.max(curve["q"])), "dilatancy": math.nan}
    censored = {}
    for f in TOLERANCES:
        v = known.get(f)
        if v is None:
            censored[f] = "unknown"
        elif isinstance(v, (list, tuple)):
            censored[f], fig[f] = v[0], float(v[1])
        else:
            fig[f] = float(v)
    return fig, censored


def score_at_least(err: dict, censored: dict) -> float:
    """The least score sum((err_X / tol_X)^2) a set can have given its errors ``err``
    ({figure: fig/target - 1}) where some figures are known only from below or not at all
    (``censored``): an unknown figure, or one whose bound lies below its target, counts 0."""
    total = 0.0
    for k, tol in TOLERANCES.items():
        how = censored.get(k)
        if how == "unknown" or (how == "at least" and not err[k] > 0):
            continue
        total += (err[k] / tol) ** 2
    return float(total)


def decided_in_run(eps1, q, target: dict, n_seeds: int, n_disks: int, smooth=0.001):
    """The first record of a run's curve at which the records so far already decide a target
    missed by the mean over ``n_seeds`` (``InRunDecision``, record by record: it reads no
    later record), or None. ``bench/calibration_stop.py`` replays a calibration with it; ``dem
    calibrate --stop-decided-runs`` stops its first runs so."""
    d = InRunDecision(target, n_seeds, n_disks, smooth)
    for a, b in zip(eps1, q):
        r = d.add(a, b)
        if r is not None:
            return r
    return None


# -- the four figures of a curve -----------------------------------------------------------------
def _half(window):
    """Half the moving average's window (``smoothed``): records on its edges count on both
    sides."""
    return 0.5 * window * (1 + 1e-6)


def _first_reach(e, qs, level):
    """The first strain where the smoothed curve ``qs`` reaches ``level``, linear between the
    records (the first record when it starts there); ``level`` <= max(qs)."""
    j = int(np.argmax(qs >= level))             # first record at the level
    if j == 0:
        return float(e[0])
    return float(e[j - 1] + (level - qs[j - 1]) / (qs[j] - qs[j - 1]) * (e[j] - e[j - 1]))


def _secant(e, q, secant_strain=SECANT_STRAIN):
    """(q(secant_strain) - q(0)) / (secant_strain - eps1(0)), q interpolated linearly on the raw
    curve (``curve_figures``' secant)."""
    return (float(np.interp(secant_strain, e, q)) - q[0]) / (secant_strain - e[0])


def smoothed(eps1, q, window):
    """q averaged over eps1 in [e - window/2, e + window/2] at every point (window 0: q)."""
    e = np.asarray(eps1, float)
    q = np.asarray(q, float)
    if window <= 0 or len(q) < 3:
        return q.copy()
    c = np.concatenate([[0.0], np.cumsum(q)])
    half = _half(window)
    lo = np.searchsorted(e, e - half, side="left")
    hi = np.searchsorted(e, e + half, side="right")
    return (c[hi] - c[lo]) / (hi - lo)


def dilatancy_ratio(eps1, eps_v, start, width=DILATANCY_STRAIN):
    """1 - d eps_v / d eps1 (compression positive; = -d eps2 / d eps1 in plane strain, Rowe's
    strain-increment ratio: 1 at constant volume, above 1 where the sample dilates), the slope
    being that of the least-squares line of eps_v over the records with eps1 in [start, start +
    width].  A curve that stops before start + width: the records from start to its end; fewer
    than 3 there: its last 3 records."""
    e = np.asarray(eps1, float)
    v = np.asarray(eps_v, float)
    m = (e >= start - 1e-12) & (e <= start + width + 1e-12)
    if m.sum() < 3:
        m = np.zeros(len(e), bool)
        m[-3:] = True
    x = e[m] - e[m].mean()
    return float(1.0 - np.dot(x, v[m] - v[m].mean()) / np.dot(x, x))


def curve_figures(eps1, q, smooth=0.001, secant_strain=SECANT_STRAIN, eps_v=None) -> dict:
    """peak_q and eps1_peak (the maximum of q smoothed over the strain window ``smooth``),
    eps1_95 (the first eps1 where the smoothed q reaches PEAK_FRACTION of peak_q, linear
    between records), peak_q_raw (max q), secant = (q(secant_strain) - q(0)) / (secant_strain
    - eps1(0)) with q interpolated linearly on the raw curve; with ``eps_v``, dilatancy =
    ``dilatancy_ratio`` over [eps1_95, eps1_95 + DILATANCY_STRAIN] (the raw eps_v: the line
    averages its noise).  eps1 must increase; ValueError if the curve stops before
    ``secant_strain``."""
    e = np.asarray(eps1, float)
    q = np.asarray(q, float)
    if len(e) < 2 or not np.all(np.diff(e) > 0):
        raise ValueError("curve_figures: eps1 must be increasing, at least 2 points")
    if e[-1] < secant_strain:
        raise ValueError(f"curve_figures: the curve stops at eps1 = {e[-1]:.4g}, before the "
                         f"secant strain {secant_strain:g}")
    qs = smoothed(e, q, smooth)
    i = int(np.argmax(qs))
    sec = _secant(e, q, secant_strain)
    e95 = _first_reach(e, qs, PEAK_FRACTION * qs[i])
    out = {"peak_q": float(qs[i]), "eps1_peak": float(e[i]), "eps1_95": float(e95),
           "secant": float(sec), "peak_q_raw": float(np.max(q))}
    if eps_v is not None:
        if len(eps_v) != len(e):
            raise ValueError("curve_figures: eps_v and eps1 differ in length")
        out["dilatancy"] = dilatancy_ratio(e, eps_v, e95)
    return out


def compare(fig, target) -> dict:
    """Relative errors err_X = fig/target - 1, met_X = |err_X| <= TOLERANCES[X], met (all)
    and score = sum((err_X / tol_X)^2)."""
    out = {}
    for k, tol in TOLERANCES.items():
        err = fig[k] / target[k] - 1.0
        out["err_" + k] = float(err)
        out["met_" + k] = bool(abs(err) <= tol)
    out["met"] = all(out["met_" + k] for k in TOLERANCES)
    out["score"] = float(sum((out["err_" + k] / t) ** 2 for k, t in TOLERANCES.items()))
    return out


def rank(rec):
    """Sort key of an evaluation: meets every target first, then the score, then its order."""
    return (not rec["met"], rec["score"], rec["index"])


# -- the H-model's curve ----------------------------------------------------------------------
HMODEL_EPS_MIN = 0.05      # the H-model's curve runs at least this far (its peak: 2.09 %)


def hmodel_curve(confining=200e3, eps_max=0.035, d_eps1=1e-5):
    """The H-model's drained biaxial test (Table I parameters, p0 = confining) to
    max(eps_max, HMODEL_EPS_MIN), so that it is past its peak whatever the DEM's eps_max:
    dict of eps1, q, eps_v, p lists."""
    eps_max = max(eps_max, HMODEL_EPS_MIN)
    from point.driver import MixedControlError, drained_biaxial, isotropic_state, run_path
    from hmodel.params import HParams
    P = HParams(p0=float(confining))
    n = int(math.ceil(eps_max / d_eps1))
    try:
        r = run_path(isotropic_state(P), P, drained_biaxial(d_eps1), n)
    except MixedControlError as e:      # softening past what the driver can follow: keep it
        r = e.partial
    s1, s2 = r.sigma[:, 0], r.sigma[:, 1]
    return {"eps1": r.eps[:, 0].tolist(), "q": (s1 - s2).tolist(),
            "eps_v": (r.eps[:, 0] + r.eps[:, 1]).tolist(), "p": (0.5 * (s1 + s2)).tolist()}


def _fmt_values(names, values):
    return ", ".join(f"{n}={v:.4g}" for n, v in zip(names, values))


def _fmt_figs(rec):
    """The four figures of a record in one line, each with its error; a figure a stopped run
    knows from below is written ">=", one it does not know "unknown" (``stopped_figures``)."""
    cens = rec.get("censored") or {}

    def fig(k, text, value, more="", eq="= "):
        how = cens.get(k)
        if how == "unknown":
            return f"{text} unknown"
        sign = ">= " if how == "at least" else ""
        return f"{text} {sign or eq}{value} ({sign}{rec['err_' + k]:+.1%}{more})"

    late = "" if rec.get("past_peak", True) or cens else ", not past the peak"
    parts = [fig("peak_q", "peak q", f"{rec['peak_q'] / 1e3:.1f} kPa"),
             fig("eps1_95", f"eps1 at {PEAK_FRACTION:.0%} of it",
                 f"{100 * rec['eps1_95']:.3f} %", late),
             fig("secant", "secant", f"{rec['secant'] / 1e6:.1f} MPa")]
    if "err_dilatancy" in rec:
        parts.append(fig("dilatancy", "dilatancy ratio", f"{rec['dilatancy']:.3f}", eq=""))
    return ", ".join(parts)
