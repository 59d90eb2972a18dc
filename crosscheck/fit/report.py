"""The report of the H-model fitted to the DEM: comparison.md (``markdown``) and its verdicts,
each decided from the numbers by the rule it states (``verdicts``)."""
from __future__ import annotations

import math

import numpy as np

from point.probes import format_arcs

__all__ = ["markdown", "verdicts", "bracket", "eta_lim_text"]


def markdown(c: dict, fit_summary: dict, argv_text: str) -> str:
    """comparison.md: the fit, the peaks and the lower boundary of the bifurcation domain, the
    states one by one and the verdicts (``c["verdicts"]``); ``argv_text`` the command that
    regenerates it."""
    h, d = c["hmodel"], c["dem"]
    st = c["states"]
    fs = fit_summary
    L = ["## The H-model fitted to the 12,000-disk DEM: bifurcation domain on an equal footing", "",
         f"Regenerate: `{argv_text}` (docs/fit.md). The paper compared its H-model (Table I) with a DEM "
         "sample of other properties; here the H-model's parameters are fitted to the DEM's own drained "
         "curve, so both describe the same material before their directional analyses are compared.", "",
         "### The fit", "", "![fit](fig_fit.png)", "",
         f"Data: `{fs['data']}`, {fs['n_points']} points, sigma2 = {fs['sigma2'] / 1e3:.2f} kPa "
         f"({fs['sigma2_from']}); weights: q by 1/max|q|, eps_v by 1/max|eps_v|; no smoothing (the "
         f"stick-slip noise is correlated: lag-1 correlation of the residuals {fs['lag1_correlation']:.2f}, "
         f"variances inflated by {fs['variance_inflation']:.1f}).", "",
         "| parameter | fitted | 95 % interval | determined |", "|---|---|---|---|"]
    for nme, e in fs["fitted"].items():
        L.append(f"| {nme} [{e['unit']}] | {e['value']:.4g} | {e['ci95'][0]:.4g} to {e['ci95'][1]:.4g} | "
                 f"{'yes' if e['determined'] else 'no: ' + e['why']} |")
    g = fs["groups"]
    opt_ = fs["optima"]
    L += ["", f"Held (not determined by a drained curve): r_g = {fs['params']['r_g']:g} m, thickness 2 r_g; "
          f"the curve fixes kn/h = {g['kn_over_h']:.4g} Pa (kn/(p0 h) = {g['kn_over_p0h']:.4g}) and "
          f"kt/kn = {g['kt_over_kn']:.3g}. RMS misfit: q {fs['rms_q'] / 1e3:.2f} kPa "
          f"({fs['rms_q'] / h['q_peak']:.1%} of the "
          f"fitted peak q), eps_v {fs['rms_eps_v']:.2e}. {len(fs['starts'])} starts reached {len(opt_)} "
          f"distinct optima: " + "; ".join(f"cost {o['cost']:.4g} ({len(o['starts'])} "
                                          f"start{'s' if len(o['starts']) > 1 else ''}: "
                                          + ", ".join(f"{k_} {v:.4g}" for k_, v in o["end"].items()) + ")"
                                          for o in opt_[:3]) + ".", ""]
    L += ["### Peaks and the lower boundary of the bifurcation domain", "",
          "![comparison](fig_comparison.png)", "", "![domain](fig_domain_pq.png)", "",
          "![by direction](fig_w2_by_direction.png)", "",
          f"The fitted H-model's full directional analysis at the DEM's first unstable fraction "
          f"({c['probes_fraction']:.3f} of its peak, eta = {c['probes_eta']:.4f}): `probes/` (Figs. 3, 6-9, 11, "
          "probes.csv, summary.json); its domain at the fitted confining stress: `domain/`.", "",
          *[f"![{p[10:-4]}]({p})\n" for p in c.get("polar_figures", [])],
          "| | DEM (12,000 disks) | H-model (fitted) |", "|---|---|---|",
          f"| peak eta (p = (s1+s2)/2) | {d['eta_peak']:.4f} | {h['eta_peak']:.4f} |",
          f"| peak q [kPa] at eps1 [%] | {c['dem_q_peak'] / 1e3:.1f} at {100 * c['dem_eps1_peak']:.2f} | "
          f"{h['q_peak'] / 1e3:.1f} at {100 * h['eps1_peak']:.2f} |",
          f"| last state with every probe settled, W2 > 0 | eta {d['last_stable_eta']:.4f} "
          f"({d['last_stable_fraction']:.3f} of the peak) | |",
          f"| first state with W2 <= 0 or a failure | eta {d['lower_eta']:.4f} ({d['lower_fraction']:.3f}; "
          f"{d['lower_why']}) | |",
          f"| first W2_sigma <= 0 (ds:de, the DEM's W2) | | eta {h['eta_w2sigma']:.4f} "
          f"({h['fraction_w2sigma']:.3f} of the peak) |",
          f"| first W2 <= 0 (Lagrangian, the paper's) | | eta {h['eta_w2']:.4f} ({h['fraction_w2']:.3f}) |",
          f"| strength under stress control | {eta_lim_text(d)} | "
          f"{h['eta_peak']:.4f} (its peak: a rate-independent material point holds any stress below it) |", ""]
    L += ["### Along the path, state by state", "",
          "DEM: minimum of ds.de/(|ds||de|) over its settled stress probes (21 directions, 5-30 deg apart). "
          "H-model: the same quantity, minimum over all directions (adaptive sweep) and over the DEM's 21 "
          "directions, at the same fraction of its own peak and at the same eta.", "",
          "| DEM state | eta (fraction) | DEM min W2 at deg | failures (deg) | H same fraction: min W2 at deg "
          "(at DEM directions) | H same eta: min W2 at deg |", "|---|---|---|---|---|---|"]
    for s in st:
        hf, he = s["h_same_fraction"], s["h_same_eta"]
        L.append(f"| {s['state']} | {s['dem_eta']:.4f} ({s['dem_fraction']:.3f}) | "
                 f"{s['dem_min_w2']:.3f} at {s['dem_alpha_min_w2']:.0f} | "
                 f"{', '.join(f'{a:.0f}' for a in s['dem_failure_directions']) or 'none'} | "
                 f"{hf['min_w2_eulerian']:.3f} at {hf['alpha_min_w2_eulerian']:.1f} "
                 f"({hf['min_w2_dem_directions']:.3f} at {hf['alpha_min_w2_dem_directions']:.0f}) | "
                 + (f"{he['min_w2_eulerian']:.3f} at {he['alpha_min_w2_eulerian']:.1f}" if he else "beyond its peak")
                 + " |")
    L += ["", "### What agrees and what does not", ""] + c["verdicts"] + [""]
    return "\n".join(L)


def bracket(x, lo, hi):
    """'inside' the DEM's bracket (lo, hi], or 'below' / 'above' it by how much."""
    if lo < x <= hi:
        return "inside the bracket"
    return f"{'below' if x <= lo else 'above'} the bracket by {min(abs(x - lo), abs(x - hi)):.4f}"


def eta_lim_text(d):
    """The DEM's strength under stress control in the DEM's own words (``dem.domain``, imported
    when asked: the rest of the comparison reads the DEM's files)."""
    from dem.domain import eta_lim_text as dem_text
    return dem_text(d["boundaries"])


def verdicts(c: dict) -> list:
    """The statements of comparison.md, each decided from the numbers by the rule it states."""
    h, d = c["hmodel"], c["dem"]
    st = c["states"]
    out = []
    for what, key_h, lo, hi in (("as a fraction of the peak", "fraction", d["last_stable_fraction"], d["lower_fraction"]),
                                ("in eta", "eta", d["last_stable_eta"], d["lower_eta"])):
        xs, xl = h[f"{key_h}_w2sigma"], h[f"{key_h}_w2"]
        ok = lo < xs <= hi
        line = (f"- **Lower boundary {what}: {'agrees' if ok else 'differs'}** (rule: the H-model's first "
                f"W2_sigma <= 0, the DEM's definition of W2, inside the DEM's bracket). DEM: between "
                f"{lo:.4f} (every probe settled, W2 > 0) and {hi:.4f} ({d['lower_why']}). H-model: W2_sigma "
                f"{xs:.4f}, {bracket(xs, lo, hi)}; W2 (Lagrangian) {xl:.4f}, {bracket(xl, lo, hi)}.")
        if key_h == "eta":
            line += (f" The peaks differ by {h['eta_peak'] - d['eta_peak']:+.4f} in eta (H-model "
                     f"{h['eta_peak']:.4f}, DEM {d['eta_peak']:.4f}), their axial strains by a factor "
                     f"{h['eps1_peak'] / c['dem_eps1_peak']:.2f} ({100 * h['eps1_peak']:.2f} % against "
                     f"{100 * c['dem_eps1_peak']:.2f} %).")
        out.append(line)
    dirs = np.array(d["directions"])
    diffs, within = [], 0
    for s in st:
        a_d, a_h = s["dem_alpha_min_w2"], s["h_same_fraction"]["alpha_min_w2_eulerian"]
        step = float(np.min(np.abs(dirs[dirs != a_d] - a_d))) if dirs.size > 1 else math.inf
        diffs.append(abs(a_h - a_d))
        within += abs(a_h - a_d) <= step
    ok = within == len(st)
    out.append(f"- **Direction of the weakest response: {'agrees' if ok else f'agrees at {within} of {len(st)} states'}** "
               f"(rule: the H-model's direction of minimum W2 within one sampling step of the DEM's, 5 deg "
               f"near it). alpha_sigma of the minimum, DEM: "
               + ", ".join(f"{s['dem_alpha_min_w2']:.0f}" for s in st) + " deg; H-model at the same fractions: "
               + ", ".join(f"{s['h_same_fraction']['alpha_min_w2_eulerian']:.1f}" for s in st)
               + f" deg; largest difference {max(diffs):.1f} deg. Both in the third quadrant, both "
               "turning towards 245 deg as the peak nears.")
    sg = [(np.sign(s["dem_min_w2"]) == np.sign(s["h_same_fraction"]["min_w2_dem_directions"])) for s in st]
    ratio = [s["dem_min_w2"] / s["h_same_fraction"]["min_w2_dem_directions"] for s in st]
    out.append(f"- **Sign of the minimum W2 state by state: {'agrees' if all(sg) else 'differs'}; its size "
               f"differs** (DEM / H-model at the DEM's 21 directions, same fraction: "
               + "; ".join(f"{s['dem_fraction']:.3f}: {s['dem_min_w2']:.3f} / "
                           f"{s['h_same_fraction']['min_w2_dem_directions']:.3f}" for s in st)
               + f"; ratios {min(ratio):.2g} to {max(ratio):.2g}). The H-model's minimum falls steadily with "
               "eta; the DEM's does not (0.013 at 0.932, then 0.099 at 0.957: relaxed samples with their own "
               "stick-slip history). The DEM's W2 comes from finite stress probes of 2.5 kPa, the "
               "H-model's from rate probes.".replace("0.013 at 0.932, then 0.099 at 0.957", dem_dip(st)))
    parts = []
    for s in st:
        bd = [b for b in s["by_direction"] if b["dem_outcome"] == "equilibrium" and np.isfinite(b["h_w2"])]
        dw = np.array([b["h_w2"] - b["dem_w2"] for b in bd])
        a = np.array([b["alpha_sigma"] for b in bd])
        weak = (a >= 215) & (a <= 245)
        parts.append(f"{s['state']}: RMS {np.sqrt(np.mean(dw ** 2)):.3f}, largest {np.max(np.abs(dw)):.3f} at "
                     f"{a[np.argmax(np.abs(dw))]:.0f} deg, {np.max(np.abs(dw[weak])):.3f} from 215 to 245 deg")
    last = st[-1]
    close = max(abs(b["h_w2"] - b["dem_w2"]) for b in last["by_direction"]
                if b["dem_outcome"] == "equilibrium" and 215 <= b["alpha_sigma"] <= 245)
    h_edge = max(arc[1] for arc in last["h_same_fraction"]["plastic_zone"]) % 360
    d_edge = max(b["alpha_sigma"] for b in last["by_direction"] if b["dem_plastic"] and b["alpha_sigma"] < 300)
    out.append(f"- **Direction by direction** (settled DEM probes against the H-model at the same fraction; "
               f"ds.de/(|ds||de|) on both sides): " + "; ".join(parts) + f". At {last['state']}, from 215 to "
               f"245 deg (the DEM's weakest directions) the two agree within {close:.3f}; the largest "
               f"differences lie at the edge of the plastic zone, which ends at {h_edge:.1f} deg in the "
               f"H-model and reaches {d_edge:.0f} deg in the DEM (its probes still slide there, W2 low, where "
               "the H-model's response is elastic, W2 high).")
    for s in st:
        if s["dem_n_failure"] == 0 and not s["dem_cone_w2"]:
            continue
        hf = s["h_same_fraction"]
        cone = hf["cone_w2_eulerian"]
        neg = sorted(a for a, w in hf["w2_at_dem_directions"].items() if w <= 0)
        dem_neg = sorted({a for arc in s["dem_cone_w2"] for a in arc})
        ok = neg == dem_neg
        out.append(f"- **Instability cone at {s['state']} ({s['dem_fraction']:.3f} of the peak): "
                   f"{'agrees' if ok else 'differs'}** (rule: the same sampled directions with W2 <= 0). "
                   f"DEM: W2 <= 0 at {', '.join(f'{a:.0f}' for a in dem_neg) or 'none'} deg among its settled "
                   f"probes; H-model: cone {format_arcs(cone)} deg, W2 <= 0 at "
                   f"{', '.join(f'{a:.0f}' for a in neg) or 'none'} deg of the DEM's directions.")
        if s["dem_n_failure"]:
            fw = [hf["w2_at_dem_directions"].get(float(a), math.nan) for a in s["dem_failure_directions"]]
            out.append(f"- **Failures outside the cone: the H-model has no counterpart.** There the DEM's probes "
                       f"in {', '.join(f'{a:.0f}' for a in s['dem_failure_directions'])} deg run away; the "
                       f"H-model's W2 in these directions is {min(fw):.3f} to {max(fw):.3f} (> 0). The DEM's "
                       f"runaways are its strength limit under stress control ({eta_lim_text(d)}, "
                       f"docs/dem.md; the smallest target that failed at this state: eta = "
                       f"{s['dem_eta_target_min_failed']:.4f}); the H-model, rate-independent, holds any "
                       "stress below its peak.")
    return out


def dem_dip(st):
    """Where the DEM's minimum W2 rises again along the path (text), or a plain statement."""
    for a, b in zip(st, st[1:]):
        if b["dem_min_w2"] > a["dem_min_w2"]:
            return (f"{a['dem_min_w2']:.3f} at {a['dem_fraction']:.3f}, then {b['dem_min_w2']:.3f} at "
                    f"{b['dem_fraction']:.3f}")
    return "it falls too, unevenly"
