"""The tangent returned with an increment is the exact derivative of the returned stress.

Central finite differences with h = 1e-11 on increments of size ~1e-5: the round-off error of a
stress of ~5e5 Pa is ~1e-10 Pa, i.e. ~5 Pa per unit strain after dividing by 2h, against tangent
entries of ~1e8 Pa: relative 1e-7 at worst, so the required 1e-6 has a margin of 10 and would
still catch a missing term (the smallest physical terms, the volume change, are ~1e-3 relative).
The patterns at +h and -h are checked to be the same (else the FD would straddle a switch).
"""
import numpy as np

from hmodel import broadcast_state, update, update_full
from hmodel.material import to_voigt

H = 1e-11
COMPONENTS = ((0, 0), (1, 1), (0, 1))


def _voigt_tangent(C):
    """(2,2,2,2,*b) -> (npts, 3, 3) d sigma_a / d v_b (v = e11, e22, e12 with e12 = e21)."""
    npts = int(np.prod(C.shape[4:], dtype=int))
    C = C.reshape(2, 2, 2, 2, npts)
    T = np.empty((npts, 3, 3))
    for a, (i, j) in enumerate(COMPONENTS):
        for b, (k, l) in enumerate(COMPONENTS):
            T[:, a, b] = C[i, j, k, l] + (C[i, j, l, k] if k != l else 0.0)
    return T


def _fd_check(state, de, params, field="stress", tangent="tangent", H=H):
    inc = update_full(state, de, params)
    T = _voigt_tangent(getattr(inc, tangent))
    batch = state.batch_shape
    for b, (k, l) in enumerate(COMPONENTS):
        E = np.zeros((2, 2) + batch)
        E[k, l] = E[l, k] = H          # v_b = e_kl = e_lk moves by H
        ip = update_full(state, de + E, params)
        im = update_full(state, de - E, params)
        for f in ("sliding", "is_open"):
            assert np.array_equal(getattr(ip.state, f), getattr(inc.state, f))
            assert np.array_equal(getattr(im.state, f), getattr(inc.state, f))
        fd = (to_voigt(getattr(ip, field)) - to_voigt(getattr(im, field))) / (2 * H)
        an = T[:, :, b]
        err = np.linalg.norm(fd - an, axis=1)
        scale = np.linalg.norm(T, axis=(1, 2))
        assert np.all(err <= 1e-6 * scale), (b, err / scale)
    return inc


def _increments(batch, scale=1e-5, seed=0):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(3,) + batch) * scale
    de = np.empty((2, 2) + batch)
    de[0, 0], de[1, 1] = v[0], v[1]
    de[0, 1] = de[1, 0] = v[2]
    return de


def test_elastic_pattern(params, iso_state):
    de = 1e-7 * np.array([[1.0, 0.3], [0.3, -0.5]])
    inc = _fd_check(iso_state, de, params)
    assert not inc.state.sliding.any() and not inc.state.is_open.any()
    _fd_check(iso_state, de, params, field="dPi", tangent="tangent_lagrangian")


def test_sliding_and_mixed_patterns_with_shear(params, state_A):
    batch = (6,)
    st = broadcast_state(state_A, batch)
    de = _increments(batch)
    de[0, 0] = np.abs(de[0, 0])         # include loading directions
    inc = _fd_check(st, de, params)
    n_sl = inc.state.sliding.sum(axis=-1)
    assert np.any(n_sl > 0)
    # mixed: sliding, elastic and open hexagons in the same points
    assert np.any((n_sl > 0) & (n_sl < params.n_dir))
    assert inc.state.is_open.any()
    _fd_check(st, de, params, field="dPi", tangent="tangent_lagrangian")


def test_opening_and_closing_hexagons(params, drained):
    s = drained.state                                    # eps1 = 5 %: many hexagons open
    assert s.is_open.sum() > 50
    de = np.array([[1e-3, 1e-4], [1e-4, 1.2e-3]])        # recompaction closes some of them
    inc = update_full(s, de, params)
    closing = s.is_open & ~inc.state.is_open
    assert closing.any(), "the recompaction must close some hexagons for this test to mean something"
    # The closing angle is the root of f(a) = 2r(1 - cos a) - l1 + 1.5 l2 cot a, whose evaluation
    # cancels terms of ~1e-3 m: the stress then carries a ~1e-14 relative noise that central
    # differences amplify by 1/H, so H is 1e-8 here (truncation error O(H^2) is still negligible
    # against the 1e-3 increment).
    _fd_check(s, de, params, H=1e-8)


def test_update_is_pure_and_batched(params, state_A):
    before = [np.copy(a) for a in state_A]
    st = broadcast_state(state_A, (2, 3))
    de = _increments((2, 3), seed=3)
    stress, tangent, new = update(st, de, params)
    assert stress.shape == (2, 2, 2, 3) and tangent.shape == (2, 2, 2, 2, 2, 3)
    assert new.d1.shape == (2, 3, params.n_dir)
    for a, b in zip(before, state_A):
        assert np.array_equal(a, b)
    # each point of the batch equals the same point computed alone
    for i in range(2):
        for j in range(3):
            s1, t1, _ = update(state_A, de[:, :, i, j], params)
            assert np.array_equal(s1, stress[:, :, i, j])
            assert np.array_equal(t1, tangent[..., i, j])


def test_tangent_minor_symmetry_and_no_rigid_rotation_effect(params, state_A):
    de = np.array([[1e-5, 2e-6], [2e-6, -1e-5]])
    stress, C, _ = update(state_A, de, params)
    assert np.allclose(C, C.transpose(1, 0, 2, 3)) and np.allclose(C, C.transpose(0, 1, 3, 2))
    W = np.array([[0.0, 3e-6], [-3e-6, 0.0]])          # a skew part is not a strain
    s2, _, _ = update(state_A, de + W, params)
    assert np.array_equal(stress, s2)
