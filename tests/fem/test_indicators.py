"""Indicator building blocks against dense linear algebra and closed forms."""
import numpy as np
import pytest
import scipy.sparse as sp

from fem.indicators import (det_sign, symmetric_inertia, lam_min_sym, local_indicators, mandel,
                            permutation_parity)


def test_permutation_parity():
    assert permutation_parity(np.arange(5)) == 1
    assert permutation_parity(np.array([1, 0, 2])) == -1
    assert permutation_parity(np.array([1, 2, 0])) == 1


@pytest.mark.parametrize("seed", range(40))
def test_sparse_det_sign_inertia_lam_min(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(12, 70))
    A = sp.random(n, n, density=0.15, random_state=seed) + sp.diags(rng.normal(size=n) * 3 + rng.uniform(-1, 5))
    A = A.toarray()
    s, _ = det_sign(sp.csr_matrix(A))
    assert s == np.sign(np.linalg.det(A))
    S = 0.5 * (A + A.T)
    S[0, 0] -= rng.uniform(0, 40)          # sometimes one isolated, very negative eigenvalue
    ev = np.linalg.eigvalsh(S)
    k = symmetric_inertia(sp.csr_matrix(S))
    assert k in (-1, int(np.sum(ev < 0)))
    lam, n_neg = lam_min_sym(sp.csr_matrix(S))
    assert lam == pytest.approx(ev[0], abs=1e-8 * np.abs(ev).max())


def test_exactly_singular_det_sign():
    A = sp.csr_matrix(np.array([[1.0, 2.0], [2.0, 4.0]]))
    assert det_sign(A)[0] == 0


@pytest.mark.parametrize("banded", [True, False])
def test_exactly_singular_stiffness(banded):
    """A zero stiffness: det K = 0 for both controls on both paths, no inertia certificate."""
    from fem.indicators import GlobalCheck
    prob = _small_problem(2, 3)
    check = GlobalCheck(prob)
    check.MAX_BAND = -1 if banded is False else check.MAX_BAND
    row, _ = check(prob.stiffness(np.zeros((2, 2, 2, 2, prob.npts))))
    assert row["det_k_sign"] == 0 and row["det_k_sign_f"] == 0
    assert row["n_neg_ks"] == -1 and row["n_neg_ks_f"] == -1


def _isotropic(lam, mu, npts=3):
    d = np.eye(2)
    D = (lam * np.einsum("ij,kl->ijkl", d, d)
         + mu * (np.einsum("ik,jl->ijkl", d, d) + np.einsum("il,jk->ijkl", d, d)))
    return np.repeat(D[..., None], npts, axis=-1)


def test_local_isotropic_elastic_closed_forms():
    lam, mu = 3e7, 2e7
    loc = local_indicators(_isotropic(lam, mu))
    # acoustic tensor (lam + mu) n n + mu I: det = (lam + 2 mu) mu for every n
    assert np.allclose(loc["rice_min"], (lam + 2 * mu) * mu, rtol=1e-12)
    # Mandel eigenvalues 2 mu (deviatoric, twice) and 2 (lam + mu)
    assert np.allclose(loc["lam_min_Ds"], 2 * mu, rtol=1e-12)
    assert np.allclose(loc["det_D"], (2 * mu) ** 2 * 2 * (lam + mu), rtol=1e-12)
    assert np.all(loc["w2_min"] > 0) and np.all(loc["w2_min"] <= 1 + 1e-12)


def test_local_w2_min_finds_negative_direction():
    # D_M = diag(1, 1, -0.5) in Mandel form (shear softening): min normalized W2 = -1 at pure shear
    D = np.zeros((2, 2, 2, 2, 1))
    D[0, 0, 0, 0] = D[1, 1, 1, 1] = 1.0
    D[0, 1, 0, 1] = D[1, 0, 1, 0] = D[0, 1, 1, 0] = D[1, 0, 0, 1] = -0.25
    M = mandel(D)[..., 0]
    assert np.allclose(M, np.diag([1.0, 1.0, -0.5]))
    loc = local_indicators(D)
    assert loc["w2_min"][0] == pytest.approx(-1.0, abs=1e-4)
    assert loc["lam_min_Ds"][0] == pytest.approx(-0.5)
    # and a positive definite, non-symmetric D: min W2 > 0 while det D > 0
    D2 = np.zeros((2, 2, 2, 2, 1))
    D2[0, 0, 0, 0] = D2[1, 1, 1, 1] = 1.0
    D2[0, 0, 1, 1], D2[1, 1, 0, 0] = 0.5, -0.5          # skew part: W2 unaffected
    D2[0, 1, 0, 1] = D2[1, 0, 1, 0] = D2[0, 1, 1, 0] = D2[1, 0, 0, 1] = 0.5
    loc2 = local_indicators(D2)
    assert loc2["w2_min"][0] > 0 and loc2["lam_min_Ds"][0] == pytest.approx(1.0)


def test_w2_min_against_brute_force():
    """The sampled + pattern-searched minimum is within 1e-4 of a 100k-direction brute force on
    random non-symmetric tangents (measured: at most 1.3e-5 above it)."""
    rng = np.random.default_rng(3)
    D = rng.normal(size=(2, 2, 2, 2, 12))
    D = 0.5 * (D + D.transpose(1, 0, 2, 3, 4))
    D = 0.5 * (D + D.transpose(0, 1, 3, 2, 4))               # minor symmetries
    M = np.moveaxis(mandel(D), -1, 0)
    X = rng.normal(size=(100_000, 3))
    X /= np.linalg.norm(X, axis=1, keepdims=True)
    DX = np.einsum("pab,nb->pna", M, X)
    brute = (np.einsum("na,pna->pn", X, DX) / np.linalg.norm(DX, axis=2)).min(axis=1)
    w = local_indicators(D)["w2_min"]
    assert np.all(w <= brute + 1e-4)
    # and never below the true minimum by more than the brute force's own sampling error
    assert np.all(w >= brute - 1e-3)


# -- the one-factorization route (GlobalCheck) against dense linear algebra and the direct route

def _small_problem(nx=3, ny=5):
    from fem.biaxial import BiaxialConfig, build_problem
    return build_problem(BiaxialConfig(nx=nx, ny=ny, n_dir=12))


def _random_stiffness(prob, seed, shift=0.0):
    """K = sum B^T D B dx of random tangents with the minor symmetries only (K non-symmetric,
    indefinite), plus ``shift`` x the elastic-like identity part to move its spectrum."""
    rng = np.random.default_rng(seed)
    D = rng.normal(size=(2, 2, 2, 2, prob.npts))
    D = 0.5 * (D + D.transpose(1, 0, 2, 3, 4))
    D = 0.5 * (D + D.transpose(0, 1, 3, 2, 4))
    d = np.eye(2)
    iso = (np.einsum("ik,jl->ijkl", d, d) + np.einsum("il,jk->ijkl", d, d))[..., None]
    return prob.stiffness(1e6 * (D + shift * iso))


def _dense_controls(prob, K):
    """(K_d, K_f) dense: platen displacement prescribed, platen force prescribed (T^T K T)."""
    K = sp.csr_matrix(K)
    return (K[prob.free][:, prob.free].toarray(), (prob.T_platen.T @ K @ prob.T_platen).toarray())


def _full(prob, suffix, v):
    u = np.zeros(prob.ndofs)
    if suffix == "":
        u[prob.free] = v
    else:
        u = prob.T_platen @ v
    return u / np.linalg.norm(u)


@pytest.mark.parametrize("banded", [True, False])
@pytest.mark.parametrize("seed", range(12))
def test_schur_det_and_inertia_identities(seed, banded):
    """det K_f = det K_d x (a - c^T K_d^-1 b) and n_neg(K_s,f) = n_neg(K_s,d) + [z_s < 0] against
    a direct LU of K_f (det_sign) and dense slogdet / eigvalsh; lam_min of both controls against
    eigvalsh (to 1e-9 of the spectral radius: ARPACK tol 1e-10 on 1/(lam - s)); the eigenvector
    against eigh (|cos| = 1 to 1e-8 when lam_min is simple). Both factorization paths: LAPACK
    band (dgbtrf, banded L D L^T) and SuperLU (MAX_BAND = -1)."""
    from fem.indicators import GlobalCheck
    prob = _small_problem()
    K = _random_stiffness(prob, seed, shift=[0.0, 0.5, 2.0][seed % 3])
    check = GlobalCheck(prob)
    if not banded:
        check.MAX_BAND = -1
    row, modes = check(K)
    assert (check._band is not None) == banded
    for suf, A in zip(("", "_f"), _dense_controls(prob, K)):
        sgn, logabs = np.linalg.slogdet(A)
        assert row["det_k_sign" + suf] == int(sgn)
        assert row["log10_abs_det_k" + suf] == pytest.approx(logabs / np.log(10), abs=1e-9 * abs(logabs) + 1e-9)
        assert row["det_k_sign" + suf] == det_sign(sp.csr_matrix(A))[0]
        S = 0.5 * (A + A.T)
        w, V = np.linalg.eigh(S)
        assert row["n_neg_ks" + suf] in (-1, int(np.sum(w < 0)))
        assert row["lam_min_ks" + suf] == pytest.approx(w[0], abs=1e-9 * np.abs(w).max())
        if row["lam_min_ks" + suf] <= 0:
            m = modes["mode_ks" + suf]
            assert m is not None and np.linalg.norm(m) == pytest.approx(1.0)
            if w[1] - w[0] > 1e-6 * np.abs(w).max():
                assert abs(m @ _full(prob, suf, V[:, 0])) == pytest.approx(1.0, abs=1e-8)
        else:
            assert modes["mode_ks" + suf] is None
    # the near-null vectors only where det K changed sign since the previous call
    assert modes["mode_detk"] is None and modes["mode_detk_f"] is None


@pytest.mark.parametrize("banded", [True, False])
def test_near_null_vector_at_a_det_sign_change(banded):
    """K(t) = K0 - t I on the free dofs crosses det K = 0 at t = an eigenvalue; at the first call
    past the crossing mode_detk is the right singular vector of the smallest singular value of
    K_d (dense SVD, |cos| = 1 to 1e-8), and of K_f for the force control."""
    from fem.indicators import GlobalCheck
    prob = _small_problem()
    K0 = sp.csr_matrix(_random_stiffness(prob, 3, shift=2.0))
    Kd0 = K0[prob.free][:, prob.free].toarray()
    ev = np.linalg.eigvals(Kd0)
    lam = np.min(np.abs(ev.real[np.abs(ev.imag) < 1e-9 * np.abs(ev).max()]))   # a real eigenvalue
    P = sp.lil_matrix((prob.ndofs, prob.ndofs))
    P[prob.free, prob.free] = 1.0
    check = GlobalCheck(prob)
    check.MAX_BAND = -1 if banded else check.MAX_BAND
    rows = []
    for t in (0.9 * lam, 1.1 * lam):
        K = K0 - t * P.tocsr() if lam > 0 else K0 + t * P.tocsr()
        row, modes = check(K)
        rows.append((row, modes, K))
    (r0, m0, _), (r1, m1, K1) = rows
    assert r0["det_k_sign"] != r1["det_k_sign"]
    assert m0["mode_detk"] is None and m1["mode_detk"] is not None
    for suf, A in zip(("", "_f"), _dense_controls(prob, K1)):
        if r0["det_k_sign" + suf] == r1["det_k_sign" + suf]:
            assert m1["mode_detk" + suf] is None
            continue
        _, s, Vt = np.linalg.svd(A)
        assert abs(m1["mode_detk" + suf] @ _full(prob, suf, Vt[-1])) == pytest.approx(1.0, abs=1e-8)


def test_new_route_equals_direct_route_through_the_peak(monkeypatch):
    """Every step of a weak-band run from the isotropic state past the peak (n_neg up to tens,
    det K of both controls changing sign): GlobalCheck (one LU, one LDL^T, eigsh k = 1 at a
    proven shift, Schur complements) gives the same det signs and n_neg as the direct route (two
    LUs, two LDL^T, eigsh k = n_neg + 1), log10 |det| to 1e-9 (rounding of the Schur complement
    against a second LU), lam_min to 1e-9 relative + 1e-12 mean|diag K_s| (both eigen-solves at
    ARPACK tol 1e-10; measured 4e-11 on the 20 x 40 benchmark)."""
    import fem.biaxial as fb
    from fem.indicators import GlobalCheck, global_indicators_direct
    pairs = []

    class Recording(GlobalCheck):
        def __call__(self, K, want_modes=True):
            row, modes = super().__call__(K, want_modes)
            Kd = sp.csr_matrix(K)[self._prob.free][:, self._prob.free]
            pairs.append((row, global_indicators_direct(K, self._prob),
                          float(np.mean(np.abs(Kd.diagonal())))))
            return row, modes

    def make(prob, **kw):
        g = Recording(prob, **kw)
        g._prob = prob
        return g

    monkeypatch.setattr(fb, "GlobalCheck", make)
    # the check in this process, where the recording is (the run's own process gives the same
    # rows: test_global_process.py)
    cfg = fb.BiaxialConfig(nx=6, ny=12, n_dir=36, d_eps1=5e-4, eps1_max=0.03, imperfection="band",
                           imp_phi_g=15.0, fields=False, mp_reference=False, global_process=False)
    r = fb.run_biaxial(cfg)
    c = r.curve
    assert 0 < int(np.argmax(c["q"])) < len(c["q"]) - 1                # through the peak
    assert np.max(c["n_neg_ks"]) >= 3 and len(pairs) == len(c["q"])
    assert len(set(c["det_k_sign_f"])) == 2                             # the limit point is met
    worst = 0.0
    for new, old, scale in pairs:
        for suf in ("", "_f"):
            assert new["det_k_sign" + suf] == old["det_k_sign" + suf]
            assert new["n_neg_ks" + suf] == old["n_neg_ks" + suf]
            assert new["log10_abs_det_k" + suf] == pytest.approx(old["log10_abs_det_k" + suf], abs=1e-9)
            lo = old["lam_min_ks" + suf]
            err = abs(new["lam_min_ks" + suf] - lo) / (abs(lo) + 1e-3 * scale)
            worst = max(worst, err)
            assert abs(new["lam_min_ks" + suf] - lo) <= 1e-9 * abs(lo) + 1e-12 * scale
    print(f"{len(pairs)} steps, max n_neg {np.max(c['n_neg_ks']):.0f}, worst lam_min difference "
          f"{worst:.1e} relative")


def test_w2_sampled_stage_is_the_plain_minimum():
    """With the pattern search switched off (spacing 0: rings of radius 0), the kernel returns
    the minimum over the sampled directions of x.Mx / (|Mx| |x|) computed plainly: its ranking by
    v |v| without square roots picks the same direction (to 1e-14, the rounding of v)."""
    from fem.indicators import _w2_min_kernel, fibonacci_sphere
    rng = np.random.default_rng(7)
    M = rng.normal(size=(50, 3, 3))
    M[0] = 0.0                                           # M x = 0: W2 = 0 by convention
    X = fibonacci_sphere(300)
    MX = np.einsum("pab,nb->pna", M, X)
    with np.errstate(invalid="ignore"):
        v = np.einsum("na,pna->pn", X, MX) / np.linalg.norm(MX, axis=2)
    v[0] = 0.0
    assert np.allclose(_w2_min_kernel(M, X, 0.0), v.min(axis=1), rtol=0, atol=1e-14)


def test_local_thread_choice_takes_the_faster_and_retries():
    """The local kernels' thread count: each count is tried once (after an untimed warm-up
    call), then the faster one, the slower re-tried every ``retry`` calls, so a change of load is
    followed; one thread when only one is allowed."""
    from common.threads import ThreadChooser as _ThreadChoice
    c = _ThreadChoice(retry=4)
    assert c.pick(1) == 1
    c.record(1, 99.0)                       # warm-up: not timed
    picks = []
    cost = {1: 1.0, 2: 3.0}
    for _ in range(12):
        n = c.pick(2)
        picks.append(n)
        c.record(n, cost[n])
    assert picks[:2] == [1, 2] and picks[2:5] == [1, 1, 1] and 2 in picks[5:]
    cost = {1: 5.0, 2: 0.5}                 # the load moved: two threads are now faster
    for _ in range(24):
        n = c.pick(2)
        c.record(n, cost[n])
    assert c.pick(2) == 2
