"""H-microdirectional model (Nicot & Darve 2011) as a material point, after Nicot, Hadda & Darve 2013:
one material of the contract of ``point`` (``hmodel.law``), with its Numba kernels."""
from common.options import listen_for_compilation
from .params import HParams
from .material import HState, Increment, reference_state, update, update_full, broadcast_state
from .law import HMODEL

listen_for_compilation()     # a script's first compilation is announced, as the CLI's

__all__ = ["HParams", "HState", "Increment", "reference_state", "update", "update_full", "broadcast_state",
           "HMODEL"]
