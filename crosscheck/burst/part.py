"""The burst section's runs and numbers: for each ratio R and start fraction f, the material
point (``hmodel.burst``), the FE perfect specimen (``fem.burst``) and the DEM sample of the
cross-check (``dem.burst``, from the states its biaxial test saved) follow the proportional strain
path d eps2 = R d eps1, find where c = s1 + R s2 peaks (W2 = 0 along the path), and hold c below and
past that peak; ``burst_conclusions`` decides, per part, whether failure came exactly where W2
vanished along the path (below: equilibrium, past: failure).
"""
from __future__ import annotations

import os

import numpy as np

__all__ = ["burst_part", "burst_jobs", "burst_conclusions", "w2_paths", "BURST_RATIOS", "BURST_FRACTIONS",
           "PARTS", "LABEL"]

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
    ``dem_biaxial_dir``: a ``dem biaxial`` folder with its states (None: no DEM part), its runs
    on ``workers`` local processes (``dem.pool``).
    Returns {part: {"rows": burst rows (dicts), "histories": E_c per volume against time,
    "eta_peak": the part's drained peak eta}}."""
    from dem.pool import run_jobs
    jobs, finish = burst_jobs(out_dir, dem_biaxial_dir, ratios, fractions, fem_mesh, fem_n_dir,
                              dem_rate, log, verbose)
    return finish(run_jobs(jobs, workers, None, None, None if len(jobs) == 1 else 1))


def burst_jobs(out_dir, dem_biaxial_dir=None, ratios=BURST_RATIOS, fractions=BURST_FRACTIONS,
               fem_mesh=(4, 8), fem_n_dir=72, dem_rate=0.01, log=print, verbose=True):
    """``burst_part`` in two: the material point's and the FE specimen's runs now (seconds),
    then ``(jobs, finish)``: ``jobs`` the DEM's staircases as generators of runs for
    ``dem.pool`` (``dem.burst.burst_job``; none without ``dem_biaxial_dir``), ``finish(results)``
    the DEM's files from {tag: result} and the section's dict (what ``burst_part`` returns).
    The cross-check runs the jobs beside the DEM's directional analysis on one pool."""
    from hmodel import HParams
    from point import burst as hb
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
    if dem_biaxial_dir is None:
        return [], lambda results: out
    from dem import io
    from dem.burst import BurstOptions, burst_job
    log(f"burst: DEM sample of {dem_biaxial_dir}")
    ddir = os.path.join(out_dir, "burst", "dem")
    jobs, finish_dem = burst_job(dem_biaxial_dir, ddir, list(ratios), list(fractions),
                                 BurstOptions(rate=dem_rate), verbose=verbose)

    def finish(results):
        rows, summ = finish_dem({tag: results[tag] for tag, _ in jobs})
        st, _ = io.load_state(os.path.join(dem_biaxial_dir, "states",
                                           f"state_f{fractions[0]:.3f}.npz"))
        vol = (st.walls[1] - st.walls[0]) * (st.walls[3] - st.walls[2]) * st.params.thickness
        out["dem"] = {"rows": _rows(rows), "eta_peak": summ["drained_eta_peak"],
                      "w2_path": _dem_w2_path(summ),
                      "histories": _csv_histories(os.path.join(ddir, "history.csv"),
                                                  "ke_backbone", vol)}
        return out

    return jobs, finish


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
