"""Second-order work identities (docs/hmodel.md, paper Eqs. 10, 15, 36-38).

Tolerances: the identities are algebraic, so they hold to round-off. W2 values are normalized by
V |dPi| |de|; the contact sum adds terms of either sign whose size is up to ~1e3 times the total
(kn dd^2 against a nearly cancelling W2 near the cone), so 1e-15 x 1e3 x margin 100 = 1e-10 is
the round-off bound used for micro against macro; the Eulerian split involves four terms of
order one: 1e-12.
"""
import numpy as np

from hmodel.probes import strain_probes


def test_micro_equals_macro_to_roundoff(params, state_A, sweep_A):
    pr = sweep_A
    # V dPi:de = sum_i omega_i w2_i (Eq. 36): both sides from the same hexagon increments
    assert np.max(np.abs(pr.w2 - pr.w2_hex)) < 1e-12
    # ... = sum over contacts of df . dl (Eq. 15/37) where no hexagon opens or closes: this
    # checks the linearized equilibrium row of the 3x3 solve in both elastic and sliding cases
    inc_open = pr.n_open == pr.n_open[0]
    assert inc_open.sum() > 100 and pr.plastic[inc_open].any() and (~pr.plastic[inc_open]).any()
    assert np.max(np.abs(pr.w2[inc_open] - pr.w2_micro[inc_open])) < 1e-10
    # W2n + W2t is the contact sum, exactly
    assert np.array_equal(pr.w2n + pr.w2t, pr.w2_micro)


def test_eulerian_split(sweep_A):
    pr = sweep_A
    assert np.max(np.abs(pr.w2 - (pr.w2_sigma + pr.w2_V + pr.w2_g))) < 1e-12
    # and the split is not trivial: each term matters in the plastic zone (paper, Fig. 9)
    pl = pr.plastic
    assert np.max(np.abs(pr.w2_g[pl])) > 0.1 and np.max(np.abs(pr.w2_V[pl])) > 0.03


def test_linearized_increment_matches_finite_step(params, state_A, sweep_A):
    """d_sigma = T1 + T2 + T3 is the linearization of step(de) - step(0): the difference is
    second order, so it shrinks (at least) tenfold when the probe is ten times smaller, for
    elastic probes (no sliding switch inside the probe)."""
    el = sweep_A.alpha_eps[~sweep_A.plastic]
    a = el[:: max(1, len(el) // 6)]                 # spread over the elastic zone at A
    big = strain_probes(state_A, params, a, norm=1e-5)
    small = strain_probes(state_A, params, a, norm=1e-6)
    assert not big.plastic.any() and not small.plastic.any()
    rel = lambda pr: np.linalg.norm(pr.d_sigma - pr.d_sigma_step, axis=1) / np.linalg.norm(pr.d_sigma, axis=1)
    assert np.all(rel(small) < 1e-5)
    assert np.all(rel(small) < rel(big) / 9.0)


def test_T3_close_to_minus_sigma_de(params, state_A):
    """Appendix A: T3 = -sigma.de + (de1 - de2) chi with chi small (compression-positive form);
    on the principal axes this means T3_11 ~ -sigma11 de11 and T3_22 ~ -sigma22 de22."""
    pr = strain_probes(state_A, params, [0.0, 90.0], norm=1e-6)
    s = state_A.stress
    assert np.isclose(pr.T3[0, 0], -s[0, 0] * 1e-6, rtol=0.5)
    assert np.isclose(pr.T3[1, 1], -s[1, 1] * 1e-6, rtol=0.5)
