"""The bifurcation domain's route (issue 19, part 4): the probes without the states and
tensors around the kernel, the sign check that stops refining once both signs are known, and
the Numba path with the states kept only for a block where a criterion fired. Each against
the general route it replaces, to the bit: the speed-up must not move the boundary."""
import numpy as np
import pytest

import hmodel.experiment as ex
from hmodel.driver import drained_biaxial, run_path
from hmodel.material import HEX_FIELDS, broadcast_state, to_voigt, update_copies, update_full
from hmodel.probes import _signs, directional_sweep, strain_probes, w2_vanishes


def _states(params, iso_state, eta_list):
    out = [iso_state]
    for eta in eta_list:
        r = run_path(iso_state, params, drained_biaxial(1e-5), 5000,
                     until=lambda e, s, eta=eta: (s[0] - s[1]) >= eta * 0.5 * (s[0] + s[1]))
        out.append(r.state)
    return out


@pytest.fixture(scope="module")
def states(params, iso_state):
    # eta 0.5 (elastic-plastic, far from W2 = 0), 0.99 and 0.995 (either side of the first
    # W2 = 0 of the directional analysis, 0.992 at 200 kPa), 0.998 (where, with 36 directions,
    # W2_sigma turns negative a refinement round before W2: a check that stopped at the first
    # sign would answer W2 > 0 there), 1.029 (point A, inside the cone)
    return _states(params, iso_state, (0.5, 0.99, 0.995, 0.998, 1.029))


def test_update_copies_is_update_full_of_copies(params, states):
    rng = np.random.default_rng(3)
    for st in states:
        for n in (5, 70):                                  # serial and parallel kernels
            de = 1e-6 * rng.standard_normal((n, 3))
            out = update_copies(st, de, params)
            d_eps = np.empty((2, 2, n))
            d_eps[0, 0], d_eps[1, 1] = de[:, 0], de[:, 1]
            d_eps[0, 1] = d_eps[1, 0] = de[:, 2]
            inc = update_full(broadcast_state(st, (n,)), d_eps, params)
            assert np.array_equal(out[12], to_voigt(inc.stress))
            assert np.array_equal(out[15], to_voigt(inc.dPi))
            assert np.array_equal(out[16], to_voigt(inc.T3), equal_nan=True)
            for k, f in enumerate(HEX_FIELDS):
                assert np.array_equal(out[k], getattr(inc.state, f).reshape(n, -1)), f
            assert np.array_equal(out[10], inc.state.sliding.reshape(n, -1))
            assert np.array_equal(out[17], inc.w2_micro_hex)


def test_update_copies_refuses_bad_input(params, states):
    with pytest.raises(ValueError, match="shape"):
        update_copies(states[0], np.zeros(3), params)
    with pytest.raises(ValueError, match="non-finite"):
        update_copies(states[0], np.full((2, 3), np.nan), params)
    with pytest.raises(ValueError, match="single-point"):
        update_copies(broadcast_state(states[0], (2,)), np.zeros((2, 3)), params)


def test_signs_are_the_probes_own(params, states):
    a = np.array([0.0, 45.0, 135.0, 200.0, 296.6, 300.0, 333.3])
    for st in states:
        full = strain_probes(st, params, a)
        lean = _signs(st, params, a)
        for f in ("alpha_eps", "alpha_sigma", "w2", "w2_sigma"):
            assert np.array_equal(getattr(lean, f), getattr(full, f), equal_nan=True), f


def test_w2_vanishes_is_the_full_sweeps_answer(params, states):
    answers = []
    for st in states:
        for n in (36, 180):
            sw = directional_sweep(st, params, n=n)
            ref = (bool(np.nanmin(sw.w2) <= 0.0), bool(np.nanmin(sw.w2_sigma) <= 0.0))
            assert w2_vanishes(st, params, n=n) == ref
            answers.append(ref)
    # the states cover both answers of both criteria (the test could catch a wrong sign)
    assert {a[0] for a in answers} == {True, False} and {a[1] for a in answers} == {True, False}


def test_domain_point_is_the_general_routes_to_the_bit(params, monkeypatch):
    """The default domain point at 200 kPa (180 probe directions, a check every 25 steps of
    1e-5) against the route before issue 19: every sweep a full ``directional_sweep``, every
    block of the path run step by step with its states."""
    fast = ex.domain_point(params, 200e3)

    def full_sweep_signs(st, p, n):
        sw = directional_sweep(st, p, n=n)
        return bool(np.nanmin(sw.w2) <= 0.0), bool(np.nanmin(sw.w2_sigma) <= 0.0)

    def step_by_step(*a, **k):
        k["keep_states"] = True
        return run_path(*a, **k)
    monkeypatch.setattr(ex, "w2_vanishes", full_sweep_signs)
    monkeypatch.setattr(ex, "run_path", step_by_step)
    ref = ex.domain_point(params, 200e3)
    assert np.isfinite(fast.p_w2) and np.isfinite(fast.p_w2sigma) and np.isfinite(fast.p_peak)
    assert tuple(fast) == tuple(ref)
