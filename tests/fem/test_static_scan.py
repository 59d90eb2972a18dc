"""The FE's decision when a load step fails however cut (issue 25): ``solver.static_scan``, the
one-parameter scan of the platen displacement along the equilibrium path, on a problem whose
answer is known (a softening spring in series with a stiff one: snap-back), and the run's
handling of it (fem biaxial ends with the outcome, every converged row written, exit 0); the
dynamic solve's time steps cut, and the failure recorded when none converges."""
import json
import math
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp

import fem.solver as solver
from fem.solver import LoadStepper, NewtonError, StaticLoss, static_scan

K_A, X0, K_B = 1.0, 1.0, 0.05       # f_A(x) = K_A x exp(-x / X0) in series with K_B: snap-back


def f_a(x):
    return K_A * x * np.exp(-x / X0)


def df_a(x):
    return K_A * (1.0 - x / X0) * np.exp(-x / X0)


class Springs:
    """Two dofs: u0 (free, the node between the springs), u1 (the platen, prescribed delta).
    Spring A between the ground and u0 (softening f_A), B between u0 and u1 (linear K_B). The
    'strain' of a state is (u0, u1 - u0); the material's committed strain and its trial from it
    follow fem.adapter.MaterialField's contract."""

    def __init__(self):
        self.free, self.prescribed = np.array([0]), np.array([1])
        self.f_lat = np.zeros(2)
        self.sigma2, self.height = 0.01, 100.0          # f_ref = sigma2 height = 1
        self.ndofs = 2
        self.material = self
        self.e = np.zeros(2)

    # the problem
    def strain(self, u):
        return np.array([u[0], u[1] - u[0]])

    def internal_force(self, s):
        return np.array([s[0] - s[1], s[1]])

    def stiffness(self, D):
        return sp.csr_matrix(np.array([[D[0] + D[1], -D[1]], [-D[1], D[1]]]))

    def prescribed_values(self, delta):
        return np.array([delta])

    # the material
    def trial(self, d):
        e = self.e + d
        return SimpleNamespace(sigma=np.array([f_a(e[0]), K_B * e[1]]),
                               D=np.array([df_a(e[0]), K_B]), e=e)

    def commit(self, trial):
        self.e = trial.e.copy()

    def stress(self):
        return self.trial(np.zeros(2)).sigma

    def pattern_changes(self, a, b):
        return 0


def turning_point():
    """u0 where d delta / d u0 = 1 + f_A'(u0) / K_B = 0, and delta there (bisection)."""
    lo, hi = 1.0, 2.0
    for _ in range(200):
        m = 0.5 * (lo + hi)
        lo, hi = (m, hi) if 1.0 + df_a(m) / K_B > 0 else (lo, m)
    return lo, lo + f_a(lo) / K_B


def test_static_scan_finds_the_snap_back():
    """From a state before the turning point, the step beyond it: 'uncontrollable' at the
    analytic delta_max (1e-6), det K_ff = f_A' + K_B changing sign there, lam_min with it."""
    x_t, d_max = turning_point()
    prob = Springs()
    x = x_t - 0.05
    d = x + f_a(x) / K_B
    prob.commit(prob.trial(np.array([x, d - x])))
    last = (0.01 * np.array([1.0 / (1.0 + df_a(x) / K_B), 1.0]), 0.01)   # a step of 0.01 in delta
    v = static_scan(prob, np.array([x, d]), d, 0.5, last)
    assert v.outcome == "uncontrollable" and v.det_sign == (1, -1)
    assert v.lam_min[0] > 0 > v.lam_min[1] and v.w2[0] > 0 > v.w2[1]
    assert v.delta_max == pytest.approx(d_max, abs=1e-3) and v.delta_max < d + 0.5
    assert "snap-back" in v.line(1.0)


def test_static_scan_finds_a_state_that_exists():
    """Before the turn, a step that Newton missed (here: any step) has its state: 'exists', the
    result in equilibrium (its residual within the tolerance) at the step's end or short of it."""
    prob = Springs()
    x = 0.2
    d = x + f_a(x) / K_B
    prob.commit(prob.trial(np.array([x, d - x])))
    v = static_scan(prob, np.array([x, d]), d, 0.1)
    assert v.outcome == "exists"
    res, delta = v.result
    assert d < delta <= d + 0.1 + 1e-12
    u0 = res.u[0]
    assert abs(f_a(u0) - K_B * (delta - u0)) <= 1e-10 and res.residuals[-1] <= 1e-10


def test_load_stepper_ends_with_the_loss(monkeypatch):
    """Steps of delta whose Newton fails past the turning point (forced: the near branch ends
    there, Newton could also land on the far one) are cut to the floor, then decided: StaticLoss
    with the scan's verdict, the converged steps committed."""
    x_t, d_max = turning_point()
    prob = Springs()
    real = solver.newton_step

    def near_branch(p, u_old, u_guess, *a, **k):
        if u_guess[1] > d_max:
            raise NewtonError("forced: past the turning point", [1.0])
        return real(p, u_old, u_guess, *a, **k)
    monkeypatch.setattr(solver, "newton_step", near_branch)
    st = LoadStepper(prob, 0.005, max_cutbacks=3)      # steps of delta 0.5 (height 100)
    with pytest.raises(StaticLoss) as e:
        st.run(0.2, on_step=None)
    v = e.value.verdict
    assert v.outcome == "uncontrollable" and v.delta_max == pytest.approx(d_max, abs=1e-3)
    assert st.delta <= d_max and d_max - st.delta < 0.5 / 8 + 1e-12


def test_steps_are_not_halved_past_the_floor(monkeypatch):
    """Near a turning point Newton's reach shrinks with the distance to it (forced: a step
    converges only if it covers at most half the platen displacement left to the turn). Each step
    then succeeds after cut-backs at a smaller increment than the last, towards the turn without
    reaching it (the Drucker-Prager specimen at sigma2 = 600 kPa did so, 1e-29 steps); the
    increment is never halved below d_eps1 / 2**max_cutbacks, so at that floor the failure goes to
    the scan, which ends the run 'uncontrollable' at the turn, within a few steps."""
    x_t, d_max = turning_point()
    prob = Springs()
    real = solver.newton_step

    calls = []

    def shrinking_reach(p, u_old, u_guess, *a, **k):
        calls.append(1)
        if len(calls) > 1000:           # without the floor the steps never end: fail, not hang
            pytest.fail("the steps shrink towards the turn without end")
        if u_guess[1] - u_old[1] > 0.5 * (d_max - u_old[1]):
            raise NewtonError("forced: beyond Newton's reach", [1.0])
        return real(p, u_old, u_guess, *a, **k)
    monkeypatch.setattr(solver, "newton_step", shrinking_reach)
    st = LoadStepper(prob, 0.005, max_cutbacks=3)      # steps of delta 0.5, floor 0.0625
    with pytest.raises(StaticLoss) as e:
        st.run(0.2, on_step=None)
    v = e.value.verdict
    assert v.outcome == "uncontrollable" and v.delta_max == pytest.approx(d_max, abs=1e-3)
    assert st.step < 40 and d_max - st.delta < 2 * 0.0625


def test_a_scan_that_finds_no_point_is_not_exists(monkeypatch):
    """A step below the platen displacement's resolution (delta + h == delta) whose points all
    fail: the scan has reached the step's end only trivially, with no state of its own; it is
    'unresolved' (it was 'exists' with no state to commit)."""
    prob = Springs()
    x = 0.2
    d = x + f_a(x) / K_B
    prob.commit(prob.trial(np.array([x, d - x])))
    real = prob.trial
    monkeypatch.setattr(prob, "trial", lambda dd: (_ for _ in ()).throw(ValueError("forced"))
                        if np.any(dd != 0) else real(dd))
    v = static_scan(prob, np.array([x, d]), d, 1e-30)
    assert d + 1e-30 == d and v.outcome == "unresolved" and v.points == 0 and v.result is None


def test_fem_biaxial_ends_with_the_outcome(tmp_path, monkeypatch, capsys):
    """The run's handling: a step without a static state (the scan's verdict forced to
    'uncontrollable' at step 4) ends the run as its result: exit 0, the converged rows in
    curve.csv, summary.json's outcome and end, the outcome printed."""
    import fem.__main__ as cli
    real = solver.static_scan

    def lost(prob, u_n, delta_n, h, *a, **k):
        return solver.StaticVerdict("uncontrollable", delta_n, delta_n + h, delta_n + 0.3 * h,
                                    (1, -1), (2.0, -1.0), (0.1, -0.05), 5)
    calls = {"n": 0}
    real_newton = solver.newton_step

    def fail_after_3(prob, u_old, u_guess, *a, **k):
        calls["n"] += 1
        if calls["n"] > 3:
            raise NewtonError("forced", [1.0])
        return real_newton(prob, u_old, u_guess, *a, **k)
    monkeypatch.setattr(solver, "static_scan", lost)
    monkeypatch.setattr(solver, "newton_step", fail_after_3)
    out = tmp_path / "f"
    assert cli.main(["biaxial", "--nx", "1", "--ny", "2", "--n-dir", "16", "--eps1-max", "0.002",
                     "--d-eps1", "2e-4", "--max-cutbacks", "1", "--no-fields", "--quiet",
                     "--out", str(out)]) == 0
    from fem.output import read_curve
    c = read_curve(out / "curve.csv")
    assert np.array_equal(c["step"], np.arange(4))
    s = json.loads((out / "summary.json").read_text())
    assert s["outcome"] == "uncontrollable" and "snap-back" in s["end"]["line"]
    assert s["end"]["det_k_ff_sign"] == [1, -1]
    text = capsys.readouterr().out
    assert "outcome: uncontrollable at eps1" in text and "python -m fem burst" in text
    log = (out / "newton.log").read_text()
    assert "ENDED" in log and "static scan" in log


def test_dynamic_time_steps_cut_and_the_failure_they_cannot_pass(monkeypatch):
    """fem.dynamics.hold on the elastic 1 x 1 tied specimen: a time step whose Newton fails
    (injected, whole steps only) is run in halves, Newmark's balance of the step still exact
    (1e-9) and the energy check of its halves within its healthy (omega dt)^2 / 16; one that
    fails however cut ends the run as 'not_converged' (never 'failure': the integrator
    stopped, not the specimen), the rows so far kept, what failed stated."""
    import fem.dynamics as dyn
    from hmodel import HParams
    from hmodel.burst_rule import BurstRule
    from fem.mesh import rectangle
    from fem.problem import Biaxial
    P = HParams(n_dir=36)
    B, H = 0.05, 0.1

    def run(fail):
        prob = Biaxial(rectangle(B, H, 1, 1), P, allow_sliding=False)
        tie = dyn.Tie(prob, -2.0)
        M = dyn.mass_matrix(prob)
        el = prob.material.trial(np.zeros((2, 2, prob.npts)), elastic=True)
        omega, _ = dyn.lowest_mode(tie.reduce_matrix(prob.stiffness(el.D)), tie.reduce_matrix(M))
        real = dyn.newmark_step
        calls = {"n": 0}

        def flaky(system, m, dt, *a, **k):
            calls["n"] += 1
            if fail(calls["n"], dt, 2 * math.pi / omega / 20):
                raise NewtonError("injected")
            return real(system, m, dt, *a, **k)
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(dyn, "newmark_step", flaky)
            return dyn.hold(tie, M, np.zeros(prob.ndofs), 1e-5 * P.p0 * B, 2 * math.pi / omega,
                            20, 0.05, BurstRule(), max_steps=30)

    r = run(lambda n, dt, dt0: n == 7 and dt == dt0)       # the 7th step, whole: fails once
    h = r.history
    assert r.cut_steps == {7: 1} and r.failure_reason == "" and len(h["t"]) == 31
    assert h["t"][7] == pytest.approx(7 * r.dt) and h["newton_work"].max() <= 1e-9
    from hmodel.burst_rule import check_columns
    assert check_columns(h)["energy_check"] <= (2 * math.pi / 20) ** 2 / 16
    r = run(lambda n, dt, dt0: n >= 10)                    # from the 10th call on, nothing converges
    assert r.outcome == "not_converged" and "did not converge even in substeps" in r.failure_reason
    assert len(r.history["t"]) == 10 and r.cut_steps == {10: 10}
