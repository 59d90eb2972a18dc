"""The toolkit's numerical analysis of the Drucker-Prager law against the closed forms
(docs/materials.md): every criterion it computes, each where an exact answer exists.

Tolerances: what is computed from the tangent (determinants, eigenvalues) to 1e-8 relative;
what uses finite probes to the error the probe's size makes, measured here (first order in the
probe's norm: halving the norm halves it); onsets along a path to one step of the path.

Along the drained path (sigma2 held, eps12 = 0) every plastic state lies on the yield surface
with coaxial principal axes: tau = mu(kappa) p, sigma2 = p - tau, so eta = q/p = 2 mu(kappa)
and h = p mu'(kappa) = sigma2 mu'(kappa) / (1 - mu(kappa)) are functions of kappa alone, and so
are P, Q and every criterion: each onset is a 1D root in kappa (``exact_kappa``), independent
of the path's integration.
"""
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from point import material_of
from point.closed_forms import (Mechanism, cone_edges as exact_edges, h_control, h_path, h_rice,
                                h_sym, plane_operator)
from point.driver import (drained_biaxial, isotropic_state, proportional_strain,
                          proportional_strain_stress, run_path)
from point.burst import proportional_path
from point.drucker_prager import DPParams, mechanism
from point.experiment import domain_point, state_at_eta
from point.probes import cone_edges, tangent_criteria
from point.tensors import mandel_tangent

P = DPParams()
DP = material_of(P)
I3 = np.array([1.0, 1.0, 0.0])
N = np.array([0.5, -0.5, 0.0])


def drained_mechanism(kappa, params=P, sigma2=None):
    """The mechanism of the drained path's state of plastic shear strain ``kappa`` (closed form)."""
    s2 = params.p0 if sigma2 is None else sigma2
    mu = float(params.mu(kappa))
    p = s2 / (1.0 - mu)
    return Mechanism(params.elastic_mandel(), N - 0.5 * mu * I3, N - 0.5 * (mu - params.mu_c) * I3,
                     p * float(params.dmu(kappa)))


def exact_kappa(h_crit, params=P, hi=None):
    """The kappa of the drained path where h = h_crit(mechanism), the first root from 0."""
    g = lambda k: float(drained_mechanism(k, params).h - h_crit(drained_mechanism(k, params)))  # noqa: E731
    return brentq(g, 1e-9, params.kappa_p if hi is None else hi, xtol=1e-15, rtol=1e-15)


@pytest.fixture(scope="module")
def drained():
    """The default drained path at 200 kPa to eps1 = 1.1 %, every state kept."""
    return run_path(isotropic_state(P), P, drained_biaxial(1e-5), 1100, keep_states=True)


def test_the_drained_states_lie_on_the_exact_curve(drained):
    eta = drained.invariants()[2]
    for s, e in zip(drained.states, eta):
        if bool(s.plastic):
            assert e == pytest.approx(2.0 * float(P.mu(s.kappa)), abs=1e-13)
    assert np.allclose(drained.sigma[:, 1], P.p0, rtol=1e-9)
    # the drained peak is h = 0, kappa = kappa_p, eta = 2 mu_p; the path's largest eta within a step
    k = int(np.argmax(eta))
    assert eta[k] == pytest.approx(2 * P.mu_p, abs=np.max(np.abs(np.diff(eta[k - 2:k + 3]))))


def test_the_default_set_shows_the_paper_argument():
    """h_sym, then Rice, then the peak along the default drained path (docs/materials.md)."""
    k_sym = exact_kappa(h_sym)
    k_loc = exact_kappa(lambda m: h_rice(m)[0])
    assert 0 < k_sym < k_loc < P.kappa_p
    assert h_rice(drained_mechanism(k_loc))[0] > 0


@pytest.mark.parametrize("row", [300, 850, 905, 950, 1000])
def test_tangent_criteria_are_the_closed_forms(drained, row):
    """det D = det E h / (h + P:E:Q), the principal block and its symmetric part, from the
    analysis (``tangent_criteria``, the law's rate tangent) and from the closed form."""
    s = drained.states[row]
    m = mechanism(P, s)
    D = m.tangent()
    Dt = mandel_tangent(DP.rate_tangent(s, np.diag([1.0, -0.3]), P))
    assert np.linalg.det(Dt) == pytest.approx(np.linalg.det(P.elastic_mandel()) * float(m.h)
                                               / float(m.h + m.PEQ), rel=1e-8)
    tc = tangent_criteria(s, P, (1.0, -0.3))
    M = D[:2, :2]
    Ms = 0.5 * (M + M.T)
    assert tc["det_M_cauchy"] == pytest.approx(np.linalg.det(M), rel=1e-8)
    assert tc["det_Msym_cauchy"] == pytest.approx(np.linalg.det(Ms), rel=1e-8)
    assert tc["lam_min_Msym_cauchy"] == pytest.approx(np.linalg.eigvalsh(Ms)[0], rel=1e-8)
    # the sign of lam_min(D_s) is the sign of h - h_sym (coaxial: the shear is elastic)
    assert (np.linalg.eigvalsh(0.5 * (D + D.T))[0] > 0) == (float(m.h - h_sym(m)) > 0)


def _first_row(states, fires):
    return next(i for i, s in enumerate(states) if bool(s.plastic) and fires(mechanism(P, s)))


def test_the_bifurcation_domain_starts_at_h_sym(drained):
    """``domain_point``'s first state with min W2 <= 0 (sampled strain probes) is the first
    state of the path past the exact onset: eta* = 2 mu(kappa*), h(kappa*) = h_sym(kappa*)."""
    eta = drained.invariants()[2]
    k_star = exact_kappa(h_sym)
    eta_star = 2.0 * float(P.mu(k_star))
    row = _first_row(drained.states, lambda m: float(m.h - h_sym(m)) <= 0)
    assert eta[row - 1] < eta_star <= eta[row]
    d = domain_point(P, P.p0)
    # the same row (the domain runs its path in blocks of 25 steps, whose Newton stops at 1e-10
    # of the stress: the same states to ~1e-10)
    assert d.q_w2 / d.p_w2 == pytest.approx(eta[row], abs=1e-9)
    assert d.q_w2sigma / d.p_w2sigma == pytest.approx(eta[row], abs=1e-9)
    assert d.eps1_w2 == pytest.approx(drained.eps[row, 0], abs=1e-12)
    assert d.q_peak / d.p_peak == pytest.approx(2 * P.mu_p, abs=np.max(np.diff(eta[-200:])) + 1e-12)


def test_rice_onset_along_the_path(drained):
    eta = drained.invariants()[2]
    k_loc = exact_kappa(lambda m: h_rice(m)[0])
    row = _first_row(drained.states, lambda m: float(m.h) <= h_rice(m)[0])
    assert eta[row - 1] < 2.0 * float(P.mu(k_loc)) <= eta[row]


@pytest.mark.parametrize("norm", [1e-6])
def test_cone_edges_in_both_probe_planes(drained, norm):
    """The cone's edges by the analysis (``probes.cone_edges``: the sweep's sign changes of W2
    bisected) against tan t = (-B +- sqrt(B^2 - AC)) / C of the closed-form plane operators,
    on the loading side. A probe of norm |d eps| sees the consistent response of a step of its
    size: the edges move by O(|d eps|) (6.7e3 deg per unit norm measured here: 0.0067 deg at
    1e-6), which halving the norm halves."""
    s = drained.states[920]
    D = mechanism(P, s).tangent()
    got = cone_edges(s, P, norm=norm)
    assert len(got) == 2
    strain = [e for e in exact_edges(plane_operator(D, "strain"))
              if (mechanism(P, s).P @ P.elastic_mandel() @ np.array([math.cos(math.radians(e)),
                                                                   math.sin(math.radians(e)), 0])) > 0]
    stress = [(90.0 - t) % 360.0 for t in exact_edges(plane_operator(D, "stress"))
              if mechanism(P, s).P @ np.array([math.cos(math.radians(t)), math.sin(math.radians(t)), 0]) > 0]
    err = []
    for e in got:
        x = min(strain, key=lambda v: abs((v - e["alpha_eps"] + 180) % 360 - 180))
        y = min(stress, key=lambda v: abs((v - e["alpha_sigma"] + 180) % 360 - 180))
        err.append((abs((x - e["alpha_eps"] + 180) % 360 - 180), abs((y - e["alpha_sigma"] + 180) % 360 - 180)))
    assert max(max(p) for p in err) < 0.01, err
    half = cone_edges(s, P, norm=0.5 * norm)
    for e, f, x in zip(got, half, err):
        ex = min(strain, key=lambda v: abs((v - f["alpha_eps"] + 180) % 360 - 180))
        ratio = x[0] / abs((ex - f["alpha_eps"] + 180) % 360 - 180)
        assert 1.9 < ratio < 2.1, ratio


@pytest.mark.parametrize("R", [-2.0, -1.0])
def test_the_c_peak_of_a_proportional_path_is_h_R(R):
    """Under strain control the path's c = s1 + R s2 peaks at u.D.u = 0 (h = h_R); under control
    of c itself (``proportional_strain_stress``) the driver ends the path 'uncontrollable' at
    the same state, within one step."""
    _, s0 = state_at_eta(P, 0.95 * 2 * P.mu_p)
    u = (1.0, R, 0.0)
    first, peak = proportional_path(s0, P, R, 1e-5)
    r = run_path(s0, P, proportional_strain(1e-5, R), len(first.eps) - 1, keep_states=True)
    assert np.array_equal(r.sigma, first.sigma)
    c = r.sigma[:, 0] + R * r.sigma[:, 1]
    g = [float(mechanism(P, s).h) - h_path(mechanism(P, s), u) for s in r.states]
    cross = next(i for i, v in enumerate(g) if v <= 0)
    k = int(np.argmax(c))
    assert cross - 1 <= k <= cross, (k, cross)
    rc = run_path(s0, P, proportional_strain_stress(R, 200.0), 5000, keep_states=True)
    assert rc.end.outcome == "uncontrollable"
    # for the reason the theory gives: the controlled block dc/d eps1 changes sign there, and
    # the control's W2 with it (not a flat response, not a jump)
    v = rc.end.verdict
    assert v.det[0] * v.det[1] < 0 and v.w2[0] * v.w2[1] < 0, v
    gl = [float(mechanism(P, s).h) - h_path(mechanism(P, s), u) for s in rc.states]
    assert gl[-1] > 0 and all(v > 0 for v in gl)
    # the last static state is within one step of the crossing: the step past it has g <= 0
    d_c = 200.0
    assert c[k] - rc.end.sigma[0] - R * rc.end.sigma[1] < 2 * d_c + (c[k] - c[k - 1])


def test_drained_controllability_is_lost_at_h_c():
    """With softening strong enough (a test set: G = 10 MPa, kappa_p = 0.002), the drained path
    (eps11 prescribed, s22 held) ends 'uncontrollable' where h reaches
    h_c = -P_T [(E^-1)_TT]^-1 Q_T, T = {11, 12}, within one step; never before."""
    Ps = DPParams(G=10e6, kappa_p=0.002)
    r = run_path(isotropic_state(Ps), Ps, drained_biaxial(1e-5), 3000, keep_states=True)
    assert r.end.outcome == "uncontrollable"
    v = r.end.verdict                  # the block d s22 / d eps22 changes sign: W2 = 0 there
    assert v.det[0] * v.det[1] < 0 and v.w2[0] * v.w2[1] < 0, v
    g = [float(mechanism(Ps, s).h) - h_control(mechanism(Ps, s), (True, False, True))
         for s in r.states if bool(s.plastic)]
    assert all(v > 0 for v in g)
    m = mechanism(Ps, r.states[-1])
    step = abs(g[-1] - g[-2])
    assert g[-1] < 2 * step
    # Nova's form of the same number
    T = [0, 2]
    Ci = np.linalg.inv(np.linalg.inv(m.E)[np.ix_(T, T)])
    assert h_control(m, (True, False, True)) == pytest.approx(float(-m.P[T] @ Ci @ m.Q[T]), rel=1e-12)


def test_the_material_point_burst_at_the_exact_c_peak():
    """The burst of the material point (``point.burst.hold``: the specimen held at c, Newmark,
    the burst rule) from the state at the exact c peak of the proportional path R = -2 (the
    strain step from the last row before it bisected to h = h_R, closed form): held 5 Pa below
    c* it settles, 5 Pa above it fails (no static state past the peak; 5 Pa is the change of c
    over one path step there, c_peak - c_(peak-1) = 5.4 Pa)."""
    from point.burst import hold
    R = -2.0
    u = (1.0, R, 0.0)
    _, s0 = state_at_eta(P, 0.95 * 2 * P.mu_p)
    first, peak = proportional_path(s0, P, R, 1e-5)
    k = peak.peak
    before = run_path(s0, P, proportional_strain(1e-5, R), k - 1)
    g = lambda st: float(mechanism(P, st).h) - h_path(mechanism(P, st), u)     # noqa: E731
    lo, hi = 0.0, 2e-5                       # the strain step from row k - 1 to the root
    step = lambda x: run_path(before.state, P, proportional_strain(x, R), 1).state  # noqa: E731
    assert g(before.state) > 0 and g(step(hi)) < 0
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if g(step(mid)) > 0 else (lo, mid)
    star = step(0.5 * (lo + hi))
    c_star = float(star.stress[0, 0] + R * star.stress[1, 1])
    assert c_star >= max(peak.c) - 1e-6 * abs(c_star)        # the exact peak is above every row
    eps_star = (float(first.eps[k - 1, 0]) + 0.5 * (lo + hi), 0.0)
    assert hold(star, P, R, c_star - 5.0, eps_star).outcome == "equilibrium"
    assert hold(star, P, R, c_star + 5.0, eps_star).outcome == "failure"
