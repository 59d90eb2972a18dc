"""H-microdirectional model (Nicot & Darve 2011) as a material point, after Nicot, Hadda & Darve 2013."""
from .params import HParams
from .material import HState, Increment, reference_state, update, update_full, broadcast_state

__all__ = ["HParams", "HState", "Increment", "reference_state", "update", "update_full", "broadcast_state"]
