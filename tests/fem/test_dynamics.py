"""The dynamics of the tied specimen (fem.dynamics): the mass, the tie, the integrator.

A time integrator is checked like a tangent: against an analytic period, an energy balance per
step, and cases where it must fail (a wrong scheme, a wrong mass)."""
import math

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse.linalg as spla

from hmodel import HParams
from hmodel.burst_rule import BurstRule, check_columns
from hmodel.driver import isotropic_state
from hmodel.material import update_full
from fem.adapter import stress_to_model
from fem.dynamics import (DENSITY, Motion, Newmark, Tie, TiedDynamics, TiedStatic,
                          generalized_mass, hold, lowest_mode, mass_matrix, newmark_step)
from fem.mesh import rectangle
from fem.problem import Biaxial
from fem.solver import LoadStepper

B, H = 0.05, 0.1


@pytest.fixture(scope="module")
def p36():
    return HParams(n_dir=36)


@pytest.mark.parametrize("kind,nx,ny", [("quad", 1, 1), ("quad", 3, 5), ("tri", 1, 1),
                                        ("tri", 2, 3)])
@pytest.mark.parametrize("ratio", [-0.5, -2.0, -3.0])
def test_mass_total_and_generalized(p36, kind, nx, ny, ratio):
    """The consistent mass integrates rho exactly: a rigid translation carries rho B H, and the
    homogeneous mode of the tie carries m_G = rho B H (1/3 + R^2 B^2 / (12 H^2)) (the linear field
    is in the element space and the rule is exact for products of basis functions). Tolerance
    1e-13 relative: round-off of a sum of ~100 entries. A lumped (row-sum) mass has the total
    but another a^T M a (checked)."""
    prob = Biaxial(rectangle(B, H, nx, ny, kind), p36)
    M = mass_matrix(prob)
    nd = np.asarray(prob.basis.nodal_dofs)
    for comp in (0, 1):
        e = np.zeros(prob.ndofs)
        e[nd[comp]] = 1.0
        assert e @ M @ e == pytest.approx(DENSITY * B * H, rel=1e-13)
    tie = Tie(prob, ratio)
    mG = generalized_mass(DENSITY, B, H, ratio)
    assert mG == pytest.approx(DENSITY * B * H * (1 / 3 + ratio ** 2 * B ** 2 / (12 * H ** 2)))
    assert tie.a @ M @ tie.a == pytest.approx(mG, rel=1e-13)
    assert abs(M - M.T).max() == 0.0
    # the reduced mass carries it as its U1 entry
    assert tie.reduce_matrix(M)[-1, -1] == pytest.approx(mG, rel=1e-13)
    # a lumped (row-sum) mass keeps the total but not m_G: the check tells them apart
    lumped = np.asarray(M.sum(axis=1)).ravel()
    assert abs(np.sum(lumped * tie.a ** 2) / mG - 1) > 1e-2


def test_mass_refuses_bad_density(p36):
    prob = Biaxial(rectangle(B, H, 1, 1), p36)
    for rho in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(ValueError, match="density"):
            mass_matrix(prob, rho)


def test_tie_moves_the_faces_rigidly_and_G_is_the_virtual_work(p36):
    """The faces of u = T z meet the tie for any z: bottom u_y = 0, top u_y = -U1, left / right
    u_x = +- R (B/H) U1 / 2; and a . f_int = B x the volume average of c = s1 + R s2 for any
    stress field (virtual work; to round-off), here a non-uniform one."""
    R = -2.0
    prob = Biaxial(rectangle(B, H, 3, 4), p36)
    tie = Tie(prob, R)
    rng = np.random.default_rng(1)
    z = rng.normal(size=tie.size)
    u = tie.displacement(z)
    U1 = z[-1]
    assert np.allclose(u[tie.bottom_y], 0.0, atol=1e-15)
    assert np.allclose(u[tie.top_y], -U1, rtol=1e-14)
    assert np.allclose(u[tie.left_x], R * B / H * U1 / 2, rtol=1e-14)
    assert np.allclose(u[tie.right_x], -R * B / H * U1 / 2, rtol=1e-14)
    assert np.array_equal(np.sort(np.concatenate([tie.free, tie.constrained])),
                          np.arange(prob.ndofs))
    sigma = -np.abs(rng.normal(size=(2, 2, prob.npts))) * 1e5
    sigma[0, 1] = sigma[1, 0]
    s = stress_to_model(sigma)
    c_avg = prob.volume_average(s[0, 0]) + R * prob.volume_average(s[1, 1])
    G = tie.a @ prob.internal_force(sigma)
    assert G == pytest.approx(B * c_avg, rel=1e-13)
    assert tie.reduce_vector(prob.internal_force(sigma))[-1] == pytest.approx(G, rel=1e-15)


def test_tied_static_path_of_the_perfect_specimen_is_homogeneous(p36):
    """From the isotropic state, U1 prescribed under the tie: every point of the perfect specimen
    has the material point's strain increment (eps1, R eps1) to round-off (the free dofs carry
    no load, the homogeneous field is exact)."""
    R = -1.5
    prob = Biaxial(rectangle(B, H, 2, 3), p36)
    tie = Tie(prob, R)
    st = LoadStepper(TiedStatic(tie, np.zeros(prob.ndofs)), 2e-4, du0=tie.a)
    st.run(1e-3)
    e = prob.strain(st.u)                     # tension positive, x lateral
    assert np.allclose(-e[1, 1], 1e-3, rtol=1e-10, atol=0)
    assert np.allclose(-e[0, 0], R * 1e-3, rtol=1e-10, atol=0)
    assert np.max(np.abs(e[0, 1])) < 1e-15


def _elastic_single_element(p36, ratio):
    """A 1 x 1 quad: every node on a face, U1 the one unknown; elastic (sliding prevented)."""
    prob = Biaxial(rectangle(B, H, 1, 1), p36, allow_sliding=False)
    tie = Tie(prob, ratio)
    assert tie.size == 1
    return prob, tie


def _fitted_omega(x, dt):
    """omega_num of samples x_n = A cos(omega_num n dt + phi) + x_mean, exactly for the discrete
    solution of a linear oscillator: x_(n+1) + x_(n-1) = 2 cos(omega_num dt) x_n + const, fitted
    by least squares."""
    A = np.column_stack([2 * x[1:-1], np.ones(len(x) - 2)])
    c, _ = np.linalg.lstsq(A, x[2:] + x[:-2], rcond=None)[0]
    return math.acos(c) / dt


def _analytic_omega(p36, ratio):
    """omega [rad/s] of the 1 x 1 tied specimen from the material point alone: k_G / m_G with
    k_G = dG/dU1 = (B/H) e:D:e, D hmodel's elastic tangent at the isotropic state."""
    D = update_full(isotropic_state(p36), np.zeros((2, 2)), p36, allow_sliding=False).tangent
    e = np.diag([1.0, ratio])          # strain per unit eps1 along the path, compression +
    kG = B / H * np.einsum("ij,ijkl,kl->", e, D, e)
    return math.sqrt(kG / generalized_mass(DENSITY, B, H, ratio))


def _single_element_omega(p36, ratio, scheme=Newmark(), mass_scale=1.0):
    """(omega_num measured, omega_num predicted by Newmark average acceleration from the
    analytic omega, the largest of Newmark's balance, ``newton_work``) of the elastic 1 x 1
    specimen released under dG."""
    prob, tie = _elastic_single_element(p36, ratio)
    omega = _analytic_omega(p36, ratio)
    M = mass_matrix(prob) * mass_scale
    t1 = 2 * math.pi / omega
    # dG: an amplitude of ~1e-9 strain, linear to ~1e-9, 5e4 x the Newton tolerance
    r = hold(tie, M, np.zeros(prob.ndofs), 1e-5 * p36.p0 * B, t1, 20, 0.0, BurstRule(),
             scheme=scheme, max_steps=200)
    dt = r.dt
    return (_fitted_omega(r.history["U1"], dt), 2 * math.atan(omega * dt / 2) / dt,
            float(r.history["newton_work"].max()))


@pytest.mark.parametrize("zeta", [0.05, 0.2])
def test_damping_decay_per_step(p36, zeta):
    """The stated damping, exactly: C = 2 zeta omega_1 M on the 1 x 1 oscillator (omega_1 the
    analytic omega) and Newmark average acceleration (the trapezoidal rule on (u, v)) multiply
    the amplitude by rho per step, rho^2 = (1 - zeta W + W^2/4) / (1 + zeta W + W^2/4), W = omega
    dt. Measured by fitting x(n+1) = p x(n) + q x(n-1) + const (q = -rho^2) to 1e-6."""
    prob, tie = _elastic_single_element(p36, -2.0)
    omega = _analytic_omega(p36, -2.0)
    r = hold(tie, mass_matrix(prob), np.zeros(prob.ndofs), 1e-5 * p36.p0 * B, 2 * math.pi / omega,
             20, zeta, BurstRule(), max_steps=60)
    x = r.history["U1"]
    A = np.column_stack([x[1:-1], x[:-2], np.ones(len(x) - 2)])
    _, q, _ = np.linalg.lstsq(A, x[2:], rcond=None)[0]
    W = omega * r.dt
    assert -q == pytest.approx((1 - zeta * W + W * W / 4) / (1 + zeta * W + W * W / 4), rel=1e-6)


@pytest.mark.parametrize("ratio", [-2.0, -0.5])
def test_period_of_a_small_elastic_oscillation(p36, ratio):
    """The analytic period: the 1 x 1 specimen under the tie is one oscillator, m_G U1'' + k_G U1
    = dG, with k_G = (B/H) e:D:e from the material point's elastic tangent (hmodel, no FE) and
    m_G the closed form. Newmark average acceleration elongates the period as omega_num dt =
    2 arctan(omega dt / 2) (here 0.8 % at 20 steps a period): measured to 1e-6 relative (the
    oscillation is linear to ~1e-9; measured 4e-9)."""
    measured, predicted, balance = _single_element_omega(p36, ratio)
    assert measured == pytest.approx(predicted, rel=1e-6)
    assert balance <= 1e-6


@pytest.mark.parametrize("what", ["beta", "gamma", "mass"])
def test_period_check_catches_a_wrong_integrator_or_mass(p36, what):
    """The checks above must fail when the mechanics is wrong: Newmark with beta = 0.26 (not
    average acceleration), gamma = 0.55 (numerical damping), or a mass 1 % too large."""
    kw = {"beta": {"scheme": Newmark(0.26, 0.5)}, "gamma": {"scheme": Newmark(0.25, 0.55)},
          "mass": {"mass_scale": 1.01}}[what]
    measured, predicted, balance = _single_element_omega(p36, -2.0, **kw)
    assert abs(measured / predicted - 1) > 1e-4
    if what != "mass":                   # a wrong mass is a wrong model, not a broken balance
        assert balance > 1e-6


def _independent_K_M(prob, density):
    """The stiffness [Pa] and mass [kg/m] (ndofs, ndofs), dense, of an elastic specimen of
    rectangular bilinear quads at the isotropic state, assembled here from hmodel's elastic
    tangent and the density: the element stiffness by 2 x 2 Gauss points with the shape
    functions written out, the consistent element mass in closed form, rho a b (1 + xi_i xi_j /
    3)(1 + eta_i eta_j / 3) / 4 (half-sizes a, b) -- neither fem.problem's B-matrices and
    assembly nor the skfem mass form of fem.dynamics.mass_matrix."""
    p36 = prob.params
    Dm = update_full(isotropic_state(p36), np.zeros((2, 2)), p36, allow_sliding=False).tangent
    q = [1, 0]                              # FE axes (x lateral, y axial) from the model's (1, 2)
    D = Dm[np.ix_(q, q, q, q)]              # compression / tension signs cancel in a tangent
    n = prob.ndofs
    K, M = np.zeros((n, n)), np.zeros((n, n))
    nd = np.asarray(prob.basis.nodal_dofs)
    g = np.array([-1.0, 1.0]) / math.sqrt(3.0)
    for e in range(prob.mesh.t.shape[1]):
        nodes = prob.mesh.t[:, e]
        x, y = prob.mesh.p[:, nodes]
        a, b = 0.5 * np.ptp(x), 0.5 * np.ptp(y)
        xi, eta = (x - x.mean()) / a, (y - y.mean()) / b          # the nodes' +-1
        dofs = np.array([nd[c, i] for i in nodes for c in (0, 1)])
        Ke = np.zeros((8, 8))
        for gx in g:
            for gy in g:
                dNdx = xi * (1 + eta * gy) / (4 * a)
                dNdy = eta * (1 + xi * gx) / (4 * b)
                Bm = np.zeros((2, 2, 8))
                for i in range(4):
                    for c in (0, 1):
                        G = np.zeros((2, 2))
                        G[c] = (dNdx[i], dNdy[i])                 # d u_c / d x_j
                        Bm[:, :, 2 * i + c] = 0.5 * (G + G.T)
                Ke += np.einsum("abm,abcd,cdn->mn", Bm, D, Bm) * a * b
        Ne = density * a * b * (1 + np.outer(xi, xi) / 3) * (1 + np.outer(eta, eta) / 3) / 4
        Me = np.zeros((8, 8))
        for c in (0, 1):
            Me[c::2, c::2] = Ne
        K[np.ix_(dofs, dofs)] += Ke
        M[np.ix_(dofs, dofs)] += Me
    return K, M


def test_lowest_mode_oscillates_at_its_independent_period(p36):
    """Several elements (3 x 5, 29 unknowns): the lowest elastic eigenpair of the tied specimen
    from a stiffness and a mass assembled in the test itself (``_independent_K_M``: hmodel's
    elastic tangent, the density and the shape functions written out), then the specimen
    released from that mode with fem's own mass_matrix, stiffness and Newmark: the motion
    stays in the mode and oscillates at Newmark's omega_num of the independent omega_1, to
    1e-6 (a wrong mass or stiffness in fem moves it: a mass 1 % off by 5e-3). fem's
    lowest_mode of its own (K, M) agrees with the independent omega_1 to 1e-10, and both are
    below the Rayleigh bound of the homogeneous mode, sqrt(k_G / m_G) from the closed forms.
    Newmark's balance holds to 1e-9 a step (the work of its Newton residual)."""
    prob = Biaxial(rectangle(B, H, 3, 5), p36, allow_sliding=False)
    tie = Tie(prob, -2.0)
    Ki, Mi = _independent_K_M(prob, DENSITY)
    T = tie.T.toarray()
    w, V = scipy.linalg.eigh(T.T @ Ki @ T, T.T @ Mi @ T)
    omega, mode = math.sqrt(w[0]), V[:, 0] / np.max(np.abs(V[:, 0]))
    assert omega <= _analytic_omega(p36, -2.0) * (1 + 1e-12)
    M = mass_matrix(prob)
    el = prob.material.trial(np.zeros((2, 2, prob.npts)), elastic=True)
    assert lowest_mode(tie.reduce_matrix(prob.stiffness(el.D)),
                       tie.reduce_matrix(M))[0] == pytest.approx(omega, rel=1e-10)
    system = TiedDynamics(tie, M, np.zeros(prob.ndofs), 0.0, 0.0)
    system.start()
    dt = 2 * math.pi / omega / 20
    z0 = 1e-9 * H * mode
    f, _ = system.force(z0)
    a0 = spla.splu(system.M).solve(system.f_ext - f)
    m = Motion(z0, np.zeros(tie.size), a0, f)
    proj, ke = [], []
    Mm = T.T @ Mi @ T
    for _ in range(120):
        m1, trial, it, _ = newmark_step(system, m, dt, rtol=1e-12)
        assert it <= 1                   # linear: one correction of the predictor solves it
        system.commit(m1.z, trial)
        dz = m1.z - m.z
        dke = 0.5 * m1.v @ (system.M @ m1.v) - 0.5 * m.v @ (system.M @ m.v)
        dw = 0.5 * dz @ ((system.f_ext - m.f) + (system.f_ext - m1.f))
        ke.append((dke, dw))
        proj.append(mode @ (Mm @ m1.z))
        m = m1
    predicted = 2 * math.atan(omega * dt / 2) / dt
    assert _fitted_omega(np.array(proj), dt) == pytest.approx(predicted, rel=1e-6)
    scale = max(abs(a) for a, _ in ke)
    assert max(abs(a - b) for a, b in ke) <= 1e-9 * scale


def _elastic_hold(p36, nx, ny, steps, zeta=0.0, periods=4, mass_scale=1.0):
    """The elastic nx x ny tied specimen (R = -2) released under a step dG (strains ~1e-9)
    from the isotropic state: ``hold`` for ``periods`` lowest periods (omega_1 from the test's
    own assembly), the integrator's mass ``mass_scale`` x fem's, the density the true one."""
    prob = Biaxial(rectangle(B, H, nx, ny), p36, allow_sliding=False)
    tie = Tie(prob, -2.0)
    Ki, Mi = _independent_K_M(prob, DENSITY)
    T = tie.T.toarray()
    omega = math.sqrt(scipy.linalg.eigh(T.T @ Ki @ T, T.T @ Mi @ T, eigvals_only=True)[0])
    r = hold(tie, mass_scale * mass_matrix(prob), np.zeros(prob.ndofs), 1e-5 * p36.p0 * B,
             2 * math.pi / omega, steps, zeta, BurstRule(), max_steps=periods * steps)
    return r, omega


def test_energy_check_closes_to_second_order(p36):
    """The energy check that Newmark cannot satisfy by itself (hmodel.burst_rule.EnergyCheck:
    E_c at mid-step of the velocity field T dz / dt integrated with the density, W2_int from
    the quadrature points' stresses and the material's own strain increments, the damping's
    work by the midpoint rule) on elastic step responses. The 1 x 1 specimen, undamped, is one
    oscillator: the residual is -dv.M dv / 8, whose largest is (omega dt)^2 / 16 of the run's
    scale (omega_num and the peaks' sampling take up to 5 % off it: measured 0.976 of it at 20
    steps a period, 6.02e-3), and halving dt divides it by 4: order 2 within 0.05 (measured
    1.97 from 20 to 40). The 1 x 2 specimen (the suite's burst mesh, damped 5 %): the step
    excites modes above the lowest, whose omega dt is not small at 20 steps a period, so the
    order tends to 2 from below as dt shrinks (measured 1.80 from 20 to 40 steps a period,
    1.94 from 40 to 80; undamped 1.91, 1.97, 1.99, 2.00 up to 320): at least 1.9 from 40 to 80.
    Every step of a linear problem converges in one Newton iteration (the
    tangent K + M / (beta dt^2) is its exact Jacobian); the stresses' work equals the
    trapezoid of the nodal forces to round-off (1e-9 of the run's scale, measured 3e-11: the
    prestress' first-order terms cancel in the nodal form)."""
    e = {}
    for n in (20, 40):
        r, omega = _elastic_hold(p36, 1, 1, n)
        c = check_columns(r.history)
        e[n] = c["energy_check"]
        bound = (omega * r.dt) ** 2 / 16
        assert 0.95 * bound <= e[n] <= bound, (n, e[n], bound)
        assert c["work_check"] <= 1e-9
        assert np.all(r.history["newton_iters"][1:] == 1)
        assert r.history["newton_work"].max() <= 1e-9
    assert math.log2(e[20] / e[40]) == pytest.approx(2.0, abs=0.05)
    e = [check_columns(_elastic_hold(p36, 1, 2, n, zeta=0.05)[0].history)["energy_check"]
         for n in (40, 80)]
    assert math.log2(e[0] / e[1]) >= 1.9, e


@pytest.mark.parametrize("bug", ["mass x5", "f_int x1.3", "tangent x1.2"])
def test_the_checks_catch_a_wrong_mass_force_or_tangent(p36, monkeypatch, bug):
    """The independent checks are not vacuous: on the elastic 1 x 1 oscillator (20 steps a
    period, 2 periods) a mass x5 in the integrator (the density unchanged) or an internal
    force x1.3 with the tangent unchanged (the switch still an equilibrium: f_ext = f(0))
    leave Newmark's own balance within the work Newton's tolerance allows (an identity of the
    scheme: |r| <= rtol sigma2 H = 2e-6 N/m against dG = 0.1 N/m, 2e-5 of dG dU1) but put the
    energy check above 0.1, 16 x its healthy bound (omega dt)^2 / 16 = 6.2e-3; the force also
    the work check (its nodal trapezoid 1.3 x the stresses' work). A tangent x1.2 changes no
    converged state (every check healthy) and shows only in Newton: two iterations or more a
    step instead of one."""
    import fem.dynamics as fd
    kw = {}
    if bug == "mass x5":
        kw["mass_scale"] = 5.0
    elif bug == "f_int x1.3":
        real = fd.TiedDynamics.force

        def force(self, z):
            f, trial = real(self, z)
            return 1.3 * f, trial
        monkeypatch.setattr(fd.TiedDynamics, "force", force)
    else:
        real = Biaxial.stiffness
        monkeypatch.setattr(Biaxial, "stiffness", lambda self, D: 1.2 * real(self, D))
    r, omega = _elastic_hold(p36, 1, 1, 20, periods=2, **kw)
    h = r.history
    c = check_columns(h)
    assert h["newton_work"].max() <= 2e-5
    if bug == "tangent x1.2":
        assert c["energy_check"] <= (omega * r.dt) ** 2 / 16 and c["work_check"] <= 1e-9
        assert np.all(h["newton_iters"][1:] >= 2)
    else:
        assert c["energy_check"] > 0.1, c
        if bug == "f_int x1.3":
            assert c["work_check"] > 0.1, c


def test_hold_refuses_bad_values(p36):
    prob, tie = _elastic_single_element(p36, -2.0)
    M = mass_matrix(prob)
    u = np.zeros(prob.ndofs)
    for kw, word in (({"steps_per_period": 9}, "steps_per_period"),
                     ({"steps_per_period": 10.5}, "steps_per_period"),
                     ({"damping_ratio": 1.0}, "damping_ratio"),
                     ({"damping_ratio": -0.1}, "damping_ratio")):
        with pytest.raises(ValueError, match=word):
            hold(tie, M, u, 1.0, 1e-3, **kw)
    for dG in (-1.0, math.nan):
        with pytest.raises(ValueError, match="dG"):
            hold(tie, M, u, dG, 1e-3)
    for R in (0.0, math.nan, math.inf):
        with pytest.raises(ValueError, match="ratio"):
            Tie(prob, R)


def test_elastic_oscillation_with_damping_settles(p36):
    """With the stated damping (zeta = 0.05 at omega_1) the released elastic specimen settles:
    the rule decides equilibrium; the damping work is the term that closes the balance
    (E_c = W2_ext - W2_int - D to 1e-9 of the energies, every step)."""
    prob, tie = _elastic_single_element(p36, -2.0)
    M = mass_matrix(prob)
    el = prob.material.trial(np.zeros((2, 2, prob.npts)), elastic=True)
    omega, _ = lowest_mode(tie.reduce_matrix(prob.stiffness(el.D)), tie.reduce_matrix(M))
    r = hold(tie, M, np.zeros(prob.ndofs), 1e-4 * p36.p0 * B, 2 * math.pi / omega, 20, 0.05,
             BurstRule())
    h = r.history
    assert r.outcome == "equilibrium"
    assert h["damping"][-1] > 0.5 * h["w2_ext"][-1]       # half of dG's work is dissipated
    # Newmark's balance, step by step and summed since the switch (the work of the Newton
    # residual), and the energy check from the density and the stresses, within its bound
    assert h["newton_work"].max() <= 1e-9 and h["newton_work_sum"].max() <= 1e-9
    assert check_columns(h)["energy_check"] <= (omega * r.dt) ** 2 / 16


def test_lowest_mode_arpack_is_reproducible_and_agrees_with_dense(p36):
    """Above 300 unknowns ARPACK (shift-invert) from a seeded start vector: the same bits at
    every call (T1 sets dt, so a run's every number depends on it), and the dense eigenvalue
    to 1e-10."""
    prob = Biaxial(rectangle(B, H, 10, 20), p36, allow_sliding=False)
    tie = Tie(prob, -2.0)
    assert tie.size > 300
    el = prob.material.trial(np.zeros((2, 2, prob.npts)), elastic=True)
    K, M = tie.reduce_matrix(prob.stiffness(el.D)), tie.reduce_matrix(mass_matrix(prob))
    w1, m1 = lowest_mode(K, M)
    w2, m2 = lowest_mode(K, M)
    assert w1 == w2 and np.array_equal(m1, m2)
    import scipy.linalg
    lam = scipy.linalg.eigvals(K.toarray(), M.toarray())
    assert w1 == pytest.approx(math.sqrt(np.min(np.abs(lam))), rel=1e-10)
