import pytest

from hmodel import HParams
from hmodel.driver import drained_biaxial, isotropic_state, run_path


@pytest.fixture(scope="session")
def params():
    return HParams()


@pytest.fixture(scope="session")
def iso_state(params):
    return isotropic_state(params)


@pytest.fixture(scope="session")
def drained(params, iso_state):
    """The Table I drained path (sigma2 = 200 kPa, d_eps1 = 1e-5) to eps1 = 5 %."""
    return run_path(iso_state, params, drained_biaxial(1e-5), 5000)


@pytest.fixture(scope="session")
def state_A(params, iso_state):
    """Point A: first state of the drained path with eta >= 1.029."""
    r = run_path(iso_state, params, drained_biaxial(1e-5), 5000,
                 until=lambda e, s: (s[0] - s[1]) >= 1.029 * 0.5 * (s[0] + s[1]))
    return r.state


@pytest.fixture(scope="session")
def sweep_A(params, state_A):
    from hmodel.probes import directional_sweep
    return directional_sweep(state_A, params, n=360)


@pytest.fixture
def no_computation(monkeypatch):
    """Every experiment entry point of the CLI fails loudly: validation must come first (the
    commands of python -m hmodel are point.cli's)."""
    import point.cli as cli

    def boom(*a, **k):
        raise AssertionError("computation started before the options were validated")
    for name in ("biaxial_test", "directional_analysis", "bifurcation_domain", "compile_kernels"):
        monkeypatch.setattr(cli, name, boom)
