import pytest

from hmodel import HParams
from fem.biaxial import BiaxialConfig, run_biaxial

# Small, fast settings for the default (not slow) tests: n_dir = 36 moves the material peak to
# eps1 ~ 2.46 % (180 orientations: 2.09 %), the mechanisms are the same.
N_DIR = 36
D_EPS1 = 5e-4


@pytest.fixture
def no_computation(monkeypatch):
    """Every runner of ``python -m fem`` fails loudly: validation must come first."""
    import fem.__main__ as fcli

    def boom(*a, **k):
        raise AssertionError("computation started before the options were validated")
    for name in ("run_biaxial", "run_burst", "compile_kernels"):
        monkeypatch.setattr(fcli, name, boom)


@pytest.fixture(scope="session")
def params36():
    return HParams(n_dir=N_DIR)


@pytest.fixture(scope="session")
def homogeneous_run(tmp_path_factory):
    """The perfect 2 x 4 quad specimen from the isotropic state past the peak (eps1 = 3 %), with
    every output written."""
    out = tmp_path_factory.mktemp("homogeneous")
    cfg = BiaxialConfig(nx=2, ny=4, n_dir=N_DIR, d_eps1=D_EPS1, eps1_max=0.03, n_sphere=300)
    return run_biaxial(cfg, out)
