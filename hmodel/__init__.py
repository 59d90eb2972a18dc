"""H-microdirectional model (Nicot & Darve 2011) as a material point, after Nicot, Hadda & Darve 2013."""
from common.options import listen_for_compilation
from .params import HParams
from .material import HState, Increment, reference_state, update, update_full, broadcast_state

listen_for_compilation()     # a script's first compilation is announced, as the CLI's

__all__ = ["HParams", "HState", "Increment", "reference_state", "update", "update_full", "broadcast_state"]
