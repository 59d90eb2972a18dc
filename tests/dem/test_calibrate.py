"""`python -m dem calibrate` (dem/calibrate.py): the three figures of a curve, the deterministic
search, the checkpoint (resume reruns nothing, refuses other options), the outputs, bad input.

Most tests replace the DEM run by a synthetic one (``_synthetic_task``: the H-model's own curve
stretched in strain and in stress by factors that depend on kn_over_d and friction_deg), so the
search is exercised in well under a second per run; one test runs the real DEM on 100 disks."""
import csv
import functools
import json
import math
import os

import numpy as np
import pytest

from dem import calibrate as C
from dem.params import DemParams, load_params


# -- the figures ---------------------------------------------------------------------------------
def _parabola(qp=400e3, ep=0.02, de=1e-4, q0=0.0):
    e = np.arange(0.0, 2 * ep + de / 2, de)
    return e, q0 + qp * (2 * e / ep - (e / ep) ** 2)


def test_figures_of_a_synthetic_curve_exact():
    qp, ep = 400e3, 0.02
    e, q = _parabola(qp, ep)
    f = C.curve_figures(e, q, smooth=0.0)
    assert f["peak_q"] == pytest.approx(qp, rel=1e-12)
    assert f["eps1_peak"] == pytest.approx(ep, abs=1e-12)     # ep is a sample point
    assert f["secant"] == pytest.approx(qp * (2 / ep - 0.0025 / ep ** 2), rel=1e-9)
    # an offset q0 at eps1 = 0 (the DEM starts within 1 % of isotropic) is taken off the secant
    f0 = C.curve_figures(e, q + 5e3, smooth=0.0)
    assert f0["secant"] == pytest.approx(f["secant"], rel=1e-9)
    assert f0["peak_q"] == pytest.approx(qp + 5e3, rel=1e-12)


def test_secant_interpolates_linearly_between_samples():
    e = np.array([0.0, 0.002, 0.003, 0.01, 0.02])
    q = np.array([0.0, 100e3, 200e3, 300e3, 250e3])
    f = C.curve_figures(e, q, smooth=0.0)
    assert f["secant"] == pytest.approx(150e3 / 0.0025, rel=1e-12)   # halfway 100 -> 200 kPa
    assert (f["peak_q"], f["eps1_peak"]) == (300e3, 0.01)


def test_smoothing_is_exact_on_a_line_and_damps_noise():
    e = np.arange(0, 0.03, 1e-4)
    line = 1e7 * e + 3.0
    s = C.smoothed(e, line, 0.001)
    inner = (e > 0.001) & (e < 0.029)
    assert np.allclose(s[inner], line[inner], rtol=1e-12)
    # a noisy plateau: the raw maximum is the largest spike, the smoothed one stays near the mean
    qp, ep = 400e3, 0.015
    e, q = _parabola(qp, ep)
    rng = np.random.default_rng(0)
    noisy = q + rng.normal(0, 8e3, len(q))
    raw = C.curve_figures(e, noisy, smooth=0.0)
    sm = C.curve_figures(e, noisy, smooth=0.002)
    assert raw["peak_q"] > qp + 10e3
    assert abs(sm["peak_q"] / qp - 1) < 0.01
    assert abs(sm["eps1_peak"] / ep - 1) < 0.1


def test_curve_must_increase_and_reach_the_secant_strain():
    with pytest.raises(ValueError, match="increasing"):
        C.curve_figures([0, 0.002, 0.001, 0.003], [0, 1, 2, 3])
    with pytest.raises(ValueError, match="secant"):
        C.curve_figures([0, 0.001, 0.002], [0, 1, 2])


def test_compare_errors_tolerances_and_score():
    t = {"peak_q": 400e3, "eps1_peak": 0.02, "secant": 90e6}
    c = C.compare({"peak_q": 419e3, "eps1_peak": 0.0149, "secant": 110e6}, t)
    assert c["err_peak_q"] == pytest.approx(0.0475)
    assert c["met_peak_q"] and not c["met_eps1_peak"] and not c["met_secant"]
    assert not c["met"]
    assert c["score"] == pytest.approx((0.0475 / 0.05) ** 2 + (0.255 / 0.25) ** 2
                                       + ((110 / 90 - 1) / 0.2) ** 2)
    assert C.compare(t, t)["met"] and C.compare(t, t)["score"] == 0.0


# -- the search on a synthetic model --------------------------------------------------------------
@functools.lru_cache(maxsize=None)
def _hcurve():
    h = C.hmodel_curve(200e3)
    return np.asarray(h["eps1"]), np.asarray(h["q"]), np.asarray(h["eps_v"])


KN_OPT, FR_OPT = 11e9, 33.0      # where the synthetic DEM matches the H-model exactly


def _stretch(d):
    """Strain and stress factors of the synthetic DEM of parameters d (1, 1 at the optimum)."""
    return math.sqrt(KN_OPT / d["kn_over_d"]), d["friction_deg"] / FR_OPT


CALLS = {"n": 0}


def _synthetic_task(a):
    """Stands in for ``calibrate._evaluate_task``: same arguments, same result keys."""
    CALLS["n"] += 1
    se, sq = _stretch(a["params"])
    e, q, ev = _hcurve()
    e1 = np.arange(0.0, a["eps_max"] + 1e-12, 1e-4)
    res = {"key": a["key"], "params": a["params"],
           "curve": {"eps1": e1.tolist(), "q": (sq * np.interp(e1 / se, e, q)).tolist(),
                     "eps_v": np.interp(e1 / se, e, ev).tolist(), "p": [0.0] * len(e1)},
           "porosity": 0.16, "compaction_converged": True, "steps": 1000, "wall_time": 0.01}
    if a.get("crash_after_result") and a["work_dir"]:
        # as if the process were killed after it finished, before the main process logged it
        from dem.io import atomic_write_bytes
        atomic_write_bytes(os.path.join(a["work_dir"], "result.json"), json.dumps(res).encode())
    return res


def _space():
    return C.make_space(("kn_over_d", "friction_deg"), DemParams(n=100),
                        {"kn_over_d": (2e9, 32e9), "friction_deg": (20.0, 50.0)})


def _figs_evaluate(log):
    """evaluate() for pattern_search straight on the synthetic model (no files)."""
    e_h, q_h, _ = _hcurve()
    target = C.curve_figures(e_h, q_h, 0.0)
    space = _space()

    def evaluate(points, stage):
        out = []
        for v in points:
            d = dict(zip(space.names, v))
            se, sq = _stretch(d)
            fig = {"peak_q": sq * target["peak_q"], "eps1_peak": se * target["eps1_peak"],
                   "secant": sq / se * target["secant"]}
            rec = C.compare(fig, target)
            rec["index"] = len(log)
            log.append((stage, v))
            out.append(rec)
        return out
    return evaluate


def test_search_is_deterministic_meets_the_targets_and_respects_the_budget():
    space = _space()
    log1, log2 = [], []
    b1, seen1, tr1, why1 = C.pattern_search(space, _figs_evaluate(log1), start=(32e9, 35.0),
                                            grid=3, min_step=1 / 64, max_evals=60)
    b2, _, tr2, _ = C.pattern_search(space, _figs_evaluate(log2), start=(32e9, 35.0),
                                     grid=3, min_step=1 / 64, max_evals=60)
    assert log1 == log2 and tr1 == tr2
    assert why1 == "targets met" and b1["met"]
    # the start set is on the grid (32e9, 35): evaluated once
    assert len(log1) == len(set(v for _, v in log1)) == len(seen1)
    assert [s for s, _ in log1[:9]] == ["start"] + ["grid"] * 8
    # every refinement batch has at most 2 d = 4 points
    assert all(t["evaluated"] <= 4 for t in tr1 if t["stage"].startswith("refine"))
    # a budget: never more evaluations than max_evals, and the path is a prefix of the longer one
    log3 = []
    b3, seen3, _, why3 = C.pattern_search(space, _figs_evaluate(log3), start=(32e9, 35.0),
                                          grid=3, min_step=1 / 64, max_evals=11)
    assert len(seen3) == 11 and why3 == "max_evals reached" and log3 == log1[:11]


def test_space_maps_and_rounds():
    s = _space()
    assert s.values((0, 0)) == (2e9, 20.0) and s.values((1, 1)) == (32e9, 50.0)
    assert s.values((0.5, 0.5)) == (8e9, 35.0)              # log midpoint of kn, linear of friction
    assert s.values((0.3, 0.3))[0] == float(f"{2e9 * 16 ** 0.3:.4g}")
    assert s.u_of((8e9, 35.0)) == pytest.approx((0.5, 0.5))
    assert s.u_of((64e9, 35.0)) is None


# -- the command on the synthetic model ----------------------------------------------------------
def _run(tmp, **kw):
    opts = dict(vary=("kn_over_d", "friction"), bounds={"kn_over_d": (2e9, 32e9)}, grid=3,
                min_step=1 / 32, max_evals=40, eps_max=0.035, workers=1, verbose=False,
                task=_synthetic_task)
    opts.update(kw)
    return C.run_calibration(str(tmp), DemParams(n=100, seed=3), **opts)


def _csv(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_outputs_and_resume_reruns_nothing(tmp_path):
    CALLS["n"] = 0
    s = _run(tmp_path)
    n_run = CALLS["n"]
    assert s["met"] and s["run_now"] == n_run == s["evaluations"] and s["stopped"] == "targets met"
    for f in ("calibrated.json", "calibration.csv", "curves.csv", "calibration.png",
              "calibration_search.png", "evaluations.jsonl", "summary.json"):
        assert (tmp_path / f).is_file(), f
    assert not (tmp_path / "work").exists()
    p = load_params(tmp_path / "calibrated.json")
    assert p.n == 100 and p.seed == 3
    assert (p.kn_over_d, p.friction_deg) == tuple(s["best"]["values"])
    rows = _csv(tmp_path / "calibration.csv")
    assert list(rows[0]) == ["kind", "index", "stage", "kn_over_d", "friction_deg"] + C.CSV_FIXED
    assert rows[0]["kind"] == "hmodel" and float(rows[0]["peak_q"]) == pytest.approx(428.3e3, rel=1e-3)
    assert float(rows[0]["eps1_peak"]) == pytest.approx(0.0209, abs=1e-4)
    dem = [r for r in rows if r["kind"] == "dem"]
    assert len(dem) == n_run and [int(r["index"]) for r in dem] == list(range(n_run))
    assert dem[0]["stage"] == "start" and float(dem[0]["friction_deg"]) == 35.0
    best = min(dem, key=lambda r: (r["met"] != "1", float(r["score"])))
    assert int(best["index"]) == s["best"]["index"] and best["met"] == "1"
    # the synthetic model is exact at (11e9, 33): the best set is close to it
    assert abs(p.friction_deg / FR_OPT - 1) <= 0.05 and abs(math.sqrt(KN_OPT / p.kn_over_d) - 1) <= 0.25
    curves = _csv(tmp_path / "curves.csv")
    assert {r["curve"] for r in curves} == {"hmodel", "dem_start", "dem_calibrated"}
    summ = json.loads((tmp_path / "summary.json").read_text())
    assert summ["options"]["vary"] == ["kn_over_d", "friction_deg"]
    assert summ["target_figures"]["peak_q"] == pytest.approx(428.3e3, rel=1e-3)
    before = (tmp_path / "calibration.csv").read_text()
    lines = (tmp_path / "evaluations.jsonl").read_text().count("\n")
    # --resume: nothing runs, the same outputs
    CALLS["n"] = 0
    s2 = _run(tmp_path, resume=True)
    assert CALLS["n"] == 0 and s2["run_now"] == 0 and s2["taken_from_checkpoint"] == n_run
    assert (tmp_path / "calibration.csv").read_text() == before
    assert (tmp_path / "evaluations.jsonl").read_text().count("\n") == lines
    # a larger budget on --resume is allowed (and reruns nothing already done)
    CALLS["n"] = 0
    s3 = _run(tmp_path, resume=True, max_evals=80)
    assert CALLS["n"] == 0 and s3["evaluations"] == n_run


def test_resume_reads_a_checkpoint_of_a_version_without_a_newer_field(tmp_path):
    """A field added to DemParams later, at its default (which keeps the earlier behaviour),
    does not make a checkpoint foreign: written without normal_damping_ratio, it resumes
    with nothing rerun; at another value of that field it is refused."""
    CALLS["n"] = 0
    _run(tmp_path, max_evals=5)
    ck = tmp_path / "evaluations.jsonl"
    lines = [json.loads(l) for l in ck.read_text().splitlines()]
    del lines[0]["header"]["start_params"]["normal_damping_ratio"]
    for r in lines[1:]:
        del r["params"]["normal_damping_ratio"]
    ck.write_text("\n".join(json.dumps(r) for r in lines) + "\n")
    CALLS["n"] = 0
    s = _run(tmp_path, max_evals=5, resume=True)
    assert CALLS["n"] == 0 and s["taken_from_checkpoint"] == 5
    ck.write_text("\n".join(json.dumps(r) for r in lines) + "\n")
    with pytest.raises(ValueError, match="normal_damping_ratio: 0.0 there, 0.1 now"):
        C.run_calibration(str(tmp_path), DemParams(n=100, seed=3, normal_damping_ratio=0.1),
                          vary=("kn_over_d", "friction"), bounds={"kn_over_d": (2e9, 32e9)},
                          grid=3, min_step=1 / 32, max_evals=5, workers=1, verbose=False,
                          task=_synthetic_task, resume=True)


@pytest.mark.parametrize("change,what", [({"base_n": 120}, "n"), ({"vary": ("kn_over_d",)}, "vary"),
                                         ({"grid": 4}, "grid"), ({"base_seed": 4}, "seed"),
                                         ({"rate": 0.02}, "rate")])
def test_resume_refuses_a_folder_made_with_other_options(tmp_path, change, what):
    _run(tmp_path, max_evals=3)
    before = (tmp_path / "evaluations.jsonl").read_text()
    kw = {k: v for k, v in change.items() if not k.startswith("base_")}
    base = DemParams(n=change.get("base_n", 100), seed=change.get("base_seed", 3))
    opts = dict(vary=("kn_over_d", "friction"), bounds={"kn_over_d": (2e9, 32e9)}, grid=3,
                min_step=1 / 32, max_evals=3, workers=1, verbose=False, task=_synthetic_task,
                resume=True)
    opts.update(kw)
    if "vary" in kw:
        opts["bounds"] = None
    with pytest.raises(ValueError, match=rf"other options \(.*{what}"):
        C.run_calibration(str(tmp_path), base, **opts)
    assert (tmp_path / "evaluations.jsonl").read_text() == before


def _interrupting_task(limit, after_result=False):
    def task(a):
        if CALLS["n"] >= limit:
            if after_result:
                _synthetic_task(dict(a, crash_after_result=True))
            raise KeyboardInterrupt
        return _synthetic_task(a)
    return task


@pytest.mark.parametrize("after_result", [False, True])
def test_interrupted_run_keeps_finished_evaluations_and_resume_runs_the_rest(tmp_path, after_result):
    CALLS["n"] = 0
    ref = _run(tmp_path / "ref")
    total = ref["evaluations"]
    CALLS["n"] = 0
    with pytest.raises(KeyboardInterrupt):
        _run(tmp_path / "cut", task=_interrupting_task(5, after_result))
    recs = [json.loads(l) for l in (tmp_path / "cut" / "evaluations.jsonl").read_text().splitlines()]
    assert "header" in recs[0] and len(recs) == 1 + 5
    assert len(_csv(tmp_path / "cut" / "calibration.csv")) >= 2     # the finished batches
    CALLS["n"] = 0
    s = _run(tmp_path / "cut", resume=True)
    # the evaluation that finished in work/ but was not logged is not run again
    assert CALLS["n"] == total - 5 - (1 if after_result else 0)
    assert s["run_now"] == CALLS["n"] and s["evaluations"] == total
    assert ((tmp_path / "cut" / "calibration.csv").read_text()
            == (tmp_path / "ref" / "calibration.csv").read_text())
    assert (tmp_path / "cut" / "calibrated.json").read_text() == \
        (tmp_path / "ref" / "calibrated.json").read_text()


def test_process_pool_gives_the_same_result(tmp_path):
    a = _run(tmp_path / "one", max_evals=12)
    b = _run(tmp_path / "two", max_evals=12, workers=2)
    strip = lambda t: [r for r in _csv(t) if r.pop("wall_time") is not None]
    assert strip(tmp_path / "one" / "calibration.csv") == strip(tmp_path / "two" / "calibration.csv")
    assert a["best"]["values"] == b["best"]["values"]


# -- the command line, on the real DEM ------------------------------------------------------------
def _cli(argv, capsys):
    from dem.__main__ import main
    with pytest.raises(SystemExit) as e:
        main(argv)
    return e.value.code, capsys.readouterr().err.strip().splitlines()


TINY = ["--n", "100", "--rate", "0.05", "--eps-max", "0.02", "--post-peak-strain", "0.005",
        "--vary", "kn_over_d", "--grid", "2", "--max-evals", "3", "--workers", "1"]


def test_cli_end_to_end_on_100_disks_and_resume(tmp_path, capsys):
    from dem.__main__ import main
    out = tmp_path / "cal"
    main(["calibrate", "--out", str(out)] + TINY)
    cap = capsys.readouterr()
    assert "[calibrate] evaluation 1 of 1 so far (start" in cap.err
    assert "targets NOT all met" in cap.out or "all targets met" in cap.out
    rows = _csv(out / "calibration.csv")
    assert [r["stage"] for r in rows] == ["target", "start", "grid", "refine1"]
    p = load_params(out / "calibrated.json")
    assert p.n == 100 and p.friction_deg == 35.0
    assert float(rows[1]["kn_over_d"]) == 32e9 and float(rows[2]["kn_over_d"]) == 2e9
    # each evaluation compacts its own sample: a softer sample has a lower secant modulus
    assert float(rows[2]["secant"]) < float(rows[1]["secant"])
    before = (out / "evaluations.jsonl").read_text()
    main(["calibrate", "--out", str(out), "--resume"] + TINY)
    cap = capsys.readouterr()
    assert "3 finished evaluations in" in cap.err and "to run" not in cap.err
    assert "(0 run now, 3 from the checkpoint)" in cap.out
    assert (out / "evaluations.jsonl").read_text() == before
    code, err = _cli(["calibrate", "--out", str(out), "--resume"] + TINY[2:] + ["--n", "120"],
                     capsys)
    assert code == 2 and len(err) == 1 and "other options" in err[0] and "--resume" in err[0]


BAD = [
    (["--vary", "foo"], "--vary"),
    (["--vary", "n"], "--vary"),
    (["--vary", "kn_over_d,kn_over_d"], "--vary"),
    (["--vary", "friction", "--bounds", "friction=50:20"], "--bounds"),
    (["--vary", "friction", "--bounds", "friction=20:95"], "--bounds"),
    (["--vary", "friction", "--bounds", "kn_over_d=1e9:2e9"], "--bounds"),
    (["--vary", "friction", "--grid", "1"], "--grid"),
    (["--vary", "friction", "--max-evals", "0"], "--max-evals"),
    (["--vary", "friction", "--eps-max", "0.001"], "--eps-max"),
    (["--vary", "friction", "--eps-max", "0.02", "--post-peak-strain", "0.03"],
     "--post-peak-strain"),
    (["--vary", "friction", "--smooth", "-1"], "--smooth"),
    (["--vary", "friction", "--target", "fem"], "--target"),
    (["--vary", "friction", "--workers", "0"], "--workers"),
    (["--vary", "friction", "--workers", "1", "--scheduler", "tcp://x:1"], "--scheduler"),
    (["--vary", "friction", "--friction", "95"], "--friction"),
]


@pytest.mark.parametrize("argv,option", BAD)
def test_bad_option_is_one_line_exit_2_nothing_written(tmp_path, capsys, argv, option):
    out = tmp_path / "out"
    code, err = _cli(["calibrate", "--out", str(out), "--n", "50"] + argv, capsys)
    assert code == 2 and len(err) == 1 and err[0].startswith("error:") and option in err[0], err
    assert not out.exists()


def test_default_vary_needs_its_fields(tmp_path, capsys):
    """The default --vary includes rolling_friction: without it in DemParams, one line naming
    --vary and the allowed names; with it, the default parses."""
    names = {f for f in C.calibratable_fields()}
    if "rolling_friction" in names:
        assert C.parse_vary(C.DEFAULT_VARY) == ("kn_over_d", "friction_deg", "rolling_friction")
        return
    out = tmp_path / "out"
    code, err = _cli(["calibrate", "--out", str(out)], capsys)
    assert code == 2 and len(err) == 1 and "--vary" in err[0] and "rolling_friction" in err[0]
    assert "allowed: " in err[0] and "kn_over_d" in err[0]
    assert not out.exists()


def test_dask_cluster_gives_the_same_evaluations_as_local_runs(tmp_path):
    """The real DEM evaluation (100 disks) on a two-worker dask cluster (each in a temporary
    folder of its worker) and in this process: the same curves and figures."""
    distributed = pytest.importorskip("distributed")
    kw = dict(vary=("kn_over_d",), grid=2, max_evals=2, rate=0.05, eps_max=0.02,
              post_peak_strain=0.005, verbose=False)
    base = DemParams(n=100, seed=2)
    C.run_calibration(str(tmp_path / "local"), base, workers=1, **kw)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        C.run_calibration(str(tmp_path / "dask"), base, scheduler=cluster.scheduler_address, **kw)
    strip = lambda t: [r for r in _csv(t) if r.pop("wall_time") is not None]
    assert strip(tmp_path / "local" / "calibration.csv") == strip(tmp_path / "dask" / "calibration.csv")
    assert (tmp_path / "local" / "curves.csv").read_text() == (tmp_path / "dask" / "curves.csv").read_text()
    assert not (tmp_path / "dask" / "work").exists()


def test_sigterm_is_one_line_and_resume_keeps_the_finished_evaluations(tmp_path, capsys):
    import signal
    from tests._interrupt import interrupt_after
    out = tmp_path / "cal"
    rc, err = interrupt_after(["dem", "calibrate", "--out", str(out)] + TINY, "[calibrate] grid:",
                              sig=signal.SIGTERM)
    assert rc == 143, err
    assert err[-1].startswith("interrupted (SIGTERM) during dem calibrate, grid batch after 1 "
                              "evaluations") and "--resume" in err[-1], err
    assert "evaluations.jsonl" in err[-1] and "calibration.csv" in err[-1]
    assert len(_csv(out / "calibration.csv")) == 2          # the target and the start set
    from dem.__main__ import main
    main(["calibrate", "--out", str(out), "--resume"] + TINY)
    cap = capsys.readouterr()
    assert "1 finished evaluations in" in cap.err and "(start" not in cap.err
    assert [r["stage"] for r in _csv(out / "calibration.csv")] == ["target", "start", "grid",
                                                                  "refine1"]
