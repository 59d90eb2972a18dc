"""The three models against each other and against the paper's conclusions (section 5).

One small cross-check run (about a minute): the H-model at its point A (Table I), the FE
specimen on a coarse mesh, and a 300-disk DEM sample (seed 1, 0.1/s, probe runs capped at
60,000 steps). The DEM part is deterministic (single thread, seeded), so these assertions are
reproducible; they are what a change that breaks the agreement between the models trips.
Thresholds state the physics asked for, with margins for a 300-disk sample whose walls carry a
~10 % share of the second-order work (docs/dem.md).
"""
import json

import pytest

from crosscheck import run_crosscheck

ALPHAS = [0.0, 60.0, 70.0, 80.0, 90.0, 150.0, 200.0, 225.0, 235.0, 240.0, 245.0, 250.0, 260.0, 300.0]


@pytest.fixture(scope="module")
def xc(tmp_path_factory):
    out = tmp_path_factory.mktemp("crosscheck")
    c, timings = run_crosscheck(out, n=300, rate=0.1, workers=2, fem_mesh=(2, 4), fem_n_dir=72,
                                dem_alphas=ALPHAS, dem_domain=False)
    return out, c


def test_outputs_written(xc):
    out, c = xc
    rep = (out / "report.md").read_text()
    for f in ("fig_stress_strain.png", "fig_polar_w2.png", "fig_micro_macro.png",
              "fig_normal_tangential.png", "fig_domain.png"):
        assert (out / f).stat().st_size > 20_000 and f"({f})" in rep
    pdir = out / "dem" / "domain" / c["dem"]["state"]["state"]
    for f in ("fig15_w2.png", "fig16_w2_micro.png", "fig17_w2_nt.png"):
        assert (pdir / f).stat().st_size > 20_000
    header = (pdir / "probes.csv").read_text().splitlines()
    assert header[0].startswith("alpha_sigma,outcome,w2,w2_micro,w2n,w2t") and len(header) == 1 + len(ALPHAS)
    assert (pdir / "probe_histories.csv").stat().st_size > 0
    saved = json.loads((out / "conclusions.json").read_text())
    assert saved["conclusions"]["hmodel"]["cone_w2"] == c["hmodel"]["cone_w2"]
    # the report says which DEM parameter set it ran
    assert saved["config"]["dem_params"].startswith("the paper's stated set")
    assert saved["config"]["dem_params_values"]["n"] == 300 and "dem_params" in rep
    # the parameters of the three parts, in the --params format (docs/parameters.md)
    from dem.params import DemParams, load_params as load_dem
    from hmodel import HParams
    from hmodel.params import load_params as load_h
    assert load_h(out / "hmodel_params.json") == HParams()
    assert load_h(out / "fem" / "params.json") == HParams(n_dir=72)
    assert load_dem(out / "dem_params.json") == load_dem(out / "dem" / "biaxial" / "params.json") \
        == DemParams(n=300, seed=1)


def test_comparison_state_by_its_rule_and_every_probe_decided(xc):
    # the highest saved state whose reference held and whose probe targets all stay below the
    # largest stress ratio held by a reference; there no probe may be undecided
    from dem import io
    from dem.domain import _eta, max_eta_increment
    out, c = xc
    st = c["dem"]["state"]
    assert st["rule_met"]
    assert st["limit"] == min([st["eta_held_max"]] + ([st["eta_failed_min"]] if st["eta_failed_min"] else []))
    assert st["eta_R"] + st["max_eta_increment"] <= st["limit"]
    held = {}
    for r in c["dem_domain"]["rows"]:
        R, meta = io.load_state(out / "dem" / "domain" / r["state"] / "stateR.npz")
        assert meta["outcome"] == r["reference"]
        if r["reference"] == "equilibrium":
            held[r["state"]] = (_eta(R.control.s_to[1], R.control.s_to[0]),
                                max_eta_increment(R, 2500.0, ALPHAS))
    assert max(e for e, _ in held.values()) == st["eta_held_max"]
    ok = [nm for nm, (e, inc) in held.items() if e + inc <= st["limit"]]
    assert st["state"] == max(ok, key=lambda nm: held[nm][0])
    # the strength under stress control is bracketed: the peak state cannot be held
    assert any(r["reference"] == "failure" for r in c["dem_domain"]["rows"])
    d = c["dem"]
    assert d["n_undecided"] == 0 and d["n_equilibrium"] + d["n_failure"] == len(ALPHAS)


def test_dem_runs_on_a_dask_cluster_give_the_same_probes(xc, tmp_path):
    # `crosscheck --scheduler`: the DEM's runs after its biaxial test (its relaxations and probe
    # runs, the burst's path, staircase and probes: one pool) go to a dask cluster (here a local
    # one of two workers) and come back the same: the probes to the byte, the burst's files but
    # their wall-time column
    import csv
    import shutil
    distributed = pytest.importorskip("distributed")
    from crosscheck import DEFAULT_SMALL
    out, c = xc
    shutil.copytree(out / "dem" / "biaxial", tmp_path / "dem" / "biaxial")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        d, _ = run_crosscheck(tmp_path, n=300, rate=0.1, fem_mesh=(2, 4), fem_n_dir=72,
                              dem_alphas=ALPHAS, dem_domain=False, domain=False, resume=True,
                              dem_max_steps=DEFAULT_SMALL["max_steps"],
                              scheduler=cluster.scheduler_address, verbose=False)
    name = c["dem"]["state"]["state"]
    assert d["dem"]["state"]["state"] == name
    probes = "dem/domain/" + name + "/probes.csv"
    assert (tmp_path / probes).read_bytes() == (out / probes).read_bytes()
    for f in ("stairs.csv", "rest.csv", "burst.csv", "probes.csv"):
        with open(out / "burst" / "dem" / f) as fa, open(tmp_path / "burst" / "dem" / f) as fb:
            ra, rb = list(csv.reader(fa)), list(csv.reader(fb))
        keep = [k for k, col in enumerate(ra[0]) if col != "wall_time"]
        assert [[r[k] for k in keep] for r in ra] == [[r[k] for k in keep] for r in rb], f


def test_instability_cone_in_third_quadrant_in_both_models(xc):
    _, c = xc
    h, d = c["hmodel"], c["dem"]
    assert h["cone_in_third_quadrant"] and h["min_w2"] < 0
    assert 180 < h["alpha_min_w2"] < 270
    # the DEM's least stable probe direction lies in the third quadrant too, near the H-model's
    assert d["min_in_third_quadrant"]
    assert abs(d["alpha_min_w2"] - h["alpha_min_w2"]) <= 20.0
    # and its W2 there is far below its elastic-zone values (~0.8-1)
    assert d["min_w2"] < 0.3


def test_plastic_zones_agree(xc):
    _, c = xc
    (h_lo, h_hi), = c["hmodel"]["plastic_zone"]
    (d_lo, d_hi), = c["dem"]["plastic_zone"]
    assert abs(h_lo - d_lo) <= 20 and abs(h_hi - d_hi) <= 20


def test_micro_against_macro(xc):
    _, c = xc
    h, d = c["hmodel"]["micro_minus_macro"], c["dem"]["micro_minus_macro"]
    # H-model: the identity W2 = sum df.dl holds to round-off (no inertia)
    assert h["elastic"]["max"] < 1e-10 and h["plastic"]["max"] < 1e-10
    # DEM: close in the elastic zone (the difference is the wall contacts' share), further in the
    # plastic zone where short-lived contacts are missed, the micro sum below the macro W2
    assert d["elastic"]["mean"] < 0.15
    assert d["plastic"]["mean"] > d["elastic"]["mean"]
    assert c["dem"]["micro_below_macro_in_plastic_zone"]


def test_tangential_part_drives_the_vanishing_in_both(xc):
    _, c = xc
    h, d = c["hmodel"], c["dem"]
    assert h["w2n_min"] > 0 and h["w2t_max_in_cone"] < 0
    assert d["w2n_min"] > 0
    assert d["w2t_at_min_w2"] < 0 < d["w2n_at_min_w2"]


def test_bifurcation_domain_w2_against_w2sigma(xc):
    _, c = xc
    for d in c["domain"]:
        assert d["q_w2sigma"] <= d["q_w2"] <= d["q_peak"]
        assert 0 <= d["rel_shift_q"] < 0.05     # the boundary barely moves (paper, Fig. 10)


def test_fe_specimen_follows_material_point(xc):
    _, c = xc
    assert c["fem"]["max_rel_q_diff_vs_material_point"] < 1e-6


def test_burst_section_failure_exactly_where_w2_vanishes_along_the_path(xc):
    """The burst section (docs/burst.md): R = -2 from 0.90 of each part's drained peak. In the
    material point, the FE specimen and the 300-disk DEM sample, c held below its peak settles
    without giving energy back (E_c gained < W2_ext of the held step) and held past it releases
    energy (E_c gained >= 2 W2_ext: hmodel.burst_rule.energy_release, the same measure in the
    three parts), none undecided or unconverged; the DEM's kinematic probes pass the theory's
    verdict; the material point's c peak lies at or above the first W2 = 0 of the directional
    analysis (the path enters the cone there) and within 0.01 of it. The report has Eq. 1's
    terms of the FE and the DEM side by side."""
    out, c = xc
    b = c["burst"]
    assert set(b["parts"]) == {"hmodel", "fem", "dem"}
    for name, p in b["parts"].items():
        (d,) = p["paths"]
        assert d["peaked"] and d["at_w2_zero"] and d["undecided"] == 0, (name, d)
        assert d["release"]["below"]["ke_w2ext_max"] < 1.0 < 2.0 <= \
            d["release"]["past"]["ke_w2ext_max"], (name, d)
    assert b["parts"]["dem"]["paths"][0]["verdict"] == "passes"
    hm = b["parts"]["hmodel"]["paths"][0]
    assert 0.0 <= hm["eta_peak_c"] - b["eta_first_w2"] <= 0.01
    # the perfect FE specimen is homogeneous: its c peak is the material point's with the FE's
    # parameters (n_dir of the cross-check) to round-off, and the report says so beside Table I's
    fe = b["parts"]["fem"]["paths"][0]
    assert abs(fe["eta_peak_c"] - fe["mp_eta_peak_c"]) <= 1e-9
    rep = (out / "report.md").read_text()
    assert f"{fe['mp_eta_peak_c']:.4f} (the material point with the FE's parameters" in rep
    assert "## Failure made to happen" in rep and "(fig_burst_ke.png)" in rep
    assert (out / "fig_burst_ke.png").stat().st_size > 20_000
    assert "(fig_burst_eq1.png)" in rep and (out / "fig_burst_eq1.png").stat().st_size > 20_000
    assert "released it on every path that peaked" in rep
    for part in ("fem", "dem"):
        assert (out / "burst" / part / "burst.csv").exists()
    # the path's own W2 side by side: the material point's (its tangent) and the FE's (its
    # static path) cross 0 at their c peak (within the last step of the rise: 2 %), the DEM's
    # (kinematic probes at rest) at or before the largest c its dead load held, with the verdict
    wp = b["w2_paths"]
    for name in ("hmodel", "fem"):
        (d,) = wp[name]
        assert d["k_start"] > 0 and abs(d["cross_fraction"] - 1.0) <= 0.02, (name, d)
    (d,) = wp["dem"]
    assert d["k_start"] > 0 and d["verdict"] in ("passes", "contradicted", "no verdict")
    assert d["cross_fraction"] is None or d["cross_fraction"] <= 1.0 + 1e-12
    assert "(fig_burst_w2_path.png)" in rep and "The path's own W2, side by side" in rep
    assert (out / "fig_burst_w2_path.png").stat().st_size > 20_000
