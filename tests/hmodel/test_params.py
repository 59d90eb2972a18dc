import math

import numpy as np
import pytest

from hmodel import HParams, reference_state, update


def test_table_one_defaults():
    p = HParams()
    assert (p.kn, p.kt, p.phi_g, p.r_g, p.alpha0, p.p0) == (1e6, 0.5e6, 20.0, 1e-3, 42.8, 200e3)
    assert p.h == 2e-3                      # spec: h = 2 r_g by default
    assert math.isclose(p.mu, math.tan(math.radians(20.0)))
    assert math.isclose(p.omega.sum(), 1.0)
    assert p.theta.shape == (180,) and p.theta[0] == 0.0 and p.theta[-1] < math.pi


@pytest.mark.parametrize("field,value,allowed", [
    ("kn", 0.0, "kn > 0"), ("kn", -1.0, "kn > 0"), ("kt", -1.0, "kt >= 0"),
    ("phi_g", 0.0, "0 < phi_g < 90"), ("phi_g", 90.0, "0 < phi_g < 90"), ("phi_g", -5.0, "0 < phi_g < 90"),
    ("alpha0", 30.0, "30 < alpha0 < 90"), ("alpha0", 90.0, "30 < alpha0 < 90"), ("alpha0", 10.0, "30 < alpha0 < 90"),
    ("n_dir", 7, "n_dir >= 8"), ("n_dir", 8.5, "n_dir >= 8"), ("r_g", 0.0, "r_g > 0"),
    ("p0", -1.0, "p0 > 0"), ("thickness", 0.0, "thickness > 0"), ("fabric_a", 1.0, "-1 < fabric_a < 1"),
])
def test_invalid_parameter_names_field_and_range(field, value, allowed):
    with pytest.raises(ValueError) as e:
        HParams(**{field: value})
    msg = str(e.value)
    assert f"HParams.{field}" in msg and allowed in msg


@pytest.mark.parametrize("field", ["kn", "kt", "phi_g", "r_g", "alpha0", "p0"])
@pytest.mark.parametrize("bad", [float("nan"), float("inf")])
def test_non_finite_parameters_refused(field, bad):
    with pytest.raises(ValueError, match=f"HParams.{field} must be finite"):
        HParams(**{field: bad})


def test_non_finite_strain_increment_refused():
    p = HParams(n_dir=16)
    s = reference_state(p)
    for bad in (np.nan, np.inf):
        de = np.array([[1e-5, 0.0], [0.0, bad]])
        with pytest.raises(ValueError, match="non-finite"):
            update(s, de, p)


def test_shape_mismatch_refused():
    p = HParams(n_dir=16)
    s = reference_state(p, (3,))
    with pytest.raises(ValueError, match="shape"):
        update(s, np.zeros((2, 2)), p)
    with pytest.raises(ValueError, match="n_dir"):
        update(reference_state(HParams(n_dir=32)), np.zeros((2, 2)), p)
