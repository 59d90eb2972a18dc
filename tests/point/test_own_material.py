"""The law written as a user would (docs/examples/own_material.py) runs through the toolkit, and
the probes of a law without the H-model's extras are exact where the law makes them so: the
hypoplastic increment d sigma = L:d eps + N |d eps| is homogeneous of degree 1 in d eps, so a
probe of any size gives the rate response itself."""
import importlib.util
from pathlib import Path

import numpy as np
import pytest

from point import check_tangent, material_of
from point.experiment import biaxial_test, domain_point
from point.probes import directional_sweep, strain_probes

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def example():
    """The example's module; its law registered for this module's tests only (a law left
    registered would be offered by every command line the later tests build)."""
    from point import contract
    spec = importlib.util.spec_from_file_location("own_material", ROOT / "docs/examples/own_material.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    yield mod
    contract.MATERIALS.pop(mod.HYPOPLASTIC.name, None)


@pytest.fixture(scope="module")
def loaded(example):
    P = example.HypoParams()
    return P, biaxial_test(P, d_eps1=1e-4, eps1_max=0.01).state


def test_the_law_is_found_from_its_record(example):
    assert material_of(example.HypoParams()).name == "hypoplastic-plane"


@pytest.mark.parametrize("d", [(1e-4, -3e-5, 0.0), (-2e-5, 1e-5, 4e-6), (1e-5, 1e-5, 1e-5)])
def test_its_tangent_agrees_with_its_stress(example, loaded, d):
    P, s = loaded
    r = check_tangent(example.HYPOPLASTIC, s, P, np.array([[d[0], d[2]], [d[2], d[1]]]))
    assert r.ok and r.error < 1e-6, r


def test_probes_of_a_law_without_extras_are_its_response(example, loaded):
    """w2 = d sigma : d eps / (|d sigma| |d eps|) of L:d eps + N |d eps| (exact for this law at
    any probe size), alpha_sigma = atan2(d sigma1, d sigma2); the H-model's own fields absent."""
    P, s = loaded
    a = np.linspace(0.0, 360.0, 37)[:-1]
    pr = strain_probes(s, P, a, norm=1e-6)
    law = material_of(P)
    for k, ak in enumerate(a):
        de = 1e-6 * np.diag([np.cos(np.radians(ak)), np.sin(np.radians(ak))])
        ds = law.update(s, de, P)[0] - s.stress
        w = np.sum(ds * de) / (np.linalg.norm(ds) * np.linalg.norm(de))
        assert pr.w2[k] == pytest.approx(w, abs=1e-9)
        assert pr.w2_sigma[k] == pytest.approx(w, abs=1e-9)
        assert pr.alpha_sigma[k] == pytest.approx(np.degrees(np.arctan2(ds[0, 0], ds[1, 1])) % 360,
                                                  abs=1e-7)
    for absent in ("w2_V", "w2_g", "w2n", "w2t", "w2_micro"):
        assert np.all(np.isnan(getattr(pr, absent)))
    # the probe's size does not matter for a response homogeneous of degree 1
    big = strain_probes(s, P, a, norm=1e-3)
    assert np.allclose(big.w2, pr.w2, atol=1e-9)


def test_w2_vanishes_before_the_drained_limit(example):
    P = example.HypoParams()
    d = domain_point(P, P.p0, d_eps1=1e-4, eps1_max=0.06, n_dir_probe=180)
    assert d.q_w2 / d.p_w2 < d.q_peak / d.p_peak - 0.05
    sw = directional_sweep(biaxial_test(P, d_eps1=1e-4, eps1_max=d.eps1_w2).state, P, n=360)
    assert np.min(sw.w2) <= 0.0


def test_the_fe_specimen_of_the_users_law(example):
    """The FE specimen takes the user's law as any other: homogeneous (no imperfection), its
    lam_min(K_s) under force control fires at the step where its points' lam_min(D_s) does
    (K_s = sum w B^T D_s B, every homogeneous field admissible), and that step lies within one
    load step of the material point's own onset under the same control."""
    from fem.biaxial import BiaxialConfig, run_biaxial
    from fem.reference import material_point_criteria
    P = example.HypoParams()
    res = run_biaxial(BiaxialConfig(nx=2, ny=4, eps1_max=0.008, d_eps1=2e-4, fields=False,
                                    n_sphere=100).with_params(P))
    ev = res.summary["events"]
    assert ev["lam_min_ks_f"]["row"] == ev["local_lam_Ds"]["row"] is not None
    mp = material_point_criteria(P, 2e-4, 40)
    k = int(np.flatnonzero(mp["lam_min_ds_force"] <= 0)[0])
    assert abs(ev["lam_min_ks_f"]["row"] - k) <= 1
