"""The DEM benchmark's LAMMPS comparison (issue 11 §2): the data file and input describe this
project's sample and contact law exactly; with LAMMPS installed it runs and reports a rate."""
import math

import numpy as np
import pytest

from dem.bench import lammps_executable, lammps_rate, write_lammps


def test_lammps_files_are_this_sample_and_contact_law(small_sample, tmp_path):
    st = small_sample
    p = st.params
    inp = write_lammps(st, tmp_path, 100)
    text = open(inp).read()
    data = open(tmp_path / "sample.data").read().splitlines()
    n = len(st.r)
    assert f"{n} atoms" in data
    start = data.index("Atoms # sphere") + 2
    atoms = np.array([[float(v) for v in line.split()] for line in data[start:start + n]])
    assert np.array_equal(atoms[:, 2], 2 * st.r)                 # diameters, full precision
    assert np.array_equal(atoms[:, 4:6], st.x)                   # positions
    mu = math.tan(math.radians(p.phi_g))
    assert f"pair_style gran/hooke/history {p.kn!r} {p.kt!r} 0.0 0.0 {mu!r} 0" in text
    assert f"density/disc {p.density * p.thickness!r}" in text   # disk masses, not spheres'
    assert f"timestep {p.dt!r}" in text and f"neighbor {p.skin!r} bin" in text
    for w in st.walls:
        assert repr(float(w)) in text                            # the state's walls


@pytest.mark.skipif(lammps_executable() is None, reason="LAMMPS (lmp) not installed")
def test_lammps_runs_the_sample(small_sample, tmp_path):
    assert lammps_rate(small_sample, 200, tmp_path) > 0
