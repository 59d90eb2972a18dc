"""Directional analysis at point A (Figs. 3, 8) and one point of the bifurcation domain (Fig. 10).

Table I, 200 kPa. ``w2`` is the normalized second-order work (Eq. 10 over V |dPi| |d eps|),
``W2`` the raw one [J]; angles in degrees, alpha_sigma from the d sigma2 axis. docs/api.md.
"""
import numpy as np

from hmodel import HParams
from point.experiment import bifurcation_domain, state_at_eta
from point.probes import arcs, directional_sweep, format_arcs, stress_probes

P = HParams()
path, state_A = state_at_eta(P, 1.029)           # the drained path to eta = 1.029 and its state

sw = directional_sweep(state_A, P, n=360)        # strain probes, refined where alpha_sigma jumps
cone = arcs(sw.alpha_sigma, sw.w2 <= 0)          # [[start, end], ...] of alpha_sigma [deg]
print(f"{len(sw.alpha_eps)} strain probes; plastic zone {format_arcs(arcs(sw.alpha_sigma, sw.plastic))} deg")
print(f"cone W2 <= 0: {format_arcs(cone)} deg; min w2 = {sw.w2.min():.4f} "
      f"at alpha_sigma = {sw.alpha_sigma[np.argmin(sw.w2)]:.2f} deg")

# stress probes: the strain direction that gives each asked stress direction
sp = stress_probes(state_A, P, [225.0, 247.5], sigma_norm=2.5e3, sweep=sw)
for a, n, w in zip(sp.alpha_sigma_target, sp.n_solutions, sp.probe.w2):
    print(f"stress probe alpha_sigma = {a:g} deg: {n} solution(s), w2 = {w:.4f}")

# the bifurcation domain at one confining pressure: first W2 <= 0, first W2_sigma <= 0, peak
(d,) = bifurcation_domain(P, [200e3], workers=1)
print(f"200 kPa: first W2 <= 0 at eta = {d.q_w2 / d.p_w2:.4f}, first W2_sigma <= 0 at "
      f"eta = {d.q_w2sigma / d.p_w2sigma:.4f}, peak at eta = {d.q_peak / d.p_peak:.4f}")
