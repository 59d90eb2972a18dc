"""The closed forms of single-mechanism elastoplasticity (point.closed_forms), each against a
brute-force computation that knows nothing of its derivation: the tangent D(h) built for a
range of h, its eigenvalues, determinants, blocks and acoustic tensors scanned, the sign change
bisected in h. And the check values published for this benchmark (plane model, G = 1,
lambda = 1.3, deviator along (1, -1, 0), P = s/(2 tau) + mu I/2, Q = s/(2 tau) + beta I/2)."""
import math

import numpy as np
import pytest

from point.closed_forms import (Mechanism, cone_edges, h_control, h_path, h_rice, h_strain_subspace,
                                h_stress_subspace, h_sym, plane_operator, rice_h_of_angle)

I3 = np.array([1.0, 1.0, 0.0])
N = np.array([0.5, -0.5, 0.0])


def _mech(mu, beta, G=1.0, lam=1.3, n=N, sign=1.0):
    E = lam * np.outer(I3, I3) + 2 * G * np.eye(3)
    return Mechanism(E, n + sign * 0.5 * mu * I3, n + sign * 0.5 * beta * I3, 0.0)


def _first_h(m, fires, lo=-5.0, hi=5.0, n=4001):
    """The largest h in [lo, hi] at which ``fires(D(h))`` (True at lo, False at hi), by a
    scan of ``n`` values from above then bisection to 1e-13."""
    hs = np.linspace(hi, lo, n)
    prev = hs[0]
    assert not fires(m._replace(h=prev).tangent())
    for h in hs[1:]:
        if fires(m._replace(h=h).tangent()):
            a, b = h, prev
            break
        prev = h
    else:
        raise AssertionError("never fires")
    while b - a > 1e-13:
        c = 0.5 * (a + b)
        a, b = (c, b) if fires(m._replace(h=c).tangent()) else (a, c)
    return 0.5 * (a + b)


def _lam_min_sym(D):
    return np.linalg.eigvalsh(0.5 * (D + D.T))[0]


# the published check values (computed by brute force, independent of any derivation)
PUBLISHED = [(0.6, 0.3, 0.035697, 0.015681, 0.016283), (0.8, 0.1, 0.203119, 0.085378, 0.199469)]


@pytest.mark.parametrize("mu, beta, hs, hl, hr", PUBLISHED)
def test_the_published_check_values(mu, beta, hs, hl, hr):
    m = _mech(mu, beta)
    assert float(h_sym(m)) == pytest.approx(hs, abs=1e-6)
    assert h_rice(m)[0] == pytest.approx(hl, abs=1e-6)
    assert h_path(m, (1.0, -0.5, 0.0)) == pytest.approx(hr, abs=1e-6)
    # h_sym / G = 1/2 [sqrt((1 + k mu^2)(1 + k beta^2)) - (1 + k mu beta)], k = K2 / G
    k = 2.3
    assert float(h_sym(m)) == pytest.approx(
        0.5 * (math.sqrt((1 + k * mu ** 2) * (1 + k * beta ** 2)) - (1 + k * mu * beta)), rel=1e-13)


@pytest.mark.parametrize("mu, beta, sign", [(0.6, 0.3, 1.0), (0.8, 0.1, -1.0), (0.5, -0.1, -1.0)])
def test_h_sym_and_the_subspaces_against_eigenvalue_scans(mu, beta, sign):
    m = _mech(mu, beta, sign=sign)
    assert float(h_sym(m)) == pytest.approx(_first_h(m, lambda D: _lam_min_sym(D) <= 0), abs=1e-10)
    # strain probes in the plane (d eps1, d eps2); a plane with shear; stress probes likewise
    for B in (np.eye(3)[:, :2], np.linalg.qr(np.array([[1.0, 0.3], [0.2, -1.0], [0.5, 0.7]]))[0]):
        fires = lambda D, B=B: np.linalg.eigvalsh(B.T @ (0.5 * (D + D.T)) @ B)[0] <= 0  # noqa: E731
        assert h_strain_subspace(m, B) == pytest.approx(_first_h(m, fires), abs=1e-10)

        def fires_s(D, B=B):
            C = np.linalg.inv(D)
            return np.linalg.eigvalsh(B.T @ (0.5 * (C + C.T)) @ B)[0] <= 0
        assert h_stress_subspace(m, B) == pytest.approx(_first_h(m, fires_s, lo=1e-6), abs=1e-10)
    # the whole space: stress and strain probes lose positive W2 at the same h
    assert h_stress_subspace(m, np.eye(3)) == pytest.approx(float(h_sym(m)), rel=1e-12)
    assert h_strain_subspace(m, np.eye(3)) == pytest.approx(float(h_sym(m)), rel=1e-12)


V = np.diag([1.0, 1.0, math.sqrt(2.0)])


def _controlled_det(D, sc, A2=None):
    """det of the controlled block of the driver's variables, from D (Mandel) directly."""
    M = np.linalg.inv(V) @ D @ V                 # d sigma_rows / d v
    A = np.eye(3)
    if A2 is not None:
        A[:2, :2] = A2
    Ai = np.linalg.inv(A)
    Mp = Ai.T @ M @ Ai
    f = [i for i, s in enumerate(sc) if not s]
    return np.linalg.det(Mp[np.ix_(f, f)])


@pytest.mark.parametrize("sc, A2", [((True, False, True), None), ((False, False, True), None),
                                    ((False, True, True), ((1.0, 0.0), (0.5, 1.0))),
                                    ((False, True, True), ((1.0, 0.0), (1.0, 1.0))),
                                    ((True, False, False), None)])
def test_controllability_against_the_controlled_block(sc, A2):
    m = _mech(0.6, 0.3, sign=-1.0)
    hc = h_control(m, sc, A2)
    d_above = _controlled_det(m._replace(h=hc + 1e-6).tangent(), sc, A2)
    d_below = _controlled_det(m._replace(h=hc - 1e-6).tangent(), sc, A2)
    assert d_above * d_below < 0
    assert abs(_controlled_det(m._replace(h=hc).tangent(), sc, A2)) < 1e-9 * abs(d_above) * 1e6
    # Nova's form: h_c = -P_T . [(E^-1)_TT]^-1 . Q_T over the strain-controlled variables T
    if A2 is None:
        T = [i for i, s in enumerate(sc) if s]
        Ci = np.linalg.inv(np.linalg.inv(m.E)[np.ix_(T, T)])
        assert hc == pytest.approx(-m.P[T] @ Ci @ m.Q[T], rel=1e-12)


def test_the_proportional_path_peak_is_the_control_of_its_conjugate():
    """u.D.u = 0 at h_R; the same as the loss of controllability of c = s1 + R s2 with the tie
    held (A = ((1, 0), (-R, 1)))."""
    m = _mech(0.6, 0.3, sign=-1.0)
    for R in (-0.5, -1.0, -2.0):
        u = np.array([1.0, R, 0.0])
        x = V @ u
        hr = h_path(m, u)
        assert x @ m._replace(h=hr).tangent() @ x == pytest.approx(0.0, abs=1e-12)
        assert hr == pytest.approx(h_control(m, (False, True, True), ((1.0, 0.0), (-R, 1.0))),
                                   rel=1e-12)


@pytest.mark.parametrize("mu, beta", [(0.6, 0.3), (0.8, 0.1), (0.55, 0.15)])
def test_rice_against_a_scan_of_acoustic_tensors(mu, beta):
    m = _mech(mu, beta, sign=-1.0)
    hl, angle = h_rice(m)
    angles = np.radians(np.linspace(0.0, 180.0, 3601))

    ns = np.stack([np.cos(angles), np.sin(angles)], 1)

    def fires(D):
        A = np.einsum("pj,ijkl,pl->pik", ns, _t4(D), ns)
        return np.min(np.linalg.det(A)) <= 0
    # the scan of 3601 normals (0.05 deg) misses the max by O(0.05 deg^2): 2e-6 of h
    assert hl == pytest.approx(_first_h(m, fires, lo=-2.0, hi=2.0, n=401), abs=2e-6)
    # the acoustic tensor at the max's normal is singular at h_loc
    n = np.array([math.cos(math.radians(angle)), math.sin(math.radians(angle))])
    A = np.einsum("j,ijkl,l->ik", n, _t4(m._replace(h=hl).tangent()), n)
    assert abs(np.linalg.det(A)) < 1e-10
    assert float(rice_h_of_angle(m, [math.radians(angle)])[0]) == pytest.approx(hl, rel=1e-14)
    # W2 is lost before localization: h_sym >= h_loc
    assert float(h_sym(m)) >= hl


def _t4(D):
    idx = np.array([[0, 2], [2, 1]])
    w = np.where(idx == 2, 1 / math.sqrt(2), 1.0)
    return D[idx[:, :, None, None], idx[None, None, :, :]] * (w[:, :, None, None] * w[None, None, :, :])


def test_cone_edges_are_where_w2_changes_sign():
    m = _mech(0.6, 0.3, sign=-1.0)._replace(h=0.01)
    D = m.tangent()
    for plane in ("strain", "stress"):
        M = plane_operator(D, plane)
        edges = cone_edges(M)
        assert len(edges) == 4
        S = 0.5 * (M + M.T)
        w2 = lambda t: np.array([math.cos(t), math.sin(t)]) @ S @ np.array([math.cos(t), math.sin(t)])  # noqa: E731
        for e in edges:
            t = math.radians(e)
            assert abs(w2(t)) < 1e-12 * np.max(np.abs(S))
            assert w2(t - 1e-4) * w2(t + 1e-4) < 0
    # no cone: positive definite symmetric part
    assert cone_edges(np.eye(2)) == []
