"""Newton with the consistent tangent converges quadratically when the sliding pattern is fixed."""
import numpy as np

from fem.mesh import rectangle
from fem.problem import Biaxial, Imperfection
from fem.solver import LoadStepper, newton_step

ROUNDOFF = 1e-13     # normalized residual below which ratios are round-off, not convergence


def quadratic_ratios(res):
    """r_{k+1} / r_k^2 over the iterates above the round-off floor."""
    return [b / a ** 2 for a, b in zip(res[:-1], res[1:]) if b > ROUNDOFF]


def test_quadratic_elastic_step(params36):
    """Elastic pattern (Coulomb cap off): a large first step (d_eps1 = 1e-3) from the isotropic
    state; the update is nonlinear (lengths x forces, volume), so several iterations."""
    prob = Biaxial(rectangle(0.05, 0.1, 2, 4), params36, allow_sliding=False)
    u0 = np.zeros(prob.ndofs)
    g = u0.copy()
    g[prob.prescribed] = prob.prescribed_values(1e-3 * prob.height)
    # predictor with some lateral expansion, so no hexagon opens between iterates
    g[prob.basis.nodal_dofs[0]] = 0.3e-3 * (prob.mesh.p[0] - 0.025)
    res = newton_step(prob, u0, g, rtol=1e-14)
    r = res.residuals
    print("normalized residuals:", ["%.3e" % x for x in r], res.pattern_changes)
    print("ratios r_k+1 / r_k^2:", ["%.3e" % x for x in quadratic_ratios(r)])
    assert all(c == 0 for c in res.pattern_changes)
    assert len(quadratic_ratios(r)) >= 2           # at least two genuine Newton contractions
    assert max(quadratic_ratios(r)) < 1.0
    assert r[-1] < 1e-14


def test_quadratic_with_sliding_when_pattern_fixed(params36):
    """The real material, non-homogeneous specimen (weak spot): every iteration of every step in
    which no hexagon switched pattern contracts quadratically."""
    prob = Biaxial(rectangle(0.05, 0.1, 3, 6), params36,
                   imperfection=Imperfection("spot", size=0.3, phi_g=17.0))
    seen = []

    def on_step(res, info):
        r, ch = res.residuals, res.pattern_changes
        print(["%.2e" % x for x in r], ch)
        for k in range(len(r) - 1):
            # iterate k -> k+1 with the same pattern at k and k+1 (the tangent of iterate k was
            # the tangent of the pattern of k+1), r_k+1 above round-off
            if ch[k + 1] == 0 and r[k + 1] > ROUNDOFF:
                seen.append(r[k + 1] / r[k] ** 2)

    LoadStepper(prob, 5e-4, rtol=1e-13).run(0.01, on_step)
    print("ratios:", ["%.2e" % x for x in seen])
    assert len(seen) >= 3
    assert max(seen) < 1.0
