"""The FE specimen of any law of the material contract (issue 40): the Drucker-Prager through the
same MaterialField, Biaxial, BiaxialConfig and command lines as the H-model; the H-model's own
options refused with another law's file (one line, exit 2, nothing written); the generic weak
zone; the outputs naming the material and saying what a law without patterns leaves absent; the
criteria read from the rate tangent where the step's tangent is not it."""
import csv
import json

import numpy as np
import pytest

import fem.__main__ as fcli
from common.paramfile import write_params
from fem.adapter import MaterialField, tangent_to_fe, strain_to_model
from fem.biaxial import BiaxialConfig, run_biaxial
from hmodel import HParams
from point import material_of
from point.drucker_prager import DPParams, UNITS
from point.tensors import mandel_tangent

P = DPParams()
SMALL = ["--nx", "2", "--ny", "4", "--eps1-max", "0.001", "--d-eps1", "5e-4", "--n-sphere", "50",
         "--quiet"]


@pytest.fixture(scope="module")
def dp_file(tmp_path_factory):
    f = tmp_path_factory.mktemp("dp") / "dp.json"
    write_params(f, P, "drucker-prager", UNITS)
    return f


def _rows(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def test_fem_biaxial_runs_a_drucker_prager_file(tmp_path, dp_file, capsys):
    """--params of a Drucker-Prager file: the run names its material (stdout, summary.json),
    records only what applies (no H-model field or n_dir), leaves open_fraction absent (an empty
    cell, no cell field) with sliding_fraction the plastic points' share, writes params.json in
    the law's format, and that file repeats the run to the bit."""
    out = tmp_path / "dp"
    assert fcli.main(["biaxial", *SMALL, "--params", str(dp_file), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "material: drucker-prager" in text
    s = json.loads((out / "summary.json").read_text())
    assert s["material"]["name"] == "drucker-prager" and "patterns" in s["material"]["absent"]
    assert "absent" in s["material"]["open_fraction"] and "rate tangent" in s["material"]["criteria"]
    assert s["config"]["material"] == {"law": "drucker-prager", **{k: getattr(P, k) for k in UNITS}}
    assert not {"kn", "n_dir", "phi_g", "imp_phi_g"} & set(s["config"]) and "n_dir" not in s["timings"]
    rows = _rows(out / "curve.csv")
    assert all(r["open_fraction"] == "" for r in rows)
    # row 0 the zero increment; the first yield (eta = 2 mu0 = 0.2) within the first step
    assert [float(r["sliding_fraction"]) for r in rows] == [0.0, 1.0, 1.0]
    assert fcli.read_any_params(out / "params.json") == P
    import meshio
    with meshio.xdmf.TimeSeriesReader(out / "fields.xdmf") as r:
        r.read_points_cells()
        _, _, cd = r.read_data(0)
    assert "sliding_fraction" in cd and "open_fraction" not in cd
    again = tmp_path / "again"
    assert fcli.main(["biaxial", *SMALL, "--params", str(out / "params.json"), "--out", str(again)]) == 0
    strip = lambda rs: [{k: v for k, v in r.items() if k != "time_s"} for r in rs]   # noqa: E731
    assert strip(_rows(again / "curve.csv")) == strip(rows)


@pytest.mark.parametrize("argv,option", [
    (["--kn", "2e6"], "--kn"), (["--n-dir", "36"], "--n-dir"), (["--phi-g", "25"], "--phi-g"),
    (["--imperfection", "spot", "--imp-phi-g", "15"], "--imp-phi-g"),
    (["--imperfection", "spot", "--imp-alpha0", "40"], "--imp-alpha0"),
])
@pytest.mark.parametrize("cmd", ["biaxial", "burst"])
def test_hmodel_options_are_refused_with_another_laws_file(tmp_path, capsys, no_computation,
                                                           dp_file, argv, option, cmd):
    out = tmp_path / "out"
    assert fcli.main([cmd, "--params", str(dp_file), *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"error: {option} is an option of the H-model") and "\n" not in err, err
    assert "drucker-prager" in err and not out.exists()


@pytest.mark.parametrize("argv,needles", [
    (["--imperfection", "spot"], ["--imperfection spot", "no weak value", "--imp-values"]),
    (["--imperfection", "spot", "--imp-values", "phi_g=18"], ["phi_g is no parameter",
                                                               "DPParams", "mu_p"]),
    (["--imperfection", "spot", "--imp-values", "mu_p=1.5"], ["--imp-values mu_p=", "1.5",
                                                               "mu_p < 1"]),
    (["--imperfection", "spot", "--imp-values", "mu_p"], ["--imp-values", "FIELD=VALUE"]),
    (["--sigma2", "-1"], ["--sigma2"]),
])
def test_bad_input_of_another_law_is_one_line(tmp_path, capsys, no_computation, dp_file, argv,
                                              needles):
    out = tmp_path / "out"
    assert fcli.main(["biaxial", "--params", str(dp_file), *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "\n" not in err, err
    for n in needles:
        assert n in err, (n, err)
    assert not out.exists()


def test_a_file_of_an_unknown_law_is_one_line(tmp_path, capsys, no_computation, dp_file):
    doc = json.loads(dp_file.read_text())
    doc["model"] = "cam-clay"
    f = tmp_path / "cc.json"
    f.write_text(json.dumps(doc))
    assert fcli.main(["biaxial", "--params", str(f), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"error: --params {f}: model = \"cam-clay\": allowed ") and \
        "drucker-prager" in err and "hmodel" in err


def test_the_weak_zone_of_any_law(dp_file):
    """imp_values: the weak zone's record of any law; for the H-model the same specimen as its
    --imp-phi-g (the same groups, the same parameters)."""
    from fem.biaxial import build_problem
    cfg = BiaxialConfig(nx=2, ny=4, imperfection="spot", imp_values={"mu_p": 0.5}).with_params(P)
    prob = build_problem(cfg)
    (p_strong, i_strong), (p_weak, i_weak) = prob.material.groups
    assert p_strong == P and p_weak == P.replace(mu_p=0.5) and i_weak.size > 0
    h = BiaxialConfig(nx=2, ny=4, n_dir=16, imperfection="spot", imp_phi_g=17.0)
    g = BiaxialConfig(nx=2, ny=4, n_dir=16, imperfection="spot", imp_phi_g=None,
                      imp_values={"phi_g": 17.0})
    for a, b in zip(build_problem(h).material.groups, build_problem(g).material.groups):
        assert a[0] == b[0] and np.array_equal(a[1], b[1])


def test_the_config_holds_one_confining_pressure():
    """A record's p0 is the confining pressure: with_params sets sigma2 from it, a different
    sigma2 is refused (never a silent replacement)."""
    c = BiaxialConfig().with_params(P.replace(p0=300e3))
    assert c.sigma2 == 300e3 and c.params().p0 == 300e3 and c.law().name == "drucker-prager"
    with pytest.raises(ValueError, match="sigma2 = 200000.0 is out of range: allowed the material's p0"):
        BiaxialConfig(material=P.replace(p0=300e3)).validate()
    assert BiaxialConfig().with_params(HParams(n_dir=36)).material is None


def test_material_field_of_a_law_without_patterns():
    """Drucker-Prager points: the plastic flag as the sliding fraction, opened None, the flags
    that changed between two trials counted by point, groups of two laws refused; the criteria's
    tangent is the law's rate tangent at the trial's state in its direction, which differs from
    the step's consistent tangent by O(step) (measured 0.23 % at a step of 1e-4, 0.023 % at
    1e-5), while for the H-model it is the trial's D itself (the same array)."""
    mf = MaterialField(3, [(P, np.arange(3))])
    de = np.zeros((2, 2, 3))
    de[1, 1] = -1e-4                   # FE frame: y axial, compression negative
    de[0, 0] = 0.3e-4
    for _ in range(95):
        t = mf.trial(de)
        mf.commit(t)
    assert np.all(t.sliding == 1.0) and t.opened is None and mf.fractions()[1] is None
    un = mf.trial(-de)                 # unloading: elastic
    assert np.all(un.sliding == 0.0) and mf.pattern_changes(t, un) == 3
    law = material_of(P)
    D = mf.rate_tangent(t)
    assert np.array_equal(D, tangent_to_fe(law.rate_tangent(t.states[0], strain_to_model(de), P)))
    rel = []
    for step in (1.0, 0.1):
        ts = mf.trial(step * de)
        A, R = mandel_tangent(ts.D)[..., 0], mandel_tangent(mf.rate_tangent(ts))[..., 0]
        rel.append(np.linalg.norm(A - R) / np.linalg.norm(R))
    assert 1e-3 < rel[0] < 1e-2 and rel[1] == pytest.approx(0.1 * rel[0], rel=0.05)
    with pytest.raises(ValueError, match="one law: got drucker-prager and hmodel"):
        MaterialField(4, [(P, [0, 1]), (HParams(n_dir=8), [2, 3])])
    h = MaterialField(2, [(HParams(n_dir=8), np.arange(2))])
    th = h.trial(np.zeros((2, 2, 2)))
    assert h.rate_tangent(th) is th.D


def test_burst_of_a_drucker_prager_specimen(monkeypatch):
    """run_burst of the Drucker-Prager 1 x 2 specimen (the material point's drained curve cut at
    eps1 = 1.2 %, past its peak at 0.95 %, for time): the c peak of the FE is the material
    point's, the held runs end in equilibrium below it and failure past it, and the summary names
    the material."""
    import fem.burst as fb
    monkeypatch.setattr(fb, "MP_EPS1_MAX", 0.012)
    spec = BiaxialConfig(nx=1, ny=2, fields=False).with_params(P)
    res = fb.run_burst(fb.BurstConfig(specimen=spec, fields=False))
    assert res.summary["material"]["name"] == "drucker-prager"
    assert res.summary["config"]["specimen"]["material"]["law"] == "drucker-prager"
    rows = {r["switch"]: r for r in res.rows}
    assert rows["below"]["outcome"] == "equilibrium" and rows["past"]["outcome"] == "failure"
    assert abs(rows["past"]["c_peak_error"]) < 1e-9
    # the c peak beside its closed form h = h_R: the path's sampled peak lies below the exact
    # one by less than c's rise over one path step there (c is concave at its peak)
    (cf,) = res.summary["closed_forms"]
    assert cf["ratio"] == rows["past"]["ratio"]
    rise = rows["past"]["dc_rule"]          # c_peak - c_(peak - 1) of the FE path
    assert -abs(rise) <= cf["c_peak"]["difference"] <= 1e-6 * cf["c_peak"]["closed_form"]


def test_every_criterion_beside_its_closed_form(tmp_path, dp_file, capsys):
    """A Drucker-Prager specimen through its peak (2 x 4 quads, steps 1e-4): summary.json and the
    printed table give each criterion's onset beside the closed form of the homogeneous
    specimen's control and the difference in load steps. The exact ones (lam_min(K_s,f) and the
    local lam_min(D_s), W2 at h_sym, Rice at h_loc) fire at the first row whose stress ratio is
    past the closed form's (eta = 2 mu(kappa) along the path: the comparison in eta is exact,
    in eps1 it carries the two paths' different steps); every other event is named with what
    its closed form is to it."""
    out = tmp_path / "cf"
    assert fcli.main(["biaxial", "--nx", "2", "--ny", "4", "--eps1-max", "0.011", "--d-eps1",
                      "1e-4", "--n-sphere", "200", "--quiet", "--no-fields", "--params",
                      str(dp_file), "--out", str(out)]) == 0
    assert "closed form: h" in capsys.readouterr().out
    s = json.loads((out / "summary.json").read_text())
    eta = [float(r["eta"]) for r in _rows(out / "curve.csv")]
    ev = s["events"]
    for key, h in (("lam_min_ks_f", "h_sym"), ("local_lam_Ds", "h_sym"), ("local_w2", "h_sym"),
                   ("local_rice", "h_loc")):
        e = ev[key]
        assert e["closed_form"]["h"] == h
        assert eta[e["row"] - 1] < e["closed_form"]["eta"] <= eta[e["row"]], (key, e)
        assert abs(e["difference"]["steps"]) < 1.0
    for key in ("det_k_f", "lam_min_ks", "det_k", "fe_peak"):
        assert ev[key]["closed_form"]["meaning"]
