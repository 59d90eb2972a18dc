"""The theory's verdict on a path's staircase (``dem.burst``): the noise of the kinematic
probes' k_path (``k_noise``), the verdict (``theory_verdict``: does W2 of the path vanish where
a held G can no longer be kept?), both drawn from a staircase's records (``staircase_verdict``,
which ``staircase`` calls and ``verdict_of_folder`` calls again on a finished run's CSV files)."""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

CLEARLY = 2.0      # k_path is clearly positive above this many times its noise
AVALANCHE = 1.0    # a probe set off an avalanche where k_path < -AVALANCHE x the largest k_path
                   # (and a relaxation collapsed where |c change| > AVALANCHE x k_max x d_eps1)


class Noise(NamedTuple):
    """k_path's noise about its sign [Pa] (``k_noise``), and what is measured beside it."""
    noise: float           # the larger of ``relax`` and ``repeat`` (NaN where neither can be had)
    relax: float           # the relaxations': sqrt 2 x RMS(c_before - c_state) / d eps1, over
                           # those that did not collapse
    repeat: float          # the repeats' whose two k_path differ in sign, neither an avalanche
    same_sign: float       # the repeats of one sign: RMS difference / sqrt 2 (not noise)
    avalanches: tuple      # (key, k_path) of the probes that set off an avalanche (not noise)
    k_max: float           # the largest k_path of the path: the stiffest response measured
    relax_collapses: tuple = ()  # (key, c_before - c_state [Pa]) of the relaxations that
                                 # collapsed (not noise)


def k_noise(probes, d_eps1, repeats=()) -> Noise:
    """The noise of k_path [Pa] about its sign, from the probes of one path, that the state's own
    response cannot inflate: the larger of (1) the relaxations', sqrt(2) times the RMS change of c
    that relaxing an equilibrium at fixed strain makes (c_before - c_state, the states held under
    the dead load: the relaxed states of the path are at rest at fixed strain already), over
    d_eps1: c_before and c_after each carry it; (2) the repeats', from ``repeats``, pairs of probes
    of the same macroscopic state before and after it was held once more with no change of load
    (the baselines' ends against the switches' starts): the RMS of their differences over
    sqrt(2), over the pairs whose two k_path differ in sign and where neither probe set off an
    avalanche. Two k_path of one sign, or a probe that sets off an avalanche, are the state's
    response, not noise about its sign: they are measured apart (``Noise.same_sign``,
    ``Noise.avalanches``). An avalanche: a probe whose c fell by more than the stiffest response
    of the path (its largest k_path, ``Noise.k_max``) raises c over the same move, k_path <
    -``AVALANCHE`` k_max: the move set off a collapse. So too a relaxation: a dead-load
    equilibrium whose c moved, its strain held, by more than the stiffest response moves it over
    the probe's whole move, |c_before - c_state| > ``AVALANCHE`` k_max d_eps1, slid on its own
    (``Noise.relax_collapses``), and its change is not counted in the relaxations' noise. Measured: a repeat whose probe set off an
    avalanche (c fell 22.9 kPa for d eps1 = 1e-5: -2.29e9 Pa against -2.06e8 Pa at the same
    state) made the former estimate (every pair) 1.04e9 Pa, 250 times the relaxations' 4.2e6 Pa,
    and nothing of the staircase clearly positive; the 2000-disk gallery's two pairs (+6.5e7 and
    +2.6e7, -5.0e7 and -5.9e7 Pa) are of one sign each."""
    ks = [p.k_path for p in probes if math.isfinite(p.k_path)]
    k_max = max(ks) if ks else math.nan
    dz = [(p.key, p.c_before - p.c_state) for p in probes if p.key.startswith("h")]
    collapsed = lambda z: bool(k_max > 0 and abs(z) > AVALANCHE * k_max * d_eps1)
    collapses = tuple((k, float(z)) for k, z in dz if collapsed(z))
    dz = [z for _, z in dz if not collapsed(z)]
    relax_noise = (math.sqrt(2.0) * math.sqrt(float(np.mean(np.square(dz)))) / d_eps1
                   if dz else math.nan)
    aval = lambda p: bool(k_max > 0 and p.k_path < -AVALANCHE * k_max)
    avalanches = tuple((p.key, float(p.k_path)) for p in probes if aval(p))
    rms = lambda d: math.sqrt(float(np.mean(np.square(d))) / 2.0) if d else math.nan
    opposite = [a.k_path - b.k_path for a, b in repeats
                if a.k_path * b.k_path < 0 and not (aval(a) or aval(b))]
    same = [a.k_path - b.k_path for a, b in repeats if a.k_path * b.k_path >= 0]
    repeat_noise = rms(opposite)
    both = [x for x in (relax_noise, repeat_noise) if math.isfinite(x)]
    return Noise(max(both) if both else math.nan, relax_noise, repeat_noise, rms(same),
                 avalanches, k_max, collapses)


def theory_verdict(eqs, fails, noise, dc) -> dict:
    """The theory's verdict on one path's staircase: at a state at rest, W2 of the path (the sign
    of k_path) vanishes where a held G can no longer be kept.

    ``eqs``: the staircase's equilibria in order, [(key, c [Pa], eps1, k_path [Pa])], the relaxed
    start first; ``fails``: its failing holds, [(key of the equilibrium it started from, step
    [Pa])]; ``noise``: k_path's noise [Pa] (``k_noise``); ``dc``: the smallest step [Pa].

    k_path is *clearly positive* above ``CLEARLY`` times its noise. The crossing: the zero of
    k_path, interpolated linearly in c between the first equilibrium with k_path <= 0 after the
    last one where it is clearly positive, and the one before it (the band: where k_path = +-
    CLEARLY noise there). A positive k_path within the noise after the crossing does not move it,
    nor do positive ones within the noise before it (they are the rise's last equilibria). The
    overshoot: how far past it, in c and in eps1, the dead load still held (the c peak at rest,
    the last equilibrium). The verdict:

    * "contradicted": a hold of +dc failed from an equilibrium where k_path is clearly positive
      (or k_path is clearly positive at the last equilibrium, where the past hold starts);
    * "passes": it could have been contradicted and was not: some equilibrium before the failing
      hold is clearly positive, the crossing is found (a k_path <= 0 after the last clearly
      positive one), and no hold of +dc failed where k_path is clearly positive;
    * "no verdict", with the reason (``why``): no failing hold of +dc, no k_path (probes off or
      undecided) or no noise, no equilibrium clearly positive (a noise as large as every k_path:
      no hold could have contradicted the theory), or no crossing.

    A failing hold of a larger step from a clearly positive k_path is reported
    (``finite_step_failures``), not counted against the theory: it speaks of an infinitesimal dG
    (the dead load's finite step also overshoots its static displacement dynamically). Nor is a
    clearly negative k_path whose next hold settled: W2 < 0 makes failure possible, not certain."""
    nan = math.nan
    k = np.array([e[3] for e in eqs], float)
    c = np.array([e[1] for e in eqs], float)
    e1 = np.array([e[2] for e in eqs], float)
    out = {"k_path_first": float(k[0]) if len(k) else nan,
           "k_path_last": float(k[-1]) if len(k) else nan,
           "k_path_ratio": float(k[-1] / k[0]) if len(k) and k[0] != 0 else nan,
           "k_noise": noise, "c_cross": nan, "c_cross_band": [nan, nan], "eps1_cross": nan,
           "overshoot_c": nan, "overshoot_eps1": nan, "finite_step_failures": 0,
           "n_clearly_positive": 0, "c_peak_rest": float(c[-1]) if len(c) else nan,
           "verdict": "no verdict", "why": ""}
    if not len(k) or not np.all(np.isfinite(k)):
        out["why"] = "no k_path at every equilibrium"
        return out
    if not math.isfinite(noise):
        out["why"] = "no noise of k_path (no relaxation of a dead-load equilibrium, no repeat)"
        return out
    pos = k > CLEARLY * noise
    out["n_clearly_positive"] = int(np.sum(pos))
    kk = {e[0]: (kv, p) for e, kv, p in zip(eqs, k, pos)}
    dc_fails = [f for f in fails if f[1] <= dc * (1 + 1e-9)]
    against = [f for f in dc_fails if kk.get(f[0], (nan, False))[1]]
    out["finite_step_failures"] = sum(1 for f in fails if f[1] > dc * (1 + 1e-9)
                                      and kk.get(f[0], (nan, False))[1])
    # the crossing: the first k_path <= 0 after the last clearly positive one (if one follows)
    above = np.flatnonzero(pos)
    after = np.flatnonzero(k[above[-1]:] <= 0) + above[-1] if len(above) else []
    if len(above) and len(after):
        a = int(after[0]) - 1

        def zero(level):
            return float(np.interp(level, [k[a + 1], k[a]], [c[a + 1], c[a]])), \
                float(np.interp(level, [k[a + 1], k[a]], [e1[a + 1], e1[a]]))

        out["c_cross"], out["eps1_cross"] = zero(0.0)
        out["c_cross_band"] = sorted([zero(CLEARLY * noise)[0], zero(-CLEARLY * noise)[0]])
        out["overshoot_c"] = float(c[-1] - out["c_cross"])
        out["overshoot_eps1"] = float(e1[-1] - out["eps1_cross"])
    if against:
        out["verdict"] = "contradicted"
        out["why"] = (f"a hold of +{dc:g} Pa failed from an equilibrium where k_path is clearly "
                      f"positive ({kk[against[0][0]][0]:.3g} Pa, noise {noise:.2g} Pa)")
    elif not dc_fails:
        out["why"] = "no hold of +dc failed"
    elif pos[-1]:
        out["verdict"] = "contradicted"
        out["why"] = f"k_path is clearly positive at the last equilibrium ({k[-1]:.3g} Pa)"
    elif not len(above):
        out["why"] = (f"no equilibrium where k_path is clearly positive (the largest "
                      f"{k.max():.3g} Pa against {CLEARLY:g} x the noise {noise:.2g} Pa): no hold "
                      "could have contradicted the theory")
    elif not math.isfinite(out["c_cross"]):
        out["why"] = (f"no k_path <= 0 after the last clearly positive one "
                      f"({k[above[-1]]:.3g} Pa): no crossing")
    else:
        out["verdict"] = "passes"
        out["why"] = (f"k_path clearly positive at {len(above)} equilibria (the last "
                      f"{k[above[-1]]:.3g} Pa at {c[above[-1]] / 1e3:.2f} kPa, noise "
                      f"{noise:.2g} Pa), 0 at {out['c_cross'] / 1e3:.2f} kPa, {k[-1]:.3g} Pa at "
                      f"the last: the holds of +{dc:g} Pa failed where W2 of the path is <= 0 "
                      "within noise, and none where it is clearly positive")
    return out


def staircase_verdict(eq, holds, probes, dc, d_eps1, end="past found") -> dict:
    """The noise and the theory's verdict of one staircase from its records (``staircase`` and
    ``verdict_of_folder``): ``eq`` its equilibria [(key, c, eps1)] in order; ``holds`` its holds
    [(role, c_from, c_target, outcome, key of the state it started from)] in order (hold k's end
    is the state "hk_end"); ``probes`` {key: ProbeResult}; ``dc``, ``d_eps1`` the options';
    ``end`` how the rest search ended. Returns ``theory_verdict``'s dict with the noise's
    estimates (``k_noise_relax``, ``k_noise_repeat``, ``k_repeat_same_sign``, ``avalanches``,
    ``relax_collapses``, ``k_max``)."""
    repeats = [(probes[h[4]], probes[f"h{i}_end"]) for i, h in enumerate(holds)
               if h[0].startswith("baseline_") and h[4] in probes and f"h{i}_end" in probes]
    n = k_noise(list(probes.values()), d_eps1, repeats)
    eqk = [(k, c, e, probes[k].k_path if k in probes and probes[k].outcome == "equilibrium"
            else math.nan) for k, c, e in eq]
    fails = [(h[4], h[2] - h[1]) for h in holds if h[0] == "stair" and h[3] == "failure"]
    verdict = theory_verdict(eqk, fails, n.noise, dc) if end == "past found" else \
        {**theory_verdict(eqk, [], n.noise, dc), "verdict": "no verdict",
         "why": f"the rest search ended: {end}"}
    verdict.update(k_noise_relax=n.relax, k_noise_repeat=n.repeat,
                   k_repeat_same_sign=n.same_sign,
                   avalanches=[{"key": a, "k_path": kp} for a, kp in n.avalanches],
                   relax_collapses=[{"key": a, "dc": z} for a, z in n.relax_collapses],
                   k_max=n.k_max, probe_d_eps1=d_eps1)
    return verdict


def verdict_of_folder(folder) -> list:
    """The verdict of every path of a finished ``dem burst`` folder drawn again from its files
    (stairs.csv, probes.csv, rest.csv, summary.json), by this module's rule, without a run: one
    dict per path (its ratio and start fraction, then ``staircase_verdict``'s)."""
    import json
    import os
    from .. import io
    from .runs import ProbeResult
    with open(os.path.join(folder, "summary.json")) as f:
        s = json.load(f)
    _, stairs = io.read_csv(os.path.join(folder, "stairs.csv"))
    _, rest = io.read_csv(os.path.join(folder, "rest.csv"))
    _, probes = io.read_csv(os.path.join(folder, "probes.csv"))
    o = s["options"]
    out = []
    for p in s["paths"]:
        mine = lambda rows: [r for r in rows if (r["ratio"], r["start_fraction"])
                             == (p["ratio"], p["start_fraction"])]
        start = next(r for r in mine(rest) if r["state"] == "start")
        eq = [("relaxed_start", start["c_rest"], start["eps1"])]
        holds = []
        for r in sorted(mine(stairs), key=lambda r: r["hold"]):
            holds.append((r["role"], r["c_from"], r["c_target"], r["outcome"], r["from"]))
            if r["role"] == "stair" and r["outcome"] == "equilibrium":
                eq.append((f"h{int(r['hold'])}_end", r["c_end"], r["eps1_end"]))
        pr = {r["key"]: ProbeResult(**{k: r[k] for k in ProbeResult._fields})
              for r in mine(probes)}
        v = staircase_verdict(eq, holds, pr, o["dc"], o["probe_d_eps1"],
                              p.get("rest_search") or "")
        out.append({"ratio": p["ratio"], "start_fraction": p["start_fraction"], **v})
    return out
