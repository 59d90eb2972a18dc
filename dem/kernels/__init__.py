"""Numba kernels: every per-particle / per-contact loop of the DEM lives in this package.

Kernels take only arrays and scalars (``advance``: tuples of them, ``common``).  Conventions
(2D, thickness t):
  x (N,2) positions [m], v (N,2) velocities [m/s], w (N,) spins [rad/s],
  r (N,) radii [m], m (N,) masses [kg], inertia (N,) [kg m^2].
  Pair list: pi, pj (P,) int32 with pi < pj, sorted by (pi, pj); ft (P,) tangential
  force history [N] expressed in the contact frame (t = z x n), which in 2D *is*
  the history rotated with the contact; mr (P,) rolling-moment history [N m] (moment on
  pi; zero without rolling resistance).
  Force convention: force exerted on pi by pj.  n = (x_j - x_i)/|.|.
  Walls: walls (4,) = [x_left, x_right, y_bottom, y_top] [m]; frictionless.

Determinism: the disks are split into contiguous blocks, one per thread; every disk sums
its contact forces in increasing pair index whatever the split (``_block_step``), so
results do not depend on the number of threads, to the bit.

Speed (issue 11; ``bench/bench_dem.py``), with the arithmetic of every force unchanged to the
bit: indices into the per-disk arrays are unsigned in the step loops (numba then skips its
negative-index test: +23 % on one thread), the contact law is branch-free (+7 %), and the step
kernels use ``error_model="numpy"`` (no zero-division test; a contact at zero distance is
impossible with positive radii: +4 %); a block's pairs go through an L1 scratch in chunks
(gather, vectorized contact law, sums in pair order) and the leapfrog runs on flat views, both
vectorized (1.2-1.3x; ``_block_step``, tested against a plain one-loop step to the bit); the
gather reads flat views and writes its rows at offsets fixed at compile time (1.10x, issue 42).

Modules (each imports only those above it):
  common       the unsigned index type U, the step kernels' compile options FAST, the records
               that group ``advance``'s arguments (Disks, PairList, WallState, Servo, Law)
  neighbours   cell sort, pair list, history carried to a new list, wall candidates
  contact      the contact law of a pair: normal force, tangential force, rolling moment
  walls        wall forces, the walls' control for a step (servo, tied servo, dead load),
               the generalized force G = F1 + k F2 of the tied walls (one definition)
  step         blocks of disks, the pairs between them, one step of a block (``_block_step``)
  driver       ``advance``: many steps in one call, with the energy ledger's slots (L_*)
  diagnostics  elastic energy, contact snapshot, per-particle stress, net forces
Every name of them is importable from here (``from dem import kernels; kernels.advance``).

Numba's cache knows a kernel's own file only (the index of each cached function holds the hash
of that one file), so a kernel of ``step`` or ``driver`` would keep, from the cache, the contact
law it inlined from ``contact`` after ``contact`` changed.  ``_drop_stale_cache`` closes that
gap: on import, every cached kernel of the package is dropped when any of its files changed.
"""
import contextlib
import hashlib
import os

from .common import FAST, U, Disks, Law, PairList, Servo, WallState
from .contact import _contact_law, _normal_force, _rolling_moment
from .diagnostics import contact_snapshot, elastic_energy, net_forces, particle_stress
from .driver import (L_D_DASH_WALL, L_DU, L_FW0, L_SIZE, L_STARTED, L_STEPS, L_W_EXT,
                     L_W_INT_WALL, _ledger_walls, advance)
from .neighbours import (_neighbours_of, build_pairs, carry_history, cell_sort, row_offsets,
                         wall_candidates)
from .step import (CHUNK, _block_step, _leapfrog_disk, _leapfrog_ledger, _ledger_disk,
                   block_partition, blocks_step, cross_forces, cross_pairs)
from .walls import _dead_load, _servo_tied, generalized_force, servo_walls, wall_forces


def _drop_stale_cache(src_dir, cache_dir) -> bool:
    """Drop the Numba cache files of this package's modules (``<module>.*.nbi``/``.nbc`` in
    ``cache_dir``) unless the hash of all its sources (``src_dir``'s ``*.py``) is the one
    recorded beside them in ``kernels-sources.sha256`` by the last drop; then record it.  A
    kernel compiled from one module and inlining another's (``advance`` and the contact law) is
    so never loaded from the cache after either changed: everything compiles again, once.
    Returns True if it dropped them.  A cache folder that cannot be written is left as it is
    (Numba caches nothing there either)."""
    stems = sorted(f[:-3] for f in os.listdir(src_dir) if f.endswith(".py"))
    h = hashlib.sha256()
    for stem in stems:
        with open(os.path.join(src_dir, stem + ".py"), "rb") as f:
            h.update(stem.encode() + b"\0" + f.read() + b"\0")
    digest = h.hexdigest()
    stamp = os.path.join(cache_dir, "kernels-sources.sha256")
    try:
        with open(stamp) as f:
            if f.read().strip() == digest:
                return False
    except OSError:
        pass
    try:
        names = os.listdir(cache_dir)
    except OSError:
        names = []
    ours = tuple(stem + "." for stem in stems)
    try:
        for name in names:
            if name.startswith(ours) and name.endswith((".nbi", ".nbc")):
                with contextlib.suppress(FileNotFoundError):     # another process was first
                    os.remove(os.path.join(cache_dir, name))
        os.makedirs(cache_dir, exist_ok=True)
        tmp = f"{stamp}.{os.getpid()}.tmp"
        with open(tmp, "w") as f:
            f.write(digest + "\n")
        os.replace(tmp, stamp)
    except OSError:
        pass
    return True


_cache = getattr(advance, "_cache", None)        # None with NUMBA_DISABLE_JIT
if getattr(_cache, "cache_path", None):
    _drop_stale_cache(os.path.dirname(os.path.abspath(__file__)), _cache.cache_path)
del _cache
