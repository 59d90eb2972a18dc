"""Compact Numba 2D DEM for the second-order work analysis of Nicot, Hadda & Darve (2013),
section 4.  Modules: params (DemParams), kernels (all @njit loops), neighbours (pair list),
walls (boundary control), simulation (State, Simulation), sample (generator, compaction),
experiment (biaxial test), probes (directional analysis, W2), io (files), bench.
CLI: python -m dem {biaxial, probes, bench}; see docs/dem.md."""

from common.options import listen_for_compilation

listen_for_compilation()     # a script's first compilation is announced, as the CLI's
