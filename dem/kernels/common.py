"""What the kernel modules share: the unsigned index type of the step loops, the step kernels'
compile options (``dem.kernels``' docstring: why), and the records that group ``advance``'s
arguments: the arrays and numbers that belong together, given to it as one plain tuple each
(``tuple(record)``), which it unpacks at its top into the locals it had before.  The step of a
block (``step._block_step``) keeps its flat list: given the same records the step was 2-5 %
slower (measured at 12,000 disks on one thread, issue 33)."""
from typing import NamedTuple

import numpy as np

U = np.uint64   # unsigned index: numba skips the negative-index wraparound test for it
FAST = dict(cache=True, error_model="numpy")   # the step kernels' compile options


class Disks(NamedTuple):
    """The per-disk arrays a step reads and writes (N rows)."""
    x: np.ndarray          # (N, 2) positions [m]
    v: np.ndarray          # (N, 2) velocities [m/s]
    w: np.ndarray          # (N,) spins [rad/s]
    theta: np.ndarray      # (N,) rotations [rad]
    r: np.ndarray          # (N,) radii [m]
    m: np.ndarray          # (N,) masses [kg]
    inertia: np.ndarray    # (N,) moments of inertia [kg m^2]
    fext: np.ndarray       # (N, 2) the walls' forces of the step [N]
    fnet: np.ndarray       # (N, 4) fx, fy, sum of tangential forces (-> torque), rolling moments
    x_ref: np.ndarray      # (N, 2) positions at the last rebuild of the pair list [m]
    disp2: np.ndarray      # (N,) squared displacement since that rebuild [m^2]


class PairList(NamedTuple):
    """pi, pj (P,) int32 with pi < pj sorted; ft (P,) tangential history [N]; mr (P,)
    rolling-moment history [N m]; cand_off (5,), cand wall candidates."""
    pi: np.ndarray
    pj: np.ndarray
    ft: np.ndarray
    mr: np.ndarray
    cand_off: np.ndarray
    cand: np.ndarray


class Law(NamedTuple):
    """The contact law's and the integration's numbers."""
    kn: float              # normal stiffness [N/m]
    kt: float              # tangential stiffness [N/m]
    mu: float              # friction coefficient (current)
    cap_on: bool           # Coulomb cap on (False: sliding prevented, the elastic probes)
    beta: float            # normal dashpot, fraction of critical damping (0 = off)
    kr: float              # rolling stiffness factor x kt [N/m] (k_r = kr R*^2)
    mur: float             # rolling friction (current; 0 = no rolling resistance)
    damping: float         # Cundall's non-viscous damping
    dt: float              # time step [s]


class WallState(NamedTuple):
    """The walls (4,) each: [x_left, x_right, y_bottom, y_top]."""
    walls: np.ndarray      # positions [m]
    walls_ref: np.ndarray  # positions at the last rebuild of the pair list [m]
    prev: np.ndarray       # their inward moves of the last step (the servo's memory) [m]
    wF: np.ndarray         # compressive force on each [N]
    wK: np.ndarray         # sum of its contacts' stiffnesses [N/m]


class Servo(NamedTuple):
    """The walls' control (``dem.walls.Control``'s fields, see there) and the servo's gains."""
    mode: np.ndarray       # (2,) int64 per axis: 0 stress, 1 strain rate; both 2 tied, 3 dead load
    s_from: np.ndarray     # (2,) stress targets at the ramp's start [Pa]
    s_to: np.ndarray       # (2,) and at its end [Pa]
    ramp_start: int        # global step of the ramp's start
    ramp_len: int          # its length in steps (0: a step change)
    rate: np.ndarray       # (2,) strain rates [1/s], compression positive
    len0: np.ndarray       # (2,) reference lengths (W0, H0) [m]
    ratio: float           # R of the tied controls
    wall_mass: float       # the walls' generalized mass under a dead load [kg]
    g_held: float          # the held generalized force under a dead load [N]
    thickness: float       # [m]
    gain: float            # the stress servo's gain
    smoothing: float       # and its smoothing
    vmax: float            # its largest wall speed [m/s]
