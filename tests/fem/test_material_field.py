"""MaterialField.trial (hmodel's kernel called directly, direct FE conversions) gives
hmodel.update_full's bits, through the adapter's conversions, two groups, trial after trial."""
import numpy as np

from hmodel import HParams, update_full
from fem.adapter import MaterialField, strain_to_model, stress_to_fe, tangent_to_fe
from tests.hmodel.test_fast_pass import path_increments


def _bits(a):
    return np.ascontiguousarray(a).view(np.uint8)


def test_material_field_matches_update_full():
    """Held trials keep their values."""
    P = HParams(n_dir=72)
    Pw = P.replace(phi_g=15.0)
    npts = 80
    idx = [np.arange(0, npts, 3), np.setdiff1d(np.arange(npts), np.arange(0, npts, 3))]
    mf = MaterialField(npts, [(P, idx[1]), (Pw, idx[0])])
    keep = []
    for de_m in path_increments(npts, 12, seed=3):
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
        mf.trial(strain_to_model(path_increments(npts, 2, seed=5)[1]))
    for t, s in zip(keep, snap):
        for st, d1 in zip(t.states, s):
            assert np.array_equal(st.d1, d1)       # no array of a live state is overwritten
    assert np.array_equal(view, view0)             # nor one a slice refers to
