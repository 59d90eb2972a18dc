"""The kernel's cached cos/sin of alpha and its vectorized fast pass.

cos_alpha, sin_alpha are carried in the state (rotated by each small angle increment) and must
stay equal to cos(alpha), sin(alpha) to round-off. The fast pass (``_kernels._fast_pass``: closed
hexagons, elastic or sliding, SIMD) and the general loop must give the same bits:
``_kernels.update_general`` sends every hexagon through the general loop, and the two drivers
(``update_serial``, ``update_parallel``), which take the fast pass wherever it applies (without
the extras), are compared with it on every one of the kernel's 20 outputs, extras on and off.
Equality is to the bit (no tolerance): the fast pass does the general loop's operations in the
same order by construction.
"""
import numpy as np
import pytest

from hmodel import HParams, broadcast_state, update_full, _kernels
from hmodel.driver import drained_biaxial, isotropic_state, run_path
from hmodel.material import kernel_args, _material_args, to_voigt

OUTPUTS = ("d1", "d2", "alpha", "N1", "T1", "N2", "l1", "l2", "cos_alpha", "sin_alpha", "sliding",
           "is_open", "stress", "tangent", "tangent_lagrangian", "dPi", "T3", "w2", "w2n", "w2t")
DRIVERS = (_kernels.update_serial, _kernels.update_parallel)


def _bits(a):
    return np.ascontiguousarray(a).view(np.uint8)


def test_cos_sin_alpha_follow_alpha(drained):
    s = drained.state                       # 5000 steps, some hexagons opened and closed
    assert np.max(np.abs(s.cos_alpha - np.cos(s.alpha))) < 1e-13
    assert np.max(np.abs(s.sin_alpha - np.sin(s.alpha))) < 1e-13


def _increments(n, seed, lo=1e-5, hi=1e-5):
    """n symmetric strain increments (2, 2, n) in random directions of (e11, e22, e12), norms
    log-uniform in [lo, hi]."""
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(3, n))
    v *= np.exp(rng.uniform(np.log(lo), np.log(hi), n)) / np.linalg.norm(v, axis=0)
    de = np.empty((2, 2, n))
    de[0, 0], de[1, 1] = v[0], v[1]
    de[0, 1] = de[1, 0] = v[2]
    return de


def _kernel_outputs(kern, st, de, P, allow, extras):
    args = kernel_args(st, P)[:-1]
    out = _kernels.allocate_outputs(*args[0].shape)
    kern(*args, to_voigt(de), *_material_args(P), allow, extras, *out)
    return out


def _assert_same_bits_as_general_loop(st, de, P):
    """Every output of both drivers equals the general loop's to the bit, extras on and off,
    sliding allowed or not."""
    for allow in (True, False):
        for extras in (True, False):
            ref = _kernel_outputs(_kernels.update_general, st, de, P, allow, extras)
            if extras:
                assert np.isfinite(ref[14]).all() and np.isfinite(ref[19]).all()   # computed
            for kern in DRIVERS:
                got = _kernel_outputs(kern, st, de, P, allow, extras)
                for name, x, y in zip(OUTPUTS, ref, got):
                    assert np.array_equal(_bits(x), _bits(y)), (kern, name, allow, extras)


def _passes(st, P):
    """(fast pass taken, its sliding variant taken) per point without the extras: the kernel's
    own rule, at least half the hexagons closed at the start, and a closed hexagon at the
    Coulomb limit."""
    closed = ~st.is_open
    at_limit = (closed & (np.abs(st.T1) >= P.mu * st.N1)).any(axis=-1)
    fast = 2 * closed.sum(axis=-1) >= P.n_dir
    return fast, fast & at_limit


def test_fast_pass_same_bits_as_general_loop(params, iso_state, state_A, drained):
    for k, state in enumerate((iso_state, state_A, drained.state)):
        st = broadcast_state(state, (70,))        # above PARALLEL_MIN_POINTS: both drivers
        _assert_same_bits_as_general_loop(st, _increments(70, seed=k, lo=1e-9, hi=1e-3), params)
    # the update_full of the probes: the general loop's extras
    st = broadcast_state(state_A, (7,))
    de = _increments(7, seed=9)
    full = update_full(st, de, params)
    ref = _kernel_outputs(_kernels.update_general, st, de, params, True, True)
    assert np.array_equal(_bits(full.w2_micro_hex), _bits(ref[17]))
    assert np.array_equal(_bits(to_voigt(full.dPi)), _bits(ref[15]))


def test_fast_pass_over_many_states_and_increments():
    """Twenty-two states of a drained path to eps1 = 6 %, past its peak (every 0.05 % to 0.5 %,
    then every 0.5 %; 72 orientations: elastic, sliding and open hexagons), 64 points each with increments of norms 1e-9 to 1e-3
    in random directions: every output to the bit; both variants of the pass (elastic, sliding)
    are taken."""
    P = HParams(n_dir=72)
    r = run_path(isotropic_state(P), P, drained_biaxial(1e-4), 600, keep_states=True)
    seen_elastic = seen_sliding = False
    for k, state in enumerate(r.states[j] for j in [*range(0, 50, 5), *range(50, 601, 50)]):
        st = broadcast_state(state, (64,))
        fast, sliding = _passes(st, P)
        seen_elastic |= bool((fast & ~sliding).any())
        seen_sliding |= bool(sliding.any())
        _assert_same_bits_as_general_loop(st, _increments(64, seed=100 + k, lo=1e-9, hi=1e-3), P)
    assert seen_elastic and seen_sliding


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


@pytest.mark.parametrize("npts, n_dir", [(70, 180), (9, 36)])
def test_fast_pass_bits_on_a_path(npts, n_dir):
    """Both drivers, sliding allowed or not, extras or not, on elastic, sliding, opening,
    reclosing and mostly open states: every output is the general loop's, to the bit; both
    variants of the fast pass (elastic, and sliding where a closed hexagon starts at the
    Coulomb limit) are exercised."""
    P = HParams(n_dir=n_dir)
    st = broadcast_state(isotropic_state(P), (npts,))
    seen_slide = seen_open = seen_reclose = False
    seen_elastic_pass = seen_sliding_pass = False
    for de in path_increments(npts, 16, seed=npts):
        fast, sliding = _passes(st, P)
        seen_sliding_pass |= bool(sliding.any())
        seen_elastic_pass |= bool((fast & ~sliding).any())
        _assert_same_bits_as_general_loop(st, de, P)
        new = update_full(st, de, P, extras=False).state
        seen_slide |= bool(new.sliding.any())
        seen_open |= bool(new.is_open.any())
        seen_reclose |= bool((st.is_open & ~new.is_open).any())
        st = new
    assert seen_slide and seen_open and seen_reclose       # every branch was exercised
    assert seen_elastic_pass and seen_sliding_pass
