"""The cross-check's burst section: failure made to happen in the three parts side by side
(docs/burst.md, paper Eq. 1).

For each ratio R and start fraction f, the material point (``hmodel.burst``), the FE perfect
specimen (``fem.burst``) and the DEM sample of the cross-check (``dem.burst``, from the states its
biaxial test saved) follow the proportional strain path d eps2 = R d eps1, find where
c = s1 + R s2 peaks (W2 = 0 along the path), and hold c below and past that peak. The section
states, with the run's numbers, whether each part failed exactly where W2 vanished along the path
(below: equilibrium, past: failure), and how the c peaks compare with the first W2 = 0 of the
H-model's directional analysis and with the FE's first lam_min(K_s) <= 0 on the drained path.

Like ``dem.crosscheck``, the one place of ``dem`` that imports ``hmodel`` and ``fem`` (lazily).
"""
from __future__ import annotations

import os

import numpy as np

__all__ = ["burst_part", "burst_conclusions", "burst_figure", "burst_eq1_figure",
           "burst_report_lines", "w2_paths", "w2_path_figure",
           "BURST_RATIOS", "BURST_FRACTIONS"]

BURST_RATIOS = (-2.0,)
BURST_FRACTIONS = (0.90,)
PARTS = ("hmodel", "fem", "dem")
LABEL = {"hmodel": "material point (H-model)", "fem": "FE perfect specimen", "dem": "DEM sample"}


def _csv_histories(path, ke_key, volume):
    """history.csv of a burst run -> [{ratio, start_fraction, switch, t [s], ke_density [J/m^3]}],
    one per run, ``ke_key`` the kinetic energy column, divided by ``volume``."""
    import csv
    runs = {}
    with open(path) as f:
        for r in csv.DictReader(f):
            key = (float(r["ratio"]), float(r["start_fraction"]), r["switch"])
            h = runs.setdefault(key, {"t": [], "ke": []})
            h["t"].append(float(r["t"]))
            h["ke"].append(float(r[ke_key]))
    return [{"ratio": k[0], "start_fraction": k[1], "switch": k[2], "t": np.array(v["t"]),
             "ke_density": np.array(v["ke"]) / volume} for k, v in runs.items()]


def _rows(rows, keys=("ratio", "start_fraction", "switch", "eta_start", "eta_peak_c",
                      "fraction_peak_c", "c_peak", "c_switch", "dc", "outcome", "ke_growth",
                      "ke_w2ext_max", "t_release", "released")):
    return [{k: (r.get(k) if not isinstance(r.get(k), np.generic) else r.get(k).item())
             for k in keys} for r in rows]


def burst_part(out_dir, dem_biaxial_dir=None, ratios=BURST_RATIOS, fractions=BURST_FRACTIONS,
               fem_mesh=(4, 8), fem_n_dir=72, dem_rate=0.01, workers=None, log=print,
               verbose=True) -> dict:
    """Run the three parts' burst experiments into ``out_dir``/burst/{hmodel,fem,dem}
    (``log``: the section's progress lines; ``verbose``: the DEM's own).
    ``dem_biaxial_dir``: a ``dem biaxial`` folder with its states (None: no DEM part).
    Returns {part: {"rows": burst rows (dicts), "histories": E_c per volume against time,
    "eta_peak": the part's drained peak eta}}."""
    from hmodel import HParams
    from hmodel import burst as hb
    from fem.biaxial import BiaxialConfig
    from fem.burst import BurstConfig, run_burst as fem_burst

    out = {}
    P = HParams()
    sp = hb.Specimen()
    log(f"burst: material point, R {list(ratios)}, start fractions {list(fractions)}")
    h = hb.run_burst(P, ratios, fractions, 1e-4 * P.p0, sp)
    area = sp.width * sp.height
    # the path's own W2 from the material's tangent at every state of each path
    w2p = []
    for info in h.paths:
        c, k = hb.path_stiffness(info.start, P, info.ratio, 1e-5, len(info.c) - 1)
        w2p.append({"ratio": info.ratio, "start_fraction": info.start_fraction,
                    "c": c.tolist(), "k": k.tolist(), "c_start": float(info.c[0]),
                    "c_peak": float(info.c[info.k_peak]) if info.k_peak is not None else None})
    out["hmodel"] = {"rows": _rows(h.rows), "eta_peak": h.eta_peak, "w2_path": w2p,
                     "histories": [{"ratio": x["ratio"], "start_fraction": x["start_fraction"],
                                    "switch": x["switch"], "t": x["t"], "ke_density": x["ke"] / area}
                                   for x in h.histories]}
    log(f"burst: FE specimen {fem_mesh[0]} x {fem_mesh[1]}, n_dir {fem_n_dir}")
    fdir = os.path.join(out_dir, "burst", "fem")
    cfg = BurstConfig(specimen=BiaxialConfig(nx=fem_mesh[0], ny=fem_mesh[1], n_dir=fem_n_dir,
                                             fields=False),
                      ratios=tuple(ratios), start_fractions=tuple(fractions), fields=False)
    f = fem_burst(cfg, fdir)
    fb = cfg.specimen
    fem_keys = ("ratio", "start_fraction", "switch", "eta_start", "eta_peak_c", "fraction_peak_c",
                "c_peak", "c_switch", "dc", "outcome", "ke_growth", "ke_w2ext_max", "t_release",
                "released", "mp_eta_peak_c")
    out["fem"] = {"rows": _rows(f.rows, fem_keys),
                  "w2_path": _fem_w2_path(os.path.join(fdir, "paths.csv"), f.rows),
                  "eta_peak": f.summary["material_point_drained_peak"]["eta"],
                  "histories": _csv_histories(os.path.join(fdir, "history.csv"), "ke",
                                              fb.width * fb.height)}
    if dem_biaxial_dir is not None:
        from . import io
        from .burst import BurstOptions, run_burst as dem_burst
        log(f"burst: DEM sample of {dem_biaxial_dir}")
        ddir = os.path.join(out_dir, "burst", "dem")
        rows, summ = dem_burst(dem_biaxial_dir, ddir, list(ratios), list(fractions),
                               BurstOptions(rate=dem_rate), workers=workers, verbose=verbose)
        st, _ = io.load_state(os.path.join(dem_biaxial_dir, "states", f"state_f{fractions[0]:.3f}.npz"))
        vol = (st.walls[1] - st.walls[0]) * (st.walls[3] - st.walls[2]) * st.params.thickness
        out["dem"] = {"rows": _rows(rows), "eta_peak": summ["drained_eta_peak"],
                      "w2_path": _dem_w2_path(summ),
                      "histories": _csv_histories(os.path.join(ddir, "history.csv"),
                                                  "ke_backbone", vol)}
    return out


def _fem_w2_path(paths_csv, rows):
    """The FE's path W2 from its static path (paths.csv, the specimen's own records): k_path =
    dc/d eps1 [Pa] between successive records, at the c of the first of each pair."""
    import csv
    runs = {}
    with open(paths_csv) as f:
        for r in csv.DictReader(f):
            if r.get("source", "fe") != "fe":
                continue
            runs.setdefault((float(r["ratio"]), float(r["start_fraction"])), []).append(
                (float(r["eps1"]), float(r["c"])))
    out = []
    for (ratio, f), pts in runs.items():
        e, c = np.array(pts).T
        row = next((r for r in rows if (r["ratio"], r["start_fraction"]) == (ratio, f)), {})
        cp = row.get("c_peak")
        out.append({"ratio": ratio, "start_fraction": f, "c": c[:-1].tolist(),
                    "k": (np.diff(c) / np.diff(e)).tolist(), "c_start": float(c[0]),
                    "c_peak": float(cp) if cp is not None and np.isfinite(cp) else None})
    return out


def _dem_w2_path(summary):
    """The DEM's path W2 at rest: the kinematic probes of the staircase's equilibria (dem burst's
    summary.json, paths[].k_path and theory), at the c at rest of each state probed."""
    out = []
    for p in summary["paths"]:
        pr = [x for x in p.get("k_path", []) if x["key"] == "relaxed_start"
              or (x["key"].startswith("h") and x["outcome"] == "equilibrium")]
        th = p.get("theory") or {}
        if not pr:
            continue
        pr.sort(key=lambda x: x["c"])
        out.append({"ratio": p["ratio"], "start_fraction": p["start_fraction"],
                    "c": [x["c"] for x in pr], "k": [x["k_path"] for x in pr],
                    "c_start": pr[0]["c"], "c_peak": th.get("c_peak_rest"),
                    "theory": th})
    return out


def w2_paths(parts: dict) -> dict:
    """Per part, ratio and start fraction: k_path at the start, where it crosses 0 as a fraction
    of the rise of c to the part's c peak, (c_cross - c_start) / (c_peak - c_start) (1: at the
    peak), and the DEM's verdict and overshoot."""
    out = {}
    for name, p in parts.items():
        rows = []
        for w in p.get("w2_path") or []:
            c, k = np.asarray(w["c"]), np.asarray(w["k"])
            d = {"ratio": w["ratio"], "start_fraction": w["start_fraction"],
                 "k_start": float(k[0]) if len(k) else None, "cross_fraction": None,
                 "verdict": (w.get("theory") or {}).get("verdict"),
                 "overshoot_c": (w.get("theory") or {}).get("overshoot_c")}
            if name == "dem":
                cx = (w.get("theory") or {}).get("c_cross")
                cp = w.get("c_peak")
            else:
                neg = np.flatnonzero(k <= 0)
                cx = None
                if len(neg) and neg[0] > 0:
                    a = int(neg[0]) - 1
                    cx = float(np.interp(0.0, [k[a + 1], k[a]], [c[a + 1], c[a]]))
                cp = w.get("c_peak")
            if cx is not None and cp is not None and np.isfinite(cx) and cp != w["c_start"]:
                d["cross_fraction"] = (cx - w["c_start"]) / (cp - w["c_start"])
            rows.append(d)
        out[name] = rows
    return out


def w2_path_figure(out, parts: dict, name="fig_burst_w2_path.png") -> str | None:
    """The path's own W2 in the three parts side by side: k_path = dc/d eps1 over its value at
    the path's start, against the rise of c, (c - c_start) / (c_peak - c_start) (each part's own
    peak: the DEM's at rest), the material point from its tangent, the FE from its static path,
    the DEM from its kinematic probes at rest. Where k_path crosses 0 W2 of the path vanishes;
    a part whose c peak lies past that (x > 1 - 0 crossing) held G past it."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from hmodel.io import save_figure
    color = {"hmodel": "C0", "fem": "C1", "dem": "C3"}
    style = {"hmodel": "-", "fem": "--", "dem": "o-"}
    fig, ax = plt.subplots(figsize=(7.5, 5))
    drawn = False
    for part, p in parts.items():
        for w in p.get("w2_path") or []:
            c, k = np.asarray(w["c"], float), np.asarray(w["k"], float)
            if not len(k) or w.get("c_peak") is None or w["c_peak"] == w["c_start"] or k[0] == 0:
                continue
            x = (c - w["c_start"]) / (w["c_peak"] - w["c_start"])
            ax.plot(x, k / k[0], style[part], color=color[part], ms=5, lw=1.2,
                    label=f"{LABEL[part]}, R = {w['ratio']:g}, f = {w['start_fraction']:g}")
            drawn = True
    if not drawn:
        plt.close(fig)
        return None
    ax.axhline(0.0, color="k", lw=0.8)
    ax.axvline(1.0, color="0.5", ls=":", lw=1)
    ax.set_xlabel(r"$(c - c_{start}) / (c_{peak} - c_{start})$: the rise of c to each part's "
                  "peak (the DEM's at rest)")
    ax.set_ylabel(r"$k_{path} / k_{path}(start)$, $k_{path} = dc/d\varepsilon_1$")
    ax.set_title("The path's own second-order work W2 = dc d eps1: material point (tangent),\n"
                 "FE (static path), DEM (kinematic probes at rest)", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower left")
    save_figure(fig, os.path.join(out, name))
    return name


def burst_conclusions(parts: dict, eta_first_w2: float | None, fem_events: dict | None) -> dict:
    """Per part, ratio and start fraction: the c peak (eta, fraction of the part's drained peak),
    the outcome of each switch, and ``at_w2_zero``: below settled and past failed (the burst came
    exactly where W2 vanished along the path, within the switches' resolution). With the H-model's
    first W2 = 0 of the drained path (``eta_first_w2``) and the FE's first lam_min(K_s) <= 0
    (``fem_events``: fem_part's events summary)."""
    c = {"parts": {}, "eta_first_w2": eta_first_w2, "eta_fem_lam_ks": None,
         "w2_paths": w2_paths(parts)}
    ev = (fem_events or {}).get("lam_min_ks") or {}
    if ev.get("row") is not None:
        c["eta_fem_lam_ks"] = ev.get("eta")
    for name, p in parts.items():
        paths = {}
        for r in p["rows"]:
            key = (r["ratio"], r["start_fraction"])
            d = paths.setdefault(key, {"ratio": r["ratio"], "start_fraction": r["start_fraction"],
                                       "eta_start": r["eta_start"], "eta_peak_c": r["eta_peak_c"],
                                       "fraction_peak_c": r["fraction_peak_c"], "outcomes": {},
                                       "release": {}})
            d["outcomes"][r["switch"]] = r["outcome"]
            # the growth against the held step's work (hmodel.burst_rule.energy_release)
            d["release"][r["switch"]] = {"ke_w2ext_max": r.get("ke_w2ext_max"),
                                         "released": bool(r.get("released")),
                                         "t_release": r.get("t_release")}
            if "mp_eta_peak_c" in r:       # the FE's: the material point with the FE's parameters
                d["mp_eta_peak_c"] = r["mp_eta_peak_c"]
        verdicts = {(w["ratio"], w["start_fraction"]): w.get("verdict")
                    for w in c["w2_paths"].get(name, [])}
        for d in paths.values():
            o, rel = d["outcomes"], d["release"]
            d["peaked"] = bool(d["eta_peak_c"] is not None and np.isfinite(d["eta_peak_c"]))
            # below settles without giving energy back, past releases it (E_c - E_c(0) >= RELEASE
            # W2_ext); for the DEM, whose past run is its staircase's failing hold by definition,
            # also the theory's verdict from the kinematic probes
            d["released_past"] = bool(rel.get("past", {}).get("released"))
            d["held_below"] = bool(o.get("below") == "equilibrium"
                                   and not rel.get("below", {}).get("released"))
            d["verdict"] = verdicts.get((d["ratio"], d["start_fraction"]))
            d["at_w2_zero"] = bool(d["peaked"] and d["held_below"] and d["released_past"]
                                   and o.get("past") == "failure"
                                   and (name != "dem" or d["verdict"] == "passes"))
            d["undecided"] = sum(v not in ("equilibrium", "failure") for v in o.values())
        c["parts"][name] = {"eta_peak": p["eta_peak"], "paths": list(paths.values())}
    return c


def burst_figure(out, parts: dict, name="fig_burst_ke.png") -> str:
    """E_c per volume [J/m^3] against the time since the switch [s], log axes, the three parts on
    one figure (colour: part; solid: past, dashed: below; the end marked by the outcome, as in
    ``hmodel.plots.fig_burst_ke``; the legend beside the axes)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from hmodel.io import save_figure
    from hmodel.plots import END_MARK
    color = {"hmodel": "C0", "fem": "C1", "dem": "C3"}
    fig, ax = plt.subplots(figsize=(7.5, 5))
    ends = set()
    for part, p in parts.items():
        ax.plot([], [], "-", color=color[part], label=LABEL[part])
        for h in p["histories"]:
            t, ke = np.asarray(h["t"]), np.asarray(h["ke_density"])
            ok = (t > 0) & (ke > 0)
            if not ok.any():
                continue
            ax.loglog(t[ok], ke[ok], "-" if h["switch"] == "past" else "--", color=color[part],
                      lw=1.1)
            row = next((r for r in p["rows"] if (r["ratio"], r["start_fraction"], r["switch"])
                        == (h["ratio"], h["start_fraction"], h["switch"])), None)
            if row is not None:
                m, fc, _ = END_MARK.get(row["outcome"], END_MARK["undecided"])
                ax.plot(t[ok][-1], ke[ok][-1], m, mec="k", mfc=fc, ms=8, mew=1.4, zorder=5)
                ends.add(row["outcome"])
    ax.plot([], [], "k-", label="past the c peak (burst expected)")
    ax.plot([], [], "k--", label="below the c peak (equilibrium expected)")
    for m, fc, lab in (v for k, v in END_MARK.items() if k in ends):
        ax.plot([], [], m, ls="none", mec="k", mfc=fc, ms=8, mew=1.4, label=lab)
    ax.set_xlabel("time since the switch to c control [s]")
    ax.set_ylabel(r"kinetic energy per volume $E_c/V$ [J/m$^3$]")
    ax.set_title("The burst of kinetic energy (Eq. 1): c = s1 + R s2 held below / past its peak,\n"
                 "from rest (DEM: the disks with two contacts or more, a dead load on the walls)",
                 fontsize=9)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)   # off the data
    save_figure(fig, os.path.join(out, name))
    return name


def burst_eq1_figure(out, fem_history, dem_history, name="fig_burst_eq1.png") -> str | None:
    """Eq. 1's terms of the past runs against the time since the switch, the FE specimen's
    (history.csv of fem burst: E_c = W2_ext - W2_int - D, Newmark's discrete balance) beside the
    DEM sample's (history.csv of dem burst: E_c - E_c(0) = W2_ext - W2_int + W_damp + U0, the
    energy ledger), one panel each, symmetric log axes: who gives the kinetic energy. None when
    a part has no past run."""
    import csv

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from hmodel.io import save_figure

    def past(path):
        if not path or not os.path.exists(path):
            return None
        with open(path) as f:
            rows = [r for r in csv.DictReader(f) if r["switch"] == "past"]
        if not rows:
            return None
        first = (rows[0]["ratio"], rows[0]["start_fraction"])
        rows = [r for r in rows if (r["ratio"], r["start_fraction"]) == first]
        return {k: np.array([float(r[k]) for r in rows]) for k in rows[0] if k != "switch"}

    fe, dm = past(fem_history), past(dem_history)
    if fe is None or dm is None:
        return None
    panels = [("FE perfect specimen: E_c = W2_ext - W2_int - D", fe["t"],
               [(fe["ke"], r"$E_c$", "k", 2.2), (fe["w2_ext"], r"$W_2^{ext}$", "C0", 1.4),
                (-fe["w2_int"], r"$-W_2^{int}$", "C3", 1.4),
                (-fe["damping"], r"$-D$ (Rayleigh damping)", "C2", 1.4)]),
              ("DEM sample: E_c - E_c(0) = W2_ext - W2_int + W_damp + U0", dm["t_ledger"],
               [(dm["dke"], r"$E_c - E_c(0)$", "k", 2.2), (dm["w2_ext"], r"$W_2^{ext}$", "C0", 1.4),
                (-dm["w2_int"], r"$-W_2^{int}$", "C3", 1.4),
                (dm["w_damp"], r"$W_{damp}$ (Cundall damping)", "C2", 1.4),
                (dm["u0"], r"$U_0$", "C4", 1.0)])]
    from hmodel.plots import symlog_axis
    fig, axes = plt.subplots(1, 2, figsize=(11, 5.0), layout="constrained")
    for ax, (title, t, terms) in zip(axes, panels):
        for y, lab, col, lw in terms:
            ax.plot(t, y, "-", color=col, lw=lw, label=lab)
        big = max(float(np.max(np.abs(y))) for y, *_ in terms)
        symlog_axis(ax, max(1e-4 * big, 1e-15))         # no tick labels piled at 0
        ax.axhline(0, color="0.5", lw=0.6)
        ax.set_xlabel("time since the switch [s]")
        ax.set_ylabel("energy since the switch [J/m]" if "FE" in title else
                      "energy since the switch [J]")
        ax.set_title(f"past the c peak - {title}", fontsize=9)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=3,
                  frameon=False)                                   # below the panel, off the data
    save_figure(fig, os.path.join(out, name))
    return name


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
