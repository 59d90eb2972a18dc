"""The paper's section-5 conclusions as numbers, for each part of the cross-check.

``conclusions`` is a pure function of the three parts' results (``crosscheck.parts``), so the
tests can assert on it; the report (``crosscheck.report``) states each one as it comes out.
"""
from __future__ import annotations

import numpy as np

__all__ = ["conclusions"]


def _zone_stats(w2, micro, plastic):
    d = np.abs(np.asarray(w2) - np.asarray(micro))
    pl = np.asarray(plastic, bool)
    f = lambda x: {"mean": float(np.mean(x)), "max": float(np.max(x)), "n": int(x.size)} if x.size else None
    return {"elastic": f(d[~pl]), "plastic": f(d[pl])}


def conclusions(h: dict, dem_rows: list | None, fem: dict | None, dem: dict | None = None) -> dict:
    """The paper's section-5 conclusions as numbers, for each model (``dem``: the result of
    ``dem_part``, for its comparison state, domain and the p = (s1 + 2 s2)/3 reading)."""
    from point.probes import arcs
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
        from point.driver import drained_biaxial, isotropic_state, run_path
        cur = fem["curve"]
        P = fem["params"]
        e1 = np.asarray(cur["eps1"], float)
        r = run_path(isotropic_state(P), P, drained_biaxial(1e-4), int(round(e1[-1] / 1e-4)))
        qm = np.interp(e1, r.eps[:, 0], r.sigma[:, 0] - r.sigma[:, 1])
        qf = np.asarray(cur["q"], float)
        c["fem"] = {"max_rel_q_diff_vs_material_point": float(np.max(np.abs(qf - qm)) / np.max(qm)),
                    "eps1_peak": float(e1[np.argmax(qf)]), "events": fem.get("events")}
    return c

