"""python -m fem burst: the perfect specimen bursts iff held past its c peak (docs/burst.md).

One CI-sized run (1 x 2 quads, n_dir 36, R = -2, f = 0.90, the CLI's other defaults, dc from
the sizing rule) serves the checks of the mechanics and of the outputs; bad input is refused
before anything is computed."""
import csv
import json
import math

import meshio
import numpy as np
import pytest

import fem.__main__ as fcli
from fem.biaxial import BiaxialConfig
from fem.burst import BURST_COLUMNS, PATH_COLUMNS, BurstConfig, limit_bracket, run_burst
from fem.dynamics import HISTORY_COLUMNS
from fem.reference import material_point_curve, material_point_path
from hmodel import HParams
from hmodel.burst_rule import RELEASE, BurstRule, decide
from tests._interrupt import HANG_S, interrupt_after

SMALL = ["--nx", "1", "--ny", "2", "--n-dir", "36"]
SMALL_CFG = BiaxialConfig(nx=1, ny=2, n_dir=36, fields=False)


def _rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def _rule_dc(path_d_eps1=1e-5):
    """The sizing rule's dc [Pa] of the suite's configuration (docs/burst.md): what the path
    sampled in steps of ``path_d_eps1`` can have missed above its c peak, the slope before the
    peak x the step = c_peak - c_(peak - 1) (``CPeak.missed``), from the material point's path
    on the FE's steps (the perfect specimen's c row by row: test_c_peak_is_the_material_points)."""
    P = HParams(n_dir=36)
    eta = material_point_curve(P, 0.05)["eta_peak"]
    d = BiaxialConfig().d_eps1
    return material_point_path(P, 0.9 * eta, -2.0, d, path_d_eps1, 0.03)["cpeak"].missed()


@pytest.fixture(scope="module")
def rule_dc():
    return _rule_dc()


@pytest.fixture(scope="module")
def burst_run(tmp_path_factory, rule_dc):
    out = tmp_path_factory.mktemp("burst") / "run"
    assert fcli.main(["burst", *SMALL, "--dc", repr(rule_dc), "--quiet", "--out", str(out)]) == 0
    return out


def test_perfect_specimen_below_settles_past_bursts(burst_run, rule_dc):
    """Below the c peak (95 % of the rise) G + dG held settles; at the peak + dG (dc the sizing
    rule's, 23.5 Pa: past the path's true peak) the rule says failure and the growth measure
    tells them apart: past, E_c - E_c(0) passes RELEASE = 2 x W2_ext (the specimen gave back
    more than dG put in: W2_int < 0 by Eq. 1); below, it stays under W2_ext itself (Eq. 1 with
    W2_int >= 0 and D >= 0 from rest), never released. Nothing numerical failed in either run
    (the failure is the rule's, not a time step that did not converge)."""
    rows = {r["switch"]: r for r in _rows(burst_run / "burst.csv")}
    assert set(rows) == {"below", "past"}
    b, p = rows["below"], rows["past"]
    assert b["outcome"] == "equilibrium" and p["outcome"] == "failure"
    assert b["failure_reason"] == p["failure_reason"] == ""
    assert p["released"] == "1" and float(p["ke_w2ext_max"]) >= RELEASE
    assert 0 < float(p["t_release"]) <= float(p["t_end"])
    assert float(p["t_release_t1"]) == pytest.approx(float(p["t_release"]) / float(p["t1"]))
    assert b["released"] == "0" and float(b["ke_w2ext_max"]) <= 1.0
    assert math.isnan(float(b["t_release"])) and math.isnan(float(b["t_release_t1"]))
    assert float(p["w2_int_end"]) < 0 < float(b["w2_int_end"])
    assert float(b["ke_max"]) <= 1.5 * float(b["w2_ext_end"])
    # dc is the sizing rule's: past held it, below at most half of what is left of the rise
    assert float(p["dc"]) == pytest.approx(rule_dc) == pytest.approx(float(p["dc_rule"]))
    c0, cp = float(b["c_start"]), float(b["c_peak"])
    assert float(b["c_switch"]) >= c0 + 0.95 * (cp - c0) and float(p["c_switch"]) == cp
    assert float(b["dc"]) <= 0.5 * (cp - float(b["c_switch"]))


def test_energy_checks_every_step(burst_run):
    """Three balances, at every step of both runs:
    - Newmark's own, |dE_c - (dW_ext - dW_int - dD)|, an identity of the scheme for any mass
      and internal force: it measures the work of the Newton residual (<= 1e-6 of the
      second-order energies, the Newton tolerance's; measured 1e-10), as does its sum since
      the switch, |E_c - (W2_ext - W2_int - D)|;
    - the energy check Newmark cannot satisfy by itself (E_c at mid-step of the velocity field
      with the density, W2_int from the quadrature points' stresses and strain increments):
      at most (omega_1 dt)^2 / 16 = 6.2e-3 of the run's largest second-order energy, the
      one-degree-of-freedom elastic step response's at 20 steps a period (test_dynamics: its
      O(dt^2) residual -dv.M dv / 8); a response from a switch is softer than the elastic one
      that sets dt, so its scale is larger: these runs measure 1.4-1.7e-4. (This mesh's
      elastic step response, its higher modes excited, reaches 1.4e-2.) A mass x5 or an
      internal force x1.3 puts it at 0.1 or more;
    - W2_int from the stresses against the trapezoid of the nodal internal forces: 1e-9 (the
      same work by two routes; measured 3e-12).
    The check's residual is recomputed from the columns (no step was cut: one midpoint a step),
    W2_ext = dG dU1 exactly as hmodel.burst_rule reads it, and the outcome replayed by the rule.
    Newton: at most 2 iterations a step and 1.5 on average (measured 1.008 and 1.000: the
    perfect specimen's tangent is exact for the step's sliding pattern, a second iteration
    only where the pattern changes; a tangent off by 20 % takes 3.3 on average, by x3 7.5)."""
    hist = _rows(burst_run / "history.csv")
    assert len(hist) > 100
    for key in ("newton_work", "newton_work_sum"):
        assert max(float(h[key]) for h in hist) <= 1e-6, key
    rows = _rows(burst_run / "burst.csv")
    for r in rows:
        assert float(r["newton_work"]) <= 1e-6 and float(r["newton_work_sum"]) <= 1e-6
        assert float(r["energy_check"]) <= (2 * math.pi / 20) ** 2 / 16
        assert float(r["work_check"]) <= 1e-9
        assert float(r["newton_iters_mean"]) <= 1.5
    assert max(int(h["newton_iters"]) for h in hist) <= 2
    for sw in ("below", "past"):
        h = [x for x in hist if x["switch"] == sw]
        col = {k: np.array([float(x[k]) for x in h]) for k in HISTORY_COLUMNS}
        phi = col["w2_ext"] - col["w2_int_stress"] - col["damping_mid"]
        res = col["ke_mid"][1:] - 0.5 * (phi[:-1] + phi[1:])
        assert np.allclose(res, col["energy_check"][1:], rtol=1e-6, atol=1e-9 * phi.max())
        row = next(r for r in rows if r["switch"] == sw)
        dG = 0.05 * float(row["dc"])
        assert np.allclose(col["w2_ext"], dG * col["U1"], rtol=1e-9, atol=1e-20)
        # the outcome is the shared rule's, replayed on the recorded columns
        t1 = col["t"][1] * 20
        assert decide(col["t"], col["ke"], col["w2_ext"], col["eps1"],
                      BurstRule().window_periods * t1) == ("equilibrium" if sw == "below"
                                                           else "failure")
        assert decide(col["t"][:-1], col["ke"][:-1], col["w2_ext"][:-1], col["eps1"][:-1],
                      BurstRule().window_periods * t1) is None


def test_c_peak_is_the_material_points(burst_run):
    """The perfect specimen under the tie is the material point with every strain component
    controlled, on the same steps: the FE path's c equals the material point's at every row to
    1e-9 of p0 (both solve the same equations to Newton tolerance 1e-10), hence the c peak, in
    c and in eta, far within the issue's 1 %."""
    paths = _rows(burst_run / "paths.csv")
    fe = [r for r in paths if r["source"] == "fe"]
    mp = [r for r in paths if r["source"] == "material_point"]
    assert len(fe) == len(mp) > 10
    for a, b in zip(fe, mp):
        for k in ("c", "s1", "s2", "eps1", "eps2"):
            assert abs(float(a[k]) - float(b[k])) <= 1e-9 * 2e5 * (1 if k[0] in "cs" else 1e-5), k
    for r in _rows(burst_run / "burst.csv"):
        assert abs(float(r["c_peak_error"])) < 1e-2 and abs(float(r["eta_peak_error"])) < 1e-2
        assert abs(float(r["c_peak_error"])) < 1e-9
        assert float(r["c_peak"]) == pytest.approx(float(r["mp_c_peak"]), rel=1e-9)
        # the peak is interior: the path went on until c had fallen from it
        assert 0 < float(r["eps1_peak_c"]) < 0.03


def test_outputs(burst_run, rule_dc):
    """The contract's columns (docs/burst.md), the figures, summary.json (every row of
    burst.csv, with the growth measure and an empty failure_reason), and fields.xdmf with the
    past run's frames (displacement, velocity, the mode normalized to 1)."""
    for name, cols in (("burst.csv", BURST_COLUMNS), ("paths.csv", PATH_COLUMNS),
                       ("history.csv", ["ratio", "start_fraction", "switch"] + HISTORY_COLUMNS)):
        with open(burst_run / name) as f:
            assert f.readline().strip().split(",") == cols
    for f in ("ke.png", "balance.png", "path.png", "mode_R-2_f0.9_past.png", "summary.json"):
        assert (burst_run / f).stat().st_size > 0, f
    s = json.loads((burst_run / "summary.json").read_text())
    assert s["config"]["ratios"] == [-2.0] and s["dc"] == rule_dc
    for r in s["runs"]:
        assert {"ke_w2ext_max", "t_release", "t_release_t1", "released", "ke_growth",
                "energy_check", "newton_work"} <= set(r) and r["failure_reason"] == ""
    assert [r["released"] for r in s["runs"]] == [False, True]
    assert s["fields"]["run"] == {"ratio": -2.0, "start_fraction": 0.9, "switch": "past"}
    assert set(s["timings"]) >= {"drained", "paths", "dynamics", "total"}
    with meshio.xdmf.TimeSeriesReader(burst_run / "fields.xdmf") as r:
        r.read_points_cells()
        assert r.num_steps > 10
        t, pd, cd = r.read_data(r.num_steps - 1)
        assert {"displacement", "velocity", "mode"} <= set(pd) and "c" in cd
        assert np.max(np.linalg.norm(pd["mode"], axis=1)) == pytest.approx(1.0)


@pytest.mark.parametrize("argv,needles", [
    (["--ratios", "0"], ["--ratios", "R < 0"]),
    (["--ratios", "-2,0"], ["--ratios", "R < 0"]),
    (["--ratios", "1.5"], ["--ratios", "R < 0"]),
    (["--ratios", "nan"], ["--ratios", "finite"]),
    (["--ratios", "-inf"], ["--ratios", "finite"]),
    (["--dc", "-1"], ["--dc", ">= 0"]),
    (["--density", "0"], ["--density", "> 0"]),
    (["--density", "-1600"], ["--density", "> 0"]),
    (["--steps-per-period", "9"], ["--steps-per-period", ">= 10"]),
    (["--damping-ratio", "1"], ["--damping-ratio"]),
    (["--start-fractions", "1.0"], ["--start-fractions", "0 < f < 1"]),
    (["--path-strain", "0"], ["--path-strain"]),
    (["--path-d-eps1", "0.02", "--path-strain", "0.01"], ["--path-d-eps1"]),
    (["--sigma2", "-1"], ["--sigma2"]),
    (["--n-dir", "4"], ["--n-dir", ">= 8"]),
])
def test_bad_input_one_line_exit_2_nothing_written(tmp_path, capsys, no_computation, argv, needles):
    out = tmp_path / "out"
    assert fcli.main(["burst", *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "\n" not in err and "Traceback" not in err, err
    for n in needles:
        assert n in err, (n, err)
    assert not out.exists()


def test_the_switches_are_static_equilibria():
    """What the held runs start from, checked without the run's own load (f_ext = f(0) makes a
    dc = 0 run stand still whatever the state, so it proves nothing): at the below and past
    switches kept by the path (its replayed states, restored), the internal force on the free
    dofs is at most the static Newton's tolerance rtol sigma2 H (the tied problem has no load
    there), a zero increment from the committed material returns its stress to round-off, and
    G_switch = a . f_int is B times the volume average of c = s1 + R s2 of the stresses
    (virtual work; 1e-12) and the path's c at that row. A wrong state restored, a tie or a
    reduction unlike the static path's, would fail it."""
    import fem.burst as fb
    from fem.biaxial import build_problem
    from fem.dynamics import Tie, TiedDynamics, mass_matrix
    cfg = BurstConfig(specimen=SMALL_CFG, fields=False)
    prob = build_problem(cfg.specimen)
    eta = material_point_curve(prob.params, 0.05)["eta_peak"]
    start = fb._drained_starts(prob, cfg, eta, lambda line: None)[0.9]
    path, switches = fb._tied_path(prob, start, -2.0, cfg, lambda line: None)
    assert [n for n, _ in switches] == ["below", "past"]
    tol = cfg.specimen.rtol * prob.sigma2 * prob.height
    for name, snap in switches:
        fb._restore(prob, snap)
        tie = Tie(prob, -2.0)
        system = TiedDynamics(tie, mass_matrix(prob), snap.u, 0.0, 0.0)
        f0 = system.start()
        assert np.max(np.abs(f0[:-1])) <= tol, name
        committed = prob.material.stress()
        zero = prob.material.trial(np.zeros((2, 2, prob.npts))).sigma
        assert np.max(np.abs(zero - committed)) <= 1e-12 * prob.sigma2
        k = path["below"] if name == "below" else path["peak"]
        assert f0[-1] == pytest.approx(prob.width * snap.row["c"], rel=1e-12)
        assert snap.row["c"] == path["c"][k]


def test_dt_study_the_outcome_and_the_measure_do_not_move():
    """The time step is not what the growth measure measures: the suite's below and past runs
    (dc from the sizing rule) at 20, 40 and 60 steps a period keep their outcomes, RELEASE
    tells them apart at every dt (past passes 2 x W2_ext, below never passes W2_ext), and the
    past run passes RELEASE at the same time to within one time step of the coarsest (0.05 T1;
    measured 6.050, 6.025, 6.017 T1) -- where ke_growth, E_c over E_c after one step, grows with
    1/dt^2 (measured past 2.6e5 / 9.2e5 / 2.0e6, below 189 / 672 / 1470). The energy check
    converges with the integrator's order through the burst (measured 1.40e-4, 3.55e-5, 1.59e-5
    on the past run: order 1.98 then 2.0): its ratio from 20 to 60 steps is at least 3^1.8."""
    dc = _rule_dc()
    out = {}
    for n in (20, 40, 60):
        cfg = BurstConfig(specimen=SMALL_CFG, steps_per_period=n, dc=dc, fields=False)
        out[n] = {r["switch"]: r for r in run_burst(cfg).rows}
    for n, rows in out.items():
        b, p = rows["below"], rows["past"]
        assert (b["outcome"], p["outcome"]) == ("equilibrium", "failure"), n
        assert p["failure_reason"] == "" and b["failure_reason"] == ""
        assert p["released"] and p["ke_w2ext_max"] >= RELEASE
        assert not b["released"] and b["ke_w2ext_max"] <= 1.0
    t = [out[n]["past"]["t_release_t1"] for n in (20, 40, 60)]
    assert max(t) - min(t) <= 1.0 / 20, t
    e = [out[n]["past"]["energy_check"] for n in (20, 60)]
    assert e[0] / e[1] >= 3 ** 1.8, e


def test_dc_scan_brackets_the_dynamic_limit_load():
    """Statics against dynamics (``fem.burst.limit_bracket``): from the c peak the path samples,
    held at c_peak + dc, the specimen settles below a dynamic limit load and bursts above it,
    and that limit lies above the sampled peak by at most the sizing rule c_peak - c_(peak-1)
    (the path's true peak lies within a step): at the path's step 1e-5 the limit is 11.40-11.44
    Pa above the sampled peak (rule 23.5 Pa), at 5e-6 1.10-1.15 Pa (rule 11.8 Pa: the sampled
    peak one step of 5e-6 nearer the true one; finer steps sample the same strain and keep
    1.1 Pa). Bisected to 1 Pa: the bracket [lo, hi] inside [0, rule] at both steps, and the
    finer step's bracket below the coarser's (it shrinks with the path's step); the limit
    itself, c_peak + [lo, hi], the same at both steps to 1.5 Pa (each path's c differs by up to
    0.5 Pa with its step: the material's increments)."""
    b = {}
    for h in (1e-5, 5e-6):
        cfg = BurstConfig(specimen=SMALL_CFG, path_d_eps1=h, fields=False)
        b[h] = limit_bracket(cfg, tol=1.0)
        r = b[h]
        assert 0.0 < r["lo"] < r["hi"] <= r["dc_rule"] and r["hi"] - r["lo"] <= 1.0, r
        assert r["dc_rule"] == pytest.approx(_rule_dc(h), rel=1e-6)
        assert all(o in ("equilibrium", "failure") for _, o, _ in r["runs"])
    assert b[5e-6]["hi"] < b[1e-5]["lo"]
    lim = {h: (r["c_peak"] + r["lo"], r["c_peak"] + r["hi"]) for h, r in b.items()}
    assert abs(sum(lim[1e-5]) / 2 - sum(lim[5e-6]) / 2) <= 1.5, lim


def test_not_converged_is_its_own_outcome(tmp_path, monkeypatch):
    """A time step that converges at no substep (injected: every Newton of the past run from its
    30th time step on fails) ends that run as 'not_converged' -- never 'failure', whatever E_c
    did before -- with what failed in failure_reason, in burst.csv and summary.json; the below
    run is untouched; no collapse mode is drawn for it."""
    import fem.dynamics as fd
    from fem.solver import NewtonError
    real = fd.newmark_step
    systems, calls = [], []          # the systems held: an id() alone may be reused once freed

    def flaky(system, m, dt, *a, **k):
        k_sys = next((i for i, s in enumerate(systems) if s is system), None)
        if k_sys is None:
            systems.append(system)
            calls.append(0)
            k_sys = len(systems) - 1
        calls[k_sys] += 1
        if k_sys == 1 and calls[k_sys] >= 30:
            raise NewtonError("injected")
        return real(system, m, dt, *a, **k)
    monkeypatch.setattr(fd, "newmark_step", flaky)
    out = tmp_path / "nc"
    run_burst(BurstConfig(specimen=SMALL_CFG, fields=False), out)
    rows = {r["switch"]: r for r in _rows(out / "burst.csv")}
    assert rows["below"]["outcome"] == "equilibrium" and rows["below"]["failure_reason"] == ""
    assert rows["past"]["outcome"] == "not_converged"
    assert "did not converge even in substeps" in rows["past"]["failure_reason"]
    s = json.loads((out / "summary.json").read_text())
    assert [r["outcome"] for r in s["runs"]] == ["equilibrium", "not_converged"]
    assert "injected" in s["runs"][1]["failure_reason"]
    assert not list(out.glob("mode_*.png"))


def test_config_validate_names_the_option():
    with pytest.raises(ValueError, match="--ratios"):
        BurstConfig(ratios=(0.0,)).validate()
    with pytest.raises(ValueError, match="--steps-per-period"):
        BurstConfig(steps_per_period=5).validate()
    with pytest.raises(ValueError, match="rule.growth"):
        BurstConfig(rule=BurstRule(growth=0.5)).validate()
    assert BurstConfig().dc_value == pytest.approx(20.0) and math.isfinite(BurstConfig().density)


def test_sigterm_is_one_line_and_exit_143(tmp_path):
    """Interrupted in the dynamics: one line, exit 143, the rows so far whole and readable."""
    out = tmp_path / "run"
    # 2000 steps a period: the dynamics that the signal cuts would take minutes
    rc, lines = interrupt_after(["fem", "burst", *SMALL, "--steps-per-period", "2000", "--out",
                                 str(out)], "R = -2, f = 0.9, below: step")
    assert rc == 143
    assert len(lines) == 1 and lines[0].startswith("interrupted (SIGTERM) during R = -2"), lines
    paths = _rows(out / "paths.csv")
    assert len(paths) > 10 and all(len(r) == len(PATH_COLUMNS) for r in paths)
    hist = _rows(out / "history.csv")       # the interrupted run's steps so far, whole rows
    assert len(hist) > 40 and all(len(r) == 3 + len(HISTORY_COLUMNS) and r["newton_iters"]
                                  for r in hist)
    assert [int(r["step"]) for r in hist] == list(range(len(hist)))
    with open(out / "burst.csv") as f:
        assert f.readline().strip().split(",") == BURST_COLUMNS


@pytest.mark.slow
def test_bit_identical_for_any_thread_count(tmp_path):
    """4 x 8 quads (128 points: the material's parallel kernel) run with 1 and 2 Numba threads:
    history.csv and paths.csv the same bytes."""
    import os
    import subprocess
    import sys
    outs = []
    for n in ("1", "2"):
        out = tmp_path / f"t{n}"
        env = dict(os.environ, NUMBA_NUM_THREADS=n)
        subprocess.run([sys.executable, "-m", "fem", "burst", "--nx", "4", "--ny", "8", "--n-dir",
                        "36", "--no-fields", "--quiet", "--out", str(out)], check=True, env=env,
                       capture_output=True, timeout=HANG_S)
        outs.append(out)
    for f in ("history.csv", "paths.csv"):
        assert (outs[0] / f).read_bytes() == (outs[1] / f).read_bytes(), f


def test_progress_and_table_lines(tmp_path, capsys):
    """What `fem burst` prints (issue 26): the held force step dG = B dc in the header, W2_ext
    named as dG dU1 (it equals dU1 when dG = 1 N/m), a path that needs no Newton iteration
    said so instead of '0 Newton iterations', no '-0.000' and no 'nan'; the growth measure is
    the table's headline (the largest (E_c - E_c(0)) / W2_ext, when it passed RELEASE, 'never'
    for the below run), and E_c's growth over its first step is not printed."""
    assert fcli.main(["burst", *SMALL, "--out", str(tmp_path / "run")]) == 0
    cap = capsys.readouterr()
    err, out = cap.err, cap.out
    assert "(held force step dG = B dc = 1 N/m)" in err          # B = 0.05 m, dc = 20 Pa
    assert "W2_ext = dG dU1 = " in err
    assert " 0 Newton iterations" not in err
    assert ("every step converged at its predictor" in err) or (" Newton iterations" in err)
    for text in (err, out):
        assert "-0.000" not in text and "nan" not in text.lower(), text
    assert "max (E_c-E_c0)/W2_ext  t_release/T1" in out and "growth" not in out + err
    table = {line.split()[2]: line.split() for line in out.splitlines()
             if line.split()[:2] == ["-2", "0.9"]}
    assert table["below"][-3] == "never" and float(table["past"][-3]) > 0
    assert "E_c - E_c(0) passed 2 W2_ext at t = " in err


def test_validate_reads_the_vocabulary_it_writes_no_copy(monkeypatch):
    """The ranges of --dc and --path-strain are read from the vocabulary's terms at validate
    (issue 33): another term's range, narrower or wider, is followed (a copy written in
    validate would keep refusing or accepting by its own), and the message says the term's."""
    import dataclasses
    import common.options as O
    from common.options import term_of

    def refused(**kw):
        try:
            BurstConfig(specimen=SMALL_CFG, **kw).validate()
        except ValueError as e:
            return str(e)
        return None

    cases = {"--dc": ("dc", "dc", {"lo": 10.0}, 5.0, {"lo": -10.0}, -5.0),
             "--path-strain": ("path_strain", "path strain", {"hi": 0.2}, 0.3, {"hi": 0.9}, 0.7)}
    for name, (field, word, narrow, out, wide, now_in) in cases.items():
        term = O.VOCABULARY[name]
        assert term_of("BurstConfig", field) is term
        assert refused(**{field: out}) is None and refused(**{field: now_in})
        monkeypatch.setitem(O.VOCABULARY, name, dataclasses.replace(term, **narrow))
        msg = refused(**{field: out})
        assert msg and msg.startswith(f"{name} {out!r} is out of range: allowed "), (name, msg)
        assert O.VOCABULARY[name].range_text().replace("value", word) in msg, (name, msg)
        monkeypatch.setitem(O.VOCABULARY, name, dataclasses.replace(term, **wide))
        assert refused(**{field: now_in}) is None, name
        monkeypatch.setitem(O.VOCABULARY, name, term)


def test_validate_follows_the_terms_of_start_damping_and_steps(monkeypatch):
    """--start-fractions (its upper end open here: a start below the drained peak),
    --damping-ratio and --steps-per-period are read from the vocabulary at validate (issue 33):
    a narrower term refuses a value accepted before, a wider one accepts a value refused before."""
    import dataclasses
    import common.options as O

    def refused(**kw):
        try:
            BurstConfig(specimen=SMALL_CFG, **kw).validate()
        except ValueError as e:
            return str(e)
        return None

    cases = {"--start-fractions": ("start_fractions", {"lo": 0.5}, (0.3,), {"hi": 2.0}, (1.5,)),
             "--damping-ratio": ("damping_ratio", {"hi": 0.5}, 0.7, {"hi": 2.0}, 1.5),
             "--steps-per-period": ("steps_per_period", {"lo": 30}, 20, {"lo": 5}, 8)}
    for name, (field, narrow, out, wide, now_in) in cases.items():
        term = O.VOCABULARY[name]
        assert O.term_of("BurstConfig", field) is term
        assert refused(**{field: out}) is None and refused(**{field: now_in}), name
        monkeypatch.setitem(O.VOCABULARY, name, dataclasses.replace(term, **narrow))
        msg = refused(**{field: out})
        assert msg and msg.startswith(f"{name} "), (name, msg)
        monkeypatch.setitem(O.VOCABULARY, name, dataclasses.replace(term, **wide))
        assert refused(**{field: now_in}) is None, name
        monkeypatch.setitem(O.VOCABULARY, name, term)
    assert "0 < f < 1" in refused(start_fractions=(1.0,))     # f = 1 refused here, as before
