"""The cross-check: H-model, finite elements and DEM side by side (paper sections 3-5).

``run_crosscheck`` runs
  1. the H-model directional analysis at its point A (eta = 1.029, Table I), its bifurcation
     domain (W2 and W2_sigma boundaries), and its stress probes in the DEM's 45 directions;
  2. the FE biaxial specimen (a coarse mesh: its perfect specimen follows the material point);
  3. the DEM experiment on a small sample (the paper's 12,000 disks with ``full=True``):
     compaction, drained biaxial test, 45 stress probes at its point A, each twice;
and writes the figures side by side, ``conclusions.json`` and ``report.md`` stating each
conclusion of the paper's section 5 as it comes out of this run.

This is the one module of ``dem`` that imports ``hmodel`` and ``fem`` (lazily): the DEM kernel
itself depends on neither. ``conclusions`` is a pure function of the three results, so the tests
can assert on it.
"""
from __future__ import annotations

import json
import os
import sys
import time

import numpy as np

__all__ = ["run_crosscheck", "conclusions", "hmodel_part", "fem_part", "dem_part", "write_report"]


def _log(msg):
    print(f"[crosscheck] {msg}", file=sys.stderr, flush=True)


def _silent(msg):
    pass


# -- the three parts ---------------------------------------------------------------------------
def hmodel_part(eta_a=1.029, sigma2=200e3, alphas=None, domain_sigma2=(100e3, 200e3, 400e3),
                n_dir=180, workers=None, params=None):
    """H-model at A: path, adaptive strain-probe sweep, stress probes in ``alphas`` [deg],
    bifurcation domain. ``params``: the HParams (default Table I with ``n_dir``), at ``sigma2``
    whatever their p0. Returns a dict of arrays (SI, compression positive)."""
    from hmodel import HParams
    from hmodel.experiment import biaxial_test, bifurcation_domain, state_at_eta
    from hmodel.probes import directional_sweep, stress_probes

    P = (HParams(n_dir=n_dir) if params is None else params).replace(p0=sigma2)
    path = biaxial_test(P, sigma2, 1e-5, 0.05)
    rA, sA = state_at_eta(P, eta_a, sigma2)
    sw = directional_sweep(sA, P, n=360)
    out = {"params": P, "path": path, "pathA": rA, "sweep": sw}
    if alphas is not None:
        out["stress_probes"] = stress_probes(sA, P, alphas, sigma_norm=2.5e3, sweep=sw)
    out["domain"] = bifurcation_domain(P, domain_sigma2, workers=workers) if domain_sigma2 else []
    return out


def fem_part(out_dir, nx=4, ny=8, n_dir=72, eps1_max=0.03, params=None, sigma2=200e3):
    """FE biaxial specimen (coarse mesh, no field output) of the material ``params`` (default
    Table I) with ``n_dir`` orientations at ``sigma2``. Returns its curve (dict of arrays)."""
    from fem.biaxial import BiaxialConfig, run_biaxial
    from hmodel import HParams
    P = (HParams() if params is None else params).replace(n_dir=n_dir, p0=sigma2)
    cfg = BiaxialConfig(nx=nx, ny=ny, eps1_max=eps1_max, d_eps1=1e-4, fields=False,
                        n_sphere=200).with_params(P)
    res = run_biaxial(cfg, out_dir=out_dir)
    return {"curve": res.curve, "events": res.events, "summary": res.summary, "n_dir": n_dir,
            "params": P}


# eta = q/p with p = (s1 + s2)/2 of the state whose eta is 1.029 with p = (s1 + 2 s2)/3 (one
# reading of the paper's DEM section): with x = q/s2, 3x/(3 + x) = 1.029 gives x = 1.5662 and
# 2x/(2 + x) = 0.8784, whatever s2
ETA_P3 = 1.029
ETA2_OF_P3 = 2 * (3 * ETA_P3 / (3 - ETA_P3)) / (2 + 3 * ETA_P3 / (3 - ETA_P3))


def comparison_state(refs, norm, alphas):
    """The DEM state of the comparison (Figs. 15-17 beside the H-model's A), by rule: the
    highest saved state whose reference R held at constant stress and whose every probe target
    stays below the largest stress ratio held by a reference (a lower bound of the strength
    under stress control eta_lim) and below the smallest one that ran away (a small sample's
    curve is jagged, so the two can cross): eta_R + max_eta_increment <= limit.  Every probe
    target then lies where the sample can hold it, so every direction can be decided.

    ``refs``: [(name, State R, outcome, meta)].  Returns (name, dict of the rule's numbers);
    when no state satisfies the rule, the lowest state whose reference held, flagged."""
    from .domain import _eta, max_eta_increment
    held = [(nm, R) for nm, R, oc, _ in refs if oc == "equilibrium"]
    if not held:
        raise RuntimeError("no saved DEM state could be held at constant stress")
    eta_r = {nm: _eta(R.control.s_to[1], R.control.s_to[0]) for nm, R in held}
    lim_low = max(eta_r.values())
    failed = [_eta(R.control.s_to[1], R.control.s_to[0]) for nm, R, oc, _ in refs if oc == "failure"]
    inc = {nm: max_eta_increment(R, norm, alphas) for nm, R in held}
    limit = min([lim_low] + failed)
    ok = [nm for nm in eta_r if eta_r[nm] + inc[nm] <= limit]
    name = max(ok, key=eta_r.get) if ok else min(eta_r, key=eta_r.get)
    return name, {"state": name, "eta_R": eta_r[name], "max_eta_increment": inc[name],
                  "eta_held_max": lim_low, "eta_failed_min": min(failed) if failed else None,
                  "limit": limit,
                  "rule_met": bool(ok)}


def dem_part(out_dir, n=1000, seed=1, rate=0.05, workers=None, eta_a=1.029, threads=None,
             alphas=None, max_steps=None, resume=False, domain=True, hmodel_boundary=None,
             params=None, scheduler=None, verbose=True):
    """DEM: compaction, drained biaxial test with states saved along the path, their
    relaxation under stress control, and the directional analysis (default: the paper's 45
    directions, each twice) at the comparison state chosen by ``comparison_state``
    and, with ``domain``, at every saved state that holds (the DEM's bifurcation domain,
    ``dem.domain``).  ``max_steps`` caps each probe run (undecided when reached).

    ``threads``: threads of the compaction, the biaxial test (default: auto; the results do
    not depend on it); the relaxations and probes run one thread each in ``workers``
    processes, or on the dask.distributed cluster of ``scheduler`` (its address), each run
    one task: the results do not depend on where a run ran.  ``resume``: keep what an
    interrupted run in ``out_dir`` finished (the biaxial test or its checkpoint, the relaxed
    references, the probe runs already on disk).
    ``params``: DemParams of the sample (default: the paper's set); n and seed override it.
    ``verbose``: progress lines on stderr.
    """
    from . import io
    from .domain import run_domain
    from .experiment import COLUMNS, SAVE_FRACTIONS, BiaxialResult, run_biaxial
    from .params import DemParams
    from .probes import ProbeOptions, directions
    from .threads import set_default_threads

    set_default_threads(threads)
    log = _log if verbose else _silent
    bdir = os.path.join(out_dir, "biaxial")
    summary_path = os.path.join(bdir, "summary.json")
    a_path = os.path.join(bdir, "stateA.npz")
    if (resume and os.path.exists(summary_path) and os.path.exists(a_path)
            and not os.path.exists(os.path.join(bdir, "checkpoint.npz"))):
        # the biaxial test finished in an earlier run: read it back
        with open(summary_path) as f:
            summ = json.load(f)
        rows = [[r[c] for c in COLUMNS] for r in io.read_csv(os.path.join(bdir, "biaxial.csv"))[1]]
        res = BiaxialResult(rows, a_path, bool(summ["eta_a_reached"]), summ.get("compaction", {}),
                            float(summ["wall_time"]))
        log(f"DEM: biaxial test taken from {bdir} ({len(rows)} rows)")
    else:
        # the states along the path; 1.0 (the peak, above what constant stress holds)
        # brackets eta_lim from above
        P = (params or DemParams()).replace(n=n, seed=seed)
        res = run_biaxial(P, bdir, rate=rate, eta_a=eta_a, vtk=False,
                          resume=resume, save_fractions=SAVE_FRACTIONS + (1.0,),
                          save_etas=(ETA2_OF_P3,), verbose=verbose)
    opts = ProbeOptions() if max_steps is None else ProbeOptions(max_steps=int(max_steps))
    alphas = directions() if alphas is None else [float(a) for a in alphas]
    t_probes0 = time.time()
    chosen = {}

    def choose(refs):
        name, info = comparison_state(refs, opts.norm, alphas)
        chosen.update(info)
        log(f"DEM: comparison state {name} (eta_R {info['eta_R']:.4f}, largest probe increment "
             f"{info['max_eta_increment']:.4f}, largest eta held {info['eta_held_max']:.4f}; "
             f"rule met: {info['rule_met']})")
        return [nm for nm, _, oc, _ in refs if domain and oc == "equilibrium"] + [name]

    ddir = os.path.join(out_dir, "domain")
    drows, bounds, probes_by = run_domain(bdir, ddir, alphas=alphas, opts=opts, workers=workers,
                                          scheduler=scheduler, resume=resume,
                                          hmodel=hmodel_boundary or False,
                                          choose=choose, verbose=verbose)
    probes = probes_by[chosen["state"]]
    stages = {"compaction + biaxial test (when it ran)": res.wall_time,
              "relaxations and probes (this run)": time.time() - t_probes0}
    eta_peak = bounds["eta_peak"]
    return {"biaxial_rows": res.rows, "state_a": res.state_a_path, "eta_a_reached": res.eta_a_reached,
            "n": n, "rate": rate,
            "compaction": res.compaction, "probes": probes, "comparison": chosen,
            "probes_dir": os.path.join(ddir, chosen["state"]),
            "reference_converged": True, "domain_rows": drows, "domain_bounds": bounds,
            "domain_dir": ddir, "eta_peak": eta_peak, "stage_times": stages,
            "probes_by_state": probes_by,
            "p3_state": _p3_state(res.rows, eta_peak)}


def _p3_state(rows, eta_peak):
    """The first recorded state with q / ((s1 + 2 s2)/3) >= 1.029, or None."""
    from .experiment import COLUMNS
    i = {c: k for k, c in enumerate(COLUMNS)}
    for r in rows:
        p3 = (r[i["s1"]] + 2 * r[i["s2"]]) / 3
        if p3 > 0 and r[i["q"]] / p3 >= ETA_P3:
            return {"eta": r[i["eta"]], "eta_fraction": r[i["eta"]] / eta_peak,
                    "eps1": r[i["eps1"]], "eta_p3": r[i["q"]] / p3,
                    "eta_p3_peak": max(x[i["q"]] / ((x[i["s1"]] + 2 * x[i["s2"]]) / 3)
                                       for x in rows if x[i["s1"]] + 2 * x[i["s2"]] > 0)}
    return None


# -- conclusions -------------------------------------------------------------------------------
def _zone_stats(w2, micro, plastic):
    d = np.abs(np.asarray(w2) - np.asarray(micro))
    pl = np.asarray(plastic, bool)
    f = lambda x: {"mean": float(np.mean(x)), "max": float(np.max(x)), "n": int(x.size)} if x.size else None
    return {"elastic": f(d[~pl]), "plastic": f(d[pl])}


def conclusions(h: dict, dem_rows: list | None, fem: dict | None, dem: dict | None = None) -> dict:
    """The paper's section-5 conclusions as numbers, for each model (``dem``: the result of
    ``dem_part``, for its comparison state, domain and the p = (s1 + 2 s2)/3 reading)."""
    from hmodel.probes import arcs
    sw = h["sweep"]
    c = {"hmodel": {}, "dem": None, "fem": None, "domain": []}
    hm = c["hmodel"]
    neg = sw.w2 <= 0
    hm["cone_w2"] = arcs(sw.alpha_sigma, neg)
    hm["cone_w2sigma"] = arcs(sw.alpha_sigma, sw.w2_sigma <= 0)
    hm["plastic_zone"] = arcs(sw.alpha_sigma, sw.plastic)
    hm["min_w2"] = float(sw.w2.min())
    hm["alpha_min_w2"] = float(sw.alpha_sigma[np.argmin(sw.w2)])
    hm["cone_in_third_quadrant"] = bool(neg.any() and np.all((sw.d_sigma[neg, 0] < 0) & (sw.d_sigma[neg, 1] < 0)))
    hm["micro_minus_macro"] = _zone_stats(sw.w2, sw.w2_micro, sw.plastic)
    hm["w2n_min"] = float(sw.w2n.min())
    hm["w2t_max_in_cone"] = float(sw.w2t[neg].max()) if neg.any() else None
    hm["w2n_min_in_cone"] = float(sw.w2n[neg].min()) if neg.any() else None
    pA, qA, etaA = h["pathA"].invariants()
    p, q, eta = h["path"].invariants()
    hm["eta_A"] = float(etaA[-1])
    hm["eps1_A"] = float(h["pathA"].eps[-1, 0])
    hm["eta_peak"] = float(eta[np.argmax(q)])
    hm["eps1_peak"] = float(h["path"].eps[np.argmax(q), 0])
    hm["q_peak"] = float(q.max())
    for d in h.get("domain", []):
        c["domain"].append({"sigma2": d.sigma2, "eta_w2": d.q_w2 / d.p_w2, "eta_w2sigma": d.q_w2sigma / d.p_w2sigma,
                            "eta_peak": d.q_peak / d.p_peak, "q_w2": d.q_w2, "q_w2sigma": d.q_w2sigma,
                            "q_peak": d.q_peak,
                            "rel_shift_q": (d.q_w2 - d.q_w2sigma) / d.q_w2})
    if dem_rows:
        g = lambda k: np.array([r[k] for r in dem_rows], float)
        a, w2, mic = g("alpha_sigma"), g("w2"), g("w2_micro")
        w2n, w2t, pl = g("w2n"), g("w2t"), g("plastic").astype(bool)
        oc = np.array([r["outcome"] for r in dem_rows])
        # Only an equilibrium probe has a W2 (Eq. 15 needs equilibrium at both ends); a
        # failure ran away (Eq. 1: W2 <= 0 in the limit); an undecided one hit the cap.
        ok = (oc == "equilibrium") & np.array([r["outcome_elastic"] == "equilibrium"
                                                for r in dem_rows])
        fail = oc == "failure"
        ka = np.flatnonzero(ok)
        k = int(ka[np.argmin(w2[ok])])
        negd = ok & (w2 <= 0)
        low = ok & (w2 <= w2[k] + 0.1)            # the low-W2 cone (within 0.1 of the minimum)
        c["dem"] = {
            "n_probes": int(a.size), "n_equilibrium": int(ok.sum()), "n_failure": int(fail.sum()),
            "n_undecided": int((oc == "undecided").sum()),
            "alpha_failure": [float(x) for x in a[fail]],
            "alpha_undecided": [float(x) for x in a[~ok & ~fail]],
            "cone_w2": arcs(a[ok], negd[ok]),
            "unstable_directions": arcs(a[ok | fail], (negd | fail)[ok | fail]),
            "min_w2": float(w2[k]), "alpha_min_w2": float(a[k]),
            "min_in_third_quadrant": bool(180.0 <= a[k] <= 270.0),
            "low_w2_cone": arcs(a[ok], low[ok]),
            "plastic_zone": arcs(a, pl),
            "micro_minus_macro": _zone_stats(w2[ok], mic[ok], pl[ok]),
            "micro_below_macro_in_plastic_zone": bool((pl & ok).any() and np.mean(mic[pl & ok] - w2[pl & ok]) < 0),
            "w2n_min": float(w2n[ok].min()),
            "w2t_max_in_plastic_zone": float(w2t[pl & ok].max()) if (pl & ok).any() else None,
            "w2t_at_min_w2": float(w2t[k]), "w2n_at_min_w2": float(w2n[k]),
        }
        if dem is not None:
            c["dem"]["state"] = dem["comparison"]
            c["dem"]["state"]["eta_fraction"] = dem["comparison"]["eta_R"] / dem["eta_peak"]
            c["dem"]["eta_peak"] = dem["eta_peak"]
            c["dem_domain"] = {"bounds": dem["domain_bounds"], "rows": dem["domain_rows"]}
            p3 = dem["p3_state"]
            c["dem_p3"] = p3
            if p3 is not None:
                b = dem["domain_bounds"]
                p3["below_lower_boundary"] = bool(b["lower_eta"] == b["lower_eta"]
                                                  and p3["eta"] < b["lower_eta"])
    if fem is not None:
        from hmodel.driver import drained_biaxial, isotropic_state, run_path
        cur = fem["curve"]
        P = fem["params"]
        e1 = np.asarray(cur["eps1"], float)
        r = run_path(isotropic_state(P), P, drained_biaxial(1e-4), int(round(e1[-1] / 1e-4)))
        qm = np.interp(e1, r.eps[:, 0], r.sigma[:, 0] - r.sigma[:, 1])
        qf = np.asarray(cur["q"], float)
        c["fem"] = {"max_rel_q_diff_vs_material_point": float(np.max(np.abs(qf - qm)) / np.max(qm)),
                    "eps1_peak": float(e1[np.argmax(qf)]), "events": fem.get("events")}
    return c


# -- figures and report ------------------------------------------------------------------------
def _angle_axes(ax):
    """W2 against alpha_sigma: the frame shared by the side-by-side figures."""
    ax.axhline(0, color="k", lw=0.6)
    ax.set_xlim(0, 360)
    ax.set_xticks(range(0, 361, 45))
    ax.set_xlabel("alpha_sigma [deg] (tan = d sigma1 / d sigma2)")
    ax.set_ylabel("normalized second-order work [-]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)


# how a DEM probe without a W2 is drawn (on W2 = 0): (outcome, marker, colour, label)
OUTCOME_MARKS = (("failure", "^", "C3", "DEM failure (runaway)"),
                 ("undecided", "s", "C7", "DEM undecided (cap)"))


def polar_figure(path, h, rows, dem_title="DEM (Fig. 15)"):
    """fig_polar_w2.png: the H-model at A (``h``: ``hmodel_part``'s, its sweep and, if any, its
    stress probes in the DEM's directions) and the DEM's probes (``rows``: probes.csv rows, or
    None) in the paper's polar diagram (``hmodel.plots``), each with its cone (H-model: W2 <= 0;
    DEM: failure or W2 <= 0) shaded and its angles written and its plastic zone at the rim, and,
    where the H-model's cone is narrow, a third panel of W2 against alpha_sigma around it with
    both parts. A DEM W2 is drawn only for an equilibrium probe (clipped to [-0.5, 1.1])."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hmodel.io import save_figure
    from hmodel.plots import cone_zoom, mark_cone, mark_plastic, needs_zoom, polar_axes, polar_series
    from hmodel.probes import arcs
    rmax = 1.6
    sw = h["sweep"]
    cone_h, plastic_h = arcs(sw.alpha_sigma, sw.w2 <= 0), arcs(sw.alpha_sigma, sw.plastic)
    series_h = [("H-model W2 (strain-probe sweep)", sw.alpha_sigma, sw.w2, "C3-")]
    if "stress_probes" in h:
        sp = h["stress_probes"]
        series_h.append(("H-model, DEM directions", sp.probe.alpha_sigma, sp.probe.w2, "ko"))
    zoom = needs_zoom(cone_h)
    fig = plt.figure(figsize=(17.5 if zoom else 12, 6.9))
    gs = fig.add_gridspec(1, 3 if zoom else 2, width_ratios=[1, 1, 0.95] if zoom else [1, 1])
    ax = fig.add_subplot(gs[0, 0], projection="polar")
    polar_axes(ax, rmax)
    mark_plastic(ax, plastic_h, rmax)
    mark_cone(ax, cone_h, rmax)
    polar_series(ax, series_h, rmax)
    ax.set_title("H-model at A (Fig. 8)", pad=28)
    axes = [ax]
    series_d = []
    ax = fig.add_subplot(gs[0, 1], projection="polar")
    polar_axes(ax, rmax)
    if rows:
        outc = np.array([r["outcome"] for r in rows])
        a = np.array([float(r["alpha_sigma"]) for r in rows])
        eq = outc == "equilibrium"
        w = np.array([float(r["w2"]) if e else np.nan for r, e in zip(rows, eq)])
        cone_d = arcs(a, (outc == "failure") | (eq & (np.nan_to_num(w, nan=1.0) <= 0)))
        mark_plastic(ax, arcs(a, np.array([bool(r["plastic"]) for r in rows]) & eq), rmax)
        mark_cone(ax, cone_d, rmax, label=r"failure or $W_2 \leq 0$")
        o = np.argsort(a)
        loop_a, loop_w = np.append(a[o], a[o][0] + 360.0), np.append(w[o], w[o][0])
        series_d.append((f"DEM W2 ({len(rows)} stress probes; clipped to [-0.5, 1.1])", loop_a,
                         np.clip(loop_w, -0.5, rmax - 0.5), "C0o-"))
        for kind, m, col, lab in OUTCOME_MARKS:
            sel = outc == kind
            if sel.any():
                series_d.append((lab, a[sel], np.zeros(sel.sum()), col + m))
        polar_series(ax, series_d, rmax)
        if not cone_d:
            ax.plot([], [], " ", label=r"every probe settled with $W_2 > 0$")
    ax.set_title(dem_title, pad=28)
    axes.append(ax)
    for ax in axes:
        ax.legend(fontsize=7.5, loc="upper center", bbox_to_anchor=(0.5, -0.08), ncol=2,
                  frameon=False)
    if zoom:
        cone_zoom(fig.add_subplot(gs[0, 2]), series_h + series_d, cone_h, plastic_h, pad_deg=15.0)
    fig.tight_layout()
    save_figure(fig, path)


def _figures(out, h, dem, fem):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hmodel.io import save_figure

    figs = {}
    sw = h["sweep"]
    o = np.argsort(sw.alpha_sigma)
    rows = dem["probes"] if dem else None
    # a probe without equilibrium has no W2 (Eq. 15 needs equilibrium at both ends): NaN, so
    # that the curves break there, and the count in the legend
    conv = lambda k: [float(r[k]) if r["outcome"] == "equilibrium" else np.nan for r in rows]
    outc = np.array([r["outcome"] for r in rows]) if rows else np.array([])
    a_dem = np.array([r["alpha_sigma"] for r in rows]) if rows else np.array([])
    failed_note = ""
    state_note = (f", state {dem['comparison']['state']} (eta {dem['comparison']['eta_R']:.3f})"
                  if dem else "")

    def outcome_marks(ax):
        """Failures (ran away: W2 <= 0 in the limit) as red triangles on W2 = 0, undecided
        probes as grey squares on W2 = 0."""
        for kind, m, col, lab in OUTCOME_MARKS:
            sel = outc == kind
            if sel.any():
                ax.plot(a_dem[sel], np.zeros(sel.sum()), m, color=col, label=lab)

    # stress-strain (Figs. 4-5 and 13-14)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.3), constrained_layout=True)
    p, q, _ = h["path"].invariants()
    e = h["path"].eps
    a1.plot(100 * e[:, 0], q / 1e3, label="H-model material point")
    a2.plot(100 * e[:, 0], 100 * (e[:, 0] + e[:, 1]), label="H-model material point")
    ends = [100 * e[-1, 0]]
    rA = h["pathA"]
    eA = 100 * rA.eps[-1, 0]
    qA = (rA.sigma[-1, 0] - rA.sigma[-1, 1]) / 1e3
    a1.plot([eA], [qA], "o", color="C0", mfc="none", ms=8, label=f"H-model A (eta {h.get('eta_a', 1.029):g})")
    a2.plot([eA], [100 * (rA.eps[-1, 0] + rA.eps[-1, 1])], "o", color="C0", mfc="none", ms=8)
    if fem is not None:
        cur = fem["curve"]
        a1.plot(100 * np.asarray(cur["eps1"]), np.asarray(cur["q"]) / 1e3, "--", label=f"FE specimen (n_dir {fem['n_dir']})")
        ends.append(100 * float(np.asarray(cur["eps1"])[-1]))
        if "eps2_mean" in cur:
            ev = np.asarray(cur["eps1"]) + np.asarray(cur["eps2_mean"])
            a2.plot(100 * np.asarray(cur["eps1"]), 100 * ev, "--", label="FE specimen")
    if dem is not None:
        from .experiment import COLUMNS
        arr = np.array(dem["biaxial_rows"], float)
        col = {k: arr[:, COLUMNS.index(k)] for k in ("eps1", "eps_v", "q", "eta")}
        lab = f"DEM sample ({dem.get('n', '?')} disks, {dem.get('rate', '?')}/s)"
        a1.plot(100 * col["eps1"], col["q"] / 1e3, label=lab, color="C2")
        a2.plot(100 * col["eps1"], 100 * col["eps_v"], label=lab, color="C2")
        ends.append(100 * float(col["eps1"][-1]))
        # the DEM state of the comparison: the first recorded row at its eta
        k = int(np.argmax(col["eta"] >= dem["comparison"]["eta_R"] - 1e-12))
        a1.plot([100 * col["eps1"][k]], [col["q"][k] / 1e3], "s", color="C2", mfc="none", ms=8,
                label=f"DEM comparison state ({dem['comparison']['state']})")
        a2.plot([100 * col["eps1"][k]], [100 * col["eps_v"][k]], "s", color="C2", mfc="none", ms=8)
    for ax, yl in ((a1, "deviatoric stress $q = s_1 - s_2$ [kPa]"),
                   (a2, r"volumetric strain $\varepsilon_v$ [%] (contraction > 0)")):
        ax.set_xlabel(r"axial strain $\varepsilon_1$ [%]")
        ax.set_ylabel(yl)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        ax.set_xlim(0, min(ends))     # every curve ends at the same strain
    a1.set_title("Drained biaxial test at 200 kPa (Figs. 4 and 13)")
    a2.set_title("Volumetric response (Figs. 5 and 14)")
    figs["stress_strain"] = "fig_stress_strain.png"
    save_figure(fig, os.path.join(out, figs["stress_strain"]))

    # polar W2 (Figs. 8 and 15)
    figs["polar_w2"] = "fig_polar_w2.png"
    polar_figure(os.path.join(out, figs["polar_w2"]), h, rows, f"DEM (Fig. 15){state_note}")

    # micro against macro (Fig. 16, and the H-model identity)
    fig, axs = plt.subplots(1, 2, figsize=(11, 4.3), constrained_layout=True)
    axs[0].plot(sw.alpha_sigma[o], sw.w2[o], label="macro W2 = V dPi:de")
    axs[0].plot(sw.alpha_sigma[o], sw.w2_micro[o], "--", label="micro: sum of df.dl over contacts")
    axs[0].set_title("H-model: micro and macro W2 (identical to round-off)")
    if rows:
        a = np.array([r["alpha_sigma"] for r in rows])
        axs[1].plot(a, conv("w2"), "o-", label="macro W2 (walls)" + failed_note)
        axs[1].plot(a, conv("w2_micro"), "s--", label="micro: sum df.dl over grain contacts")
        pl = np.array([r["plastic"] for r in rows], bool)
        axs[1].plot(a[pl], np.array(conv("w2"))[pl], "x", color="C3", label="plastic probe")
        outcome_marks(axs[1])
    axs[1].set_title(f"DEM (Fig. 16){state_note}")
    for ax in axs:
        _angle_axes(ax)
    figs["micro_macro"] = "fig_micro_macro.png"
    save_figure(fig, os.path.join(out, figs["micro_macro"]))

    # normal and tangential parts (Figs. 11 and 17)
    fig, axs = plt.subplots(1, 2, figsize=(11, 4.3), constrained_layout=True)
    axs[0].plot(sw.alpha_sigma[o], sw.w2n[o], label="W2n (normal)")
    axs[0].plot(sw.alpha_sigma[o], sw.w2t[o], label="W2t (tangential)")
    axs[0].plot(sw.alpha_sigma[o], sw.w2[o], "k:", lw=0.8, label="W2")
    axs[0].set_title("H-model (Fig. 11)")
    if rows:
        a = np.array([r["alpha_sigma"] for r in rows])
        axs[1].plot(a, conv("w2n"), "o-", label="W2n (normal)" + failed_note)
        axs[1].plot(a, conv("w2t"), "s-", label="W2t (tangential)")
        axs[1].plot(a, conv("w2"), "k:", lw=0.8, label="W2 macro")
        outcome_marks(axs[1])
    axs[1].set_title(f"DEM (Fig. 17){state_note}")
    for ax in axs:
        _angle_axes(ax)
    figs["normal_tangential"] = "fig_normal_tangential.png"
    save_figure(fig, os.path.join(out, figs["normal_tangential"]))

    if h.get("domain"):
        from hmodel.plots import fig_domain
        figs["domain"] = "fig_domain.png"
        fig_domain(h["domain"], os.path.join(out, figs["domain"]))
    if dem is not None:
        import shutil
        for src, key in (("fig_domain.png", "dem_domain"), ("fig_domain_w2.png", "dem_domain_w2")):
            p = os.path.join(dem["domain_dir"], src)
            if os.path.exists(p):
                figs[key] = f"fig_dem_{src[4:]}"
                shutil.copyfile(p, os.path.join(out, figs[key]))
    return figs


# the probes' cap is the same in both: a cap is no criterion (dem.settle decides), and the
# slow creep at the edge of the plastic zone needs ~120,000-260,000 steps at 1000 disks
# (20 equilibrium windows of the sample: 20 x 20,000 steps at 1000 disks, 20 x 70,000 at 12,000,
# where plastic probes settle in 210,000-390,000 steps and two of them crept past 400,000)
DEFAULT_SMALL = {"n": 1000, "rate": 0.05, "max_steps": 400_000}
DEFAULT_FULL = {"n": 12000, "rate": 0.01, "max_steps": 1_400_000}


def write_report(out, c: dict, figs: dict, timings: dict, config: dict):
    """report.md: every figure embedded and the paper's section-5 conclusions in numbers."""
    from hmodel.io import atomic_open
    from .domain import eta_lim_text
    from hmodel.probes import format_arcs
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
        from .crosscheck_burst import burst_report_lines
        L += [""] + burst_report_lines(c["burst"], figs.get("burst"), figs.get("burst_eq1"),
                                       figs.get("burst_w2"))
    L += ["", "## Wall times", ""] + [f"- {k}: {v:.1f} s" for k, v in timings.items()] + [""]
    with atomic_open(os.path.join(out, "report.md")) as f:
        f.write("\n".join(L))


def run_crosscheck(out_dir, full=False, n=None, seed=1, rate=None, workers=None, skip_dem=False,
                   fem_mesh=(4, 8), fem_n_dir=72, domain=True, dem_alphas=None,
                   dem_max_steps=None, threads=None, resume=False, dem_domain=None,
                   dem_params=None, scheduler=None, hmodel_params=None, burst=True,
                   burst_ratios=None, burst_fractions=None, verbose=True):
    """Run all three parts and write figures, conclusions.json and report.md in ``out_dir``.

    Default: 1000 disks at 0.05/s (minutes); ``full``: the paper's 12,000 disks at 0.01/s.
    ``dem_alphas`` [deg] replaces the 45 probe directions, ``dem_max_steps`` the probe cap;
    ``threads`` and ``resume``: see ``dem_part`` (the H-model and FE parts always rerun).
    ``dem_domain``: the DEM's directional analysis at every saved state (its bifurcation
    domain), default on except with ``full`` (there only at the comparison state: the
    12,000-disk domain is ``python -m dem domain``'s job).  ``dem_params``: a DemParams file
    for the DEM sample (default: the paper's stated set); the report names it.
    ``hmodel_params``: an HParams file for the H-model and the FE parts (default Table I; the FE
    at ``fem_n_dir`` orientations, both at the DEM's 200 kPa whatever the file's p0).
    ``scheduler``: the address of a dask.distributed scheduler for the DEM's relaxations and
    probe runs (see ``dem_part``; the H-model's domain stays in local processes).
    ``burst``: the burst section (``dem.crosscheck_burst``): the proportional strain paths of
    ``burst_ratios`` (default -2) from ``burst_fractions`` (default 0.90) of each part's drained
    peak, c held below and past its peak, in the H-model, the FE specimen and the DEM sample.
    ``verbose``: progress lines on stderr.
    """
    from hmodel.io import atomic_open

    from .params import DemParams, load_params
    from .probes import directions
    from hmodel.params import load_params as load_hparams
    P = load_params(dem_params, option="--dem-params") if dem_params else DemParams()
    H = load_hparams(hmodel_params, option="--hmodel-params") if hmodel_params else None
    os.makedirs(out_dir, exist_ok=True)
    dflt = DEFAULT_FULL if full else DEFAULT_SMALL
    n = dflt["n"] if n is None else int(n)
    rate = dflt["rate"] if rate is None else float(rate)
    dem_max_steps = dflt["max_steps"] if dem_max_steps is None else int(dem_max_steps)
    timings = {}
    log = _log if verbose else _silent
    t = time.time()
    log("H-model: drained path, point A, directional analysis, bifurcation domain")
    h = hmodel_part(alphas=directions() if dem_alphas is None else list(dem_alphas),
                    domain_sigma2=(100e3, 200e3, 400e3) if domain else (), workers=workers,
                    params=H)
    timings["H-model (path, probes, domain)"] = time.time() - t
    t = time.time()
    log(f"FE: {fem_mesh[0]} x {fem_mesh[1]} quads, n_dir {fem_n_dir}")
    fem = fem_part(os.path.join(out_dir, "fem"), nx=fem_mesh[0], ny=fem_mesh[1], n_dir=fem_n_dir,
                   params=H)
    timings["FE specimen"] = time.time() - t
    dem = None
    if not skip_dem:
        t = time.time()
        log(f"DEM: {n} disks, rate {rate}/s, 45 probes x 2")
        hb = None
        for d in h.get("domain", []):
            if abs(d.sigma2 - 200e3) < 1.0:
                peak = d.q_peak / d.p_peak
                hb = {"sigma2": d.sigma2, "eta_w2": d.q_w2 / d.p_w2,
                      "eta_w2sigma": d.q_w2sigma / d.p_w2sigma, "eta_peak": peak,
                      "eta_w2_fraction": d.q_w2 / d.p_w2 / peak}
        dem = dem_part(os.path.join(out_dir, "dem"), n=n, seed=seed, rate=rate, workers=workers,
                       alphas=dem_alphas, max_steps=dem_max_steps, threads=threads,
                       resume=resume, domain=(not full) if dem_domain is None else dem_domain,
                       hmodel_boundary=hb, params=P, scheduler=scheduler, verbose=verbose)
        n_runs = 2 * sum(len(r) for r in dem["probes_by_state"].values())
        timings[f"DEM ({n} disks: compaction, biaxial, {len(dem['domain_rows'])} relaxations, "
                f"{n_runs} probe runs)"] = time.time() - t
        for k, v in dem["stage_times"].items():
            timings[f"  DEM {k}"] = v
    bparts = None
    if burst:
        from . import crosscheck_burst as cb
        t = time.time()
        bparts = cb.burst_part(out_dir, os.path.join(out_dir, "dem", "biaxial") if dem else None,
                               ratios=tuple(burst_ratios or cb.BURST_RATIOS),
                               fractions=tuple(burst_fractions or cb.BURST_FRACTIONS),
                               fem_mesh=fem_mesh, fem_n_dir=fem_n_dir, dem_rate=rate,
                               workers=workers, log=log, verbose=verbose)
        timings["burst (H-model, FE, DEM)"] = time.time() - t
    c = conclusions(h, dem["probes"] if dem else None, fem, dem)
    figs = _figures(out_dir, h, dem, fem)
    if bparts:
        d200 = [d for d in c["domain"] if abs(d["sigma2"] - 200e3) < 1.0]
        c["burst"] = cb.burst_conclusions(bparts, d200[0]["eta_w2"] if d200 else None,
                                          (fem["summary"] or {}).get("events"))
        figs["burst"] = cb.burst_figure(out_dir, bparts)
        figs["burst_w2"] = cb.w2_path_figure(out_dir, bparts)
        figs["burst_eq1"] = cb.burst_eq1_figure(
            out_dir, os.path.join(out_dir, "burst", "fem", "history.csv"),
            os.path.join(out_dir, "burst", "dem", "history.csv"))
    config = {"full": full, "dem_n": n, "dem_seed": seed, "dem_rate": rate,
              "dem_params": (os.path.abspath(dem_params) if dem_params else
                             "the paper's stated set (kn/D 32 GPa, kt/kn 0.42, 35 deg)"),
              "dem_params_values": P.replace(n=n, seed=seed).to_dict(),
              "hmodel_params": (os.path.abspath(hmodel_params) if hmodel_params else
                                "Table I (the FE at fem_n_dir orientations)"),
              "dem_probe_max_steps": dem_max_steps, "fem_mesh": list(fem_mesh),
              "fem_n_dir": fem_n_dir, "dem_eta_a_reached": dem["eta_a_reached"] if dem else None}
    with atomic_open(os.path.join(out_dir, "conclusions.json")) as f:
        json.dump({"conclusions": c, "timings": timings, "config": config}, f, indent=1, default=str)
    # the parameters of the three parts, in the --params format (dem/biaxial/ and fem/ hold theirs
    # too): --dem-params DIR/dem_params.json repeats the DEM sample
    from hmodel.params import save_params as save_hparams

    from .params import save_params
    save_hparams(os.path.join(out_dir, "hmodel_params.json"), h["params"],
                 "python -m dem crosscheck: the H-model part (--hmodel-params repeats it; the FE "
                 "part: fem/params.json)")
    save_params(os.path.join(out_dir, "dem_params.json"), P.replace(n=n, seed=seed),
                "python -m dem crosscheck: the DEM sample (--dem-params repeats it)")
    write_report(out_dir, c, figs, timings, config)
    return c, timings
