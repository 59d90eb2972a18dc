"""Bifurcation indicators of the biaxial specimen, at every converged step:

- ``global_check``: the global ones, on the condensed tangent stiffness (sign of det K, inertia
  and smallest eigenvalue of its symmetric part, their modes, for both platen controls;
  ``GlobalCheck``), the earlier route kept as the tests' oracle, the second-order work of an
  increment;
- ``process``: the global check in a process of its own (``GlobalCheckProcess``);
- ``linalg``: the factorizations they use (SuperLU, LAPACK's banded LU, a banded L D L^T) and the
  OpenBLAS thread count while they run;
- ``local``: the local ones, at every quadrature point from its tangent (det, lam_min of the
  symmetric part, the minimum normalized second-order work, Rice's acoustic tensor).

The names below are those of the former single module ``fem/indicators.py``.
"""
from .global_check import GlobalCheck, global_indicators, global_indicators_direct, global_w2
from .linalg import det_sign, lam_min_sym, one_blas_thread, permutation_parity, symmetric_inertia
from .local import fibonacci_sphere, local_indicators, mandel
from .process import GlobalCheckProcess
# The Numba kernels of the modules, named here too: ``fem.__main__._fem_kernels`` finds the
# kernels to compile ahead of a run in this namespace. The tests call some of them from here.
from .linalg import _band_ldlt, _band_solve, _parity                    # noqa: F401
from .local import _rice_kernel, _w2_min_kernel, _w2_one  # noqa: F401

__all__ = ["permutation_parity", "det_sign", "symmetric_inertia", "lam_min_sym", "GlobalCheck",
           "GlobalCheckProcess",
           "global_indicators", "global_indicators_direct", "global_w2", "mandel",
           "local_indicators", "fibonacci_sphere"]
