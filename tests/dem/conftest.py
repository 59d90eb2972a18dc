import pytest

from dem.params import DemParams
from dem.sample import compact


@pytest.fixture(scope="session")
def small_sample():
    """A 200-disk sample compacted to 200 kPa (friction restored), about 10 s."""
    sim, rep = compact(DemParams(n=200, seed=5))
    assert rep.converged
    return sim.state()
