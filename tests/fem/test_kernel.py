"""fem._kernel (hmodel's update kernel with the sliding hexagons in the vectorized pass) gives
hmodel's bits: every output of the update, on elastic, sliding, opening and reclosing states,
through the FE adapter and through the kernels themselves (serial and parallel drivers)."""
import numpy as np
import pytest

from hmodel import HParams, broadcast_state, update_full, _kernels
from hmodel.driver import isotropic_state
from hmodel.material import kernel_args, _material_args, to_voigt
from fem import _kernel
from fem.adapter import MaterialField, strain_to_model, stress_to_fe, tangent_to_fe


def _bits(a):
    return np.ascontiguousarray(a).view(np.uint8)


def _path(npts, steps, seed):
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


def _kernel_outputs(kern, st, de, P, allow, fe):
    args = list(kernel_args(st, P)[:-1])
    if fe:
        args.insert(11, np.ascontiguousarray(st.sliding))
    out = _kernels.allocate_outputs(*args[0].shape)
    kern(*args, to_voigt(de), *_material_args(P), allow, False, *out)
    return out[:14]


@pytest.mark.parametrize("npts, n_dir", [(70, 180), (9, 36)])
def test_fe_kernel_bits(npts, n_dir):
    P = HParams(n_dir=n_dir)
    st = broadcast_state(isotropic_state(P), (npts,))
    pairs = ((_kernels.update_parallel, _kernel.fe_update_parallel),
             (_kernels.update_serial, _kernel.fe_update_serial))
    seen_slide = seen_open = seen_reclose = False
    for de in _path(npts, 16, seed=npts):
        for allow in (True, False):
            for ref, fe in pairs:
                a = _kernel_outputs(ref, st, de, P, allow, fe=False)
                b = _kernel_outputs(fe, st, de, P, allow, fe=True)
                for x, y in zip(a, b):
                    assert np.array_equal(_bits(x), _bits(y))
        new = update_full(st, de, P, extras=False).state
        seen_slide |= bool(new.sliding.any())
        seen_open |= bool(new.is_open.any())
        seen_reclose |= bool((st.is_open & ~new.is_open).any())
        st = new
    assert seen_slide and seen_open and seen_reclose       # every branch was exercised


def test_material_field_matches_update_full():
    """MaterialField.trial (fem._kernel, direct FE conversions) against hmodel.update_full +
    the adapter's conversions, two groups, trial after trial; held trials keep their values."""
    P = HParams(n_dir=72)
    Pw = P.replace(phi_g=15.0)
    npts = 80
    idx = [np.arange(0, npts, 3), np.setdiff1d(np.arange(npts), np.arange(0, npts, 3))]
    mf = MaterialField(npts, [(P, idx[1]), (Pw, idx[0])])
    keep = []
    for de_m in _path(npts, 12, seed=3):
        de_fe = strain_to_model(de_m)              # the relabelling and sign flip are involutions
        tr = mf.trial(de_fe)
        keep.append(tr)                            # held trials must keep their values
        for (params, ix), st, ns in zip(mf.groups, mf.states, tr.states):
            inc = update_full(st, de_m[:, :, ix], params, extras=False)
            assert np.array_equal(_bits(tr.sigma[:, :, ix]), _bits(stress_to_fe(inc.stress)))
            assert np.array_equal(_bits(tr.D[..., ix]), _bits(tangent_to_fe(inc.tangent)))
            assert np.array_equal(tr.sliding[ix], inc.state.sliding.mean(axis=-1))
            assert np.array_equal(tr.opened[ix], inc.state.is_open.mean(axis=-1))
            for f in inc.state._fields:
                x, y = getattr(inc.state, f), getattr(ns, f)
                if f == "params_key":
                    assert x == y
                else:
                    assert x.shape == y.shape and x.dtype == y.dtype
                    assert np.array_equal(_bits(x), _bits(y))
        mf.trial(0.5 * de_fe)                      # a discarded trial
        mf.commit(tr)
    snap = [[np.copy(s.d1) for s in t.states] for t in keep]
    view = mf.trial(0.3 * de_fe).states[0].N1[2:5]     # only a slice of a trial kept
    view0 = view.copy()
    for _ in range(5):
        mf.trial(strain_to_model(_path(npts, 2, seed=5)[1]))
    for t, s in zip(keep, snap):
        for st, d1 in zip(t.states, s):
            assert np.array_equal(st.d1, d1)       # no array of a live state is overwritten
    assert np.array_equal(view, view0)             # nor one a slice refers to
