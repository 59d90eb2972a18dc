"""The directional analysis at point A against the paper's statements (section 3.3-3.4):
plastic tensorial zone for alpha_sigma between about 70 and 250 deg; instability cone (W2 <= 0)
in the third quadrant (d sigma1 < 0, d sigma2 < 0), larger for W2_sigma than for W2; W2n > 0
everywhere; W2t < 0 where W2 vanishes; elastic zone positive definite."""
import numpy as np
import pytest

from hmodel.probes import min_w2, stress_probes, strain_probes, tangent_criteria


def _arc(alpha, mask):
    a = np.sort(np.asarray(alpha)[mask])
    return a[0], a[-1]


def test_plastic_zone_matches_paper(sweep_A):
    lo, hi = _arc(sweep_A.alpha_sigma, sweep_A.plastic)
    # the paper reads "alpha_sigma ranging between 70 and 250 deg" off its Figs. 6-7: +-10 deg
    assert 60 <= lo <= 80 and 240 <= hi <= 260
    # one contiguous arc: every probe between the ends is plastic, every probe outside elastic
    inside = (sweep_A.alpha_sigma >= lo) & (sweep_A.alpha_sigma <= hi)
    assert np.array_equal(inside, sweep_A.plastic)


def test_instability_cone_in_third_quadrant(sweep_A):
    neg = sweep_A.w2 <= 0
    assert neg.any()
    ds = sweep_A.d_sigma[neg]
    assert np.all(ds[:, 0] < 0) and np.all(ds[:, 1] < 0)            # d sigma1 < 0, d sigma2 < 0
    lo, hi = _arc(sweep_A.alpha_sigma, neg)
    assert 180 < lo < hi < 270
    # the cone of W2_sigma is more developed (Fig. 9) and contains the W2 cone
    ls, hs = _arc(sweep_A.alpha_sigma, sweep_A.w2_sigma <= 0)
    assert ls < lo and hs >= hi - 1e-9
    # the cone lies inside the plastic zone, close to its border (paper, Fig. 9)
    assert sweep_A.plastic[neg].all()


def test_normal_part_positive_tangential_negative_in_cone(sweep_A):
    assert np.all(sweep_A.w2n > 0)                                   # Fig. 11: W2n > 0 always
    neg = sweep_A.w2 <= 0
    assert np.all(sweep_A.w2t[neg] < 0)                              # W2t drives W2 below zero


def test_elastic_zone_positive(sweep_A):
    el = ~sweep_A.plastic
    assert np.all(sweep_A.w2[el] > 0.5)


def test_min_w2_and_tangent_criteria(params, state_A, iso_state, sweep_A):
    w, a = min_w2(state_A, params, sweep=sweep_A)
    assert w < 0 and 180 < a < 270
    w0, _ = min_w2(iso_state, params, n=72)
    assert w0 > 0                                    # the isotropic state is stable
    tc = tangent_criteria(state_A, params)
    # before the peak: det(M) > 0 but the symmetric part is no longer positive definite
    assert tc["det_M_cauchy"] > 0 and tc["det_Msym_cauchy"] < 0


def test_stress_probes_hit_direction_and_norm(params, state_A, sweep_A):
    targets = np.array([0.0, 45.0, 90.0, 135.0, 200.0, 245.0, 300.0])
    sp = stress_probes(state_A, params, targets, sigma_norm=2.5e3, sweep=sweep_A)
    ok = sp.n_solutions > 0
    assert ok.sum() >= 6
    got = sp.probe.alpha_sigma[ok]
    err = (got - targets[ok] + 180) % 360 - 180
    # the bisection resolves the direction to 1e-6 deg (tol_deg)
    assert np.all(np.abs(err) < 1e-6)
    nrm = np.linalg.norm(sp.probe.d_sigma[ok][:, :2], axis=1)
    assert np.allclose(nrm, 2.5e3, rtol=1e-12)
    # the plastic-zone targets need far larger strains than the elastic ones (soft response)
    de = np.linalg.norm(sp.probe.d_eps[ok][:, :2], axis=1)
    assert de[sp.probe.plastic[ok].astype(bool)].min() > 2 * de[~sp.probe.plastic[ok].astype(bool)].max()
    assert set(np.unique(sp.status)) <= {"unique", "multiple", "none"}
    assert np.all((sp.status == "unique") == (sp.n_solutions == 1))


def test_probe_pattern_decided_by_probe_not_path(params, state_A):
    """Opposite probes from the same state: loading slides, unloading is elastic."""
    pr = strain_probes(state_A, params, [300.0, 120.0])      # (de1 > 0, de2 < 0) and its reverse
    assert pr.plastic[0] and not pr.plastic[1]


def test_bad_probe_input(params, state_A, iso_state):
    with pytest.raises(ValueError, match="norm"):
        strain_probes(state_A, params, [0.0], norm=0.0)
    with pytest.raises(ValueError, match="finite"):
        strain_probes(state_A, params, [np.nan])
