"""Property tests (hypothesis) of the update at point A, over arbitrary strain increments:
the identities that must hold for every increment, not only the ones the other tests chose."""
import numpy as np
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from hmodel import update_full
from hmodel.probes import strain_probes

# derandomize: the examples follow from the test itself, so a CI run is reproducible (a random
# draw once found a case the bound had not foreseen, on one run in many)
settings.register_profile("hmodel", deadline=None, max_examples=60, derandomize=True,
                          suppress_health_check=[HealthCheck.function_scoped_fixture])
settings.load_profile("hmodel")

angle = st.floats(0.0, 360.0, allow_nan=False)
norm = st.floats(1e-8, 1e-4, allow_nan=False)


@given(a=angle, n=norm)
@example(a=302.0, n=1e-8)   # 1.1e-10 when the force increments were differences of states
def test_micro_macro_and_eulerian_split_hold_for_any_probe(params, state_A, a, n):
    pr = strain_probes(state_A, params, [a], norm=n)
    # Eq. 36 and Eq. 38 (compression-positive form): algebraic, to round-off
    assert abs(pr.w2[0] - pr.w2_hex[0]) < 1e-12
    assert abs(pr.w2[0] - (pr.w2_sigma[0] + pr.w2_V[0] + pr.w2_g[0])) < 1e-12
    # the contact sum, wherever no hexagon opens or closes during the probe: an identity of the
    # force increments and the linearized equilibrium, to round-off at any norm (3.4e-15 at
    # most over 180 directions at n = 1e-4, 1e-6, 1e-8) because the kernel takes the law's
    # increments directly (see hmodel/_kernels.py, the extras)
    if pr.n_open[0] == int(state_A.is_open.sum()):
        assert abs(pr.w2[0] - pr.w2_micro[0]) < 1e-12


@given(e=st.lists(st.floats(-1e-4, 1e-4, allow_nan=False), min_size=3, max_size=3),
       w=st.floats(-1e-4, 1e-4, allow_nan=False))
def test_only_the_symmetric_part_acts_and_input_is_untouched(params, state_A, e, w):
    de = np.array([[e[0], e[2]], [e[2], e[1]]])
    skew = np.array([[0.0, w], [-w, 0.0]])
    before = state_A.alpha.copy()
    a = update_full(state_A, de, params)
    b = update_full(state_A, de + skew, params)
    # equal up to the rounding of (e12 + w + e12 - w)/2, one ulp of the shear increment
    assert np.allclose(a.stress, b.stress, rtol=1e-12, atol=1e-12 * np.abs(a.stress).max())
    assert np.allclose(a.state.alpha, b.state.alpha, rtol=1e-13, atol=0)
    assert np.array_equal(state_A.alpha, before)
    # Coulomb is never exceeded and no closed contact carries tension
    s = a.state
    closed = ~s.is_open
    assert np.all(np.abs(s.T1[closed]) <= params.mu * s.N1[closed] * (1 + 1e-12) + 1e-15)
    assert np.all(s.N1[closed] >= 0) and np.all(s.N2[closed] >= 0)
