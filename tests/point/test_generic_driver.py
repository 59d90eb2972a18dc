"""The driver's generic Newton (``point.mixed._newton``, what every law without a fast path
uses) against the H-model's Numba kernel (``mixed_step_single``, the same algorithm, tested for
years of this project), and its convergence on the Drucker-Prager law: with the consistent
tangent and the block of the free variables taken from the right rows and columns, Newton
converges in a few iterations (quadratically); a block from the wrong rows is singular or
converges slowly."""
import numpy as np
import pytest

from hmodel import HParams
from point import material_of
from point.driver import (MixedControl, drained_biaxial, isotropic_state, mixed_step,
                          proportional_strain, proportional_strain_stress, run_path)
from point.drucker_prager import DPParams
from point.mixed import _newton
from point.tensors import to_voigt

CONTROLS = [drained_biaxial(1e-5), proportional_strain_stress(-2.0, 100.0),
            MixedControl((False, False, True), (0, 0, 0), (300.0, -100.0, 0.0)),
            MixedControl((True, False, False), (1e-5, 0, 0), (0.0, 0.0, 0.0))]


@pytest.fixture(scope="module")
def hmodel_state():
    P = HParams(n_dir=36)
    s = run_path(isotropic_state(P), P, drained_biaxial(1e-5), 300).state
    return P, s


@pytest.mark.parametrize("k", range(len(CONTROLS)))
def test_the_generic_newton_is_the_kernel(hmodel_state, k):
    """The same iterations and the same increment (to the round-off of a different order of
    operations: 1e-12 of the increment) as the H-model's kernel, on the H-model."""
    P, s = hmodel_state
    ctl = CONTROLS[k]
    law = material_of(P)
    general, A, Ainv = ctl.matrices()
    sig = to_voigt(s.stress)[0]
    s0 = ctl.to_controlled(v_stress=sig) if general else sig
    target = s0 + np.asarray(ctl.d_sigma)
    tol = 1e-10 * max(float(np.max(np.abs(target))), 1e-3 * P.p0)
    it_f, rn_f, inc_f, de_f = law.mixed_step_fast(s, P, ctl, target, None, tol, 40)
    it_g, rn_g, inc_g, de_g = _newton(law, s, P, ctl, target, None, tol, 40)
    assert it_f == it_g and it_f > 0
    assert np.allclose(de_g, de_f, rtol=0, atol=1e-12 * np.max(np.abs(de_f)))
    assert np.allclose(inc_g.stress, inc_f.stress, rtol=1e-12, atol=0)


@pytest.mark.parametrize("k", range(len(CONTROLS)))
def test_newton_converges_quadratically_on_drucker_prager(k):
    P = DPParams()
    # a plastic state by strain control alone (no Newton: the test must not need what it tests)
    s = run_path(isotropic_state(P), P, proportional_strain(1e-5, -0.3), 400).state
    assert bool(s.plastic)
    ctl = CONTROLS[k]
    general, _, _ = ctl.matrices()
    sig = to_voigt(s.stress)[0]
    s0 = ctl.to_controlled(v_stress=sig) if general else sig
    _, _, it = mixed_step(s, P, ctl, s0 + np.asarray(ctl.d_sigma))
    assert 1 <= it <= 4, it
