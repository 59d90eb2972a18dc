"""Neighbour search: cell list -> Verlet pair list, with tangential history carried over.

The list holds every pair with gap < skin; it stays valid while no particle (and no wall)
has moved more than skin/2 since the rebuild (two particles then approach by < skin).
"""
from __future__ import annotations

import numpy as np

from . import kernels
from .kernels import PairList     # the record the step kernels take


def build_pair_list(x, r, walls, skin, old_pi=None, old_pj=None, old_ft=None,
                    old_mr=None) -> PairList:
    """Build the pair list for positions x (N,2) [m], radii r (N,) [m], box walls (4,).

    If an old list is given, the tangential and rolling histories of pairs present in both
    are kept.
    """
    n = x.shape[0]
    cell = 2.0 * float(r.max()) + skin
    lo_x = min(float(walls[0]), float(x[:, 0].min())) - cell
    lo_y = min(float(walls[2]), float(x[:, 1].min())) - cell
    hi_x = max(float(walls[1]), float(x[:, 0].max())) + cell
    hi_y = max(float(walls[3]), float(x[:, 1].max())) + cell
    ncx = max(1, int((hi_x - lo_x) / cell))
    ncy = max(1, int((hi_y - lo_y) / cell))
    # cells at least `cell` wide: widen them so ncx cells cover the box exactly
    cell = max((hi_x - lo_x) / ncx, (hi_y - lo_y) / ncy, cell)
    ncx = max(1, int((hi_x - lo_x) / cell) + 1)
    ncy = max(1, int((hi_y - lo_y) / cell) + 1)
    pi, pj = kernels.build_pairs(x, r, skin, lo_x, lo_y, cell, ncx, ncy)
    if old_pi is not None and len(old_pi):
        if old_mr is None:
            old_mr = np.zeros(len(old_pi))
        ft, mr = kernels.carry_history(old_pi, old_pj, old_ft, old_mr, pi, pj, n)
    else:
        ft, mr = np.zeros(len(pi)), np.zeros(len(pi))
    return finish_pair_list(x, r, walls, skin, pi, pj, ft, mr)


def finish_pair_list(x, r, walls, skin, pi, pj, ft, mr) -> PairList:
    """Wall-candidate lists for a given pair list (deterministic)."""
    cand_off, cand = kernels.wall_candidates(x, r, np.asarray(walls, float), skin)
    return PairList(pi, pj, ft, mr, cand_off, cand)


def brute_force_pairs(x, r, skin):
    """Reference O(N^2) pair set {(i, j)}, for tests."""
    d = np.sqrt(((x[:, None, :] - x[None, :, :]) ** 2).sum(-1))
    rc = r[:, None] + r[None, :] + skin
    i, j = np.nonzero(np.triu(d < rc, 1))
    return set(zip(i.tolist(), j.tolist()))
