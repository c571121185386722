"""Numba kernels of :mod:`~stylize3d_core.render.rasterize_fast` (imported by it where Numba imports).

Module-level functions, so Numba's on-disk cache (``cache=True``) finds them again in a new process.
"""

import numba
import numpy as np

EPS = 1e-8
"""Smallest depth in the projection's division (``geometry.camera.project``'s ``eps``)."""

CULLED = -(1 << 30)
"""The corner :func:`taps` gives a culled point."""

jit = numba.njit(cache=True, nogil=True)


@numba.njit(inline="always")
def taps(pc, i, fx, fy, cx, cy, H, W, near):
    """Corner 00 (x0, y0), the fractional parts' tap weights and z of point i; x0 = CULLED if culled."""
    one, half = np.float32(1.0), np.float32(0.5)
    z = pc[2, i]
    if not (z > near and z < np.float32(np.inf)):
        return CULLED, 0, z, one, one, one, one
    zs = z if z > np.float32(EPS) else np.float32(EPS)
    a = fx * pc[0, i] / zs + cx - half
    b = fy * pc[1, i] / zs + cy - half
    if not (a > -one and a < np.float32(W) and b > -one and b < np.float32(H)):
        return CULLED, 0, z, one, one, one, one
    x0f, y0f = np.floor(a), np.floor(b)
    wx0 = max(one - abs(x0f - a), np.float32(0.0))
    wx1 = max(one - abs(x0f + one - a), np.float32(0.0))
    wy0 = max(one - abs(y0f - b), np.float32(0.0))
    wy1 = max(one - abs(y0f + one - b), np.float32(0.0))
    return int(x0f), int(y0f), z, wx0, wx1, wy0, wy1


ZBUFFERS, FILL = 0, 1
"""The passes of :func:`splat_pass`."""


@jit
def splat_pass(pc, lo, hi, fx, fy, cx, cy, H, W, near, mode, strong, tol, zbuf, zfront, front, counts, pos,
               index, weight):
    """One pass over points lo..hi-1 and their bilinear taps (in the image, weight > 0).

    ``ZBUFFERS``: the least depth per pixel of every tap (``zbuf``) and of the taps of weight >= ``strong``
    (``zfront``), and the number of taps per pixel (``counts``: room for the taps ``FILL`` may keep).
    ``FILL``: each tap kept by the front test against ``front``: its point and weight written at
    ``pos[pixel]`` of ``index`` / ``weight`` (then ``pos`` advanced; the two may be strided views of one
    interleaved array). Arrays a pass does not use may be any of the right dtype.
    """
    for i in range(lo, hi):
        x0, y0, z, wx0, wx1, wy0, wy1 = taps(pc, i, fx, fy, cx, cy, H, W, near)
        if x0 == CULLED:
            continue
        for dy in range(2):
            yy = y0 + dy
            wy = wy0 if dy == 0 else wy1
            if yy < 0 or yy >= H:
                continue
            for dx in range(2):
                xx = x0 + dx
                w = wy * (wx0 if dx == 0 else wx1)
                if xx < 0 or xx >= W or not w > 0:
                    continue
                q = yy * W + xx
                if mode == ZBUFFERS:
                    counts[q] += 1
                    if z < zbuf[q]:
                        zbuf[q] = z
                    if w >= strong and z < zfront[q]:
                        zfront[q] = z
                    continue
                f = front[q]
                if not (z <= f * tol and z * tol >= f):
                    continue
                k = pos[q]
                index[k] = i
                weight[k] = w
                pos[q] = k + 1


@jit
def normalise(offsets, pos, end, weight, index, threshold, wsum, weight_out, index_out, q0, q1):
    """Bags q0..q1-1, sized for every tap (``ZBUFFERS``' counts) and filled by ``FILL`` part by part: part
    t's slots of pixel q run from part t - 1's ``end`` (the bag's start for t = 0) to ``end[t, q]``, its kept
    taps up to ``pos[t, q]``. Per bag: the kept taps' weight sum (in bag order) into ``wsum``; their weights
    / sum (0 where the sum is below threshold) and indices into ``weight_out`` / ``index_out``, contiguous
    as ``embedding_bag`` takes them; the slots of dropped taps get weight 0 and the index of the bag's first
    kept tap (a finite feature wherever the bag's sum is finite: no 0 * inf), so each bag sums what a bag
    of the kept taps alone sums. The fill's interleaved slots are read once, in memory order."""
    parts = pos.shape[0]
    for q in range(q0, q1):
        s = np.float32(0.0)
        first = -1
        a = offsets[q]
        for t in range(parts):
            for k in range(a, pos[t, q]):
                s += weight[k]
            if first < 0 and pos[t, q] > a:
                first = index[a]
            a = end[t, q]
        wsum[q] = s
        inv = np.float32(0.0) if s < threshold else np.float32(1.0) / s
        if first < 0:  # an empty bag (a bag with taps keeps its front tap)
            first = 0
        a = offsets[q]
        for t in range(parts):
            for k in range(a, pos[t, q]):
                weight_out[k] = weight[k] * inv
                index_out[k] = index[k]
            for k in range(pos[t, q], end[t, q]):
                weight_out[k] = 0.0
                index_out[k] = first
            a = end[t, q]
