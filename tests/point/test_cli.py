"""python -m point: the commands of any law (point.cli), run in-process on Drucker-Prager (fast:
its drained path of 1000 steps takes about a second).

- the law from --model or the file's "model", one loader of every law's file, an option of
  another law's field refused in one line, Drucker-Prager's options checked by its record;
- every summary names the material, the outputs it lacks ("absent", their columns left out of
  the CSV files) and stands each onset beside its closed form; the H-model's says there is none;
- the contract's errors are the user's first contact: a law made broken here (a wrong tangent,
  a NaN stress, a tangent of the wrong shape, a state without eps) is refused in one line, exit
  2, nothing written; a MaterialError inside a run leaves what was finished written complete;
- the fit of any law.

Tolerances: each stated where it is used, from what the closed form and the analysis can differ
by (one step of a path, the probes' finite norm).
"""
from __future__ import annotations

import csv
import dataclasses
import json
import math
from typing import NamedTuple

import numpy as np
import pytest

import point.burst as pburst
from common.io import read_csv, write_csv
from hmodel import HParams
from point import contract
from point.cli import main
from point.contract import MaterialError
from point.drucker_prager import DPParams, DruckerPrager
from point.experiment import biaxial_columns, biaxial_test
from point.params import load_params
from point.tensors import mandel_tangent

DP = ["--model", "drucker-prager"]
P = DPParams()


def _run(argv, capsys):
    """(exit code, stdout, stderr lines) of ``python -m point ARGV``."""
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err.strip().splitlines()


def _summary(folder):
    return json.loads((folder / "summary.json").read_text())


def _header(path):
    with open(path, newline="") as f:
        return next(csv.reader(f))


# -- the law and its parameters ----------------------------------------------------------------
def test_params_of_any_law_and_options_of_another_refused(tmp_path, capsys):
    f = tmp_path / "dp.json"
    code, out, _ = _run(["params", *DP, "--shear-modulus", "3e7", "--out", f], capsys)
    assert code == 0 and "material: drucker-prager" in out
    doc = json.loads(f.read_text())
    assert doc["model"] == "drucker-prager" and doc["units"]["G"] == "Pa"
    assert load_params(f) == P.replace(G=3e7)            # one loader: the file's "model"
    h = tmp_path / "h.json"
    assert _run(["params", "--n-dir", "36", "--out", h], capsys)[0] == 0
    assert load_params(h) == HParams(n_dir=36)          # the default law, the H-model
    # an option of another law's field: one line naming the option and both laws, nothing written
    for argv in (["--params", f, "--kn", "2e6"], [*DP, "--phi-g", "25"]):
        out_dir = tmp_path / "refused"
        code, _, err = _run(["biaxial", *argv, "--out", out_dir], capsys)
        assert code == 2 and len(err) == 1, err
        assert err[0].startswith("error: --") and "of hmodel's parameters, not of drucker-prager" in err[0]
        assert not out_dir.exists()
    # the file's law and --model disagree
    code, _, err = _run(["biaxial", "--params", f, "--model", "hmodel", "--out", tmp_path / "x"],
                        capsys)
    assert code == 2 and "--model hmodel: the file" in err[0] and "drucker-prager" in err[0]
    # Drucker-Prager's record checks its options: the option and its range
    code, _, err = _run(["params", *DP, "--nu", "0.5", "--out", tmp_path / "nu.json"], capsys)
    assert code == 2 and err == ["error: --nu 0.5 is out of range: allowed 0 <= nu < 0.5"]
    code, _, err = _run(["params", *DP, "--mu0", "0.6", "--out", tmp_path / "mu.json"], capsys)
    assert code == 2 and err[0].startswith("error: --mu0 0.6 is out of range")
    assert not (tmp_path / "nu.json").exists() and not (tmp_path / "mu.json").exists()


def test_the_hmodel_through_point_is_python_m_hmodel(tmp_path, capsys):
    """The same drained test by ``python -m point --model hmodel`` and ``python -m hmodel``:
    the same CSV to the bit (one code path), the material named, no closed form."""
    from hmodel.cli import main as hmain
    small = ["--n-dir", "36", "--eps1-max", "0.004", "--d-eps1", "1e-4", "--quiet"]
    assert _run(["biaxial", "--model", "hmodel", *small, "--out", tmp_path / "p"], capsys)[0] == 0
    assert hmain(["biaxial", *small, "--out", str(tmp_path / "h")]) == 0
    assert (tmp_path / "p" / "biaxial.csv").read_bytes() == (tmp_path / "h" / "biaxial.csv").read_bytes()
    s = _summary(tmp_path / "h")
    assert s["material"]["name"] == "hmodel" and s["absent"] == []
    assert s["closed_forms"] == "no closed form for this law"
    assert "closed forms: no closed form for this law" in capsys.readouterr().out


# -- summaries: the material, what it lacks, each onset beside its closed form -------------------
def test_biaxial_stands_the_peak_beside_h_zero(tmp_path, capsys):
    """The drained peak (largest q) against h = 0, whose exact eta is 2 mu_p: the closed form
    from the path's states (a parabola in g = h through three rows: O(step^3)) within 1e-7 of
    it (a line through two rows misses the peak by O(step^2), 5e-7 here); the analysis's row
    within one step of the path's eta of it (2.5e-6 near the peak)."""
    out = tmp_path / "b"
    code, stdout, _ = _run(["biaxial", *DP, "--eps1-max", "0.011", "--quiet", "--out", out], capsys)
    assert code == 0
    s = _summary(out)
    assert s["material"]["name"] == "drucker-prager" and "mu_p 0.55" in s["material"]["describe"]
    assert s["absent"] == ["n_sliding", "n_open"]
    head = _header(out / "biaxial.csv")
    assert "n_sliding" not in head and "n_open" not in head and "q" in head
    pk = s["closed_forms"]["peak"]
    assert pk["eta"]["closed_form"] == pytest.approx(2 * P.mu_p, abs=1e-7)
    eta = read_csv(out / "biaxial.csv")["eta"]
    k = int(np.argmax(eta))
    assert abs(pk["eta"]["difference"]) <= abs(eta[k] - eta[k - 1]) + abs(eta[k + 1] - eta[k])
    assert pk["eta"]["value"] == pytest.approx(float(eta[k]), rel=1e-9)   # the CSV's 10 digits
    assert "drained peak (largest q): eta = " in stdout and "closed form" in stdout


def test_first_root_is_the_exact_onset_along_the_drained_path():
    """``onsets.first_root`` on the drained path's own states against the exact 1D roots in
    kappa (tests/point/test_exact_analysis.py: eta = 2 mu(kappa) on the path): the first W2 <= 0
    (h = h_sym) and Rice's onset, to 1e-7 in eta (the parabola's O(step^3) error, measured
    5e-10; a step of the path moves eta by 1.5e-4 there)."""
    from point.closed_forms import h_rice, h_sym
    from point.driver import drained_biaxial, isotropic_state, run_path
    from point.onsets import first_root
    from tests.point.test_exact_analysis import exact_kappa
    r = run_path(isotropic_state(P), P, drained_biaxial(1e-5), 960, keep_states=True)
    p, q, eta = r.invariants()
    vals = {"eta": eta, "eps1": r.eps[:, 0]}
    got = first_root(r.states, P, h_sym, vals)
    assert got["eta"] == pytest.approx(2 * float(P.mu(exact_kappa(h_sym))), abs=1e-7)
    assert eta[got["row"] - 1] < got["eta"] <= eta[got["row"]]
    rice = lambda m: h_rice(m, n_grid=90)[0]                      # noqa: E731
    got = first_root(r.states, P, rice, vals, stride=32)         # every 32nd row, then bisected
    assert got["eta"] == pytest.approx(2 * float(P.mu(exact_kappa(lambda m: h_rice(m)[0]))),
                                       abs=1e-7)
    assert first_root(r.states, P, lambda m: -1e30, vals) is None


def test_probes_stand_the_cone_beside_its_exact_edges(tmp_path, capsys):
    """At A (eta = 1.095, inside the domain): the cone's edges in both probe planes within 0.02
    deg of the exact ones (a probe of norm 1e-6 sees the consistent response of its step: 0.011
    deg measured here, halving with the norm: tests/point/test_exact_analysis.py), lam_min and
    det of the principal block and det D to 1e-9 relative (the same tangent, two routes), min W2
    of the sweep within 1e-3 of the exact minimum (the sweep samples directions ~1 deg apart
    near it: 2.3e-4 measured). The outputs the law lacks: named, their columns and figures
    left out."""
    out = tmp_path / "p"
    code, stdout, _ = _run(["probes", *DP, "--eta-a", "1.095", "--n-probes", "180", "--stress-step",
                            "30", "--quiet", "--out", out], capsys)
    assert code == 0
    s = _summary(out)
    c = s["closed_forms"]
    for plane in ("cone_edges_strain_plane", "cone_edges_stress_plane"):
        assert len(c[plane]["value"]) == 2 == len(c[plane]["closed_form_all"])
        assert max(abs(d) for d in c[plane]["difference"]) < 0.02, c[plane]
    assert s["cone_w2_alpha_sigma"][0][0] == pytest.approx(min(c["cone_edges_stress_plane"]["value"]), abs=1.0)
    for k in ("lam_min_Msym", "det_M", "det_D"):
        assert c[k]["difference"] == pytest.approx(0.0, abs=1e-9 * abs(c[k]["closed_form"])), k
    assert c["min_w2"]["closed_form"] < 0 and abs(c["min_w2"]["difference"]) < 1e-3
    assert c["h"] < c["h_sym"]                                 # inside the domain: h below h_sym
    for gone in ("w2_V", "w2_g", "w2n", "w2t", "w2_micro", "n_sliding", "min_w2n",
                 "det_M_lagrangian", "fig9_w2_split.png", "fig11_w2_normal_tangential.png"):
        assert gone in s["absent"], gone
        assert gone not in s
    for f in ("probes.csv", "stress_probes.csv"):
        head = _header(out / f)
        assert not set(head) & set(s["absent"]) and {"w2", "w2_sigma", "alpha_sigma"} <= set(head)
    assert not (out / "fig9_w2_split.png").exists() and (out / "fig8_polar_w2.png").exists()
    assert "cone edges alpha_sigma: [" in stdout and "det D [Pa^3]" in stdout


def test_domain_stands_each_onset_beside_its_closed_form(tmp_path, capsys):
    """One pressure: the first W2 <= 0 of the domain's scan against h = h_sym (the scan's first
    row past the root: within one step of the path's eta, 1.5e-4 there), the peak against
    h = 0, Rice's onset by its closed form alone, between them (docs/materials.md)."""
    out = tmp_path / "d"
    code, stdout, _ = _run(["domain", *DP, "--sigma2", "200e3", "--n-probes", "72", "--workers", "1",
                            "--quiet", "--out", out], capsys)
    assert code == 0
    (c,) = _summary(out)["closed_forms"]
    w = c["first_w2"]
    assert 0 <= w["eta"]["difference"] < 2.5e-4 and w["closed_form_row"] > 0
    assert c["peak"]["eta"]["closed_form"] == pytest.approx(2 * P.mu_p, abs=1e-7)
    assert w["eta"]["closed_form"] < c["rice"]["eta_closed_form"] < c["peak"]["eta"]["closed_form"]
    assert c["rice"]["value"] is None
    assert stdout.count("(closed form ") == 3


def test_burst_stands_each_c_peak_and_verdict_beside_h_R_and_h_c(tmp_path, capsys):
    """One path (R = -2 from 0.95 of the peak): its c peak against h = h_R within one step of
    the path's eta (3e-4 there); the static verdicts of the run held below (a state exists) and
    past the peak (uncontrollable) agree with the closed form's (c_hold against the c where h
    falls to h_c, the tie's loss of control, which is h_R's c)."""
    out = tmp_path / "u"
    code, stdout, _ = _run(["burst", *DP, "--ratios", "-2", "--start-fractions", "0.95",
                            "--no-cone", "--d-eps1", "5e-5", "--quiet", "--out", out], capsys)
    assert code == 0
    (c,) = _summary(out)["closed_forms"]
    assert abs(c["eta"]["difference"]) < 3e-4
    assert c["c_at_h_control"] == pytest.approx(c["c"]["closed_form"], rel=1e-12)
    assert [(r["switch"], r["verdict"]["value"], r["verdict"]["agree"]) for r in c["runs"]] == \
        [("below", "exists", True), ("past", "uncontrollable", True)]
    assert "verdicts: below exists (closed form exists)" in stdout


# -- the contract's errors: a law made broken here ------------------------------------------------
class NoEps(NamedTuple):
    """A state that records no strain (the contract's state records stress and eps)."""
    stress: np.ndarray
    eps_p: np.ndarray
    kappa: np.ndarray
    plastic: np.ndarray

    @property
    def batch_shape(self):
        return self.kappa.shape


class Broken(DruckerPrager):
    """Drucker-Prager with one bug: 'tangent' (an entry of the tangent 30 % off), 'nan' (a NaN
    stress), 'shape' (the tangent as a Mandel matrix (3, 3), not (2, 2, 2, 2)), 'no-eps' (a new
    state without eps), 'refuses' (a MaterialError once eps11 passes 0.4 %), 'refuses-p' (once
    p passes 600 kPa: a region of the stress the law does not describe, as Drucker-Prager's
    apex)."""

    def __init__(self, bug, record):
        self.bug, self.name, self.params_type = bug, f"broken-{bug}", record

    def update(self, state, d_eps, params):
        stress, tangent, new = super().update(state, d_eps, params)
        if self.bug == "tangent":
            tangent = tangent.copy()
            tangent[0, 0, 1, 1] *= 1.3
        elif self.bug == "nan":
            stress = stress.copy()
            stress[0, 0] = np.nan
        elif self.bug == "shape":
            tangent = mandel_tangent(tangent)
        elif self.bug == "no-eps":
            new = NoEps(new.stress, new.eps_p, new.kappa, new.plastic)
        elif self.bug == "refuses" and np.any(new.eps[0, 0] > 0.004):
            raise MaterialError(f"material {self.name}: refused past eps11 = 0.4 % (the bug)")
        elif self.bug == "refuses-p" and np.any(new.stress[0, 0] + new.stress[1, 1] > 1.2e6):
            raise MaterialError(f"material {self.name}: refused past p = 600 kPa (the bug)")
        return stress, tangent, new


@pytest.fixture
def broken(monkeypatch):
    """broken(bug) -> the name of a law registered for this test only (its own record class)."""
    def make(bug):
        @dataclasses.dataclass(frozen=True)
        class Record(DPParams):
            def replace(self, **changes):
                kw = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
                kw.update(changes)
                return type(self)(**kw)
        law = Broken(bug, Record)
        monkeypatch.setitem(contract.MATERIALS, law.name, law)
        monkeypatch.setattr(Record, "material", law, raising=False)
        return law.name
    return make


@pytest.mark.parametrize("bug, says", [
    ("nan", "update returned a non-finite stress"),
    ("shape", "update returned a tangent of shape (3, 3)"),
    ("no-eps", "the new state has no field eps"),
])
@pytest.mark.parametrize("command", ["biaxial", "probes"])
def test_a_broken_contract_is_one_line_and_nothing_written(broken, bug, says, command, tmp_path,
                                                            capsys):
    out = tmp_path / "out"
    code, stdout, err = _run([command, "--model", broken(bug), "--out", out, "--quiet"], capsys)
    assert code == 2 and len(err) == 1, err
    assert err[0].startswith(f"error: material broken-{bug}: {says}"), err[0]
    assert not out.exists() and stdout == ""


def test_check_tangent_refuses_a_tangent_that_disagrees(broken, tmp_path, capsys):
    """--check-tangent: central differences of the law's own stress against its tangent, at the
    isotropic state and at a loaded one (``contract.check_tangent``, tolerance 1e-5 of the
    largest entry: a consistent tangent agrees to 1e-7, tests/point/test_drucker_prager.py)."""
    out = tmp_path / "out"
    code, _, err = _run(["biaxial", "--model", broken("tangent"), "--check-tangent", "--out", out],
                        capsys)
    assert code == 2 and len(err) == 1
    assert err[0].startswith("error: material broken-tangent: --check-tangent: the tangent") and \
        "at the isotropic state: relative error 0.1" in err[0] and "allowed <= 1e-05" in err[0]
    assert not out.exists()
    # the same law passes without the check (its stress is right): the check is what refused it
    code, stdout, _ = _run(["params", "--model", "drucker-prager", "--out", tmp_path / "p.json"], capsys)
    code, stdout, _ = _run(["biaxial", *DP, "--check-tangent", "--eps1-max", "0.002", "--quiet",
                            "--out", tmp_path / "ok"], capsys)
    assert code == 0 and "tangent check (central differences of the law's own stress): the " \
        "isotropic state" in stdout


def test_a_material_error_inside_a_run_keeps_the_finished_part(broken, tmp_path, capsys):
    """The law refuses a state in the middle of the run: one line, exit 2, naming the law and
    what is written; the rows before are written complete (every column, the last row the last
    state reached)."""
    out = tmp_path / "b"
    code, _, err = _run(["biaxial", "--model", broken("refuses"), "--d-eps1", "1e-4", "--quiet",
                         "--out", out], capsys)
    # eps11 counts from the stress-free state: the isotropic state's p0 / (2 K2) = 0.125 %
    # before the test's own, so the path reaches 0.27 % (27 steps) and step 28 is refused
    done = int((0.004 - P.p0 / (2 * P.K2)) / 1e-4 + 1e-9)
    assert code == 2 and len(err) == 1 and done == 27
    assert err[0].startswith("error: material broken-refuses: refused past eps11") and \
        f"(drained biaxial, step {done + 1}); written complete: biaxial.csv ({done} steps), " \
        "params.json" in err[0], err[0]
    c = read_csv(out / "biaxial.csv")
    assert len(c["eps1"]) == done + 1 and c["eps1"][-1] == pytest.approx(done * 1e-4)
    assert all(np.all(np.isfinite(v)) for v in c.values())
    assert json.loads((out / "params.json").read_text())["model"] == "broken-refuses"



def test_a_region_the_law_refuses_ends_the_path_with_its_refusal(broken, tmp_path, capsys):
    """The drained path at 400 kPa runs into stresses the law refuses (p > 600 kPa): the driver
    cuts the step, decides it (``controllability.decide``: the refused increments left out of the
    scan), finds no static state among those the law accepts, and ends the path with the law's
    own refusal: exit 2 (not 1, a Newton failure), the rows before written complete."""
    out = tmp_path / "b"
    code, _, err = _run(["biaxial", "--model", broken("refuses-p"), "--sigma2", "400e3",
                         "--d-eps1", "1e-4", "--quiet", "--out", out], capsys)
    assert code == 2 and len(err) == 1, err
    assert err[0].startswith("error: material broken-refuses-p: refused past p = 600 kPa") and \
        "among the increments it refuses" in err[0] and "written complete: biaxial.csv (" in err[0]
    c = read_csv(out / "biaxial.csv")
    assert len(c["p"]) > 10 and c["p"][-1] < 6e5 and np.all(np.isfinite(c["q"]))


def test_a_material_error_in_the_domain_keeps_the_pressures_finished(tmp_path, capsys,
                                                                     monkeypatch):
    """The domain: the law refusing a state on the second pressure's path (made to here: the
    pressure's job raises the law's MaterialError): the first pressure's row is written."""
    import point.experiment as pe
    real = pe.domain_point

    def domain_point(params, sigma2, **kw):
        if sigma2 > 300e3:
            raise MaterialError("material drucker-prager: refused on this path (the test's)")
        return real(params, sigma2, **kw)
    monkeypatch.setattr(pe, "domain_point", domain_point)
    out = tmp_path / "d"
    code, _, err = _run(["domain", *DP, "--sigma2", "100e3,400e3", "--n-probes", "36",
                         "--d-eps1", "1e-4", "--workers", "1", "--quiet", "--out", out], capsys)
    assert code == 2 and len(err) == 1 and "domain.csv (1 of 2 pressures)" in err[0], err
    assert list(read_csv(out / "domain.csv")["sigma2"]) == [100e3]


def test_a_material_error_in_the_burst_keeps_the_runs_finished(tmp_path, capsys, monkeypatch):
    """The burst: a MaterialError in the second run held (the law refusing a state the dynamics
    reach): the first run's row, history and path are written complete."""
    real, calls = pburst.hold, []

    def hold(*a, **k):
        calls.append(1)
        if len(calls) == 2:
            raise MaterialError("material drucker-prager: refused in the dynamics (the test's)")
        return real(*a, **k)
    monkeypatch.setattr(pburst, "hold", hold)
    out = tmp_path / "u"
    code, _, err = _run(["burst", *DP, "--ratios", "-2", "--start-fractions", "0.95", "--no-cone",
                         "--d-eps1", "5e-5", "--quiet", "--out", out], capsys)
    assert code == 2 and len(err) == 1
    assert "written complete: burst.csv, history.csv, paths.csv, params.json" in err[0], err[0]
    with open(out / "burst.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [(r["switch"], r["outcome"]) for r in rows] == [("below", "equilibrium")]
    with open(out / "history.csv", newline="") as f:
        assert {r["switch"] for r in csv.DictReader(f)} == {"below"}
    assert not (out / "summary.json").exists()


# -- the fit of any law ----------------------------------------------------------------------------
def test_fit_recovers_drucker_prager(tmp_path, capsys):
    """A Drucker-Prager curve (steps 1e-4, to 1.2 %) fitted from a start 25 % off in G and 10 %
    in mu_p, with the data's own step: both recovered to 1e-4 (the optimizer's tolerances; the
    model is the data's); the default bounds and the free set are the law's."""
    r = biaxial_test(P, None, 1e-4, 0.012)
    data = tmp_path / "curve.csv"
    write_csv(data, biaxial_columns(r))
    start = tmp_path / "start.json"
    assert _run(["params", *DP, "--shear-modulus", "3e7", "--mu-p", "0.5", "--out", start], capsys)[0] == 0
    out = tmp_path / "f"
    code, stdout, _ = _run(["fit", "--params", start, "--data", data, "--free", "G,mu_p",
                            "--starts", "1", "--d-eps1", "1e-4", "--d-eps1-search", "1e-4",
                            "--quiet", "--out", out], capsys)
    assert code == 0, stdout
    fitted = load_params(out / "params.json")
    assert fitted.G == pytest.approx(P.G, rel=1e-4) and fitted.mu_p == pytest.approx(P.mu_p, rel=1e-4)
    s = _summary(out)
    assert s["material"]["name"] == "drucker-prager" and s["bounds"]["G"] == [3e5, 3e9]
    assert "G = 4" in stdout and "mu_p = 0.55" in stdout and "mu_p = 0.55 -" not in stdout
    # a name the law's fit cannot free: one line naming --free and the law's choices
    code, _, err = _run(["fit", "--params", start, "--data", data, "--free", "kn", "--out",
                         tmp_path / "x"], capsys)
    assert code == 2 and err[0].startswith("error: --free / --bounds: free parameter 'kn': allowed G, nu")
    assert not (tmp_path / "x").exists()
    assert math.isfinite(s["cost"])
