"""The plane non-associated Drucker-Prager law (point.drucker_prager): elasticity, the exact
return mapping, its consistent tangent against finite differences, the rate tangent, unloading,
the apex refused, objectivity, the contract's shapes."""
import math

import numpy as np
import pytest

from point import MaterialError, ParamError, check_tangent, material_of
from point.closed_forms import det_D
from point.contract import check_update_output
from point.drucker_prager import DPParams, DPState, invariants, mechanism
from point.tensors import mandel_tangent, to_mandel

P = DPParams()
DP = material_of(P)


def _plastic_state(steps=120, d=(1e-4, -0.3e-4)):
    """A state on the loading branch: strain-controlled steps from the isotropic state."""
    s = DP.initial_state(P)
    inc = np.diag(d)
    for _ in range(steps):
        s = DP.update(s, inc, P)[2]
    assert bool(s.plastic)
    return s


def test_params_are_validated_naming_the_field():
    for field, bad in (("G", 0.0), ("nu", 0.5), ("mu0", 0.0), ("mu_p", 1.0), ("kappa_p", -1e-3),
                       ("mu_c", 0.0), ("p0", -1.0), ("G", math.nan), ("nu", "0.2")):
        with pytest.raises(ParamError) as e:
            P.replace(**{field: bad})
        assert e.value.name == field
    with pytest.raises(ParamError, match="mu0"):
        DPParams(mu0=0.6, mu_p=0.55)


def test_initial_state_and_elasticity():
    s = DP.initial_state(P, (3,))
    assert np.array_equal(s.stress[:, :, 1], P.p0 * np.eye(2))
    # sigma = E : eps from the stress-free state
    assert np.allclose(s.stress[:, :, 0], P.lam * np.trace(s.eps[:, :, 0]) * np.eye(2)
                       + 2 * P.G * s.eps[:, :, 0], rtol=1e-15, atol=0)
    d = np.zeros((2, 2, 3))
    d[:, :, 0] = [[1e-6, 2e-7], [2e-7, -3e-7]]
    stress, C, new = DP.update(s, d, P)
    E = P.elastic_mandel()
    assert np.allclose(mandel_tangent(C)[..., 0], E, rtol=1e-15, atol=0)
    assert not new.plastic.any()
    assert np.allclose(to_mandel(stress[:, :, 0]) - to_mandel(s.stress[:, :, 0]),
                       E @ to_mandel(d[:, :, 0]), rtol=1e-10, atol=0)
    # the plane bulk modulus: p = K2 tr(eps)
    assert P.K2 == pytest.approx(P.lam + P.G, rel=1e-15)


def test_return_mapping_is_exact_and_its_records_agree():
    """After a plastic step the stress is on the yield surface to round-off, kappa grew by the
    multiplier, the plastic strain has the direction Q and sigma = E : (eps - eps_p)."""
    s = _plastic_state()
    p, tau, n = invariants(s.stress)
    f = tau - P.mu(s.kappa) * p
    assert abs(float(f)) <= 1e-12 * float(p)
    s1 = DP.update(s, np.diag([1e-4, -0.3e-4]), P)[2]
    dl = float(s1.kappa - s.kappa)
    assert dl > 0
    beta = float(P.beta(s1.kappa))
    _, _, n1 = invariants(s1.stress)
    Q = n1 - 0.5 * beta * np.array([1.0, 1.0, 0.0])
    assert np.allclose(to_mandel(s1.eps_p - s.eps_p), dl * Q, rtol=1e-9, atol=1e-18)
    E = P.elastic_mandel()
    assert np.allclose(to_mandel(s1.stress), E @ to_mandel(s1.eps - s1.eps_p), rtol=1e-12, atol=1e-6)


@pytest.mark.parametrize("d", [(1e-4, -0.3e-4, 0.0), (2e-4, 1e-4, 5e-5), (1e-5, -1e-5, -3e-6),
                               (1e-3, -8e-4, 2e-4)])
def test_consistent_tangent_against_finite_differences(d):
    """Central differences of the returned stress, h = 1e-6 |d_eps|: truncation O(h^2),
    round-off ~ ulp |sigma| / h ~ 1e-10 of the tangent; measured 5e-9 at most."""
    s = _plastic_state()
    inc = np.array([[d[0], d[2]], [d[2], d[1]]])
    r = check_tangent(DP, s, P, inc)
    assert r.ok and r.error < 1e-6, r


def test_finite_difference_check_catches_a_wrong_tangent():
    """The check itself: the tangent's shear column scaled by 2 (a Mandel weight taken as 1)."""
    from point.contract import Material

    class Wrong(Material):
        name = "wrong"
        params_type = DPParams

        def update(self, state, d_eps, params):
            s, C, n = DP.update(state, d_eps, params)
            C = C.copy()
            C[..., 0, 1, :] *= 2.0
            C[..., 1, 0, :] *= 2.0
            return s, C, n
    s = _plastic_state()
    assert not check_tangent(Wrong(), s, P, np.diag([1e-4, -3e-5]) + 1e-5 * np.eye(2)[::-1]).ok


def test_rate_tangent_is_the_closed_form_and_the_limit_of_the_consistent_one():
    s = _plastic_state()
    d = np.diag([1.0, -0.3])
    D = mandel_tangent(DP.rate_tangent(s, d, P))
    m = mechanism(P, s)
    assert np.allclose(D, m.tangent(), rtol=1e-14, atol=1e-14 * P.G)
    assert np.linalg.det(D) == pytest.approx(float(det_D(m)), rel=1e-10)
    # D_alg(t d) -> D as t -> 0, to first order: the error halves with t
    errs = []
    for t in (1e-5, 5e-6, 2.5e-6):
        Da = mandel_tangent(DP.update(s, t * d, P)[1])
        errs.append(np.max(np.abs(Da - D)) / np.max(np.abs(D)))
    assert 1.8 < errs[0] / errs[1] < 2.2 and 1.8 < errs[1] / errs[2] < 2.2, errs


def test_unloading_is_elastic():
    s = _plastic_state()
    E = P.elastic_mandel()
    stress, C, new = DP.update(s, -np.diag([1e-5, -0.3e-5]), P)
    assert not bool(new.plastic)
    assert np.array_equal(mandel_tangent(C), E)
    assert np.array_equal(mandel_tangent(DP.rate_tangent(s, -np.diag([1.0, -0.3]), P)), E)
    assert float(new.kappa) == float(s.kappa)


def test_the_apex_is_refused():
    s = DP.initial_state(P)
    with pytest.raises(MaterialError, match="apex"):
        DP.update(s, -np.diag([0.02, 0.02]), P)


def test_objectivity_of_the_isotropic_law():
    """Rotating the state's tensors and the increment by R rotates the response: R sigma R^T and
    the tangent's components (a wrong shear weight breaks it)."""
    s = _plastic_state()
    d = np.array([[1e-4, 2e-5], [2e-5, -4e-5]])
    a = 0.37
    R = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    rot = lambda t: R @ t @ R.T                                               # noqa: E731
    sr = DPState(rot(s.eps), rot(s.stress), rot(s.eps_p), s.kappa, s.plastic)
    s1, C1, _ = DP.update(s, d, P)
    s2, C2, _ = DP.update(sr, rot(d), P)
    assert np.allclose(s2, rot(s1), rtol=1e-12, atol=1e-12 * P.p0)
    C1r = np.einsum("ia,jb,kc,ld,abcd->ijkl", R, R, R, R, C1)
    assert np.allclose(C2, C1r, rtol=1e-10, atol=1e-10 * P.G)


@pytest.mark.parametrize("batch", [(), (4,), (2, 3)])
def test_contract_shapes_and_the_state_is_not_modified(batch):
    s0 = DP.initial_state(P)
    s = DP.broadcast(_plastic_state(), batch) if batch else _plastic_state()
    keep = [np.copy(v) for v in s]
    rng = np.random.default_rng(1)
    d = rng.normal(scale=1e-4, size=(2, 2) + batch)
    out = DP.update(s, d, P)
    check_update_output(DP, s, d, out)
    for a, b in zip(keep, s):
        assert np.array_equal(a, b)
    assert s0.batch_shape == ()
    if batch:
        one = DP.take(s, [0])
        assert one.batch_shape == (1,)


def test_contract_check_names_the_material_and_what_failed():
    s = _plastic_state()
    d = np.diag([1e-4, 0.0])
    stress, C, new = DP.update(s, d, P)
    with pytest.raises(MaterialError, match="drucker-prager.*non-finite stress"):
        check_update_output(DP, s, d, (stress * np.nan, C, new))
    with pytest.raises(MaterialError, match="drucker-prager.*tangent of shape"):
        check_update_output(DP, s, d, (stress, C[..., 0], new))


def test_the_return_of_one_point_is_the_vectorized_one():
    """``_return_one`` (floats, the driver's single points) and the vectorized ``_return`` (a
    field's points): the same operations, the same bits, on 200 random plastic trials."""
    from point.drucker_prager import _return, _return_one
    rng = np.random.default_rng(0)
    pt = 3e5 + 1e5 * rng.random(200)
    tt = 0.56 * pt + 1e4 * rng.random(200)
    kn = 0.03 * rng.random(200)
    v = _return(P, pt, tt, kn)
    assert np.all(v > 0)
    assert np.array_equal(v, [_return_one(P, a, b, c) for a, b, c in zip(pt, tt, kn)])
