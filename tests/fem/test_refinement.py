"""Mesh refinement leaves the pre-bifurcation response unchanged.

Non-homogeneous specimen: a horizontal weak layer (phi_g 17 deg instead of 20) of two coarse
element rows through mid-height, the same region on every mesh (band edges on element edges), so
only the discretization changes. Before any bifurcation indicator fires the fields are smooth and
the load-displacement response converges with h: we assert the q(eps1) curves of the two meshes
agree within 2e-3 relative (measured: 6.6e-4 for 2x8 vs 4x16, 1.3e-3 and 6.5e-4 for 2x8 and 4x16
vs 8x32: the difference halves per refinement, first order, since the material jump at the layer
and the sliding pattern make the fields only piecewise smooth), and (slow test) that the finer
mesh is closer to the finest one.
"""
import numpy as np
import pytest

from fem.mesh import rectangle
from fem.problem import Biaxial, Imperfection
from fem.solver import LoadStepper


def _curve(params, nx, ny, eps1_max, d=5e-4):
    # half-width 0.24 * width = 12 mm from mid-height: the element rows whose centroids lie within
    # it make the same layer [37.5, 62.5] mm on the ny = 8, 16 and 32 meshes
    prob = Biaxial(rectangle(0.05, 0.1, nx, ny), params,
                   imperfection=Imperfection("band", size=0.24, phi_g=17.0, angle=0.0))
    q = []

    def on_step(res, info):
        s1 = -prob.platen_force(res.f_int) / prob.width
        q.append(s1 - params.p0)

    LoadStepper(prob, d).run(eps1_max, on_step)
    return np.array(q), prob


def _perfect(params, eps1_max, d=5e-4):
    prob = Biaxial(rectangle(0.05, 0.1, 1, 2), params)
    q = []
    LoadStepper(prob, d).run(eps1_max, lambda res, info: q.append(
        -prob.platen_force(res.f_int) / prob.width - params.p0))
    return q


def test_refinement_pre_bifurcation(params36):
    eps1_max = 0.006      # before the first lam_min(D_s) <= 0 of the weak material (~0.9 %)
    qa, pa = _curve(params36, 2, 8, eps1_max)
    qb, pb = _curve(params36, 4, 16, eps1_max)
    # the weak region is the same on both meshes
    assert pb.weak_elements.size == 4 * pa.weak_elements.size == 4 * 2 * 2
    # the layer matters: the response differs from the perfect specimen's far more than meshes do
    qp = np.array(_perfect(params36, eps1_max))
    d_ab = np.max(np.abs(qa - qb) / np.abs(qb))
    assert np.max(np.abs(qb - qp) / np.abs(qp)) > 10 * d_ab
    print("max relative difference of q, 2x8 vs 4x16:", d_ab)
    assert d_ab < 2e-3


@pytest.mark.slow
def test_refinement_three_meshes(params36):
    eps1_max = 0.006
    qa, _ = _curve(params36, 2, 8, eps1_max)
    qb, _ = _curve(params36, 4, 16, eps1_max)
    qc, _ = _curve(params36, 8, 32, eps1_max)
    d_ab = np.max(np.abs(qa - qc) / np.abs(qc))
    d_bc = np.max(np.abs(qb - qc) / np.abs(qc))
    print("differences to the 8x32 mesh:", d_ab, d_bc)
    assert d_bc < d_ab and d_bc < 1e-3
