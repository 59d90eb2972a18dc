"""The cross-check's report: report.md, every figure embedded and each conclusion of the
paper's section 5 stated with this run's numbers (``crosscheck.conclusions``), the burst section
(``crosscheck.burst.report``) and the wall times.
"""
from __future__ import annotations

import json
import os

__all__ = ["write_report"]


def write_report(out, c: dict, figs: dict, timings: dict, config: dict, graph: dict | None = None):
    """report.md: every figure embedded and the paper's section-5 conclusions in numbers."""
    from common.io import atomic_open
    from dem.domain import eta_lim_text
    from point.probes import format_arcs
    hm, dm, fm = c["hmodel"], c["dem"], c["fem"]
    L = ["# Cross-check: H-model, finite elements and DEM", "",
         f"Configuration: {json.dumps(config)}", "",
         "Conventions: compression positive; alpha_sigma with tan(alpha_sigma) = d sigma1 / d sigma2; "
         "W2 normalized by |d sigma||d eps| (H-model: |dPi||d eps|).", "",
         "## Stress-strain curves", "", f"![stress-strain]({figs['stress_strain']})", "",
         f"- H-model: peak q = {hm['q_peak'] / 1e3:.1f} kPa at eps1 = {100 * hm['eps1_peak']:.2f} % "
         f"(eta = {hm['eta_peak']:.4f}); point A (eta = {hm['eta_A']:.4f}) at eps1 = {100 * hm['eps1_A']:.2f} %, before the peak."]
    if fm:
        L.append(f"- FE specimen (perfect, coarse mesh) against the material point with the same "
                 f"orientations: max |q_FE - q_mp| / q_max = {fm['max_rel_q_diff_vs_material_point']:.2e}; "
                 f"FE peak at eps1 = {100 * fm['eps1_peak']:.2f} %.")
    if dm is not None:
        L.append(f"- DEM sample: peak eta = {dm.get('eta_peak', float('nan')):.4f} (p = (s1 + s2)/2; "
                 f"eta = 1.029 reached: {config.get('dem_eta_a_reached')}).")
        st = dm.get("state")
        if st:
            L.append(
                f"- DEM comparison state, by rule: the highest saved state whose reference held at "
                f"constant stress and whose every probe target stays below the largest stress ratio "
                f"held by a reference (eta_R + largest probe increment <= max eta_R held, a lower "
                f"bound of the strength under stress control eta_lim) and the smallest that failed: "
                f"**{st['state']}**, eta_R = "
                f"{st['eta_R']:.4f} ({st['eta_fraction']:.3f} of the peak), largest probe increment "
                f"{st['max_eta_increment']:.4f}, largest eta held {st['eta_held_max']:.4f}"
                + (f", smallest eta that failed {st['eta_failed_min']:.4f}" if st['eta_failed_min'] else "")
                + ("" if st["rule_met"] else " (no state met the rule: the lowest held state)") + ".")
    L += ["", "## Second-order work at A (H-model) and at the comparison state (DEM)", "",
          f"![polar W2]({figs['polar_w2']})", "",
          f"![micro and macro]({figs['micro_macro']})", "",
          f"![normal and tangential parts]({figs['normal_tangential']})", ""]
    if "domain" in figs:
        L += [f"![bifurcation domain]({figs['domain']})", ""]
    for key in ("dem_domain", "dem_domain_w2"):
        if key in figs:
            L += [f"![DEM bifurcation domain]({figs[key]})", ""]
    L += ["## The paper's conclusions (section 5), as they come out of this run", ""]
    # 1. instability cone
    s = (f"1. **Instability cone in the third quadrant.** H-model: W2 <= 0 for alpha_sigma in "
         f"{format_arcs(hm['cone_w2'])} deg (third quadrant: {hm['cone_in_third_quadrant']}), "
         f"minimum W2 = {hm['min_w2']:.3f} at {hm['alpha_min_w2']:.1f} deg, inside the plastic zone "
         f"{format_arcs(hm['plastic_zone'])} deg.")
    if dm:
        fl, und = dm["alpha_failure"], dm["alpha_undecided"]
        s += (f" DEM ({dm['n_probes']} probes: {dm['n_equilibrium']} equilibrium, {len(fl)} failures"
              + (f" at alpha_sigma = {', '.join(f'{x:.0f}' for x in fl)} deg (the sample ran away: "
                 f"W2 <= 0 in the limit, Eq. 1)" if fl else "")
              + f", {len(und)} undecided"
              + (f" at {', '.join(f'{x:.0f}' for x in und)} deg" if und else "")
              + f"): unstable directions (W2 <= 0 or failure) "
              f"{format_arcs(dm['unstable_directions']) if dm['unstable_directions'] else 'none'}; W2 <= 0 for {format_arcs(dm['cone_w2']) if dm['cone_w2'] else 'no direction'}; minimum W2 = {dm['min_w2']:.3f} at "
              f"{dm['alpha_min_w2']:.0f} deg (third quadrant: {dm['min_in_third_quadrant']}); low-W2 cone "
              f"(within 0.1 of the minimum) {format_arcs(dm['low_w2_cone'])} deg; plastic zone "
              f"{format_arcs(dm['plastic_zone'])} deg.")
    L.append(s)
    # 2. micro vs macro
    mm = hm["micro_minus_macro"]
    s = (f"2. **Micro sum against macro W2.** H-model: max |W2 - sum df.dl| = "
         f"{mm['elastic']['max']:.1e} (elastic zone), {mm['plastic']['max']:.1e} (plastic zone): "
         f"the identity holds to round-off in the absence of inertia.")
    if dm:
        d = dm["micro_minus_macro"]
        fz = lambda z: f"mean {z['mean']:.3f}, max {z['max']:.3f} over {z['n']} probes" if z else "no probe"
        s += (f" DEM: |W2 - micro| {fz(d['elastic'])} in the elastic zone and {fz(d['plastic'])} in the "
              f"plastic zone; the micro sum is {'below' if dm['micro_below_macro_in_plastic_zone'] else 'not below'} "
              f"the macro W2 on average in the plastic zone (paper: the macro W2 exceeds the micro sum there).")
    L.append(s)
    # 3. normal / tangential
    s = (f"3. **The tangential part drives the vanishing.** H-model: min W2n = {hm['w2n_min']:.3f} (> 0 everywhere); "
         f"inside the cone max W2t = {hm['w2t_max_in_cone']:.3f} (< 0) while W2n >= {hm['w2n_min_in_cone']:.3f}."
         if hm["w2t_max_in_cone"] is not None else
         f"3. **Tangential part.** H-model: min W2n = {hm['w2n_min']:.3f}; no cone at this A.")
    if dm:
        s += (f" DEM: min W2n = {dm['w2n_min']:.3f}; max W2t in the plastic zone = "
              f"{dm['w2t_max_in_plastic_zone']:.3f}; at the minimum of W2, W2n = {dm['w2n_at_min_w2']:.3f} "
              f"and W2t = {dm['w2t_at_min_w2']:.3f}.")
    L.append(s)
    # 4. domain
    if c["domain"]:
        parts = [f"sigma2 = {d['sigma2'] / 1e3:.0f} kPa: eta = {d['eta_w2']:.3f} (W2), {d['eta_w2sigma']:.3f} "
                 f"(W2_sigma), peak {d['eta_peak']:.3f}; q moves by {100 * d['rel_shift_q']:.1f} %"
                 for d in c["domain"]]
        L.append("4. **Bifurcation domain: W2 against W2_sigma.** First direction with W2 <= 0 on the drained "
                 "path, against W2_sigma <= 0: " + "; ".join(parts) + ". The W2_sigma domain is slightly "
                 "larger and the boundary moves little: the geometric terms barely shift it.")
    dd = c.get("dem_domain")
    if dd:
        b = dd["bounds"]
        hb = b.get("hmodel") or {}
        s = ("5. **Bifurcation domain of both models at 200 kPa.** DEM: "
             + (f"the first state with W2 <= 0 or a failure is {b['lower_state']} at eta = "
                f"{b['lower_eta']:.4f} ({b['lower_eta_fraction']:.3f} of its peak {b['eta_peak']:.4f}; "
                f"{b['lower_why']})" if b["lower_state"] else "no state with W2 <= 0 or a failure")
             + f"; strength under stress control: {eta_lim_text(b)}.")
        n_probed = sum(1 for r in dd["rows"] if r["probed"])
        if n_probed < sum(1 for r in dd["rows"] if r["reference"] != "failure"):
            s += (f" Only {n_probed} of the {len(dd['rows'])} saved states were probed (the others "
                  "only relaxed), so that first state is an upper bound of the DEM's lower "
                  "boundary; `python -m dem domain` probes every state.")
        if hb:
            s += (f" H-model: first W2 <= 0 at eta = {hb['eta_w2']:.4f} ({hb['eta_w2_fraction']:.3f} "
                  f"of its peak {hb['eta_peak']:.4f}), W2_sigma <= 0 at {hb['eta_w2sigma']:.4f}.")
        rows = sorted(dd["rows"], key=lambda r: r["eta"])
        s += " Along the DEM path (eta, fraction, min W2 of equilibrium probes, failures): " + "; ".join(
            f"{r['eta']:.3f} ({r['eta_fraction']:.2f}): "
            + ("reference failed" if r["reference"] == "failure" else
               "not probed" if not r["probed"] else f"{r['min_w2']:.3f}, {r['n_failure']}")
            for r in rows) + "."
        L.append(s)
    p3 = c.get("dem_p3")
    if dm is not None:
        if p3:
            L.append(
                f"\n**Which eta for the DEM's A.** With p = (s1 + 2 s2)/3 the DEM's peak is "
                f"{p3['eta_p3_peak']:.3f} and 1.029 is reached at eps1 = {100 * p3['eps1']:.2f} %, "
                f"eta (p = (s1 + s2)/2) = {p3['eta']:.4f}, {p3['eta_fraction']:.3f} of the peak. "
                + ("That state lies below the DEM's lower boundary of the bifurcation domain (no "
                   "W2 <= 0 and no failure there), while the paper finds an instability cone at its "
                   "DEM A: the data do not favour this reading; they favour a state closer to the "
                   "peak (the paper's A is 0.995 of the H-model's peak)." if p3.get("below_lower_boundary")
                   else "That state lies inside the DEM's bifurcation domain, consistent with the "
                   "paper's cone at its DEM A: the data are consistent with this reading."))
        else:
            L.append("\n**Which eta for the DEM's A.** eta = 1.029 with p = (s1 + 2 s2)/3 is not "
                     "reached either.")
    if c.get("burst"):
        from .burst.report import burst_report_lines
        L += [""] + burst_report_lines(c["burst"], figs.get("burst"), figs.get("burst_eq1"),
                                       figs.get("burst_w2"))
    L += ["", "## Wall times", ""] + [f"- {k}: {v:.1f} s" for k, v in timings.items()] + [""]
    if graph:
        L += graph_lines(graph)
    with atomic_open(os.path.join(out, "report.md")) as f:
        f.write("\n".join(L))



def graph_lines(graph: dict) -> list:
    """The stages' graph of a run (``crosscheck.run.critical_path``): every stage's start and
    end, what it waited for, and the critical path, as report lines."""
    mode = ("the DEM's stages after its biaxial test on one pool" if graph["mode"] == "graph"
            else "the DEM's stages one after the other")
    L = [f"Wall time {graph['wall_time']:.1f} s ({mode}); the stages' own times add up to "
         f"{graph['busy']:.1f} s.", "",
         "| stage | start [s] | end [s] | waited for |", "|---|---|---|---|"]
    L += [f"| {s['name']} | {s['start']:.1f} | {s['end']:.1f} | {', '.join(s['after']) or '-'} |"
          for s in sorted(graph["stages"], key=lambda s: (s["start"], s["end"]))]
    L += ["", "Critical path (each stage the one its successor waited for that ended last): "
          + " -> ".join(graph["critical_path"]) + ".", ""]
    return L
