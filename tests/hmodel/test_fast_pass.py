"""The kernel's cached cos/sin of alpha and its vectorized fast pass.

cos_alpha, sin_alpha are carried in the state (rotated by each small angle increment) and must
stay equal to cos(alpha), sin(alpha) to round-off. The fast pass (``_kernels._fast_pass``: closed
hexagons, elastic or sliding, SIMD) and the general loop must give the same bits: with
``extras=True`` every hexagon goes through the general loop (the kernel computes the extras there
only), so ``extras=False`` against ``extras=True`` compares the two, on the stress, the tangent
and every field of the new state.
"""
import numpy as np
import pytest

from hmodel import HParams, broadcast_state, update, update_full, _kernels
from hmodel.driver import isotropic_state
from hmodel.material import HEX_FIELDS, kernel_args, _material_args, to_voigt


def _bits(a):
    return np.ascontiguousarray(a).view(np.uint8)


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


def test_fast_pass_same_bits_as_general_loop(params, iso_state, state_A, drained):
    for k, state in enumerate((iso_state, state_A, drained.state)):
        st = broadcast_state(state, (7,))
        de = _increments(7, seed=k)
        stress, tangent, new = update(st, de, params)                  # fast pass
        full = update_full(st, de, params)                              # general loop only
        assert np.array_equal(_bits(stress), _bits(full.stress))
        assert np.array_equal(_bits(tangent), _bits(full.tangent))
        for f in HEX_FIELDS + ("sliding", "is_open"):
            assert np.array_equal(_bits(getattr(new, f)), _bits(getattr(full.state, f))), f


def path_increments(npts, steps, seed):
    """Strain increments (steps, 2, 2, npts), compression +: a biaxial-like loading in random
    directions per point (axial compression, lateral extension, some shear), growing, with two
    reversals (unloading closes open hexagons again) and one large increment."""
    rng = np.random.default_rng(seed)
    base = np.zeros((2, 2, npts))
    base[0, 0] = 1.0
    base[1, 1] = rng.uniform(-0.9, 0.3, npts)
    base[0, 1] = base[1, 0] = rng.uniform(-0.3, 0.3, npts)
    out = []
    for k in range(steps):
        h = 2e-4 * (1 + k / 4)
        if k in (steps // 2, steps // 2 + 1):
            h = -3e-4                          # unloading
        if k == steps - 1:
            h = 5e-3                           # large rotations
        out.append(h * base)
    return out


def _kernel_outputs(kern, st, de, P, allow, extras):
    args = kernel_args(st, P)[:-1]
    out = _kernels.allocate_outputs(*args[0].shape)
    kern(*args, to_voigt(de), *_material_args(P), allow, extras, *out)
    return out[:14]             # new hexagon fields, sliding, open, stress, tangent


@pytest.mark.parametrize("npts, n_dir", [(70, 180), (9, 36)])
def test_fast_pass_bits_on_a_path(npts, n_dir):
    """Both drivers, sliding allowed or not, on elastic, sliding, opening and reclosing states:
    the fast pass (extras=False) gives the general loop's bits (extras=True); both variants of
    the fast pass (elastic, and sliding where a closed hexagon starts at the Coulomb limit) are
    exercised."""
    P = HParams(n_dir=n_dir)
    st = broadcast_state(isotropic_state(P), (npts,))
    seen_slide = seen_open = seen_reclose = False
    seen_elastic_pass = seen_sliding_pass = False
    for de in path_increments(npts, 16, seed=npts):
        closed = ~st.is_open
        at_limit = (closed & (np.abs(st.T1) >= P.mu * st.N1)).any(axis=-1)
        fast = 2 * closed.sum(axis=-1) >= n_dir
        seen_sliding_pass |= bool((fast & at_limit).any())
        seen_elastic_pass |= bool((fast & ~at_limit).any())
        for allow in (True, False):
            ref = _kernel_outputs(_kernels.update_serial, st, de, P, allow, extras=True)
            for kern in (_kernels.update_serial, _kernels.update_parallel):
                got = _kernel_outputs(kern, st, de, P, allow, extras=False)
                for x, y in zip(ref, got):
                    assert np.array_equal(_bits(x), _bits(y))
        new = update_full(st, de, P, extras=False).state
        seen_slide |= bool(new.sliding.any())
        seen_open |= bool(new.is_open.any())
        seen_reclose |= bool((st.is_open & ~new.is_open).any())
        st = new
    assert seen_slide and seen_open and seen_reclose       # every branch was exercised
    assert seen_elastic_pass and seen_sliding_pass
