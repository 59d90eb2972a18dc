"""The H-model fitted to the 12,000-disk DEM, domains compared (``dem/crosscheck_fit.py``, a
cross-check job: the full run is docs/gallery/fit_dem12000)."""
import os

from hmodel import cli
from hmodel.params import HParams

DEM_CURVE = os.path.join(os.path.dirname(__file__), "..", "..", "docs", "gallery", "full",
                         "biaxial.csv")


def test_param_argv_gives_the_parameters_bit_for_bit():
    """The fitted parameters reach ``hmodel probes`` / ``domain`` unchanged (repr of floats)."""
    from dem.crosscheck_fit import param_argv
    P = HParams(kn=6522853.516818995, kt=309858.622001449, phi_g=7.96141084437897,
                alpha0=64.47550826699585, p0=202536.92708975545, fabric_a=0.1, thickness=2.5e-3)
    args = cli.build_parser().parse_args(["probes", *param_argv(P), "--sigma2", repr(P.p0),
                                          "--out", "never-written"])
    assert cli.params_from(args) == P


def test_dem_domain_and_bracket_rule():
    from dem.crosscheck_fit import _bracket, read_dem_domain
    rows, b, probes = read_dem_domain(os.path.dirname(DEM_CURVE))
    assert {p["outcome"] for p in probes if p["state"] == "state_f0.970"} == {"equilibrium", "failure"}
    assert [r["state"] for r in rows][-1] == "state_f1.000" and b["lower_state"] == "state_f0.970"
    f970 = next(r for r in rows if r["state"] == "state_f0.970")
    assert f970["failure_directions"] == [150.0, 180.0, 200.0, 210.0] and f970["n_failure"] == 4
    assert _bracket(0.96, 0.957, 0.971) == "inside the bracket"
    assert _bracket(0.971, 0.957, 0.971) == "inside the bracket"      # (lo, hi]: hi is unstable
    assert _bracket(0.957, 0.957, 0.971).startswith("below the bracket by 0.0000")
    assert _bracket(0.98, 0.957, 0.971) == "above the bracket by 0.0090"
