import numpy as np
import pytest

from hmodel.driver import (MixedControl, MixedControlError, drained_biaxial, isotropic_compression,
                           mixed_step, proportional_strain, run_path, undrained_biaxial)


def test_isotropic_state(params, iso_state):
    s = iso_state.stress
    assert np.allclose(s, params.p0 * np.eye(2), rtol=0, atol=1e-9 * params.p0)
    assert not iso_state.sliding.any() and not iso_state.is_open.any()
    # isotropic fabric and state: every hexagon alike
    assert np.ptp(iso_state.N1) < 1e-12 * iso_state.N1.max()


def test_drained_path_peak_then_softening_and_point_A_before_peak(drained):
    p, q, eta = drained.invariants()
    k = int(np.argmax(q))
    assert 0.005 < drained.eps[k, 0] < 0.045                 # an interior peak
    assert q[-1] < 0.95 * q[k]                               # softening after it
    kA = int(np.argmax(eta >= 1.029))
    assert eta[kA] >= 1.029 and 0 < kA < k                   # eta = 1.029 reached before the peak
    # the lateral stress is held (mixed control) and the shear strain stays zero
    assert np.max(np.abs(drained.sigma[:, 1] - 200e3)) < 1e-10 * 200e3 * 10
    assert np.all(drained.eps[:, 2] == 0)
    # contractant then dilatant (Fig. 5): eps_v rises, then falls below zero
    ev = drained.eps[:, 0] + drained.eps[:, 1]
    assert ev.max() > 0 and ev[-1] < 0


def test_numba_path_equals_step_by_step(params, iso_state):
    a = run_path(iso_state, params, drained_biaxial(1e-5), 400)
    b = run_path(iso_state, params, drained_biaxial(1e-5), 400, keep_states=True)
    assert np.array_equal(a.sigma, b.sigma) and np.array_equal(a.eps, b.eps)
    assert np.array_equal(a.state.alpha, b.states[-1].alpha)


def test_until_stops_at_first_step(params, iso_state):
    r = run_path(iso_state, params, drained_biaxial(1e-5), 5000, chunk=97,
                 until=lambda e, s: e[0] >= 0.00123 - 1e-12)
    assert len(r.eps) == 124 and np.isclose(r.eps[-1, 0], 0.00123)
    assert np.array_equal(r.state.stress, np.array([[r.sigma[-1, 0], r.sigma[-1, 2]], [r.sigma[-1, 2], r.sigma[-1, 1]]]))


def test_general_mixed_control_reaches_stress_targets(params, iso_state):
    # stress-controlled on 22 and 12 (with a shear stress ramp), strain on 11
    ctl = MixedControl(strain_controlled=(True, False, False), d_eps=(1e-5, 0, 0), d_sigma=(0, -200.0, 150.0))
    r = run_path(iso_state, params, ctl, 200)
    k = np.arange(len(r.sigma))
    assert np.allclose(r.sigma[:, 1], 200e3 - 200.0 * k, rtol=0, atol=1e-4)
    assert np.allclose(r.sigma[:, 2], 150.0 * k, rtol=0, atol=1e-4)
    assert np.any(r.eps[:, 2] != 0)


def test_undrained_and_proportional_paths(params, iso_state):
    r = run_path(iso_state, params, undrained_biaxial(1e-5), 300)
    assert np.allclose(r.eps[:, 0] + r.eps[:, 1], 0, atol=1e-15)
    p, q, _ = r.invariants()
    assert q[-1] > 0
    r2 = run_path(iso_state, params, proportional_strain(1e-5, -0.25), 100)
    assert np.allclose(r2.eps[:, 1], -0.25 * r2.eps[:, 0])


def test_isotropic_compression_stress_control(params):
    r = isotropic_compression(params, 150e3)
    assert np.allclose(r.sigma[-1], [150e3, 150e3, 0], atol=1e-6)


def test_non_convergence_is_an_error_not_a_wrong_answer(params, iso_state, monkeypatch):
    ctl = drained_biaxial(1e-3)
    with pytest.raises(MixedControlError, match="did not converge"):
        mixed_step(iso_state, params, ctl, [0, 200e3, 0], max_iter=1)
    # a path whose step the decision can neither solve nor exclude: an error carrying what had
    # converged (tests/hmodel/test_controllability.py: the steps it does decide)
    import hmodel.driver as drv
    from hmodel.controllability import Verdict
    nan2 = (np.nan, np.nan)
    monkeypatch.setattr(drv, "decide", lambda *a, **k: Verdict(
        "unresolved", 1, 0.0, 1.0, 0.0, 0.0, nan2, nan2, nan2, 0.032, 801, {}, np.nan))
    r0 = run_path(iso_state, params, drained_biaxial(1e-5), 5)
    with pytest.raises(MixedControlError, match="none excluded") as e:
        run_path(r0.state, params, MixedControl((True, False, True), (1e-4, 0, 0), (0, -1e9, 0)), 50)
    assert e.value.partial is not None and len(e.value.partial.eps) == 1


@pytest.mark.parametrize("bad", [0.0, float("nan"), float("inf")])
def test_bad_path_input(bad):
    with pytest.raises(ValueError, match="d_eps1"):
        drained_biaxial(bad)
    with pytest.raises(ValueError):
        MixedControl(d_eps=(bad if bad != 0 else float("nan"), 0, 0))
