"""The burst section of the cross-check's report (``burst_report_lines``): per ratio and start
fraction, each part's c peak and switch outcomes, then the verdict with its numbers.
"""
from __future__ import annotations

import numpy as np

from .part import LABEL

__all__ = ["burst_report_lines"]


def burst_report_lines(c: dict, fig: str | None, fig_eq1: str | None = None,
                       fig_w2: str | None = None) -> list:
    """The report's burst section: per ratio and start fraction, each part's c peak and switch
    outcomes, then the verdict with its numbers (the growth of E_c from rest past the peak)."""
    L = ["## Failure made to happen: the proportional strain path and the burst (Eq. 1)", "",
         "From the drained state at f of each part's drained peak eta, the path d eps2 = R d eps1 "
         "until c = s1 + R s2 peaks (W2 = d eps1 dc = 0 there), then c held below the peak "
         "(`below`) and past it (`past`) with the tie kept, from rest (docs/burst.md). The "
         "material point and the FE follow the path quasi-statically and switch from their static "
         "states; the DEM finds its peak at rest by a staircase of dead-load holds from its "
         "relaxed start (its strain-controlled path carries a rate overstress) and switches from "
         "its equilibria.", ""]
    if fig:
        L += [f"![burst]({fig})", ""]
    if fig_eq1:
        L += ["Eq. 1's terms of the past runs, the FE's beside the DEM's (who gives the kinetic "
              "energy: -W2_int > 0, the contacts or the material points):", "",
              f"![Eq. 1]({fig_eq1})", ""]
    wp = c.get("w2_paths") or {}
    if any(wp.values()):
        L += ["**The path's own W2, side by side.** W2 = dc d eps1 along the path: the material "
              "point's from its tangent, the FE's from its static path, the DEM's from kinematic "
              "probes at rest (docs/burst.md). Where k_path = dc/d eps1 crosses 0, as a fraction of "
              "the rise of c to the part's c peak (1: at the peak; the DEM's peak is the largest c "
              "its dead load held at rest):", ""]
        if fig_w2:
            L += [f"![W2 along the path]({fig_w2})", ""]
        L += ["| part | R | f | k_path at the start [MPa] | k_path = 0 at (fraction of the rise) | "
              "DEM: verdict, the dead load held past it [Pa] |", "|---|---|---|---|---|---|"]
        f3 = lambda x, s: "-" if x is None or not np.isfinite(x) else format(x, s)
        for name, rows in wp.items():
            for d in rows:
                L.append(f"| {LABEL[name]} | {d['ratio']:g} | {d['start_fraction']:g} | "
                         f"{f3(d['k_start'] / 1e6 if d['k_start'] is not None else None, '.4g')} | "
                         f"{f3(d['cross_fraction'], '.3f')} | "
                         + (f"{d['verdict']}, {f3(d['overshoot_c'], '.0f')} |" if name == "dem"
                            else "- |"))
        L.append("")
    L += ["The growth is measured against the work the held step put in, r = (E_c - E_c(0)) / "
          "W2_ext (`hmodel.burst_rule.energy_release`, the same in the three parts): r > 1 "
          "proves W2_int < 0 by Eq. 1, the burst is r >= 2 (the specimen gave back at least what "
          "the step put in); neither the kinetic-energy floor nor the time step enters it.", "",
          "| part | R | f | eta_start | eta of the c peak (fraction of the drained peak) | below: "
          "outcome, largest r | past: outcome, r >= 2 at [s] |", "|---|---|---|---|---|---|---|"]
    fmt = lambda x, s: "-" if x is None or not np.isfinite(x) else format(x, s)
    for name, p in c["parts"].items():
        for d in p["paths"]:
            o, rel = d["outcomes"], d["release"]
            rb, rp = rel.get("below", {}), rel.get("past", {})
            L.append(f"| {LABEL[name]} | {d['ratio']:g} | {d['start_fraction']:g} | "
                     f"{d['eta_start']:.4f} | {fmt(d['eta_peak_c'], '.4f')} "
                     f"({fmt(d['fraction_peak_c'], '.3f')}) | {o.get('below', '-')}, "
                     f"{fmt(rb.get('ke_w2ext_max'), '.3g')} | {o.get('past', '-')}, "
                     + (f"{fmt(rp.get('t_release'), '.3g')} |" if rp.get("released") else
                        "never |"))
    L.append("")
    exact = {n: all(d["at_w2_zero"] for d in p["paths"] if d["peaked"]) and
             any(d["peaked"] for d in p["paths"]) for n, p in c["parts"].items()}
    und = sum(d["undecided"] for p in c["parts"].values() for d in p["paths"])
    why = {"hmodel": "failure came at the c peak of the static path, where W2 of the path vanishes",
           "fem": "failure came at the c peak of the static path, where W2 of the path vanishes",
           "dem": "its kinematic probes at rest put W2 of the path <= 0 where its holds of +dc "
                  "failed (the theory's verdict passes)"}
    s = ("**Where failure came.** " + "; ".join(
        f"{LABEL[n]}: " + (f"below settled without releasing energy and past released it on "
                           f"every path that peaked: {why[n]}" if ok else
                           "not on every path (see the tables)") for n, ok in exact.items())
         + f"; {und} run(s) neither equilibrium nor failure (undecided, not converged).")
    L.append(s)
    hm = c["parts"].get("hmodel")
    if hm and c["eta_first_w2"] is not None:
        pk = [d for d in hm["paths"] if d["peaked"]]
        s = (f"\n**Against the directional analysis and the FE's K_s.** The H-model's first W2 = 0 "
             f"on the drained path is at eta = {c['eta_first_w2']:.4f}")
        if c["eta_fem_lam_ks"] is not None:
            s += f", the FE's first lam_min(K_s) <= 0 at eta = {c['eta_fem_lam_ks']:.4f}"
        s += ("; the material point's c peaks at " + ", ".join(
            f"eta = {d['eta_peak_c']:.4f} (R = {d['ratio']:g}, from f = {d['start_fraction']:g}: "
            f"{d['eta_peak_c'] - c['eta_first_w2']:+.4f} from the first W2 = 0)" for d in pk)
            + ". The proportional path's own history moves the state a little past the drained "
            "path's boundary before c turns (docs/burst.md: R = -2 is inside the cone of strain "
            "directions at the first W2 = 0; other R peak later).") if pk else "."
        L.append(s)
    fe, dm = c["parts"].get("fem"), c["parts"].get("dem")
    if fe and hm:
        pairs = [(a, b) for a in hm["paths"] for b in fe["paths"]
                 if (a["ratio"], a["start_fraction"]) == (b["ratio"], b["start_fraction"])
                 and a["peaked"] and b["peaked"]]
        if pairs:
            L.append("\n**FE against the material point.** " + "; ".join(
                f"R = {a['ratio']:g}, f = {a['start_fraction']:g}: c peak at eta {b['eta_peak_c']:.4f} "
                f"(FE, its material with n_dir of the cross-check)"
                + (f", {b['mp_eta_peak_c']:.4f} (the material point with the FE's parameters: the "
                   f"perfect specimen is homogeneous, so the two are one path)"
                   if b.get("mp_eta_peak_c") is not None else "")
                + f" and {a['eta_peak_c']:.4f} (material point, Table I)" for a, b in pairs) + ".")
    if dm:
        L.append("\n**DEM.** " + "; ".join(
            f"R = {d['ratio']:g}, f = {d['start_fraction']:g}: "
            + (f"c peaks at {d['fraction_peak_c']:.3f} of the DEM's drained peak (H-model "
               + ", ".join(f"{a['fraction_peak_c']:.3f}" for a in (hm or {"paths": []})["paths"]
                           if (a["ratio"], a["start_fraction"]) == (d["ratio"], d["start_fraction"])
                           and a["peaked"])
               + f"); below {d['outcomes'].get('below', '-')}, past {d['outcomes'].get('past', '-')}"
               if d["peaked"] else "c does not peak within the path")
            for d in dm["paths"]) + ". The DEM's peak is the one at rest (its staircase of "
            "dead-load holds), under the strain-controlled path's by its rate overstress; its "
            "below switch is at half of the rise at rest (docs/dem.md).")
    return L + [""]
