"""The dynamics of the tied specimen (fem.dynamics): the mass, the tie, the integrator.

A time integrator is checked like a tangent: against an analytic period, an energy balance per
step, and cases where it must fail (a wrong scheme, a wrong mass)."""
import math

import numpy as np
import pytest
import scipy.sparse.linalg as spla

from hmodel import HParams
from hmodel.burst_rule import BurstRule
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
    analytic omega, max balance residual) of the elastic 1 x 1 specimen released under dG."""
    prob, tie = _elastic_single_element(p36, ratio)
    omega = _analytic_omega(p36, ratio)
    M = mass_matrix(prob) * mass_scale
    t1 = 2 * math.pi / omega
    # dG: an amplitude of ~1e-9 strain, linear to ~1e-9, 5e4 x the Newton tolerance
    r = hold(tie, M, np.zeros(prob.ndofs), 1e-5 * p36.p0 * B, t1, 20, 0.0, BurstRule(),
             scheme=scheme, max_steps=200)
    dt = r.dt
    return (_fitted_omega(r.history["U1"], dt), 2 * math.atan(omega * dt / 2) / dt,
            float(r.history["balance_residual"].max()))


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


def test_lowest_mode_oscillates_at_its_period(p36):
    """Several elements (3 x 5, 29 unknowns): released from the lowest elastic eigenmode of the
    reduced (K, M) (``lowest_mode``), the motion stays in that mode and oscillates with
    Newmark's omega_num of omega_1, to 1e-6; the energy balance holds to 1e-9 each step (the
    elastic tangent is symmetric here, so omega_1 is also bounded by the Rayleigh quotient of
    the homogeneous mode)."""
    prob = Biaxial(rectangle(B, H, 3, 5), p36, allow_sliding=False)
    tie = Tie(prob, -2.0)
    M = mass_matrix(prob)
    el = prob.material.trial(np.zeros((2, 2, prob.npts)), elastic=True)
    K = tie.reduce_matrix(prob.stiffness(el.D))
    system = TiedDynamics(tie, M, np.zeros(prob.ndofs), 0.0, 0.0)
    system.start()
    omega, mode = lowest_mode(K, system.M)
    # Rayleigh: the homogeneous mode (the last reduced coordinate) bounds omega_1 from above
    assert omega <= math.sqrt(K[-1, -1] / system.M[-1, -1]) * (1 + 1e-12)
    dt = 2 * math.pi / omega / 20
    z0 = 1e-9 * H * mode
    f, _ = system.force(z0)
    a0 = spla.splu(system.M).solve(system.f_ext - f)
    m = Motion(z0, np.zeros(tie.size), a0, f)
    proj, ke = [], []
    for _ in range(120):
        m1, trial, _, _ = newmark_step(system, m, dt, rtol=1e-12)
        system.commit(m1.z, trial)
        dz = m1.z - m.z
        dke = 0.5 * m1.v @ (system.M @ m1.v) - 0.5 * m.v @ (system.M @ m.v)
        dw = 0.5 * dz @ ((system.f_ext - m.f) + (system.f_ext - m1.f))
        ke.append((dke, dw))
        proj.append(mode @ (system.M @ m1.z))
        m = m1
    predicted = 2 * math.atan(omega * dt / 2) / dt
    assert _fitted_omega(np.array(proj), dt) == pytest.approx(predicted, rel=1e-6)
    scale = max(abs(a) for a, _ in ke)
    assert max(abs(a - b) for a, b in ke) <= 1e-9 * scale


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
    assert h["balance_residual"].max() <= 1e-9 and h["eq1_residual"].max() <= 1e-9


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
