"""What the kernel modules share: the unsigned index type of the step loops and the step
kernels' compile options (``dem.kernels``' docstring: why)."""
import numpy as np

U = np.uint64   # unsigned index: numba skips the negative-index wraparound test for it
FAST = dict(cache=True, error_model="numpy")   # the step kernels' compile options
