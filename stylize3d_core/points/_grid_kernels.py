"""Numba kernels of :class:`~stylize3d_core.points.neighbours.GridKNN` and of the IDW weights
(:func:`~stylize3d_core.points.interpolate.idw_from_knn`), imported where Numba imports.

A uniform grid over the points' bounding box, its cells in CSR form (the points sorted by cell), and an
exact k-nearest-neighbour search that visits the cells in shells of growing Chebyshev distance around
the query's cell and stops when no unvisited cell can hold a nearer point. Module-level functions, so
Numba's on-disk cache (``cache=True``) finds them again in a new process.
"""

import numba
import numpy as np

jit = numba.njit(cache=True, nogil=True)


@jit
def cell_of(pts, lo, inv_h, dims):
    """(N,) int64 cell index of each point (x fastest), coordinates clamped into the grid."""
    n = pts.shape[0]
    out = np.empty(n, np.int64)
    nx, ny, nz = dims[0], dims[1], dims[2]
    for i in range(n):
        cx = int((pts[i, 0] - lo[0]) * inv_h)
        cy = int((pts[i, 1] - lo[1]) * inv_h)
        cz = int((pts[i, 2] - lo[2]) * inv_h)
        cx = min(max(cx, 0), nx - 1)
        cy = min(max(cy, 0), ny - 1)
        cz = min(max(cz, 0), nz - 1)
        out[i] = (cz * ny + cy) * nx + cx
    return out


@jit
def bucket(cells, n_cells):
    """CSR of the points by cell: ``start`` (n_cells + 1,) and ``order`` (N,), each cell's points in index order."""
    n = cells.shape[0]
    start = np.zeros(n_cells + 1, np.int64)
    for i in range(n):
        start[cells[i] + 1] += 1
    for c in range(n_cells):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    order = np.empty(n, np.int64)
    for i in range(n):
        c = cells[i]
        order[fill[c]] = i
        fill[c] += 1
    return start, order


@jit
def knn_query(src, order, start, lo, h, dims, qry, q0, q1, k, out_idx, out_d):
    """The k (<= len(src)) nearest source points of queries q0..q1-1, nearest first (ties: the one
    found first), into rows q0..q1-1 of ``out_idx`` / ``out_d`` (squared distances, float32, summed
    as ``dx*dx + dy*dy + dz*dz``). ``src`` holds the points sorted by cell (``src[t]`` is source point
    ``order[t]``): a cell's points are read from consecutive memory."""
    nx, ny, nz = dims[0], dims[1], dims[2]
    inv_h = np.float32(1.0) / h
    max_r = max(nx, max(ny, nz))
    best_d = np.empty(k, np.float32)
    best_i = np.empty(k, np.int64)
    for q in range(q0, q1):
        x, y, z = qry[q, 0], qry[q, 1], qry[q, 2]
        cx = min(max(int((x - lo[0]) * inv_h), 0), nx - 1)
        cy = min(max(int((y - lo[1]) * inv_h), 0), ny - 1)
        cz = min(max(int((z - lo[2]) * inv_h), 0), nz - 1)
        found = 0
        r = 0
        while True:
            z0, z1 = max(cz - r, 0), min(cz + r, nz - 1)
            y0, y1 = max(cy - r, 0), min(cy + r, ny - 1)
            x0, x1 = max(cx - r, 0), min(cx + r, nx - 1)
            for gz in range(z0, z1 + 1):
                on_z = gz == cz - r or gz == cz + r
                for gy in range(y0, y1 + 1):
                    on_zy = on_z or gy == cy - r or gy == cy + r
                    row = (gz * ny + gy) * nx
                    gx = x0
                    while gx <= x1:
                        if not on_zy and gx != cx - r and gx != cx + r:
                            gx = cx + r  # inside the shell: jump to its far face in x
                            if gx > x1:
                                break
                            continue
                        c = row + gx
                        for t in range(start[c], start[c + 1]):
                            dx = src[t, 0] - x
                            dy = src[t, 1] - y
                            dz = src[t, 2] - z
                            d = dx * dx + dy * dy + dz * dz
                            if found < k:
                                p = found
                                found += 1
                            elif d < best_d[k - 1]:
                                p = k - 1
                            else:
                                continue
                            while p > 0 and best_d[p - 1] > d:  # insertion: ascending, ties keep the earlier
                                best_d[p] = best_d[p - 1]
                                best_i[p] = best_i[p - 1]
                                p -= 1
                            best_d[p] = d
                            best_i[p] = t
                        gx += 1
            # every point not yet seen lies in a cell r + 1 or more shells out: at least r * h away
            # (less a hair: a coordinate's cell is rounded like any float32 product)
            if found == k:
                bound = np.float32(r) * h * np.float32(0.9999)
                if best_d[k - 1] <= bound * bound:
                    break
            if r >= max_r:
                break
            r += 1
        for p in range(k):
            out_idx[q, p] = order[best_i[p]]
            out_d[q, p] = best_d[p]


@jit
def nn_distance_sample(src, sample):
    """Squared distance from each ``sample`` row (indices into ``src``) to its nearest other point of ``src``
    (brute force; for sizing the grid)."""
    n = src.shape[0]
    out = np.empty(sample.shape[0], np.float32)
    for s in range(sample.shape[0]):
        i = sample[s]
        best = np.float32(np.inf)
        for j in range(n):
            if j == i:
                continue
            dx = src[j, 0] - src[i, 0]
            dy = src[j, 1] - src[i, 1]
            dz = src[j, 2] - src[i, 2]
            d = dx * dx + dy * dy + dz * dz
            if d < best:
                best = d
        out[s] = best
    return out


@jit
def idw_rows(sq_dist, eps, a0, a1, out):
    """Rows a0..a1-1 of the IDW weights (``interpolate.idw_from_knn``) from squared distances (N, k) float32,
    the same bits as its torch lines: in float64, ``d = sqrt(max(d2, 0))``, ``w = 1 / (d + eps)`` divided by
    its row sum (summed left to right), one-hot on the first column where ``d[0] < eps``; stored as float32.
    Returns False (rows left unfinished) at a non-finite distance: the caller's checked path then says so."""
    k = sq_dist.shape[1]
    for r in range(a0, a1):
        for j in range(k):
            if not (np.float64(sq_dist[r, j]) < np.inf):  # NaN or inf
                return False
        if np.sqrt(max(np.float64(sq_dist[r, 0]), 0.0)) < eps:
            out[r, 0] = 1.0
            for j in range(1, k):
                out[r, j] = 0.0
            continue
        total = 0.0
        for j in range(k):
            total += 1.0 / (np.sqrt(max(np.float64(sq_dist[r, j]), 0.0)) + eps)
        for j in range(k):
            out[r, j] = np.float32((1.0 / (np.sqrt(max(np.float64(sq_dist[r, j]), 0.0)) + eps)) / total)
    return True
