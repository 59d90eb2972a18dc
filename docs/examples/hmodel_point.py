"""The material point and its driver: one increment, then the drained biaxial test to point A.

Table I, 200 kPa; SI units, compression positive, tensors (11, 22, 12). docs/api.md.
"""
import numpy as np

from hmodel import HParams, update
from point.driver import drained_biaxial, isotropic_state, run_path, stress_invariants

P = HParams()                      # Table I (kn, kt [N/m], phi_g, alpha0 [deg], r_g [m], p0 [Pa])
s0 = isotropic_state(P)            # every hexagon compressed to p0 = 200 kPa

# one strain increment (2, 2) of the point: Cauchy stress (2, 2) [Pa], tangent (2, 2, 2, 2) [Pa]
d_eps = np.array([[1e-5, 0.0], [0.0, -0.3e-5]])
stress, tangent, s1 = update(s0, d_eps, P)    # s0 is not modified
print(f"after one increment: s11 = {stress[0, 0]:.1f} Pa, s22 = {stress[1, 1]:.1f} Pa, "
      f"D1111 = {tangent[0, 0, 0, 0]:.4g} Pa")

# the drained biaxial test (axial strain steps of 1e-5, s22 held) until eta = q/p >= 1.029
until_A = lambda eps, sig: stress_invariants(sig)[2] >= 1.029
r = run_path(s0, P, drained_biaxial(1e-5), 5000, until=until_A)
p, q, eta = r.invariants()         # arrays (n + 1,) [Pa, Pa, -]
print(f"point A: eps1 = {100 * r.eps[-1, 0]:.3f} %, p = {p[-1] / 1e3:.1f} kPa, "
      f"q = {q[-1] / 1e3:.1f} kPa, eta = {eta[-1]:.4f}, {r.n_sliding[-1]} sliding and "
      f"{r.n_open[-1]} open hexagons of {P.n_dir}")
state_A = r.state                  # the HState at A, for probes (hmodel_directions.py)
