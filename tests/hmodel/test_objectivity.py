"""Objectivity of the localization: rotating the fabric and the strain increments together
rotates the stress. The rotation is a whole number of orientation steps pi/n_dir so that the
rotated hexagon set is the same set (the map is then exact up to summation order: 1e-9 relative
covers round-off in sums of 48 terms over ~300 steps)."""
import math

import numpy as np

from hmodel import HParams, reference_state, update


def _rot(beta):
    c, s = math.cos(beta), math.sin(beta)
    return np.array([[c, -s], [s, c]])


def test_rotating_fabric_and_strain_rotates_stress():
    n = 48
    k = 7
    beta = k * math.pi / n
    p1 = HParams(n_dir=n, fabric_a=0.4, fabric_b=10.0)
    p2 = p1.replace(fabric_b=10.0 + math.degrees(beta))
    R = _rot(beta)
    s1, s2 = reference_state(p1), reference_state(p2)
    rng = np.random.default_rng(5)
    n_sliding = 0
    for step in range(300):
        base = np.array([[1.5e-5, 0.0], [0.0, 1.0e-5]]) if step < 40 else np.array([[1e-5, 2e-6], [2e-6, -6e-6]])
        de = base + 1e-6 * rng.normal(size=(2, 2))
        de = 0.5 * (de + de.T)
        sig1, C1, s1 = update(s1, de, p1)
        sig2, C2, s2 = update(s2, R @ de @ R.T, p2)
        scale = np.abs(sig1).max()
        assert np.allclose(sig2, R @ sig1 @ R.T, rtol=0, atol=1e-9 * scale)
        n_sliding += int(s1.sliding.sum())
    assert n_sliding > 0, "the path must include sliding for the check to cover it"
    # the tangent rotates as a fourth-order tensor
    C1r = np.einsum("ia,jb,kc,ld,abcd->ijkl", R, R, R, R, C1)
    assert np.allclose(C2, C1r, rtol=0, atol=1e-9 * np.abs(C1).max())
