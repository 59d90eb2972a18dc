"""Neighbour search: cell sort, pair list, history carried to a new list, wall candidates
(``dem.neighbours`` builds the pair list with them)."""
import numpy as np
from numba import njit, prange


@njit(cache=True)
def cell_sort(x, lo_x, lo_y, cell, ncx, ncy):
    """Counting sort of particles into square cells of side `cell` [m].

    Returns (cell_start (ncx*ncy+1,), cell_part (N,)) ; particles keep index order
    inside a cell so the pair list is reproducible.
    """
    n = x.shape[0]
    cid = np.empty(n, np.int64)
    counts = np.zeros(ncx * ncy + 1, np.int64)
    for p in range(n):
        cx = int((x[p, 0] - lo_x) / cell)
        cy = int((x[p, 1] - lo_y) / cell)
        cx = min(max(cx, 0), ncx - 1)
        cy = min(max(cy, 0), ncy - 1)
        cid[p] = cy * ncx + cx
        counts[cid[p] + 1] += 1
    for c in range(ncx * ncy):
        counts[c + 1] += counts[c]
    fill = counts[:-1].copy()
    part = np.empty(n, np.int64)
    for p in range(n):
        part[fill[cid[p]]] = p
        fill[cid[p]] += 1
    return counts, part, cid


@njit(cache=True)
def _neighbours_of(i, x, r, skin, start, part, cid, ncx, ncy, pi, pj, k, fill):
    """Scan the 3x3 cells around particle i for partners j > i within the skin. With
    ``fill`` the pairs are written from index k on; returns k plus the number found."""
    c = cid[i]
    cx = c % ncx
    cy = c // ncx
    for oy in range(-1, 2):
        yy = cy + oy
        if yy < 0 or yy >= ncy:
            continue
        for ox in range(-1, 2):
            xx = cx + ox
            if xx < 0 or xx >= ncx:
                continue
            cc = yy * ncx + xx
            for s in range(start[cc], start[cc + 1]):
                j = part[s]
                if j <= i:
                    continue
                dx = x[j, 0] - x[i, 0]
                dy = x[j, 1] - x[i, 1]
                rc = r[i] + r[j] + skin
                if dx * dx + dy * dy < rc * rc:
                    if fill:
                        pi[k] = i
                        pj[k] = j
                    k += 1
    return k


@njit(cache=True, parallel=True)
def build_pairs(x, r, skin, lo_x, lo_y, cell, ncx, ncy):
    """Pairs (i<j) whose gap is below `skin`: |x_i - x_j| < r_i + r_j + skin.

    Cell side must be >= 2 r_max + skin.  Returns pi, pj (int32), sorted by (i, j).
    Two passes over the same scan: count per particle, then fill at the prefix offsets.
    """
    n = x.shape[0]
    start, part, cid = cell_sort(x, lo_x, lo_y, cell, ncx, ncy)
    cnt = np.zeros(n + 1, np.int64)
    dummy = np.empty(0, np.int32)
    for i in prange(n):
        cnt[i + 1] = _neighbours_of(i, x, r, skin, start, part, cid, ncx, ncy, dummy, dummy, 0, False)
    for i in range(n):
        cnt[i + 1] += cnt[i]
    npairs = cnt[n]
    pi = np.empty(npairs, np.int32)
    pj = np.empty(npairs, np.int32)
    for i in prange(n):
        _neighbours_of(i, x, r, skin, start, part, cid, ncx, ncy, pi, pj, cnt[i], True)
        # insertion sort of this particle's segment by j (segments are short)
        for a in range(cnt[i] + 1, cnt[i + 1]):
            v = pj[a]
            b = a - 1
            while b >= cnt[i] and pj[b] > v:
                pj[b + 1] = pj[b]
                b -= 1
            pj[b + 1] = v
    return pi, pj


@njit(cache=True)
def row_offsets(pi, n):
    """CSR offsets (n+1,) of a pair list sorted by pi."""
    off = np.zeros(n + 1, np.int64)
    for k in range(pi.shape[0]):
        off[pi[k] + 1] += 1
    for i in range(n):
        off[i + 1] += off[i]
    return off


@njit(cache=True, parallel=True)
def carry_history(old_pi, old_pj, old_ft, old_mr, new_pi, new_pj, n):
    """Tangential and rolling histories (ft, mr) of the new pair list, copied from the old one
    for pairs in both (zero for new pairs)."""
    off = row_offsets(old_pi, n)
    ft = np.zeros(new_pi.shape[0])
    mr = np.zeros(new_pi.shape[0])
    for k in prange(new_pi.shape[0]):
        i = new_pi[k]
        j = new_pj[k]
        for a in range(off[i], off[i + 1]):
            if old_pj[a] == j:
                ft[k] = old_ft[a]
                mr[k] = old_mr[a]
                break
    return ft, mr


@njit(cache=True)
def wall_candidates(x, r, walls, skin):
    """Particles closer than r + skin to each wall.  Returns (off (5,), idx)."""
    n = x.shape[0]
    cnt = np.zeros(5, np.int64)
    tmp = np.empty((4, n), np.int64)
    for p in range(n):
        if x[p, 0] - walls[0] < r[p] + skin:
            tmp[0, cnt[1]] = p
            cnt[1] += 1
        if walls[1] - x[p, 0] < r[p] + skin:
            tmp[1, cnt[2]] = p
            cnt[2] += 1
        if x[p, 1] - walls[2] < r[p] + skin:
            tmp[2, cnt[3]] = p
            cnt[3] += 1
        if walls[3] - x[p, 1] < r[p] + skin:
            tmp[3, cnt[4]] = p
            cnt[4] += 1
    off = np.zeros(5, np.int64)
    for w in range(4):
        off[w + 1] = off[w] + cnt[w + 1]
    idx = np.empty(off[4], np.int64)
    for w in range(4):
        for a in range(cnt[w + 1]):
            idx[off[w] + a] = tmp[w, a]
    return off, idx
