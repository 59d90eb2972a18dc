"""The commands when a path has no static state under its control (issue 25): a result with
every computed row (exit 0); a Newton failure where a state exists: exit 1 with the rows so far;
Ctrl-C / SIGTERM: the rows so far; the fit pays a stated penalty; the burst's time steps cut."""
import json
import signal

import numpy as np
import pytest

import hmodel.cli as cli
import point.cli
from hmodel import HParams
from hmodel.driver import MixedControlError, drained_biaxial, isotropic_state, run_path
from common.io import read_csv
from tests._interrupt import interrupt_after

JUMP = ["--phi-g", "40", "--alpha0", "55"]       # the published failure (discontinuous at 0.2 %)


def test_biaxial_writes_its_path_to_the_end_and_says_why(tmp_path, capsys):
    out = tmp_path / "b"
    assert cli.main(["biaxial", *JUMP, "--eps1-max", "0.01", "--out", str(out), "--quiet"]) == 0
    text = capsys.readouterr().out
    c = read_csv(out / "biaxial.csv")
    s = json.loads((out / "summary.json").read_text())
    end = s["end"]
    assert s["outcome"] == end["outcome"] == "discontinuous"
    assert len(c["eps1"]) - 1 == s["steps"] and c["eps1"][-1] == pytest.approx(end["eps"][0])
    assert 0.0019 <= c["eps1"][-1] <= 0.0021 and np.allclose(c["s2"], 200e3, rtol=1e-9)
    assert end["control"] == "eps11, eps12 prescribed, s22 held" and end["verdict"]["jump"] > 100
    assert min(end["verdict"]["det"]) > 0 and min(end["verdict"]["w2"]) > 0
    assert s["steps_cut"] and "python -m hmodel burst" in s["burst"]
    assert "outcome: discontinuous at eps1 = 0.20" in text and "python -m hmodel burst" in text
    for f in ("fig4_q_eps1.png", "fig5_epsv_eps1.png"):
        assert (out / f).stat().st_size > 10_000


def test_biaxial_complete_says_so(tmp_path, capsys):
    out = tmp_path / "b"
    assert cli.main(["biaxial", "--eps1-max", "0.005", "--d-eps1", "1e-4", "--n-dir", "36",
                     "--out", str(out), "--quiet"]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["outcome"] == "complete" and s["steps_cut"] == {} and "verdict" not in s["end"]
    assert "outcome: complete" in capsys.readouterr().out


def test_newton_failure_with_a_state_is_exit_1_with_the_rows(tmp_path, capsys, monkeypatch):
    """A MixedControlError (a static state exists, Newton did not reach it): exit 1, one line
    with the residual, the rows computed so far written."""
    P = HParams(n_dir=16)
    part = run_path(isotropic_state(P), P, drained_biaxial(1e-4), 7)

    def fails(*a, **k):
        e = MixedControlError("drained biaxial, step 8: a static state exists ... residual 3.1e-03 Pa")
        e.partial = part
        raise e
    monkeypatch.setattr(point.cli, "biaxial_test", fails)    # python -m hmodel's commands
    out = tmp_path / "b"
    assert cli.main(["biaxial", "--n-dir", "16", "--out", str(out), "--quiet"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("error: drained biaxial, step 8") and "residual" in err[-1]
    assert len(read_csv(out / "biaxial.csv")["eps1"]) == 8


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_interrupted_biaxial_keeps_every_row(tmp_path, sig, code):
    out = tmp_path / "b"
    # the signal goes at the first progress line (stderr is a pipe: plain lines, the first at a
    # tenth of the path, "drained biaxial: 45000/450000 steps (10 %), ..."), in a run of 450,000
    # steps that no machine finishes in between
    rc, err = interrupt_after(["hmodel", "biaxial", "--n-dir", "8", "--eps1-max", "0.45",
                               "--d-eps1", "1e-6", "--out", str(out)],
                              "drained biaxial: ", sig=sig)
    assert rc == code and "biaxial.csv" in err[-1]
    c = read_csv(out / "biaxial.csv")
    n = len(c["eps1"])
    assert 45_000 < n < 450_000 and np.allclose(c["eps1"], 1e-6 * np.arange(n), rtol=1e-9, atol=1e-15)


def test_domain_names_a_path_that_ends(tmp_path, capsys):
    out = tmp_path / "d"
    assert cli.main(["domain", "--sigma2", "200e3", *JUMP, "--n-dir", "36", "--n-probes", "36",
                     "--d-eps1", "1e-5", "--workers", "1", "--out", str(out)]) == 0
    c = read_csv(out / "domain.csv")
    assert list(c) == ["sigma2", "p_w2", "q_w2", "p_w2sigma", "q_w2sigma", "p_peak", "q_peak",
                       "eps1_w2", "eps1_w2sigma", "eps1_peak"]       # the columns of before
    s = json.loads((out / "summary.json").read_text())
    assert s["paths"][0]["outcome"] == "discontinuous" and "discontinuous at eps1" in s["paths"][0]["end"]
    assert "ends discontinuous at eps1" in capsys.readouterr().out


def test_probes_mark_stress_directions_without_solution(tmp_path, monkeypatch):
    """A stress probe direction with no static strain response is a result, marked on the
    polar figure (fig8): the CLI hands the figure the directions whose n_solutions is 0."""
    import hmodel.experiment as experiment      # the CLI's directional analysis calls it there
    seen = {}
    real = experiment.stress_probes

    def some_none(*a, **k):
        sp = real(*a, **k)
        n = sp.n_solutions.copy()
        n[::3] = 0
        return sp._replace(n_solutions=n)

    def fig(series, path, title="", no_solution=None, **kw):
        seen["none"] = np.asarray(no_solution)
        return probes_fig(series, path, title=title, no_solution=no_solution, **kw)
    probes_fig = cli.plots.fig_polar_w2
    monkeypatch.setattr(experiment, "stress_probes", some_none)
    monkeypatch.setattr(cli.plots, "fig_polar_w2", fig)
    out = tmp_path / "p"
    assert cli.main(["probes", "--n-dir", "16", "--n-probes", "16", "--d-eps1", "2e-4", "--stress-step", "30",
                     "--eta-a", "0.9", "--out", str(out)]) == 0
    assert np.array_equal(seen["none"], np.arange(0.0, 360.0, 30.0)[::3])
    assert (out / "fig8_polar_w2.png").stat().st_size > 10_000
    assert json.loads((out / "summary.json").read_text())["stress_probes_without_solution"] == 4


def test_probes_before_a_path_that_ends(tmp_path, capsys):
    """Point A beyond the end of the drained path: one line naming --eta's reach and why."""
    assert cli.main(["probes", *JUMP, "--n-dir", "36", "--eta-a", "1.0", "--out", str(tmp_path / "p")]) == 2
    err = capsys.readouterr().err
    assert "eta = 1.0 is never reached" in err and "the path ends discontinuous" in err


def test_fit_penalty_where_the_path_ends():
    """A parameter set whose drained path ends before the data's last strain: q = 0 beyond, so
    every point beyond costs its own q (docs/fit.md); finite residuals, no exception."""
    from hmodel.fit import _Problem, make_curve, model_curve
    P = HParams(phi_g=40.0, alpha0=55.0, n_dir=36)
    e1 = np.linspace(0.0, 0.01, 101)
    q, v, fail = model_curve(P, e1, 1e-5)
    assert 0.0019 <= fail <= 0.0021 and np.all(q[e1 > fail] == 0) and np.all(q[1:][e1[1:] <= fail] > 0)
    data = make_curve(e1, 1e5 * np.sin(np.pi * e1 / 0.02), sigma2=200e3)
    prob = _Problem(data, P, ("phi_g", "alpha0"), 0.0)
    r = prob.residuals(prob.x_of(P), 1e-5)
    beyond = e1 > fail
    assert np.all(np.isfinite(r)) and np.allclose(r[beyond], -data.q[beyond] / data.q.max())


def test_burst_hold_cuts_a_time_step_and_ends_a_failure_that_cannot_converge(monkeypatch):
    """The material point's dynamics: a time step whose Newton fails is run in substeps (their
    Newmark balance exact: the step's stays at round-off; the energy check, each half its own
    midpoint, within its healthy 1e-3); one that fails however small ends the run as
    'not_converged' (never 'failure': the integrator stopped, not the specimen), the rows so
    far kept, what failed stated."""
    import hmodel.burst as hb
    P = HParams(n_dir=36)
    from hmodel.experiment import state_at_eta
    st = state_at_eta(P, 0.9)[1]
    c0 = float(hb.conjugate_stress(st.stress[[0, 1], [0, 1]], -2.0))
    real = hb._tie_newmark
    calls = {"n": 0}

    def flaky(st_, params, ratio, m, damp, B, H, G_ext, dt, v, a, x, tol, max_iter):
        calls["n"] += 1
        if calls.get("mode") == "once" and calls["n"] == 4:
            raise hb._NewtonFailed("injected")
        if calls.get("mode") == "always" and calls["n"] >= 6:
            raise hb._NewtonFailed("injected")
        return real(st_, params, ratio, m, damp, B, H, G_ext, dt, v, a, x, tol, max_iter)
    monkeypatch.setattr(hb, "_tie_newmark", flaky)
    calls["mode"] = "once"
    r = hb.hold(st, P, -2.0, c0 + 20.0)
    assert r.cut_steps == {4: 1} and r.failure_reason == ""
    assert np.max(r.history["newton_work"]) < 1e-6 and r.history["t"][4] == pytest.approx(4 * r.dt)
    from hmodel.burst_rule import check_columns
    assert check_columns(r.history)["energy_check"] <= 1e-3
    calls.update(n=0, mode="always")
    r = hb.hold(st, P, -2.0, c0 + 20.0)
    assert r.outcome == "not_converged" and "did not converge" in r.failure_reason
    assert len(r.history["t"]) == 6


def test_interrupted_domain_keeps_the_pressures_finished(tmp_path):
    out = tmp_path / "d"
    rc, err = interrupt_after(["hmodel", "domain", "--sigma2", "100e3,200e3,300e3,400e3,500e3,600e3",
                               "--n-dir", "36", "--n-probes", "36", "--d-eps1", "1e-6", "--workers", "1",
                               "--out", str(out)], "domain: sigma2 = 100000 Pa done", sig=signal.SIGINT)
    assert rc == 130 and "domain.csv (" in err[-1]
    c = read_csv(out / "domain.csv")
    assert 100e3 in list(c["sigma2"]) and len(c["sigma2"]) < 6
