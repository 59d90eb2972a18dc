"""The burst of kinetic energy in the FE specimen (docs/burst.md; paper Eq. 1, issue 18).

``run_burst(BurstConfig(...), out_dir)`` is what ``python -m fem burst`` calls:

1. the drained FE path (``LoadStepper``, confining pressure) to each start state: the first
   converged step with eta >= f x the material point's drained peak eta;
2. from each start and for each ratio R, the proportional strain path under the tie
   (``fem.dynamics.Tie``), U1 prescribed in steps of d_eps1 H (static Newton, cut-back), c = G/B
   recorded until it has peaked (``hmodel.burst.CPeak``) or the path strain;
3. from the ``below`` and ``past`` switch states, at rest, G held at G_switch + dG
   (``fem.dynamics.hold``, Newmark average acceleration, Rayleigh mass damping), the outcome by
   ``hmodel.burst_rule.decide`` ('not_converged' when a time step converges at no substep),
   the growth measure by ``hmodel.burst_rule.energy_release`` (the largest (E_c - E_c(0)) /
   W2_ext and when it passed RELEASE), the energy check (``hmodel.burst_rule.EnergyCheck``);
4. beside it, the material point on the same path with the same steps
   (``fem.reference.material_point_path``): the c peak the perfect specimen must reproduce.

Outputs in ``out_dir`` (docs/burst.md, docs/fem.md): burst.csv (a row per run), history.csv
(every time step of every run), paths.csv (the quasi-static paths, FE and material point),
fields.xdmf + fields.h5 (the first ``past`` run: displacement, velocity, the mode), ke.png
(E_c and the energy release), balance.png (Newmark's balance, the energy check), path.png,
mode_*.png (the collapse mode of each failure run), summary.json. ``limit_bracket``: the dc
scan of the past switch (statics against dynamics).
"""
from __future__ import annotations

import dataclasses
import json
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np

from point.burst_rule import (RELEASE, BurstRule, check_columns, ke_growth, release_columns,
                               release_ratio)
from common.io import atomic_write_bytes, fmt, save_figure
from common.options import vocabulary_range
from .adapter import stress_to_model, strain_to_model
from .biaxial import BiaxialConfig, build_problem, material_record, _cells
from .dynamics import DENSITY, Tie, TiedStatic, hold, lowest_mode, mass_matrix, HISTORY_COLUMNS
from .output import CurveWriter, FieldWriter, cell_tensor, nodal_vector, plot_mode
from point.burst import CPeak, check_ratio

from point.contract import material_of
from point.onsets import NO_CLOSED_FORM, compare, has_mechanism

from .reference import closed_form_c_peak, material_point_curve, material_point_path
from .solver import LoadStepper, StaticLoss

__all__ = ["BurstConfig", "run_burst", "BurstResult", "BURST_COLUMNS", "PATH_COLUMNS",
           "DRAINED_EPS1_MAX", "limit_bracket"]

# the record's name in the vocabulary's terms (``common.options.VOCABULARY``: "BurstConfig.dc")
RECORD = "BurstConfig"
# the drained FE path gives up here if a start state is not reached [-]
DRAINED_EPS1_MAX = 0.1
# the material point's drained curve is computed to this axial strain (its peak ~2.1 %) [-]
MP_EPS1_MAX = 0.05

BURST_COLUMNS = ["ratio", "start_fraction", "eta_start", "eta_peak_c", "fraction_peak_c",
                 "eps1_peak_c", "c_start", "c_peak", "c_switch", "switch", "dc", "dc_rule",
                 "outcome", "ke_w2ext_max", "t_release", "t_release_t1", "released",
                 "ke_growth", "ke_max", "w2_ext_end", "w2_int_end", "t_end", "steps",
                 "newton_work", "newton_work_sum", "energy_check", "work_check", "t1", "dt",
                 "eps1_switch", "eta_switch", "mp_c_peak", "mp_eta_peak_c", "c_peak_error",
                 "eta_peak_error", "mode_band_share", "band_area_share", "mode_nonuniform",
                 "newton_iters_mean", "seconds", "failure_reason"]
PATH_COLUMNS = ["ratio", "start_fraction", "source", "step", "eps1", "eps2", "s1", "s2", "p",
                "q", "eta", "c"]


@dataclass
class BurstConfig:
    """Every option of ``python -m fem burst`` (SI units, compression positive).

    specimen : the mesh, material, imperfection, d_eps1 (the static steps of both paths) and
    Newton options, as for ``python -m fem biaxial`` (its eps1_max, n_sphere, fields are not
    used); ratios : R of the paths (R < 0); start_fractions : f of the start states (0 < f < 1);
    dc : the held step of c [Pa] (dG = B dc), None: 1e-4 sigma2; density [kg/m^3];
    damping_ratio : zeta of the mass-proportional damping at the lowest elastic mode;
    steps_per_period : T1 / dt (>= 10); path_strain : the largest eps1 of a path from its start;
    path_d_eps1 : the axial strain step of the proportional paths (specimen.d_eps1 is the
    drained path's);
    fields : write fields.xdmf; rule : the thresholds of hmodel.burst_rule.decide.
    """

    specimen: BiaxialConfig = field(default_factory=BiaxialConfig)
    ratios: tuple = (-2.0,)
    start_fractions: tuple = (0.90,)
    dc: float | None = None
    density: float = DENSITY
    damping_ratio: float = 0.05
    steps_per_period: int = 20
    path_strain: float = 0.03
    path_d_eps1: float = 1e-5
    fields: bool = True
    rule: BurstRule = BurstRule()

    @property
    def dc_value(self) -> float:
        """dc [Pa]: the given one, or 1e-4 sigma2 (docs/fem.md: well below what the 95 % switch
        leaves to the peak, above what a peak sampled in steps of path_d_eps1 can miss)."""
        return 1e-4 * self.specimen.sigma2 if self.dc is None else float(self.dc)

    def validate(self) -> "BurstConfig":
        """Every value of this config out of its range raises ValueError naming the option
        (the CLI's spelling) and the allowed range: the ranges of --start-fractions (its upper end
        open), --dc, --damping-ratio, --steps-per-period and --path-strain are the vocabulary's
        terms', read from it at each call (``common.options.vocabulary_range``, as
        ``dem.burst``'s and ``hmodel.burst.run_burst`` do: written once, in the term)."""
        def bad(name, v, allowed):
            raise ValueError(f"{name} {v!r} is out of range: allowed {allowed}")
        if not self.ratios:
            bad("--ratios", self.ratios, "one or more ratios R")
        for r in self.ratios:
            check_ratio(r)
        if not self.start_fractions:
            bad("--start-fractions", self.start_fractions, "one or more fractions")
        # the term's range with its upper end open: a start lies below the drained peak (f < 1;
        # the DEM's saved states include the peak, f = 1)
        r = vocabulary_range(RECORD, "start_fractions", hi_open=True)
        for f in self.start_fractions:
            if not r.contains(f):
                bad(r.option, f, r.text("f") + " (a fraction of the drained peak eta)")
        r = vocabulary_range(RECORD, "dc")
        if not r.contains(self.dc_value):
            bad(r.option, self.dc, r.text("dc", unit=True))
        if not (math.isfinite(self.density) and self.density > 0):
            bad("--density", self.density, "density > 0 [kg/m^3]")
        r = vocabulary_range(RECORD, "damping_ratio")
        if not r.contains(self.damping_ratio):
            bad(r.option, self.damping_ratio, r.text("zeta"))
        r = vocabulary_range(RECORD, "steps_per_period")
        if not r.contains(self.steps_per_period):
            bad(r.option, self.steps_per_period, f"{r.text('steps')}, an integer (dt = T1 / steps "
                "must resolve the lowest period T1)")
        r = vocabulary_range(RECORD, "path_strain")
        if not r.contains(self.path_strain):
            bad(r.option, self.path_strain, r.text("path strain", unit=True))
        if not (math.isfinite(self.path_d_eps1)
                and 0 < self.path_d_eps1 < min(0.05, self.path_strain)):
            bad("--path-d-eps1", self.path_d_eps1, "0 < step < min(0.05, --path-strain)")
        self.rule.validate("rule.")
        return self


class Snapshot(NamedTuple):
    """A committed static state: displacement u (ndofs,) [m], the material states (immutable
    records: kept by reference), internal force (ndofs,) [N/m], and its path row (a dict)."""

    u: np.ndarray
    states: list
    f_int: np.ndarray
    row: dict


class BurstResult(NamedTuple):
    rows: list
    paths: dict
    summary: dict
    out_dir: Path | None


def _averages(prob, sigma, u, ratio=None) -> dict:
    """Volume averages of a state (compression positive): s1, s2, p, q, eta, eps1, eps2, and
    c = s1 + R s2 (by virtual work, a . f_int / B for the tie of R)."""
    s = stress_to_model(sigma)
    e = strain_to_model(prob.strain(u))
    s1, s2 = float(prob.volume_average(s[0, 0])), float(prob.volume_average(s[1, 1]))
    row = {"eps1": float(prob.volume_average(e[0, 0])),
           "eps2": float(prob.volume_average(e[1, 1])), "s1": s1, "s2": s2, "p": 0.5 * (s1 + s2),
           "q": s1 - s2, "eta": (s1 - s2) / (0.5 * (s1 + s2))}
    if ratio is not None:
        row["c"] = s1 + ratio * s2
    return row


def _restore(prob, snap: Snapshot) -> None:
    prob.material.states = list(snap.states)


def _mode_measures(prob, ratio: float, v: np.ndarray) -> tuple:
    """How a collapse mode v (ndofs,) (the velocity at the end of a failure run) departs from
    the homogeneous motion: (share of its strain, sum |eps(v)|^2 dx, in the weak elements, their
    share of the area: NaN without an imperfection; |v - a U1'| / |v|, the part of v off the
    tie's homogeneous mode a, U1' = the platen's velocity)."""
    tie = Tie(prob, ratio)
    w = v - tie.a * float(-np.mean(v[tie.top_y]))
    nonuniform = float(np.linalg.norm(w) / np.linalg.norm(v))
    if not len(prob.weak_elements):
        return math.nan, math.nan, nonuniform
    area = prob.dx.sum(axis=1)
    g = prob.per_element(np.sum(prob.strain(v).reshape(4, -1) ** 2, axis=0)) * area
    wk = prob.weak_elements
    return float(g[wk].sum() / g.sum()), float(area[wk].sum() / area.sum()), nonuniform


def run_burst(cfg: BurstConfig, out_dir=None, progress=None) -> BurstResult:
    """Run the experiment of ``cfg``; with ``out_dir``, write the outputs there (history.csv
    and paths.csv row by row as they are computed, the rest at the end). ``progress`` a callable
    taking one line of text (None: silent). A static step that fails after every cut-back
    raises RuntimeError (the rows so far are on disk)."""
    cfg.validate()
    say = progress or (lambda line: None)
    t_start = time.perf_counter()
    timings = {"drained": 0.0, "paths": 0.0, "material_point": 0.0, "dynamics": 0.0}
    sc = cfg.specimen
    prob = build_problem(sc)
    params = prob.params
    B = prob.width
    M = mass_matrix(prob, cfg.density)
    dc = cfg.dc_value
    rule = cfg.rule
    if not sc.imperfection:
        imp = ", perfect specimen"
    elif sc.is_hmodel() and not sc.imp_values:
        imp = (f", {sc.imperfection} imperfection (phi_g {sc.imp_phi_g}, alpha0 {sc.imp_alpha0}, "
               f"size {sc.imp_size}, angle {sc.imp_angle})")
    else:
        weak = ", ".join(f"{k} {v:g}" for k, v in sc.weak_values().items())
        imp = f", {sc.imperfection} imperfection ({weak}, size {sc.imp_size}, angle {sc.imp_angle})"
    law = prob.law.name + (f", n_dir {params.n_dir}" if sc.is_hmodel() else "")
    say(f"fem burst: {prob.nel} elements, {prob.npts} points, {law}{imp}; "
        f"sigma2 {sc.sigma2:g} Pa; R {', '.join(f'{r:g}' for r in cfg.ratios)}; f "
        f"{', '.join(f'{f:g}' for f in cfg.start_fractions)}; dc {dc:g} Pa (held force step "
        f"dG = B dc = {B * dc:.4g} N/m); density "
        f"{cfg.density:g} kg/m^3; damping ratio {cfg.damping_ratio:g}; {cfg.steps_per_period} "
        f"steps a period; d_eps1 {sc.d_eps1:g} (drained), {cfg.path_d_eps1:g} (paths)")

    t0 = time.perf_counter()
    mp_curve = material_point_curve(params, MP_EPS1_MAX)
    if not mp_curve["peak_is_interior"]:
        raise RuntimeError(f"the material point's drained path does not peak by eps1 = "
                           f"{MP_EPS1_MAX}: no drained peak eta to start from")
    eta_peak = mp_curve["eta_peak"]
    timings["material_point"] += time.perf_counter() - t0

    out = Path(out_dir) if out_dir is not None else None
    hist_w = path_w = burst_w = fields = None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        hist_w = CurveWriter(out / "history.csv",
                             ["ratio", "start_fraction", "switch"] + HISTORY_COLUMNS)
        path_w = CurveWriter(out / "paths.csv", PATH_COLUMNS)
        burst_w = CurveWriter(out / "burst.csv", BURST_COLUMNS)
    rows, paths, runs = [], {}, []
    closed = []              # each path's c peak beside its closed form (a law with a mechanism)
    fields_run = None
    try:
        # 1. the drained FE path to every start state
        t0 = time.perf_counter()
        starts = _drained_starts(prob, cfg, eta_peak, say)
        timings["drained"] += time.perf_counter() - t0

        for f in cfg.start_fractions:
            start = starts[float(f)]
            for R in cfg.ratios:
                key = {"ratio": float(R), "start_fraction": float(f)}
                # 2. the tied path (and the material point's) from the start
                t0 = time.perf_counter()
                path, switches = _tied_path(prob, start, float(R), cfg, say)
                timings["paths"] += time.perf_counter() - t0
                t0 = time.perf_counter()
                mp = material_point_path(params, float(f) * eta_peak, float(R), sc.d_eps1,
                                         cfg.path_d_eps1, cfg.path_strain)
                timings["material_point"] += time.perf_counter() - t0
                paths[(float(R), float(f))] = {"fe": path, "material_point": mp}
                if path_w is not None:
                    for src, p in (("fe", path), ("material_point", mp)):
                        for k in range(len(p["c"])):
                            path_w.write(dict(key, source=src, step=k,
                                              **{c: p[c][k] for c in PATH_COLUMNS[4:]}))
                peak = path["peak"]
                base = dict(key, eta_start=path["eta"][0], c_start=path["c"][0], dc=dc,
                            eta_peak_c=path["eta"][peak] if peak is not None else math.nan,
                            fraction_peak_c=(path["eta"][peak] / eta_peak if peak is not None
                                             else math.nan),
                            eps1_peak_c=(path["eps1"][peak] - path["eps1"][0]
                                         if peak is not None else math.nan),
                            c_peak=path["c"][peak] if peak is not None else math.nan,
                            mp_c_peak=mp["c"][mp["peak"]] if mp["peak"] is not None else math.nan,
                            mp_eta_peak_c=(mp["eta"][mp["peak"]] if mp["peak"] is not None
                                           else math.nan))
                base["c_peak_error"] = base["c_peak"] / base["mp_c_peak"] - 1
                base["eta_peak_error"] = base["eta_peak_c"] / base["mp_eta_peak_c"] - 1
                exact = closed_form_c_peak(params, float(f) * eta_peak, float(R), sc.d_eps1,
                                           cfg.path_d_eps1, len(mp["c"]) + 2)
                if exact is not None:
                    nan = math.nan
                    closed.append(dict(key, criterion="the c peak: h = h_R = (u.E.Q)(P.E.u)/(u.E.u)"
                                                      " - P:E:Q, u = (1, R, 0)",
                                       eta_peak_c=compare(base["eta_peak_c"], exact["eta"]),
                                       c_peak=compare(base["c_peak"], exact["c"]),
                                       material_point_eta_peak_c=compare(base["mp_eta_peak_c"],
                                                                         exact["eta"]),
                                       material_point_c_peak=compare(base["mp_c_peak"], exact["c"])))
                    say(f"  closed form (h = h_R): c peak {exact['c'] / 1e3:.4f} kPa at eta "
                        f"{exact['eta']:.5f}; the FE's {fmt(base['c_peak'] / 1e3, '.4f')} kPa at "
                        f"{fmt(base.get('eta_peak_c', nan), '.5f')}, the material point's "
                        f"{fmt(base['mp_c_peak'] / 1e3, '.4f')} kPa at "
                        f"{fmt(base['mp_eta_peak_c'], '.5f')}")
                if peak is not None:
                    b = base
                    say(f"path R = {R:g}, f = {f:g}: c peak {b['c_peak'] / 1e3:.3f} kPa at eta "
                        f"{b['eta_peak_c']:.4f} (material point {b['mp_c_peak'] / 1e3:.3f} kPa at "
                        f"eta {b['mp_eta_peak_c']:.4f}: {fmt(100 * b['c_peak_error'], '+.3f')} %, "
                        f"{fmt(100 * b['eta_peak_error'], '+.3f')} %)")
                else:
                    say(f"path R = {R:g}, f = {f:g}: c does not peak within the path strain "
                        f"{cfg.path_strain}: one below run at its end")
                # 3. the runs at a held force
                for name, snap in switches:
                    t0 = time.perf_counter()
                    tag = dict(key, switch=name)
                    frames = None
                    if cfg.fields and out is not None and name == "past" and fields is None:
                        fields = FieldWriter(out / "fields.xdmf", prob.mesh.p.T, _cells(prob))
                        fields_run = tag
                        frames = fields
                    k_sw = path["below"] if name == "below" else path["peak"]
                    dc_run = path["cpeak"].dc_below(k_sw, dc)
                    res, t1 = _held_run(prob, M, snap, float(R), B * dc_run, cfg, rule, tag, say,
                                        hist_w, frames)
                    timings["dynamics"] += time.perf_counter() - t0
                    h = res.history
                    share, area, nonuniform = (_mode_measures(prob, float(R), res.v)
                                               if res.outcome == "failure" else (math.nan,) * 3)
                    row = dict(base, switch=name, dc=dc_run, dc_rule=path["cpeak"].missed(),
                               c_switch=snap.row["c"], outcome=res.outcome,
                               **release_columns(h["t"], h["ke"], h["w2_ext"], t1),
                               ke_growth=ke_growth(h["ke"]), ke_max=float(h["ke"].max()),
                               w2_ext_end=h["w2_ext"][-1], w2_int_end=h["w2_int"][-1],
                               t_end=h["t"][-1], steps=int(h["step"][-1]),
                               newton_work=float(h["newton_work"].max()),
                               newton_work_sum=float(h["newton_work_sum"].max()),
                               **check_columns(h), t1=t1, dt=res.dt,
                               eps1_switch=snap.row["eps1"], eta_switch=snap.row["eta"],
                               mode_band_share=share, band_area_share=area,
                               mode_nonuniform=nonuniform,
                               newton_iters_mean=float(h["newton_iters"][1:].mean())
                               if len(h["t"]) > 1 else 0.0,
                               seconds=res.seconds, failure_reason=res.failure_reason,
                               time_steps_cut=res.cut_steps, path_end=path["end"])
                    rows.append(row)
                    runs.append((tag, res))
                    if burst_w is not None:
                        burst_w.write(row)
                    say(f"{_label(tag)}: {res.outcome} after {row['steps']} steps "
                        f"({row['t_end'] / t1:.1f} T1, T1 = {1e3 * t1:.4f} ms), "
                        + _release_text(row)
                        + f"; energy check {row['energy_check']:.1e}, Newton's work "
                        f"{row['newton_work']:.1e}, {res.seconds:.1f} s"
                        + (f"; {res.failure_reason}" if res.failure_reason else ""))
    finally:
        for w in (hist_w, path_w, burst_w, fields):
            if w is not None:
                w.close()
    timings["total"] = time.perf_counter() - t_start
    config = asdict(cfg)
    config["specimen"] = sc.record()
    summary = {"config": config, "dc": dc, "parameters": asdict(params),
               "material": material_record(params),
               "material_point_drained_peak": {"eta": eta_peak, "eps1": mp_curve["eps1_peak"]},
               "mesh": {"elements": prob.nel, "points": prob.npts, "dofs": prob.ndofs},
               "fields": ({"run": fields_run, "frames_every": _frame_every(cfg)}
                          if fields_run else None),
               "closed_forms": closed if has_mechanism(material_of(params)) else NO_CLOSED_FORM,
               "runs": rows, "timings": timings}
    if out is not None:
        t0 = time.perf_counter()
        _figures(out, prob, paths, runs, rows, mp_curve)
        timings["figures"] = time.perf_counter() - t0
        atomic_write_bytes(out / "summary.json",
                           json.dumps(summary, indent=1, default=_json_default).encode())
    return BurstResult(rows, paths, summary, out)


def _drained_starts(prob, cfg: BurstConfig, eta_peak: float, say) -> dict:
    """{f: Snapshot} of the drained FE path at each start fraction f of cfg (the first converged
    step with eta >= f x ``eta_peak``, the material point's drained peak). RuntimeError when one
    is not reached by DRAINED_EPS1_MAX."""
    sc = cfg.specimen
    fractions = sorted(set(float(f) for f in cfg.start_fractions))
    starts = {}
    stepper = LoadStepper(prob, sc.d_eps1, rtol=sc.rtol, max_iter=sc.max_iter,
                          max_cutbacks=sc.max_cutbacks)
    last = {}

    def on_drained(res, info):
        row = _averages(prob, res.trial.sigma, stepper.u)
        last.update(row, step=stepper.step)
        for f in fractions:
            if f not in starts and row["eta"] >= f * eta_peak:
                starts[f] = Snapshot(stepper.u.copy(), list(prob.material.states),
                                     res.f_int.copy(), dict(row, step=stepper.step))
                say(f"drained path: start state f = {f:g} at step {stepper.step}, eps1 = "
                    f"{100 * row['eps1']:.4f} %, eta = {row['eta']:.4f} (target "
                    f"{f * eta_peak:.4f})")

    lost = ""
    try:
        stepper.run(DRAINED_EPS1_MAX, on_drained, until=lambda: len(starts) == len(fractions))
    except StaticLoss as e:
        lost = f"; the drained path has no static state beyond: {e}"
    missing = [f for f in fractions if f not in starts]
    if missing:
        raise RuntimeError(f"start fraction(s) {missing} not reached on the FE drained path "
                           f"by eps1 = {DRAINED_EPS1_MAX} (largest eta {last.get('eta', 0):.4f}"
                           f", material point peak {eta_peak:.4f}){lost}")
    return starts


def limit_bracket(cfg: BurstConfig, tol: float = 1.0, progress=None) -> dict:
    """Statics against dynamics (docs/burst.md): the dynamic limit load of the ``past`` switch,
    bracketed. From the c peak that the path of the first ratio and start fraction of ``cfg``
    samples in steps of cfg.path_d_eps1 (a static state, at rest), G held at B (c_peak + dc):
    the largest dc that settles (``lo``) and the smallest that fails (``hi``), by bisection
    from lo = 0 (the peak's own static state: nothing moves) and hi = the sizing rule's
    ``dc_rule`` = c_peak - c_(peak - 1) (``hmodel.burst.CPeak.missed``: past the path's true
    peak if c is concave there; doubled until a hold fails) down to hi - lo <= ``tol`` [Pa].
    The true limit load lies in c_peak + [lo, hi]; the sampled peak misses it by at most
    dc_rule, so the bracket shrinks with the path's step.

    Returns {"c_peak" [Pa], "eta_peak", "dc_rule" [Pa], "lo" [Pa], "hi" [Pa], "runs": [(dc [Pa],
    outcome, t_end / T1), ...] in the order run}. RuntimeError when the path does not peak or a
    hold ends neither in equilibrium nor in failure (undecided, not converged: no bracket)."""
    cfg.validate()
    if not (math.isfinite(tol) and tol > 0):
        raise ValueError(f"tol = {tol!r} is out of range: allowed tol > 0 [Pa]")
    say = progress or (lambda line: None)
    sc = cfg.specimen
    prob = build_problem(sc)
    M = mass_matrix(prob, cfg.density)
    mp_curve = material_point_curve(prob.params, MP_EPS1_MAX)
    f, R = float(cfg.start_fractions[0]), float(cfg.ratios[0])
    start = _drained_starts(prob, dataclasses.replace(cfg, start_fractions=(f,)),
                            mp_curve["eta_peak"], say)[f]
    path, switches = _tied_path(prob, start, R, cfg, say)
    if path["peak"] is None:
        raise RuntimeError(f"c does not peak within the path strain {cfg.path_strain} (R = {R:g}, "
                           f"f = {f:g}): no limit load to bracket")
    snap = dict(switches)["past"]
    c_peak, rule = float(path["c"][path["peak"]]), path["cpeak"].missed()
    runs = []

    def fails(dc):
        res, t1 = _held_run(prob, M, snap, R, prob.width * dc, cfg, cfg.rule,
                            {"ratio": R, "start_fraction": f, "switch": "past"}, say, None, None)
        runs.append((float(dc), res.outcome, float(res.history["t"][-1] / t1)))
        say(f"limit bracket: c_peak + {dc:.4g} Pa: {res.outcome} at {runs[-1][2]:.1f} T1")
        if res.outcome not in ("equilibrium", "failure"):
            raise RuntimeError(f"the hold at c_peak + {dc:.6g} Pa ended {res.outcome} "
                               f"{res.failure_reason}: no bracket")
        return res.outcome == "failure"

    lo, hi = 0.0, rule
    while not fails(hi):
        lo, hi = hi, 2.0 * hi
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if fails(mid) else (mid, hi)
    return {"c_peak": c_peak, "eta_peak": float(path["eta"][path["peak"]]), "dc_rule": rule,
            "lo": lo, "hi": hi, "runs": runs}


def _json_default(v):
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (np.floating,)):
        return float(v)
    if isinstance(v, np.ndarray):
        return v.tolist()
    return str(v)


def _release_text(row: dict) -> str:
    """The growth measure of a run in words (``hmodel.burst_rule.energy_release``)."""
    if row["released"]:
        return (f"E_c - E_c(0) passed {RELEASE:g} W2_ext at t = {row['t_release_t1']:.2f} T1 "
                f"(largest {row['ke_w2ext_max']:.3g} W2_ext)")
    return (f"E_c - E_c(0) stayed below {RELEASE:g} W2_ext (largest "
            f"{fmt(row['ke_w2ext_max'], '.3g', 'none: dG = 0')} W2_ext)")


def _label(tag: dict) -> str:
    return f"R = {tag['ratio']:g}, f = {tag['start_fraction']:g}, {tag['switch']}"


def _tied_path(prob, start: Snapshot, ratio: float, cfg: BurstConfig, say):
    """The quasi-static proportional path from ``start`` under the tie of ``ratio`` (U1 in steps
    of cfg.path_d_eps1 H): rows (eps1, eps2, s1, s2, p, q, eta, c; row 0 the start), the peak
    row, the below row, and the switch states [(name, Snapshot)]: ('below', ...) and, if c
    peaked, ('past', the peak).

    The path runs twice: once to find the peak and the below row, then again from the start to
    keep those two states (a state of 800 points x 180 orientations is ~12 MB: the states of a
    whole path are not kept). The steps are deterministic, so the second run is the first one
    again, bit for bit (checked on c)."""
    sc = cfg.specimen

    def stepper():
        _restore(prob, start)
        return LoadStepper(static, cfg.path_d_eps1, rtol=sc.rtol, max_iter=sc.max_iter,
                           max_cutbacks=sc.max_cutbacks, u0=start.u, du0=tie.a)

    tie = Tie(prob, ratio)
    static = TiedStatic(tie, start.u)
    st = stepper()
    row0 = _averages(prob, prob.material.stress(), start.u, ratio)
    rows = {k: [v] for k, v in row0.items()}
    peak = CPeak(row0["c"])
    last = {}

    def on_step(res, info):
        row = _averages(prob, res.trial.sigma, st.u, ratio)
        for k, v in row.items():
            rows[k].append(v)
        peak.add(row["c"])
        last["snap"] = Snapshot(st.u.copy(), list(prob.material.states), res.f_int.copy(), row)

    end = None
    try:
        st.run(cfg.path_strain, on_step, until=lambda: peak.confirmed)
    except StaticLoss as e:
        # no static state beyond under U1 prescribed: the path ends there, as at its strain
        end = str(e)
        say(f"path R = {ratio:g}: {e}")
    its = st.times["iterations"]
    say(f"path R = {ratio:g}: {st.step} steps to eps1 = "
        f"{100 * (rows['eps1'][-1] - rows['eps1'][0]):.3f} % from the start, "
        + (f"{its} Newton iterations" if its else
           "every step converged at its predictor (the homogeneous increment is in "
           "equilibrium: no Newton iteration needed)"))
    path = {k: np.array(v) for k, v in rows.items()}
    path["peak"] = peak.peak
    path["below"] = peak.below()
    path["cpeak"] = peak
    path["end"] = end
    if peak.peak is None:
        return path, [("below", last["snap"])] if last else []
    want = {peak.peak: "past"}
    if path["below"] is not None:            # None: c falls at once, no state below the peak
        want[path["below"]] = "below"
    kept = {}
    st = stepper()

    def keep(res, info):
        if st.step in want:
            row = _averages(prob, res.trial.sigma, st.u, ratio)
            if row["c"] != path["c"][st.step]:
                raise RuntimeError(f"the replayed path differs from the first at step {st.step}")
            kept[want[st.step]] = Snapshot(st.u.copy(), list(prob.material.states),
                                           res.f_int.copy(), row)

    if path["below"] == 0:
        kept["below"] = Snapshot(start.u.copy(), list(start.states), start.f_int, row0)
    if peak.peak > 0:
        st.run(cfg.path_strain, keep, until=lambda: st.step >= peak.peak)
    else:
        kept["past"] = Snapshot(start.u.copy(), list(start.states), start.f_int, row0)
    return path, [(n, kept[n]) for n in ("below", "past") if n in kept]


def _frame_every(cfg: BurstConfig) -> int:
    """Steps between two frames of fields.xdmf: four frames a lowest period."""
    return max(1, cfg.steps_per_period // 4)


def _held_run(prob, M, snap: Snapshot, ratio: float, dG: float, cfg: BurstConfig, rule, tag,
              say, history, fields):
    """From the switch state ``snap`` at rest: its lowest elastic period T1 (sliding prevented,
    U1 free), then ``hold`` at G_switch + dG, each step written to ``history`` (a CurveWriter
    or None) as it converges, four frames a period to ``fields`` (FieldWriter or None).
    Returns (HoldResult, T1)."""
    _restore(prob, snap)
    tie = Tie(prob, ratio)
    elastic = prob.material.trial(np.zeros((2, 2, prob.npts)), elastic=True)
    omega1, _ = lowest_mode(tie.reduce_matrix(prob.stiffness(elastic.D)), tie.reduce_matrix(M))
    t1 = 2.0 * math.pi / omega1
    every = _frame_every(cfg)
    report = max(1, 2 * cfg.steps_per_period)
    t0 = time.perf_counter()

    def on_step(k, m, system, row):
        if history is not None:
            history.write(dict(tag, **row))
        if fields is not None and k % every == 0:
            _frame(fields, prob, tie, snap.u, k * (t1 / cfg.steps_per_period), m, ratio)
        if k and k % report == 0:
            u1 = float(m.z[-1])
            ke = 0.5 * float(m.v @ (system.M @ m.v))
            say(f"{_label(tag)}: step {k} t = {k / cfg.steps_per_period:.1f} T1 E_c = {ke:.3e} J/m "
                f"dU1 = {u1:.3e} m W2_ext = dG dU1 = {system.dG * u1:.3e} J/m "
                f"({time.perf_counter() - t0:.1f} s)")

    sc = cfg.specimen
    res = hold(tie, M, snap.u, dG, t1, cfg.steps_per_period, cfg.damping_ratio, rule,
               eps_ref=(snap.row["eps1"], snap.row["eps2"]), rtol=sc.rtol, max_iter=sc.max_iter,
               on_step=on_step, density=cfg.density)
    return res, t1


def _frame(fields, prob, tie, u_ref, t, m, ratio):
    """One frame of fields.xdmf: point data displacement (since the isotropic state), velocity
    [m/s], mode (the velocity scaled to a largest nodal value of 1, dimensionless); cell data
    c = s1 + R s2 [Pa] and the sliding fraction of the committed state."""
    u = u_ref + tie.displacement(m.z)
    v = tie.displacement(m.v)
    vel = nodal_vector(prob, v)
    top = float(np.max(np.linalg.norm(vel, axis=1)))
    s = stress_to_model(prob.material.stress())
    sliding, _ = prob.material.fractions()
    fields.write(t, {"displacement": nodal_vector(prob, u), "velocity": vel,
                     "mode": vel / top if top > 0 else vel},
                 {"c": [prob.per_element(s[0, 0] + ratio * s[1, 1])],
                  "sliding_fraction": [prob.per_element(sliding)],
                  "strain_tension_positive": [cell_tensor(prob, prob.strain(u))]})


def _figures(out: Path, prob, paths, runs, rows, mp_curve) -> None:
    """ke.png (E_c and the energy release), balance.png (Newmark's balance and the energy
    check), path.png and mode_*.png (see docs/fem.md)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    def finish(fig, ax, xlabel, ylabel, title, name):
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ax.set_title(title, fontsize=8)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
        save_figure(fig, out / name, dpi=120)

    starts = sorted({(tag["ratio"], tag["start_fraction"]) for tag, _ in runs})
    color = {s: f"C{i % 10}" for i, s in enumerate(starts)}
    style = {"below": "--", "past": "-"}
    # E_c(t) and the energy release r(t) = (E_c - E_c(0)) / W2_ext, log axes
    fig, (ax, ar) = plt.subplots(1, 2, figsize=(13, 5))
    for tag, res in runs:
        h = res.history
        s = (tag["ratio"], tag["start_fraction"])
        t = 1e3 * h["t"][1:]
        pos = lambda x: np.where(x > 0, x, np.nan)         # noqa: E731 (log axis: E_c = 0 left out)
        ax.semilogy(t, pos(h["ke"][1:]), style[tag["switch"]], color=color[s],
                    lw=1.3, label=f"R = {s[0]:g}, f = {s[1]:g}, {tag['switch']}: {res.outcome} "
                                  f"(T1 = {1e3 * res.t1:.3f} ms)")
        ax.plot(t[-1], h["ke"][-1], {"failure": "x", "not_converged": "D"}.get(res.outcome, "o"),
                color=color[s], mfc="none")
        ax.semilogy(t, pos(h["w2_ext"][1:]), ":", color=color[s], lw=0.9,
                    label=r"$W_{2,ext} = dG\,\Delta U_1$ (Eq. 1: $E_c \leq W_{2,ext}$ while "
                          r"$W_{2,int} \geq 0$)" if (tag, res) == runs[0] else None)
        r = release_ratio(h["ke"], h["w2_ext"])[1:]
        ar.semilogy(h["t"][1:] / res.t1, pos(r), style[tag["switch"]], color=color[s], lw=1.3,
                    label=f"R = {s[0]:g}, f = {s[1]:g}, {tag['switch']}: {res.outcome}")
        k = [row for tg, row in zip((tg for tg, _ in runs), rows) if tg == tag][0]
        if k["released"]:
            ar.plot(k["t_release_t1"], RELEASE, "*", color=color[s], ms=11, mfc="none",
                    label=f"passes {RELEASE:g} at {k['t_release_t1']:.2f} T1")
    ar.axhline(RELEASE, color="k", lw=0.9, ls="--",
               label=f"RELEASE = {RELEASE:g}: the specimen gave back more than dG put in")
    ar.axhline(1.0, color="0.5", lw=0.8, ls=":", label=r"1: $W_{2,int} = 0$ (Eq. 1, no damping)")
    if not any(np.any(res.history["ke"] > 0) for _, res in runs):
        ax.set_yscale("linear")                       # dc = 0: nothing moved, E_c = 0
        ar.set_yscale("linear")
    ar.set_xlabel("time since the switch t / T1 [-]")
    ar.set_ylabel(r"energy release $(E_c - E_c(0)) / W_{2,ext}$ [-]")
    ar.set_title("the growth measure (hmodel.burst_rule.energy_release):\nthe kinetic energy "
                 "gained against the work of dG", fontsize=8)
    ar.grid(alpha=0.3, which="both")
    ar.legend(fontsize=7)
    finish(fig, ax, "time since the switch t [ms]",
           r"kinetic energy $E_c$ [J/m] (per unit thickness)",
           "G held at G_switch + dG: kinetic energy; dotted: the work of dG\n(x: failure, o: "
           "equilibrium / undecided, by hmodel.burst_rule; diamond: not converged)", "ke.png")
    # Newmark's balance (the work of the Newton residual) and the energy check, per step
    fig, (ax, ac) = plt.subplots(1, 2, figsize=(13, 4.5))
    for tag, res in runs:
        h = res.history
        s = (tag["ratio"], tag["start_fraction"])
        lab = f"R = {s[0]:g}, f = {s[1]:g}, {tag['switch']}"
        ax.semilogy(h["step"][1:], np.where(h["newton_work"][1:] > 0, h["newton_work"][1:],
                                            np.nan),
                    style[tag["switch"]], color=color[s], lw=1, label=lab)
        run_scale = max(float(np.max(h["ke_mid"])), float(np.max(np.abs(h["w2_ext"]))),
                        float(np.max(np.abs(h["w2_int_stress"]))), float(np.max(h["damping_mid"])))
        e = np.abs(h["energy_check"][1:]) / run_scale if run_scale > 0 else h["energy_check"][1:]
        ac.semilogy(h["t"][1:] / res.t1, np.where(e > 0, e, np.nan), style[tag["switch"]],
                    color=color[s], lw=1, label=lab)
    ax.axhline(1e-6, color="k", lw=0.8, ls=":", label="1e-6")
    ac.set_xlabel("time since the switch t / T1 [-]")
    ac.set_ylabel(r"$|E_c^{mid} - (\Phi_n + \Phi_{n+1})/2|$ / the run's largest $W_2$ [-]")
    ac.set_title("the energy check (O(dt$^2$)): $E_c$ of the velocity field with the density"
                 "\n" r"against $\Phi = W_{2,ext} - W_{2,int}$(the stresses)$ - D$", fontsize=8)
    ac.grid(alpha=0.3, which="both")
    ac.legend(fontsize=7)
    finish(fig, ax, "time step since the switch",
           r"$|\Delta E_c - (\Delta W_{ext} - \Delta W_{int} - \Delta D)|$ / "
           r"max($E_c$, |$W_2$|, D) [-]",
           "Newmark's own balance of each step: the work of the Newton residual\n(an identity "
           "of the scheme for any M and f_int)", "balance.png")
    # c against eps1, FE and material point, peaks and switches marked
    fig, ax = plt.subplots(figsize=(7.5, 5))
    for s in starts:
        p = paths[s]
        fe, mp = p["fe"], p["material_point"]
        ax.plot(100 * fe["eps1"], fe["c"] / 1e3, "o-", ms=3, color=color[s], lw=1,
                label=f"FE, R = {s[0]:g}, f = {s[1]:g}")
        ax.plot(100 * mp["eps1"], mp["c"] / 1e3, "k--", lw=0.9,
                label="material point, same steps" if s == starts[0] else None)
        if fe["peak"] is not None:
            k = fe["peak"]
            ax.plot(100 * fe["eps1"][k], fe["c"][k] / 1e3, "*", ms=13, color=color[s], mfc="none",
                    label=f"FE c peak, eta = {fe['eta'][k]:.4f} (past switch)")
        if mp["peak"] is not None:
            k = mp["peak"]
            ax.plot(100 * mp["eps1"][k], mp["c"][k] / 1e3, "k+", ms=12,
                    label=f"material point c peak, eta = {mp['eta'][k]:.4f}")
        k = fe["below"]
        ax.plot(100 * fe["eps1"][k], fe["c"][k] / 1e3, "v", ms=9, color=color[s], mfc="none",
                label=f"below switch (95 % of the rise), eta = {fe['eta'][k]:.4f}")
    finish(fig, ax, r"axial strain $\varepsilon_1$ [%] (compression +)",
           r"$c = \sigma_1 + R\,\sigma_2$ [kPa]",
           f"proportional strain paths from the drained path (material point drained peak eta "
           f"{mp_curve['eta_peak']:.4f})", "path.png")
    # the collapse mode of each failure run
    for tag, res in runs:
        if res.outcome == "failure" and np.any(res.v):
            name = f"mode_R{tag['ratio']:g}_f{tag['start_fraction']:g}_{tag['switch']}.png"
            plot_mode(out / name, prob, res.v,
                      title=(f"collapse mode (velocity at the end), {_label(tag)}, "
                             f"t = {1e3 * res.history['t'][-1]:.3f} ms"))
