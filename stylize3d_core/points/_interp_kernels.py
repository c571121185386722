"""Numba kernel of :func:`~stylize3d_core.points.interpolate.interpolate` at inference (imported where
Numba imports). Module-level, so Numba's on-disk cache (``cache=True``) finds it again in a new process."""

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def weighted_rows(idx, weight, table, out, a, b):
    """Rows a..b-1 of ``out[n] = sum_j weight[n, j] * table[idx[n, j]]``, the neighbours added in column
    order in float32 (as ``embedding_bag``'s weighted sum)."""
    k = idx.shape[1]
    c = table.shape[1]
    for n in range(a, b):
        for ch in range(c):
            out[n, ch] = np.float32(0.0)
        for j in range(k):
            i = idx[n, j]
            w = weight[n, j]
            for ch in range(c):
                out[n, ch] += w * table[i, ch]
