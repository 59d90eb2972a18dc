"""The kernel's cached cos/sin of alpha and its vectorized common case (issue 2).

cos_alpha, sin_alpha are carried in the state (rotated by each small angle increment) and must
stay equal to cos(alpha), sin(alpha) to round-off; the common case (closed, elastic hexagons,
SIMD) and the general loop (every hexagon when extras=True) must give the same bits.
"""
import numpy as np

from hmodel import broadcast_state, update, update_full
from hmodel.material import HEX_FIELDS


def test_cos_sin_alpha_follow_alpha(drained):
    s = drained.state                       # 5000 steps, some hexagons opened and closed
    assert np.max(np.abs(s.cos_alpha - np.cos(s.alpha))) < 1e-13
    assert np.max(np.abs(s.sin_alpha - np.sin(s.alpha))) < 1e-13


def _increments(n, seed):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(3, n)) * 1e-5
    de = np.empty((2, 2, n))
    de[0, 0], de[1, 1] = v[0], v[1]
    de[0, 1] = de[1, 0] = v[2]
    return de


def test_common_case_same_bits_as_general_loop(params, iso_state, state_A, drained):
    for k, state in enumerate((iso_state, state_A, drained.state)):
        st = broadcast_state(state, (7,))
        de = _increments(7, seed=k)
        stress, tangent, new = update(st, de, params)                  # common case
        full = update_full(st, de, params)                              # general loop only
        assert np.array_equal(stress, full.stress)
        assert np.array_equal(tangent, full.tangent)
        for f in HEX_FIELDS + ("sliding", "is_open"):
            assert np.array_equal(getattr(new, f), getattr(full.state, f)), f
