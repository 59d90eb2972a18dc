"""Global indicators of the homogeneous specimen against the material-point criteria under the
same mixed control (eps11 driven, sigma22 = p0, sigma12 = 0), step by step.

The bounds are rigorous, not fitted:
- K_s = sum_points w B^T D_s B with positive weights, so if D_s is positive definite at every
  point, K_s is positive definite whatever the BCs: the first lam_min(K_s) <= 0 cannot come
  before the first lam_min(D_s) <= 0 of the material point;
- a homogeneous mode is admissible in the FE (lateral stretch and simple shear with the platen
  displacement prescribed; also axial stretch with the platen force prescribed), so lam_min(K_s)
  goes <= 0 no later than the material block of those free components does;
- at the peak of q with the platen force prescribed, the homogeneous increment is a null vector
  of K_f (dF = 0 on every free dof): det K_f changes sign there, within one load step.
"""
import numpy as np
import pytest

from fem.reference import material_point_criteria


def _first(mask):
    k = np.flatnonzero(mask)
    return int(k[0]) if k.size else None


@pytest.fixture(scope="module")
def both(homogeneous_run, params36):
    c = homogeneous_run.curve
    n = len(c["step"]) - 1
    assert np.allclose(np.diff(c["eps1"]), 5e-4, rtol=1e-9)     # no cut-back: rows = steps
    mp = material_point_criteria(params36, 5e-4, n)
    return c, mp


def test_same_path(both):
    c, mp = both
    assert np.max(np.abs(c["q"] - mp["q"])) / 200e3 < 1e-8
    assert np.max(np.abs(c["s2"] - 200e3)) / 200e3 < 1e-9


def test_force_controlled_platen_matches_material_point(both):
    c, mp = both
    k_fe = _first(c["lam_min_ks_f"] <= 0)
    k_mp = _first(mp["lam_min_ds_force"][1:] <= 0) + 1
    assert k_fe is not None
    # both bounds together: the same step
    assert k_fe == k_mp
    # and the local indicator of every point fires at the same step (homogeneous specimen)
    assert _first(c["min_lam_Ds"] <= 0) == k_mp
    # sampled W2 sign agrees with the exact lam_min(D_s) sign at that step
    assert _first(c["min_w2_local"] <= 0) == k_mp


def test_limit_point_at_peak(both):
    c, mp = both
    k_det = _first(c["det_k_sign_f"] != c["det_k_sign_f"][0])
    k_peak = int(np.argmax(c["q"]))
    assert 0 < k_peak < len(c["q"]) - 1                          # the run passes the peak
    assert k_det is not None and abs(k_det - k_peak) <= 1
    k_mp_det = _first(np.sign(mp["det_force"][1:]) != np.sign(mp["det_force"][1])) + 1
    assert abs(k_det - k_mp_det) <= 1
    # Hill's criterion first: lam_min(K_s) <= 0 no later than the det K sign change
    assert _first(c["lam_min_ks_f"] <= 0) <= k_det


def test_displacement_controlled_platen_bounds(both):
    c, mp = both
    k_fe = _first(c["lam_min_ks"] <= 0)
    lower = _first(mp["lam_min_ds_force"][1:] <= 0) + 1
    upper = _first(mp["lam_min_ds_disp"][1:] <= 0)
    assert k_fe is not None and k_fe >= lower
    if upper is not None:
        assert k_fe <= upper + 1
    k_det = _first(c["det_k_sign"] != c["det_k_sign"][0])
    if k_det is not None:
        assert k_fe <= k_det
    # the inertia count agrees with the sign of the smallest eigenvalue wherever it is known
    known = c["n_neg_ks"] >= 0
    assert np.all((c["n_neg_ks"][known] > 0) == (c["lam_min_ks"][known] < 0))
    known = c["n_neg_ks_f"] >= 0
    assert np.all((c["n_neg_ks_f"][known] > 0) == (c["lam_min_ks_f"][known] < 0))


def test_global_second_order_work_sign(both):
    """du . dF of the converged increments: positive before the peak, negative after it (the
    displacement-driven platen does work dF1 d(delta))."""
    c, _ = both
    k_peak = int(np.argmax(c["q"]))
    w = c["w2_global_raw"][1:]
    assert np.all(w[:k_peak - 1] > 0)
    assert np.all(w[k_peak + 1:] < 0)
    assert np.allclose(c["w2_global_raw"], c["w2_ext_raw"], rtol=1e-6, atol=1e-12)


@pytest.mark.slow
def test_default_problem_table1(tmp_path):
    """The CLI default problem (10 x 20 quads, n_dir 180, d_eps1 1e-4 to 2.5 %): the perfect
    specimen follows the material point, its limit point is the material peak (2.09 %), and Hill's
    condition fires well before it."""
    from fem.biaxial import BiaxialConfig, run_biaxial
    from hmodel import HParams
    r = run_biaxial(BiaxialConfig(fields=False), tmp_path)
    c = r.curve
    mp = material_point_criteria(HParams(), 1e-4, len(c["step"]) - 1)
    assert np.max(np.abs(c["q"] - mp["q"])) / 200e3 < 1e-8
    ev = r.summary["events"]
    assert abs(ev["det_k_f"]["eps1"] - r.summary["material_point"]["eps1_peak"]) <= 2e-4
    assert ev["lam_min_ks_f"]["eps1"] < 0.6 * ev["det_k_f"]["eps1"]
    assert ev["lam_min_ks_f"]["row"] == _first(mp["lam_min_ds_force"][1:] <= 0) + 1
