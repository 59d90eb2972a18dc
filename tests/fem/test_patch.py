"""Patch test: the perfect specimen follows the material-point driver at every step.

Why 1e-8: both sides solve the same equations (the homogeneous field is exactly representable by
bilinear / linear elements, and the lateral pressure acts on the initial faces, which is what the
material point's s22 = const means in small strain), each to a Newton tolerance of 1e-10 relative;
round-off of the B-matrix strains is ~1e-16. The only way to exceed 1e-8 is a real discrepancy
(sign, axis relabelling, BCs, load increments, a state committed from a non-converged iterate).
"""
import numpy as np
import pytest

from hmodel.driver import isotropic_state, run_path, drained_biaxial
from fem.adapter import stress_to_model, strain_to_model
from fem.mesh import rectangle
from fem.problem import Biaxial
from fem.solver import LoadStepper

D_EPS1 = 5e-4


@pytest.mark.parametrize("kind,nx,ny", [("quad", 2, 4), ("tri", 2, 3)])
def test_patch_follows_driver(params36, kind, nx, ny):
    n = 60                                               # to eps1 = 3 %, past the peak (~2.46 %)
    ref = run_path(isotropic_state(params36), params36, drained_biaxial(D_EPS1), n)
    prob = Biaxial(rectangle(0.05, 0.1, nx, ny, kind), params36)
    rows = []

    def on_step(res, info):
        s = stress_to_model(res.trial.sigma)             # (2, 2, npts), compression +
        e = strain_to_model(prob.strain(stepper.u))
        s1_platen = -prob.platen_force(res.f_int) / prob.width
        rows.append((stepper.eps1, s1_platen, s, e))

    stepper = LoadStepper(prob, D_EPS1)
    stepper.run(n * D_EPS1, on_step)
    assert len(rows) == n
    p0 = params36.p0
    worst = 0.0
    for k, (eps1, s1, s, e) in enumerate(rows, start=1):
        assert eps1 == pytest.approx(ref.eps[k, 0], abs=1e-14)
        sig_ref = ref.sigma[k]
        # every quadrature point: axial, lateral and shear stress
        for comp, (i, j) in enumerate(((0, 0), (1, 1), (0, 1))):
            err = np.max(np.abs(s[i, j] - sig_ref[comp])) / p0
            worst = max(worst, err)
            assert err < 1e-8, (k, comp, err)
        # the platen reaction gives the same axial stress
        assert abs(s1 - sig_ref[0]) / p0 < 1e-8
        # lateral strain at every point equals the driver's
        assert np.max(np.abs(e[1, 1] - ref.eps[k, 1])) < 1e-10
    # the path does pass the peak, so sliding, unloading and softening are all covered
    q = ref.sigma[:, 0] - ref.sigma[:, 1]
    assert 0 < np.argmax(q) < n


def test_initial_state_in_equilibrium(params36):
    prob = Biaxial(rectangle(0.05, 0.1, 3, 5), params36)
    f = prob.internal_force(prob.material.stress())
    r = (f - prob.f_lat)[prob.free]
    assert np.linalg.norm(r) / (params36.p0 * prob.height) < 1e-13
    # the lateral load is the confining pressure times the face length, on each side
    assert np.sum(prob.f_lat[prob.basis.nodal_dofs[0]][prob.mesh.p[0] < 1e-12]) == pytest.approx(
        params36.p0 * prob.height, rel=1e-12)
