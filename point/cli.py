"""Command line of the material point of any law: ``python -m point {biaxial,probes,domain,burst,
fit,params} ...``, and the same commands as ``python -m hmodel`` with the H-model as their one law
(``build_parser(law=...)``, ``main(argv, prog, law)``): a thin layer over ``point.experiment``,
``point.burst``, ``point.fit`` and ``point.plots``.

The law of a command: the "model" of ``--params FILE``, else ``--model NAME`` (its default
record), else the H-model (``point.params.params_from``; the options of its fields on top, an
option of another law's field refused). Before anything is computed the law is held to its
contract (``point.contract.check_law``: the first update of the command checked, and with
``--check-tangent`` its tangent against central differences of its own stress); a
``MaterialError`` is one line, exit 2, with what was finished written complete.

Every summary names the material (``material``: its name and ``describe``), the outputs it does
not provide (``absent``: their columns are left out of the CSV files), and, for a law with a
single mechanism, stands each onset of the analysis beside its closed form (``closed_forms``,
``point.onsets``; "no closed form for this law" otherwise). The files of fit, probes and domain
are written by ``write_fit``, ``write_probes`` and ``write_domain`` from a record and the
library's results, so that a caller with its own record (``python -m crosscheck.fit``) writes the
same folders without an argv.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from functools import partial
from typing import NamedTuple

import numpy as np

from common import options as opt
from common.io import atomic_open, fmt, json_safe, write_csv

from . import fit as pfit
from . import onsets, plots
from .contract import MaterialError, ParamError, check_law, material_named, material_of
from .driver import (MixedControlError, drained_biaxial, isotropic_state, proportional_strain,
                     proportional_strain_stress, run_path)
from .experiment import (DOMAIN_COLUMNS, DOMAIN_EPS1_MAX, absent_outputs, biaxial_columns,
                         biaxial_test, bifurcation_domain, compile_kernels, directional_analysis,
                         present, probe_columns)
from .params import add_param_options, known_laws, params_from, record_params, save_params
from .probes import arcs, cone_edges, format_arcs

# memory of one step of a path [bytes]: run_path's histories (3 + 3 floats, 3 ints), the
# PathResult rows (6 floats) and the CSV columns (12), all float64 / int64
PATH_BYTES_PER_STEP = 8 * (3 + 3 + 3 + 6 + 12)
# memory of one strain probe per orientation [bytes]: its broadcast state and the update's
# outputs (10 floats + 2 flags each), twice for the refinement's concatenation
PROBE_BYTES_PER_DIR = 2 * 2 * (10 * 8 + 2)


class Cli(NamedTuple):
    """A command line of the material point: its ``prog`` ("python -m point") and its one
    ``law`` (the H-model's ``python -m hmodel``), or None for any law (--params, --model)."""

    prog: str
    law: object = None

    def command(self, name: str) -> str:
        return f"{self.prog} {name}"

    def burst_pointer(self) -> str:
        """Where a loss of the static solution is made to happen dynamically."""
        return (f"held past such a point the specimen cannot stay at rest: {self.command('burst')} "
                "makes this failure happen dynamically (docs/burst.md)")


def _label(law) -> str:
    return law.label or law.name


def _material(P) -> dict:
    """The summaries' record of the material: its name and its one line (``describe``)."""
    law = material_of(P)
    return {"name": law.name, "describe": law.describe(P)}


def _absent(P, names) -> list:
    """Of the outputs ``names`` a command writes, those the law of ``P`` does not provide."""
    gone = absent_outputs(material_of(P))
    return [n for n in names if n in gone]


def _check_path(args, eps1_max, options="--d-eps1"):
    """--d-eps1 against the path length ``eps1_max`` and the memory of the path's histories."""
    if args.d_eps1 > eps1_max:
        raise opt.OptionError(f"--d-eps1 {args.d_eps1:g} is out of range: allowed 0 < value <= "
                              f"{eps1_max:g} (the axial strain where the path ends)")
    n = eps1_max / args.d_eps1
    opt.check_memory(n * PATH_BYTES_PER_STEP, f"a path of {n:.3g} steps to eps1 = {eps1_max:g}",
                     options, f"fewer steps ({options})")


def _check_probes(args, P):
    n = 2 * args.n_probes     # the refinement typically doubles the uniform grid near the peak
    dirs = getattr(P, "n_dir", 1)       # the H-model's orientations; one point of another law
    opt.check_memory(n * dirs * PROBE_BYTES_PER_DIR, f"{args.n_probes} strain probes of "
                     f"{dirs} orientations", "--n-probes / --n-dir",
                     "fewer directions or orientations")


def _start(args, stage, text, P):
    """Validated: check the output folder, compile the law's kernels if this is the first run
    (apart from the timings), hold the law to its contract (its first update, and its tangent
    with --check-tangent: ``check_law``), and say what starts. Returns the start time of the
    timings."""
    opt.check_out_dir(args.out)
    law = material_of(P)
    compile_kernels(material=law)
    _check_law(args, P)
    stage.quiet = args.quiet
    _say(stage, text)
    return time.time()


def _check_law(args, P):
    """``check_law`` before anything is written: a broken contract (or, with --check-tangent, a
    tangent that disagrees with the law's own stress) is a MaterialError, one line, exit 2."""
    tangent = getattr(args, "check_tangent", False)
    checks = check_law(material_of(P), P, tangent=tangent)
    if tangent:
        print("tangent check (central differences of the law's own stress): "
              + ", ".join(f"{where} {c.error:.2g}" for where, c in checks)
              + f" (allowed {checks[0][1].tol:g})")


def _say(stage, text):
    stage.at(text)
    if not getattr(stage, "quiet", False):
        print(text, file=sys.stderr, flush=True)


def _written(stage) -> str:
    return ", ".join(stage.written) if stage.written else "nothing"


def _no_closed_form(closed) -> bool:
    """True (and its one line printed) where the law has no closed form."""
    if isinstance(closed, str):
        print(f"closed forms: {closed}")
        return True
    return False


# -- biaxial -------------------------------------------------------------------------------
def cmd_biaxial(args, stage, cli):
    P = params_from(args, cli.law)
    law = material_of(P)
    sigma2 = P.p0
    _check_path(args, args.eps1_max, "--eps1-max / --d-eps1")
    t0 = _start(args, stage, f"drained biaxial test, sigma2 = {sigma2:g} Pa, to eps1 = {args.eps1_max:g}", P)
    note = f"{cli.command('biaxial')}; {args.params_note}"
    exact = onsets.has_mechanism(law)
    try:
        r = biaxial_test(P, sigma2, args.d_eps1, args.eps1_max, progress=not args.quiet,
                         keep_states=exact)
    except BaseException as e:
        # interrupted, or a Newton failure where a static state exists: the rows so far stay
        part = getattr(e, "partial", None)
        if part is not None:
            os.makedirs(args.out, exist_ok=True)
            write_csv(os.path.join(args.out, "biaxial.csv"), present(biaxial_columns(part), law))
            stage.wrote(f"biaxial.csv ({len(part.eps) - 1} steps)", record_params(args.out, P, note))
        if isinstance(e, MaterialError):
            raise MaterialError(f"{e} (drained biaxial, step {len(part.eps) if part else 1}); "
                                f"written complete: {_written(stage)}") from None
        raise
    cols = present(biaxial_columns(r), law)
    t_run = time.time() - t0
    end = r.end
    _say(stage, "writing biaxial.csv, summary.json and Figs. 4-5")
    os.makedirs(args.out, exist_ok=True)
    write_csv(os.path.join(args.out, "biaxial.csv"), cols)
    stage.wrote("biaxial.csv", record_params(args.out, P, note))
    closed = onsets.biaxial_onsets(r, P) if exact else onsets.NO_CLOSED_FORM
    cut = {int(k): int(r.cuts[k]) for k in np.flatnonzero(r.cuts)}
    with atomic_open(os.path.join(args.out, "summary.json")) as f:
        json.dump(json_safe({"parameters": args.params_note, "sigma2": sigma2,
                             "outcome": end.outcome, "end": end.as_dict(), "steps": len(r.eps) - 1,
                             "steps_cut": cut, "burst": cli.burst_pointer(),
                             "material": _material(P),
                             "absent": _absent(P, biaxial_columns(r)),
                             "closed_forms": closed}), f, indent=1)
    stage.wrote("summary.json")
    k_pk = int(np.argmax(cols["q"]))
    hit = np.flatnonzero(cols["eta"] >= args.eta_a)
    a = (cols["eps1"][hit[0]], cols["q"][hit[0]], cols["eps_v"][hit[0]]) if hit.size else None
    mark = (f"no static state beyond: {end.outcome} at {100 * cols['eps1'][-1]:.3f} %"
            if end.outcome != "complete" else None)
    label = _label(law)
    plots.fig_q_eps1([(label, cols["eps1"], cols["q"])], os.path.join(args.out, "fig4_q_eps1.png"),
                     point_a=a[:2] if a else None,
                     peak=(cols["eps1"][k_pk], cols["q"][k_pk]) if 0 < k_pk < len(cols["q"]) - 1 else None,
                     title=f"{label} drained biaxial test, $\\sigma_2$ = {sigma2 / 1e3:g} kPa (Fig. 4)",
                     end=(cols["eps1"][-1], cols["q"][-1], mark) if mark else None)
    stage.wrote("fig4_q_eps1.png")
    plots.fig_epsv_eps1([(label, cols["eps1"], cols["eps_v"])], os.path.join(args.out, "fig5_epsv_eps1.png"),
                        point_a=(a[0], a[2]) if a else None,
                        title=f"{label} drained biaxial test, $\\sigma_2$ = {sigma2 / 1e3:g} kPa (Fig. 5)",
                        end=(cols["eps1"][-1], cols["eps_v"][-1], mark) if mark else None)
    stage.wrote("fig5_epsv_eps1.png")
    print(args.params_note)
    print(f"material: {law.describe(P)}")
    print(f"drained biaxial, sigma2 = {sigma2:g} Pa, {len(cols['eps1']) - 1} steps in {t_run:.2f} s"
          + (f" ({len(cut)} cut in substeps)" if cut else ""))
    print(f"outcome: {end.line()}")
    if end.outcome != "complete":
        print(f"the path ends there (every computed row written); {cli.burst_pointer()}")
    print(f"peak: q = {cols['q'][k_pk]:.6g} Pa, eta = {cols['eta'][k_pk]:.4f} at eps1 = {cols['eps1'][k_pk]:.4%}")
    if a:
        print(f"point A (eta >= {args.eta_a}): eps1 = {a[0]:.4%}, q = {a[1]:.6g} Pa"
              f" ({'before' if hit[0] < k_pk else 'after'} the peak)")
    if not _no_closed_form(closed):
        e1 = closed["peak"]["eps1"]
        pct = lambda x: "none" if x is None else f"{x:.4%}"          # noqa: E731
        print(onsets.line("drained peak (largest q)", closed["peak"], "eta")
              + f" at eps1 = {pct(e1['value'])} (closed form {pct(e1['closed_form'])})")
    print(f"wrote {args.out}/biaxial.csv, params.json, summary.json, fig4_q_eps1.png, fig5_epsv_eps1.png")


# -- probes --------------------------------------------------------------------------------
def cmd_probes(args, stage, cli):
    P = params_from(args, cli.law)
    _check_path(args, DOMAIN_EPS1_MAX)
    _check_probes(args, P)
    t0 = _start(args, stage, f"drained path to point A (eta = {args.eta_a:g}), sigma2 = {P.p0:g} Pa", P)
    try:
        da = directional_analysis(P, args.eta_a, args.d_eps1, args.n_probes, args.strain_norm,
                                  args.stress_step, args.stress_norm, progress=lambda m: _say(stage, m))
    except MaterialError as e:
        raise MaterialError(f"{e} (the directional analysis at A); written complete: nothing")
    tc = da.tangent
    closed = probes_closed_forms(P, da, args.strain_norm)
    t_run = time.time() - t0
    _say(stage, "writing probes.csv, stress_probes.csv, Figs. 3, 6-9, 11 and summary.json")
    summary = write_probes(args.out, P, args.eta_a, da, args.params_note, stage,
                           command=cli.command("probes"), closed_forms=closed)
    law = material_of(P)
    print(args.params_note)
    print(f"material: {law.describe(P)}")
    print(f"point A: eta = {summary['eta_A']:.4f} at eps1 = {summary['eps1_A']:.4%} "
          f"({summary['n_probes']} strain probes, {t_run:.2f} s)")
    print(f"plastic tensorial zone (alpha_sigma, deg): {format_arcs(summary['plastic_zone_alpha_sigma'])}")
    print(f"instability cone W2 <= 0: {format_arcs(summary['cone_w2_alpha_sigma'])}; "
          f"W2_sigma <= 0: {format_arcs(summary['cone_w2sigma_alpha_sigma'])}")
    print(f"min W2 = {summary['min_w2']:.4f} at alpha_sigma = {summary['alpha_sigma_min_w2']:.2f} deg"
          + (f"; min W2n = {summary['min_w2n']:.4f}" if "min_w2n" in summary else ""))
    print(f"det(M) = {tc['det_M_cauchy']:.4g}, det(M_sym) = {tc['det_Msym_cauchy']:.4g} (Cauchy, loading pattern)")
    if not _no_closed_form(closed):
        for name, what in (("cone_edges_strain_plane", "cone edges alpha_eps"),
                           ("cone_edges_stress_plane", "cone edges alpha_sigma")):
            e = closed[name]
            show = lambda y: ", ".join("none" if a is None else f"{a:.4f}" for a in y)  # noqa: E731
            print(f"{what}: [{show(e['value'])}] deg (closed form [{show(e['closed_form'])}], "
                  f"difference [{', '.join('none' if a is None else format(a, '.2g') for a in e['difference'])}])")
        for name, what in (("min_w2", "min W2"), ("lam_min_Msym", "lam_min(M_sym) [Pa]"),
                           ("det_M", "det(M) [Pa^2]"), ("det_D", "det D [Pa^3]")):
            print(onsets.line(what, closed[name]))
    figs = "3, 6-9, 11" if not _absent(P, ("fig9_w2_split.png",)) else "3, 6-8"
    print(f"wrote {args.out}/probes.csv, stress_probes.csv, summary.json, params.json and Figs. {figs}")


def probes_closed_forms(P, da, norm):
    """The closed forms of the directional analysis ``da`` of the law of ``P``
    (``onsets.probe_onsets``: the cone's edges bisected on probes of norm ``norm``), or
    ``onsets.NO_CLOSED_FORM``."""
    if not onsets.has_mechanism(material_of(P)):
        return onsets.NO_CLOSED_FORM
    s_a = da.path.state
    edges = cone_edges(s_a, P, norm=norm, sweep=da.sweep)
    return onsets.probe_onsets(s_a, P, da.sweep, edges, da.tangent)


def write_probes(out, P, eta_a, da, note, stage=None, command="python -m point probes",
                 closed_forms=None) -> dict:
    """The files of a directional analysis at A (``experiment.directional_analysis`` of the
    material ``P`` at ``eta_a``) in the folder ``out`` (created): probes.csv, stress_probes.csv,
    params.json (``P``), Figs. 3, 6-9, 11 (9 and 11 where the law provides their works) and
    summary.json, whose "parameters" is ``note`` (where the values came from) and whose
    "closed_forms" are ``closed_forms`` (default ``probes_closed_forms`` at the default strain
    probe norm). ``command``: the command the params.json note names. Returns the summary;
    ``stage`` (an ``options.Stage``) hears of each file written."""
    stage = stage or opt.Stage()
    law = material_of(P)
    if closed_forms is None:
        closed_forms = probes_closed_forms(P, da, float(np.linalg.norm(da.sweep.d_eps[0])))
    sw, targets, sp, tc = da.sweep, da.targets, da.stress, da.tangent
    os.makedirs(out, exist_ok=True)
    write_csv(os.path.join(out, "probes.csv"), present(probe_columns(sw), law))
    stage.wrote("probes.csv", record_params(out, P, f"{command}; {note}"))
    cols = {"alpha_sigma_target": targets, "n_solutions": sp.n_solutions}
    cols.update({k: v for k, v in probe_columns(sp.probe).items()})
    write_csv(os.path.join(out, "stress_probes.csv"), present(cols, law))
    stage.wrote("stress_probes.csv")
    pth = lambda n: os.path.join(out, n)
    label = _label(law)
    split = "lagrangian" in law.provides
    plots.fig_probes(sw, pth("fig3_probes.png"))
    plots.fig_stress_components(sw, 0, pth("fig6_axial_components.png"), split=split)
    plots.fig_stress_components(sw, 1, pth("fig7_lateral_components.png"), split=split)
    plots.fig_polar_w2([(f"{label} W2", sw.alpha_sigma, sw.w2, "C0-")], pth("fig8_polar_w2.png"),
                       title=f"Normalized second-order work at A ($\\eta$ = {eta_a}) (Fig. 8)",
                       cone=arcs(sw.alpha_sigma, sw.w2 <= 0), plastic=arcs(sw.alpha_sigma, sw.plastic),
                       no_solution=targets[sp.n_solutions == 0])
    if split:
        plots.fig_w2_split(sw, pth("fig9_w2_split.png"))
    if "micro" in law.provides:
        plots.fig_w2_normal_tangential(sw, pth("fig11_w2_normal_tangential.png"),
                                       title=f"{label}: normal and tangential parts of W2 (Fig. 11)")
    stage.wrote("Figs. 3, 6-9, 11" if split else "Figs. 3, 6-8")
    r = da.path
    p, q, eta = r.invariants()
    summary = {
        "parameters": note, "sigma2": P.p0, "eta_A": float(eta[-1]), "eps1_A": float(r.eps[-1, 0]),
        "p_A": float(p[-1]), "q_A": float(q[-1]), "n_probes": int(len(sw.alpha_eps)),
        "plastic_zone_alpha_sigma": arcs(sw.alpha_sigma, sw.plastic),
        "cone_w2_alpha_sigma": arcs(sw.alpha_sigma, sw.w2 <= 0),
        "cone_w2sigma_alpha_sigma": arcs(sw.alpha_sigma, sw.w2_sigma <= 0),
        "min_w2": float(np.min(sw.w2)), "alpha_sigma_min_w2": float(sw.alpha_sigma[np.argmin(sw.w2)]),
    }
    if "micro" in law.provides:
        summary.update({
            "min_w2n": float(np.min(sw.w2n)),
            "max_w2t_in_cone": float(np.max(sw.w2t[sw.w2 <= 0])) if np.any(sw.w2 <= 0) else None,
            "max_abs_w2_minus_micro": float(np.max(np.abs(sw.w2 - sw.w2_micro)))})
    summary.update({
        "stress_probes_without_solution": int(np.sum(sp.n_solutions == 0)),
        "stress_probes_with_several_solutions": int(np.sum(sp.n_solutions > 1)),
        **tc,
        "material": _material(P),
        "absent": _absent(P, [*probe_columns(sw), "min_w2n", "max_w2t_in_cone",
                              "max_abs_w2_minus_micro", "det_M_lagrangian", "det_Msym_lagrangian",
                              "lam_min_Msym_lagrangian", "fig9_w2_split.png",
                              "fig11_w2_normal_tangential.png"]),
        "closed_forms": closed_forms,
    })
    with atomic_open(pth("summary.json")) as f:
        json.dump(summary, f, indent=2)
    stage.wrote("summary.json")
    return summary


# -- domain --------------------------------------------------------------------------------
def cmd_domain(args, stage, cli):
    P = params_from(args, cli.law)
    if args.sigma2 is None:
        pressures = [0.5 * P.p0, P.p0, 2.0 * P.p0]
        note = f"{args.params_note}; pressures p0/2, p0, 2 p0"
    else:
        pressures = args.sigma2
        note = f"{args.params_note}; pressures --sigma2 (p0 {P.p0:g} not used)"
    _check_path(args, DOMAIN_EPS1_MAX)
    _check_probes(args, P)
    t0 = _start(args, stage, f"bifurcation domain at sigma2 = {', '.join(f'{s:g}' for s in pressures)} Pa", P)
    command = cli.command("domain")
    try:
        pts = bifurcation_domain(P, pressures, workers=args.workers, d_eps1=args.d_eps1,
                                 n_dir_probe=args.n_probes, progress=lambda m: _say(stage, m))
        closed = domain_closed_forms(P, pts, args.d_eps1)
    except BaseException as e:
        if getattr(e, "partial", None):     # interrupted: the pressures finished stay
            write_domain_rows(args.out, P, e.partial, len(pressures), note, stage, command)
        if isinstance(e, MaterialError):
            raise MaterialError(f"{e} (the bifurcation domain); written complete: "
                                f"{_written(stage)}") from None
        raise
    t_run = time.time() - t0
    write_domain(args.out, P, pts, note, stage, command, closed)
    print(note)
    print(f"material: {material_of(P).describe(P)}")
    pq = lambda p, q: (f"(p, q) = ({p:.4g}, {q:.4g}) Pa" if np.isfinite(p) else "never before the peak")
    for d in pts:
        print(f"sigma2 = {d.sigma2:g} Pa: first W2 <= 0 at {pq(d.p_w2, d.q_w2)}; first W2_sigma <= 0 "
              f"at {pq(d.p_w2sigma, d.q_w2sigma)}; peak at {pq(d.p_peak, d.q_peak)}")
        if d.outcome != "complete":
            print(f"  the drained path at {d.sigma2:g} Pa ends {d.end}")
    if not _no_closed_form(closed):
        for c in closed:
            s2 = f"sigma2 = {c['sigma2']:g} Pa"
            print(onsets.line(f"{s2}: first W2 <= 0 (h = h_sym)", c["first_w2"], "eta"))
            rice = c["rice"]["eta_closed_form"]
            print(f"{s2}: Rice's localization (h = h_loc): eta = "
                  f"{'none before the peak' if rice is None else format(rice, '.6g')} (closed form "
                  "only: the material point has no localization check)")
            print(onsets.line(f"{s2}: peak (h = 0)", c["peak"], "eta"))
    print(f"wrote {args.out}/domain.csv, params.json, summary.json, fig10_domain.png ({t_run:.1f} s)")


def domain_closed_forms(P, pts, d_eps1):
    """The closed forms of the domain points ``pts`` of the law of ``P`` (``onsets.domain_onsets``
    along each pressure's drained path run again with its states, steps ``d_eps1``, to two
    steps past the domain's peak, or to its end), or ``onsets.NO_CLOSED_FORM``."""
    if not onsets.has_mechanism(material_of(P)):
        return onsets.NO_CLOSED_FORM
    out = []
    for d in pts:
        p = P.replace(p0=float(d.sigma2))
        end = d.eps1_peak if np.isfinite(d.eps1_peak) else DOMAIN_EPS1_MAX
        n = max(2, int(round(end / d_eps1)) + 2)
        try:
            r = run_path(isotropic_state(p), p, drained_biaxial(d_eps1), n, keep_states=True)
        except MixedControlError as e:
            r = e.partial
        out.append(onsets.domain_onsets(r, p, d))
    return out


def write_domain_rows(out, P, pts, n_pressures, note, stage=None, command="python -m point domain"):
    """domain.csv of the domain points ``pts`` (``experiment.bifurcation_domain``: ``n_pressures``
    asked for, all of them or those finished) and params.json (``P``, with ``note``: where the
    values came from, after ``command``) in the folder ``out`` (created)."""
    stage = stage or opt.Stage()
    os.makedirs(out, exist_ok=True)
    cols = {k: np.array([getattr(d, k) for d in pts]) for k in DOMAIN_COLUMNS}
    write_csv(os.path.join(out, "domain.csv"), cols)
    stage.wrote(f"domain.csv ({len(pts)} of {n_pressures} pressures)" if len(pts) < n_pressures
                else "domain.csv", record_params(out, P, f"{command}; {note}"))


def write_domain(out, P, pts, note, stage=None, command="python -m point domain",
                 closed_forms=None):
    """The files of a bifurcation domain (``experiment.bifurcation_domain`` of the material
    ``P``) in the folder ``out`` (created): domain.csv, params.json, summary.json (its
    "parameters": ``note``; its "closed_forms": ``closed_forms``, default ``domain_closed_forms``
    with steps of 1e-5) and Fig. 10."""
    stage = stage or opt.Stage()
    if closed_forms is None:
        closed_forms = domain_closed_forms(P, pts, 1e-5)
    write_domain_rows(out, P, pts, len(pts), note, stage, command)
    with atomic_open(os.path.join(out, "summary.json")) as f:
        json.dump(json_safe({"parameters": note, "paths": [
            {"sigma2": d.sigma2, "outcome": d.outcome, "end": d.end or None} for d in pts],
            "material": _material(P), "absent": [], "closed_forms": closed_forms}), f, indent=1)
    stage.wrote("summary.json")
    plots.fig_domain(pts, os.path.join(out, "fig10_domain.png"))


# -- burst ---------------------------------------------------------------------------------
def cmd_burst(args, stage, cli):
    from . import burst
    P = params_from(args, cli.law)
    args.sigma2 = P.p0               # the confining stress of the test: --sigma2, else the file's
    if args.dc is None:
        args.dc = 1e-4 * args.sigma2
    try:
        spec = burst.Specimen(args.width, args.height, args.density).validate()
    except ValueError as e:
        raise opt.record_error(e, "Specimen") from None
    try:
        dyn = burst.Dynamics(args.damping_ratio, args.steps_per_period).validate()
    except ValueError as e:
        raise opt.record_error(e, "Dynamics") from None
    # --start-fractions' range with its upper end open (a state below the drained peak); the
    # parser checked the term's own
    r = opt.vocabulary_range(burst.RECORD, "start_fractions", hi_open=True)
    bad = [f for f in args.start_fractions if not r.contains(f)]
    if bad:
        raise opt.OptionError(f"--start-fractions {bad[0]:g} is out of range: allowed {r.text()} "
                              "(a state below the drained peak)")
    if args.path_d_eps1 > args.path_strain:      # the parser checked the term's range; and:
        t = opt.VOCABULARY["--path-d-eps1"]
        r = opt.Range("hmodel.cmd_burst", "path_d_eps1", "real", t.lo, "path_strain", t.lo_open,
                      False)
        raise opt.OptionError(f"--path-d-eps1 {args.path_d_eps1:g} is out of range: allowed "
                              f"{r.text()} {args.path_strain:g}")
    _check_path(args, DOMAIN_EPS1_MAX)
    t0 = _start(args, stage, f"burst: R = {', '.join(f'{R:g}' for R in args.ratios)}, start at "
                f"{', '.join(f'{f:g}' for f in args.start_fractions)} of the drained peak eta, "
                f"sigma2 = {args.sigma2:g} Pa, dc = {args.dc:g} Pa", P)
    law = material_of(P)
    note = f"{cli.command('burst')}; {args.params_note}"
    try:
        res = burst.run_burst(P, args.ratios, args.start_fractions, args.dc, spec, dyn, args.d_eps1,
                              args.path_strain, progress=lambda m: _say(stage, m),
                              path_d_eps1=args.path_d_eps1)
    except MaterialError as e:
        part = getattr(e, "partial", None)
        if part is not None and part.rows:      # the runs finished stay, complete
            os.makedirs(args.out, exist_ok=True)
            write_burst_tables(args.out, part, stage)
            stage.wrote(record_params(args.out, P, note))
        raise MaterialError(f"{e} (the burst experiment); written complete: "
                            f"{_written(stage)}") from None
    cone = {}
    if not args.no_cone:
        _say(stage, "directional analysis: where each path direction enters the cone W2 <= 0, "
                    "and the first W2 = 0 of the drained path")
        from .experiment import domain_point
        d = domain_point(P, args.sigma2, d_eps1=args.d_eps1)
        cone["eta_first_w2"] = float(d.q_w2 / d.p_w2)
        if np.isfinite(cone["eta_first_w2"]):
            cone["cone_at_first_w2"] = burst.cone_at(P, cone["eta_first_w2"], args.d_eps1)
        cone["paths"] = {f"{R:g}": v for R, v in
                         burst.cone_entries(P, args.ratios, args.d_eps1).items()}
    closed = burst_closed_forms(P, res, args.path_d_eps1)
    t_run = time.time() - t0
    _say(stage, "writing burst.csv, history.csv, paths.csv, the figures and summary.json")
    os.makedirs(args.out, exist_ok=True)
    pth = lambda n: os.path.join(args.out, n)
    write_burst_tables(args.out, res, stage)
    outcome = {(r["ratio"], r["start_fraction"], r["switch"]): r["outcome"] for r in res.rows}
    for h in res.histories:
        h["outcome"] = outcome[(h["ratio"], h["start_fraction"], h["switch"])]
    _, _, eta_d = res.drained.invariants()
    paths = [{"ratio": pi.ratio, "start_fraction": pi.start_fraction, "eps1_start": pi.eps1_start,
              "eps1": pi.path.eps[:, 0], "eta": pi.eta, "c": pi.c, "k_peak": pi.k_peak,
              "p": pi.path.invariants()[0]}
             for pi in res.paths]
    plots.fig_burst_paths((res.drained.eps[:, 0], eta_d), paths, res.rows, pth("fig_burst_paths.png"),
                          eta_w2=cone.get("eta_first_w2"),
                          title=f"{_label(law)}, $\\sigma_2$ = {args.sigma2 / 1e3:g} kPa (drained peak "
                                f"$\\eta$ = {res.eta_peak:.4f})")
    plots.fig_burst_ke(res.histories, pth("fig_burst_ke.png"),
                       title=f"Material point (homogeneous specimen {args.width:g} x {args.height:g} m, "
                             f"{args.density:g} kg/m$^3$, $\\zeta$ = {args.damping_ratio:g}):\n"
                             f"kinetic energy after the switch, c held at c_switch + {args.dc:g} Pa")
    plots.fig_burst_residual(res.histories, pth("fig_burst_residual.png"))
    stage.wrote("fig_burst_paths.png", "fig_burst_ke.png", "fig_burst_residual.png")
    stage.wrote(record_params(args.out, P, note))
    summary = {"params": {f.name: getattr(P, f.name) for f in dataclasses.fields(P) if f.init},
               "params_note": args.params_note,
               "options": {k: v for k, v in vars(args).items() if k not in ("func", "command")},
               "eta_peak_drained": res.eta_peak, "directional_analysis": cone,
               "runs": res.rows, "wall_time_s": t_run, "material": _material(P), "absent": [],
               "closed_forms": closed}
    with atomic_open(pth("summary.json")) as f:
        json.dump(json_safe(summary), f, indent=1, allow_nan=False)
    stage.wrote("summary.json")
    print(args.params_note)
    print(f"material: {law.describe(P)}")
    print(f"drained peak eta = {res.eta_peak:.4f} at sigma2 = {args.sigma2:g} Pa"
          + (f"; first W2 = 0 of the directional analysis at eta = "
             f"{fmt(cone['eta_first_w2'], '.4f', 'never (before the peak)')}" if cone else ""))
    # eta_peak_c: none where c does not peak within --path-strain (one below run, at its end);
    # the growth measure (burst_rule.energy_release): the largest (E_c - E_c(0)) / W2_ext and
    # when it passed RELEASE (never: it did not)
    print("    R  start  eta_start  eta_peak_c  (fraction)  switch  static  outcome        "
          "max (E_c-E_c0)/W2_ext  t_release/T1")
    for r in res.rows:
        frac = f"({fmt(r['fraction_peak_c'], '.3f')})" if np.isfinite(r["eta_peak_c"]) else ""
        print(f"{r['ratio']:5g}  {r['start_fraction']:5g}  {r['eta_start']:9.4f}  "
              f"{fmt(r['eta_peak_c'], '10.4f')}  {frac:7s}     {r['switch']:6s}  "
              f"{'yes' if r['static_solution'] else 'none':6s}  {r['outcome']:13s}  "
              f"{fmt(r['ke_w2ext_max'], '21.3g')}  {fmt(r['t_release_t1'], '12.2f', 'never')}")
    if cone.get("cone_at_first_w2"):
        ca = cone["cone_at_first_w2"]
        rr = ca["ratio_range"]
        print(f"cone W2 <= 0 at that state: alpha_eps {format_arcs(ca['alpha_eps_arcs'])} deg"
              + (f", i.e. the proportional paths of R in [{rr[0]:.3f}, {rr[1]:.3f}]" if rr else ""))
    if cone:
        for R, ce in cone["paths"].items():
            where = (f"enters the cone W2 <= 0 of the drained path at eta = {ce['eta']:.4f}"
                     if np.isfinite(ce["eta"]) else
                     "never enters the cone W2 <= 0 of the drained path before its peak")
            print(f"R = {R}: strain direction alpha_eps = {ce['alpha_eps']:.2f} deg {where}")
    if res.rows:
        print(f"energy check (the material's stress and strain, the field's kinetic energy, "
              f"O(dt^2)): largest relative residual {max(r['energy_check'] for r in res.rows):.2e}"
              f"; Newmark's own balance (the work of the Newton residual): largest "
              f"{max(r['newton_work'] for r in res.rows):.2e} a step")
    for r in res.rows:
        if r["failure_reason"]:
            print(f"R = {r['ratio']:g}, start {r['start_fraction']:g}, {r['switch']}: not "
                  f"converged: {r['failure_reason']}")
    if not _no_closed_form(closed):
        for c in closed:
            head = f"R = {c['ratio']:g}, start {c['start_fraction']:g}"
            verdicts = "; ".join(f"{v['switch']} {v['verdict']['value']} (closed form "
                                 f"{v['verdict']['closed_form']})" for v in c["runs"])
            print(onsets.line(f"{head}: c peak (h = h_R)", c, "eta") + f"; verdicts: {verdicts}")
    print(f"wrote {args.out}/burst.csv, history.csv, paths.csv, params.json, summary.json, fig_burst_*.png "
          f"({t_run:.1f} s)")


def write_burst_tables(out, res, stage):
    """burst.csv, history.csv and paths.csv of the burst experiment ``res`` (``burst.run_burst``'s
    result, or the runs it finished) in the folder ``out``."""
    from . import burst
    pth = lambda n: os.path.join(out, n)
    write_csv(pth("burst.csv"), {k: [r[k] for r in res.rows] for k in burst.BURST_COLUMNS}, nan="")
    stage.wrote("burst.csv")
    hist = {k: [] for k in burst.HISTORY_COLUMNS}
    for h in res.histories:
        n = len(h["t"])
        for k in burst.HISTORY_COLUMNS:
            hist[k].extend([h[k]] * n if k in ("ratio", "start_fraction", "switch")
                           else (range(n) if k == "step" else h[k]))
    write_csv(pth("history.csv"), hist, nan="")
    stage.wrote("history.csv")
    pcols = {k: [] for k in burst.PATH_COLUMNS}
    for pi in res.paths:
        pp, qq, ee = pi.path.invariants()
        n = len(pp)
        vals = {"ratio": [pi.ratio] * n, "start_fraction": [pi.start_fraction] * n,
                "eps1": pi.path.eps[:, 0], "eps2": pi.path.eps[:, 1], "s1": pi.path.sigma[:, 0],
                "s2": pi.path.sigma[:, 1], "p": pp, "q": qq, "eta": ee, "c": pi.c}
        for k in pcols:
            pcols[k].extend(vals[k])
    write_csv(pth("paths.csv"), pcols)
    stage.wrote("paths.csv")


def burst_closed_forms(P, res, path_d_eps1):
    """The closed forms of the burst experiment ``res`` of the law of ``P``
    (``onsets.path_onsets``: each proportional path run again from its start with its states,
    steps ``path_d_eps1``, to its last row; each run's static verdict against the closed form's
    under the tie's c control), or ``onsets.NO_CLOSED_FORM``."""
    if not onsets.has_mechanism(material_of(P)):
        return onsets.NO_CLOSED_FORM
    out = []
    for pi in res.paths:
        n = len(pi.path.eps) - 1
        r = run_path(pi.start, P, proportional_strain(path_d_eps1, pi.ratio), max(n, 1),
                     keep_states=True)
        holds = [(row["switch"], row["c_switch"] + row["dc"], row["static_verdict"])
                 for row in res.rows if (row["ratio"], row["start_fraction"])
                 == (pi.ratio, pi.start_fraction)]
        out.append({"ratio": pi.ratio, "start_fraction": pi.start_fraction,
                    **onsets.path_onsets(r, P, pi.ratio, pi.c, pi.k_peak,
                                         proportional_strain_stress(pi.ratio), holds)})
    return out


# -- fit -----------------------------------------------------------------------------------
def cmd_fit(args, stage, cli):
    """Exit 0 fitted, 1 not fittable (summary.json and fig_fit.png say why), 2 bad option."""
    opt.check_csv(args.data, ("eps1", "q"), "--data",
                  "a CSV file with a header row naming eps1 and q (and eps_v or eps2, s2 or "
                  "sigma2 where present): a drained curve, e.g. the biaxial.csv of a biaxial test")
    try:
        curve = pfit.read_curve(args.data, sigma2=args.sigma2)
    except pfit.CurveError as e:
        raise opt.OptionError(f"--data {args.data}: {e}") from None
    P = params_from(args, cli.law, p0=curve.sigma2)
    law = material_of(P)
    if args.free is None:
        args.free = pfit.space_of(law).default_free
    try:
        pfit.check_free_bounds(args.free, args.bounds, P)
    except ParamError as e:
        raise opt.OptionError(f"--bounds {e.name}: {e.value!r} is out of range: allowed {e.allowed}") from None
    except ValueError as e:
        raise opt.OptionError(f"--free / --bounds: {e}") from None
    fitted, held = pfit.structural_reduction(args.free, P)
    if not fitted:
        raise opt.OptionError("--free: none of " + ", ".join(args.free) + " enters a drained curve ("
                              + "; ".join(f"{n} {w}" for n, w in held.items()) + ")")
    e_max = float(curve.eps1[-1])
    _check_path(args, e_max)
    if args.d_eps1_search > e_max:
        raise opt.OptionError(f"--d-eps1-search {args.d_eps1_search:g} is out of range: allowed 0 < "
                              f"value <= {e_max:g} (the last eps1 of the data)")
    t0 = _start(args, stage, f"fit of {', '.join(args.free)} to {args.data} ({curve.eps1.size} points, "
                f"sigma2 = {curve.sigma2:.6g} Pa: {curve.sigma2_from}), {args.starts} starts", P)
    res = pfit.fit_curve(curve, P, args.free, args.bounds, n_starts=args.starts, seed=args.seed,
                         w_epsv=args.w_epsv, d_eps1=args.d_eps1, d_eps1_search=args.d_eps1_search,
                         max_nfev=args.max_nfev, progress=lambda m: _say(stage, m))
    t_run = time.time() - t0
    write_fit(args.out, curve, res, f"{cli.command('fit')} --data {args.data}: fitted "
              f"{', '.join(args.free)}; {args.params_note}",
              {k: v for k, v in vars(args).items() if k != "func"}, t_run, stage, P)
    if res.status != "fitted":
        print(f"not fittable: {res.reason}", file=sys.stderr)
        print(f"wrote {args.out}/summary.json, fig_fit.png")
        return 1
    print(f"material: {law.describe(res.params)}")
    print(pfit.format_result(res, curve))
    print(f"wrote {args.out}/params.json, fit.csv, residuals.csv, correlation.json, summary.json, "
          f"fig_fit.png ({t_run:.1f} s)")
    return 0


def write_fit(out, curve, res, note, options=None, wall_time=None, stage=None, start=None) -> dict:
    """The files of a fit (``fit.fit_curve``'s result ``res`` on the data ``curve``) in the
    folder ``out`` (created): params.json (the fitted record, with ``note``: how it was
    fitted), fit.csv, residuals.csv and correlation.json when it fitted; summary.json
    (``fit.summary_dict`` with the run's ``options``, ``wall_time`` [s] and the material: of
    the fitted record, else of ``start``, the record the fit started from) and fig_fit.png
    always. Returns the summary (what summary.json holds)."""
    stage = stage or opt.Stage()
    os.makedirs(out, exist_ok=True)
    pth = lambda n: os.path.join(out, n)
    summary = pfit.summary_dict(res, curve)
    summary["options"] = {k: (list(v) if isinstance(v, tuple) else v)
                          for k, v in (options or {}).items()}
    summary["wall_time_s"] = wall_time
    rec = res.params if res.params is not None else start
    if rec is not None:
        summary["material"] = _material(rec)
    if res.status == "fitted":
        save_params(pth("params.json"), res.params, note)
        stage.wrote("params.json")
        cols = {"eps1": curve.eps1, "q": curve.q, "q_fit": res.model_q}
        rcols = {"eps1": curve.eps1, "r_q": res.residuals_q,
                 "r_q_weighted": res.residuals_q * res.info["weight_q"]}
        if curve.eps_v is not None:
            cols.update(eps_v=curve.eps_v, eps_v_fit=res.model_eps_v)
            rcols.update(r_eps_v=res.residuals_eps_v,
                         r_eps_v_weighted=res.residuals_eps_v * res.info["weight_eps_v"])
        write_csv(pth("fit.csv"), cols)
        write_csv(pth("residuals.csv"), rcols)
        with atomic_open(pth("correlation.json")) as fh:
            json.dump(pfit.correlation_dict(res), fh, indent=2)
        stage.wrote("fit.csv", "residuals.csv", "correlation.json")
    with atomic_open(pth("summary.json")) as fh:
        json.dump(summary, fh, indent=2)
    stage.wrote("summary.json")
    pfit.plot_fit(curve, res, pth("fig_fit.png"), _label(material_of(rec)) if rec is not None
                  else "H-model")
    stage.wrote("fig_fit.png")
    return summary


# -- params --------------------------------------------------------------------------------
def cmd_params(args, stage, cli):
    P = params_from(args, cli.law)
    opt.check_out_file(args.out)
    save_params(args.out, P, f"{cli.command('params')}; {args.params_note}")
    stage.wrote(os.path.basename(args.out))
    print(args.params_note)
    print(f"material: {material_of(P).describe(P)}")
    print(f"wrote {args.out}")


# -- the parser ----------------------------------------------------------------------------
DESCRIPTION = """The material point of any constitutive law of the plane (the contract of point:
the H-model, non-associated Drucker-Prager, or a law registered with point.register): the
analysis of Nicot, Hadda & Darve (2013) on it. The law: the "model" of --params FILE, else
--model NAME (its defaults), else the H-model. python -m point COMMAND --help lists a command's
options, each with its unit and default. --out is required: a folder (the parameter file for
params) that records the command that wrote it (command.json); another command refuses that
folder unless --force."""

def _fit_defaults(law):
    """(--free's default, its text, --bounds' text) of the fit of ``law`` (None: any law)."""
    if law is not None:
        space = pfit.space_of(law)
        return (space.default_free, ", ".join(space.choices), space.bounds_text)
    spaces = {n: pfit.space_of(material_named(n)) for n in known_laws()}
    return (None, "; ".join(f"{n}: {', '.join(s.choices)}" for n, s in spaces.items()),
            "; ".join(f"{n}: {s.bounds_text}" for n, s in spaces.items()))


def build_parser(prog: str = "python -m point", law=None,
                 description: str = DESCRIPTION) -> argparse.ArgumentParser:
    """The parser of the material point's commands: of any law (``law`` None: --model and every
    law's parameter options), or of the one ``law`` (``python -m hmodel``)."""
    cli = Cli(prog, law)
    add = opt.add
    ap = opt.Parser(prog=prog, description=description,
                    formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="command", required=True, metavar="COMMAND")
    record = law.params_type.__name__ if law is not None else None
    defaults = law.defaults_name if law is not None else "the law's defaults"
    p0 = (f"the p0 of --params FILE, else {defaults}'s {law.params_type().p0 / 1e3:g}e3"
          if law is not None else "the p0 of --params FILE, else the law's default (" + ", ".join(
              f"{n}: {material_named(n).params_type().p0 / 1e3:g}e3" for n in known_laws()) + ")")
    what = f"the {_label(law)}" if law is not None else "the law"

    def common(p):
        add(p, "--check-tangent")
        opt.add_quiet(p)
        add_param_options(p, law)

    b = sub.add_parser("biaxial", help="drained biaxial test (Figs. 4-5)")
    opt.add_out(b)
    add(b, "--sigma2", record=record, default_text=p0)
    add(b, "--eps1-max", 0.05)
    add(b, "--d-eps1", 1e-5)
    add(b, "--eta-a", 1.029, note="marked on the curves")
    common(b)
    b.set_defaults(func=partial(cmd_biaxial, cli=cli))

    p = sub.add_parser("probes", help="directional analysis at point A (Figs. 3, 6-9, 11)")
    opt.add_out(p)
    add(p, "--eta-a", 1.029, note="the state of the probes (q/p < 2 while sigma2 > 0)")
    add(p, "--sigma2", record=record, default_text=p0)
    add(p, "--n-probes", 360, note="refined where the response jumps")
    add(p, "--strain-norm", 1e-6)
    add(p, "--d-eps1", 1e-5, note="to point A")
    add(p, "--stress-step", 5.0)
    add(p, "--stress-norm", 2.5e3)
    common(p)
    p.set_defaults(func=partial(cmd_probes, cli=cli))

    d = sub.add_parser("domain", help="bifurcation domain over confining stresses (Fig. 10)")
    opt.add_out(d)
    add(d, "--sigma2", many=True, note="comma-separated, one drained path each",
        default_text=f"p0/2, p0, 2 p0 with the p0 of --params FILE: 100e3,200e3,400e3 for "
                     f"{defaults}")
    add(d, "--d-eps1", 1e-5)
    add(d, "--n-probes", 180, note="of each check")
    add(d, "--workers", default_text="min(pressures, cores)")
    common(d)
    d.set_defaults(func=partial(cmd_domain, cli=cli))

    u = sub.add_parser("burst", help="proportional strain paths, c controlled past its peak: the "
                                     "burst of kinetic energy (docs/burst.md)")
    opt.add_out(u)
    add(u, "--ratios", [-1.0, -1.5, -2.0, -3.0], parse=opt.argtype(_check_ratios))
    add(u, "--start-fractions", [0.90, 0.95], note="f < 1 here (a state below the drained peak)")
    add(u, "--dc", default_text="1e-4 sigma2, as fem burst")
    add(u, "--sigma2", record=record, default_text=p0)
    add(u, "--d-eps1", 1e-5, note="to the start states")
    add(u, "--path-d-eps1", 1e-5)
    add(u, "--path-strain", 0.03)
    add(u, "--density", 1600.0, record="Specimen",
        note="bulk, of the homogeneous specimen (dry granular: 1500-1700)")
    add(u, "--width", 0.05, record="Specimen")
    add(u, "--height", 0.1, record="Specimen")
    add(u, "--damping-ratio", 0.05, record="Dynamics")
    add(u, "--steps-per-period", 20, record="Dynamics")
    add(u, "--no-cone")
    common(u)
    u.set_defaults(func=partial(cmd_burst, cli=cli))

    free, choices, bounds = _fit_defaults(law)
    f = sub.add_parser("fit", help=f"fit {what} to a measured drained biaxial curve (docs/fit.md)")
    opt.add_out(f)
    add(f, "--data", required=True, metavar="CSV")
    if law is not None:
        add(f, "--free", free, parse=opt.argtype(partial(pfit.parse_free,
                                                         choices=pfit.space_of(law).choices),
                                                 "parse_free"),
            note=f"of {choices}; the others as given")
        add(f, "--bounds", {}, parse=opt.argtype(partial(pfit.parse_bounds,
                                                         choices=pfit.space_of(law).choices),
                                                 "parse_bounds"),
            default_text=bounds)
    else:
        add(f, "--free", parse=opt.argtype(pfit.parse_free), note=f"of the law's fields ({choices}); "
            "the others as given", default_text="the law's: " + "; ".join(
                f"{n}: {','.join(pfit.space_of(material_named(n)).default_free)}"
                for n in known_laws()))
        add(f, "--bounds", {}, parse=opt.argtype(pfit.parse_bounds), default_text=bounds)
    add(f, "--starts", 8)
    add(f, "--seed", 0, note="of the starts")
    add(f, "--sigma2", note="the data's", default_text="the median of the data's column s2 or "
        "sigma2")
    add(f, "--w-epsv", 1.0)
    add(f, "--d-eps1", 1e-5, note="of the final fit")
    add(f, "--d-eps1-search", 1e-4)
    add(f, "--max-nfev", 100)
    common(f)
    f.set_defaults(func=partial(cmd_fit, cli=cli))

    w = sub.add_parser("params", help="write a parameter file: " + (
        f"{law.defaults_name}, or --params FILE, with the options given on top (docs/parameters.md)"
        if law is not None else "the defaults of --model, or --params FILE, with the options "
        "given on top (docs/parameters.md)"))
    opt.add_out(w, "file")
    add(w, "--sigma2", record=record, note="the file's p0", default_text=p0)
    add_param_options(w, law)
    w.set_defaults(func=partial(cmd_params, cli=cli))
    return ap


def _check_ratios(text):
    """--ratios: comma-separated R, each finite and < 0 (``burst.check_ratio`` says why not)."""
    from .burst import check_ratio
    vals = opt.reals()(text)
    return [check_ratio(v, None) for v in vals]


def main(argv=None, prog: str = "python -m point", law=None, description: str = DESCRIPTION) -> int:
    """``python -m point ...`` (``law`` None) or a command line of one law (``python -m hmodel``):
    0 done (also a path that ends without a static state: a result), 1 not fittable (``fit``) or
    a Newton failure where a static state exists, 2 bad option or a law that breaks its contract
    or cannot go on (``MaterialError``, one line), 130 / 143 interrupted."""
    def run(args, stage):
        try:
            return args.func(args, stage) or 0
        except MixedControlError as e:
            # a static state exists but Newton did not reach it: a failure, not bad input
            print(f"error: {e}", file=sys.stderr)
            return 1
    return opt.run_cli(build_parser(prog, law, description), argv, run, errors=(ValueError,))
