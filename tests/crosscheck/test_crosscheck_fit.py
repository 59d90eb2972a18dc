"""The H-model fitted to the 12,000-disk DEM, domains compared (``crosscheck.fit``, formerly
``dem/crosscheck_fit.py``: the full run is docs/gallery/fit_dem12000)."""
import dataclasses
import os

import pytest

from hmodel.params import HParams, load_params

DEM_DIR = os.path.join(os.path.dirname(__file__), "..", "..", "docs", "gallery", "full")

# a fitted record (the DEM fit's kn, kt, phi_g, alpha0, p0) with every other field away from
# Table I too, so that a field lost or rebuilt on the way shows; 12 orientations keep it quick
FITTED = HParams(kn=6522853.516818995, kt=309858.622001449, phi_g=7.96141084437897,
                 alpha0=64.47550826699585, p0=202536.92708975545, r_g=1.3e-3, thickness=2.5e-3,
                 n_dir=12, fabric_a=0.1, fabric_b=17.0)


def _same(a: HParams, b: HParams) -> bool:
    """Every field of the two records equal, bit for bit."""
    return all(getattr(a, f.name) == getattr(b, f.name) for f in dataclasses.fields(HParams))


def test_the_fitted_record_reaches_the_probes_and_the_domain_unchanged(tmp_path, monkeypatch):
    """``run_fit`` hands the fit's HParams record itself to the directional analysis and to the
    bifurcation domain (library calls: no argv, nothing read back from disk), every field bit for
    bit; the probes stand at the DEM's lower-boundary fraction of the fitted model's peak, the
    domain at the record's confining stress, and both folders record the record."""
    import crosscheck.fit.run as run
    from hmodel.experiment import biaxial_test
    from common.io import read_csv

    class Fitted:              # what fit_curve returns, as far as run_fit reads it
        status, reason, params = "fitted", None, FITTED

    monkeypatch.setattr(run, "fit_to_curve", lambda *a, **k: (Fitted, {}, None))
    monkeypatch.setattr(run.hfit, "format_result", lambda res, curve: "")
    seen = []
    for name in ("directional_analysis", "bifurcation_domain"):
        real = getattr(run, name)
        monkeypatch.setattr(run, name, lambda params, *a, _real=real, _name=name, **k:
                            seen.append((_name, params, a, k)) or _real(params, *a, **k))

    class Stop(Exception):
        pass

    def stop(*a, **k):
        raise Stop

    monkeypatch.setattr(run, "compare", stop)          # the comparison itself is not this test's
    with pytest.raises(Stop):
        run.run_fit(DEM_DIR, str(tmp_path), n_dir=FITTED.n_dir, n_probes=8)
    assert [s[0] for s in seen] == ["directional_analysis", "bifurcation_domain"]
    for _, got, _, _ in seen:
        assert got is FITTED or _same(got, FITTED), got
    (_, _, (eta_a,), _), (_, _, (pressures,), kw) = seen
    _, _, e = biaxial_test(FITTED, FITTED.p0, 1e-5, 0.03).invariants()
    rows, bounds, _ = run.read_dem_domain(DEM_DIR)
    assert eta_a == bounds["lower_eta_fraction"] * e.max()
    assert pressures == [FITTED.p0] and kw["n_dir_probe"] == run.DOMAIN_PROBES
    for sub in ("probes", "domain"):
        assert _same(load_params(tmp_path / sub / "params.json"), FITTED), sub
    (sigma2,) = read_csv(tmp_path / "domain" / "domain.csv")["sigma2"]      # 10 digits in a CSV
    assert sigma2 == pytest.approx(FITTED.p0, rel=1e-9)


def test_dem_domain_and_bracket_rule():
    from crosscheck.fit import bracket, read_dem_domain
    rows, b, probes = read_dem_domain(DEM_DIR)
    assert {p["outcome"] for p in probes if p["state"] == "state_f0.970"} == {"equilibrium", "failure"}
    assert [r["state"] for r in rows][-1] == "state_f1.000" and b["lower_state"] == "state_f0.970"
    f970 = next(r for r in rows if r["state"] == "state_f0.970")
    assert f970["failure_directions"] == [150.0, 180.0, 200.0, 210.0] and f970["n_failure"] == 4
    assert bracket(0.96, 0.957, 0.971) == "inside the bracket"
    assert bracket(0.971, 0.957, 0.971) == "inside the bracket"      # (lo, hi]: hi is unstable
    assert bracket(0.957, 0.957, 0.971).startswith("below the bracket by 0.0000")
    assert bracket(0.98, 0.957, 0.971) == "above the bracket by 0.0090"
