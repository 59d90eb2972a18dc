"""The theory's verdict on a path's staircase (``dem.burst``): the noise of the kinematic
probes' k_path (``k_noise``) and the verdict (``theory_verdict``: does W2 of the path vanish where
a held G can no longer be kept?)."""
from __future__ import annotations

import math

import numpy as np


def k_noise(probes, d_eps1, repeats=()) -> tuple:
    """The noise of k_path [Pa] from the probes of one path, (the larger of the two below, the
    relaxations', the repeats'): (1) sqrt(2) times the RMS change of c that relaxing an
    equilibrium at fixed strain makes (c_before - c_state, the states held under the dead load:
    the relaxed states of the path are at rest at fixed strain already), over d_eps1: c_before
    and c_after each carry it; (2) the scatter of k_path on one macroscopic state, from
    ``repeats``, pairs of probes of the same state before and after it was held once more with no
    change of load (the baselines' ends against the switches' starts): the RMS of their
    differences over sqrt(2). The second is the larger where the packing's last hold changes its
    response (2000 disks: +6.5e7 and +2.6e7 Pa at the below state before and after the hold, where
    the relaxations give 6.9e6 Pa). NaN where neither can be had."""
    dz = [p.c_before - p.c_state for p in probes if p.key.startswith("h")]
    relax_noise = (math.sqrt(2.0) * math.sqrt(float(np.mean(np.square(dz)))) / d_eps1
                   if dz else math.nan)
    dk = [a.k_path - b.k_path for a, b in repeats]
    repeat_noise = (math.sqrt(float(np.mean(np.square(dk))) / 2.0) if dk else math.nan)
    both = [x for x in (relax_noise, repeat_noise) if math.isfinite(x)]
    return (max(both) if both else math.nan), relax_noise, repeat_noise


CLEARLY = 2.0      # k_path is clearly positive above this many times its noise


def theory_verdict(eqs, fails, noise, dc) -> dict:
    """The theory's verdict on one path's staircase (``shared/spec/burst.md``): at a state at
    rest, W2 of the path (the sign of k_path) vanishes where a held G can no longer be kept.

    ``eqs``: the staircase's equilibria in order, [(key, c [Pa], eps1, k_path [Pa])], the relaxed
    start first; ``fails``: its failing holds, [(key of the equilibrium it started from, step
    [Pa])]; ``noise``: k_path's noise [Pa] (``k_noise``); ``dc``: the smallest step [Pa].

    k_path is *clearly positive* above ``CLEARLY`` times its noise. The crossing: the zero of
    k_path, interpolated linearly in c between the first equilibrium with k_path <= 0 after the
    last one where it is clearly positive, and the one before it (the band: where k_path = +-
    CLEARLY noise there). A positive k_path within the noise after the crossing does not move it
    (at 4000 disks one, +1.8e6 Pa against a noise of 4.1e6 Pa, lies between two of -1.6e7 and
    -5.6e8 Pa), nor do positive ones within the noise before it (they are the rise's last
    equilibria). The overshoot: how far past it, in c and in eps1, the dead load still held (the
    c peak at rest, the last equilibrium). The verdict:
    "passes" when no hold of +dc failed from an equilibrium where k_path is clearly positive
    and k_path is not clearly positive at the last equilibrium; "contradicted" when a hold of +dc
    failed from an equilibrium where k_path is clearly positive; "no verdict" without a failing
    hold of +dc or without k_path (probes off or undecided). A failing hold of a larger step
    from a clearly positive k_path is reported (``finite_step_failures``), not counted against
    the theory: it speaks of an infinitesimal dG (the dead load's finite step also overshoots
    its static displacement dynamically)."""
    nan = math.nan
    k = np.array([e[3] for e in eqs], float)
    c = np.array([e[1] for e in eqs], float)
    e1 = np.array([e[2] for e in eqs], float)
    out = {"k_path_first": float(k[0]) if len(k) else nan,
           "k_path_last": float(k[-1]) if len(k) else nan,
           "k_path_ratio": float(k[-1] / k[0]) if len(k) and k[0] != 0 else nan,
           "k_noise": noise, "c_cross": nan, "c_cross_band": [nan, nan], "eps1_cross": nan,
           "overshoot_c": nan, "overshoot_eps1": nan, "finite_step_failures": 0,
           "c_peak_rest": float(c[-1]) if len(c) else nan,
           "verdict": "no verdict", "why": ""}
    if not len(k) or not np.all(np.isfinite(k)) or not math.isfinite(noise):
        out["why"] = "no k_path at every equilibrium"
        return out
    pos = k > CLEARLY * noise
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
    elif not len(above):
        out["why"] = "k_path not clearly positive already at the first equilibrium"
    if against:
        out["verdict"] = "contradicted"
        out["why"] = (f"a hold of +{dc:g} Pa failed from an equilibrium where k_path is clearly "
                      f"positive ({kk[against[0][0]][0]:.3g} Pa, noise {noise:.2g} Pa)")
    elif not dc_fails:
        out["why"] = "no hold of +dc failed"
    elif pos[-1]:
        out["verdict"] = "contradicted"
        out["why"] = f"k_path is clearly positive at the last equilibrium ({k[-1]:.3g} Pa)"
    else:
        out["verdict"] = "passes"
        out["why"] = (f"k_path {k[0]:.3g} Pa at the first equilibrium, {k[-1]:.3g} Pa at the "
                      f"last (noise {noise:.2g} Pa): the holds of +{dc:g} Pa failed where W2 of "
                      "the path is <= 0 within noise")
    return out
