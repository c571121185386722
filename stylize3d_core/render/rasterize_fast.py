"""Compiled inference path of :func:`~stylize3d_core.render.rasterize.rasterize_points` (Numba).

The common case of inference, bilinear splats (no point sizes) at supersample 1 without
``soft_edges`` or ``blend_coverage``, float32 on the CPU, without gradients, is the same
computation as the tensor path, done in two passes over the points that keep nothing
per point:

1. z-buffers: per pixel the least depth of every tap and of the front-setting taps
   (weight >= the hole threshold); the front is the latter where there is one; and the number of
   taps per pixel, which sizes each pixel's bag;
2. bags: each tap the front test keeps (``zfront / tol <= z <= zfront * tol``) writes its point
   index and splat weight, pixel-major, into one 8-byte slot (int32 index and float32 weight
   interleaved: one cache line per scattered write; a counting sort: within a pixel the taps keep
   the points' order);
3. per pixel (not per point), the kept taps' weight sum (in bag order), the hole test and the
   normalised weights, written with the indices as the contiguous arrays that
   ``torch.nn.functional.embedding_bag`` sums the features with; the slots of the taps the front
   test dropped get weight 0 and the index of the bag's first kept tap, so each bag sums what a
   bag of the kept taps alone sums.

Pass 2 interleaves index and weight and counts while it fills, rather than counting the kept taps in
a pass of its own and filling two arrays: a scattered write then touches one cache line, not two.

A tap's position and weight come from the same float32 formulas as the tensor path's
(``u = fx * x / max(z, 1e-8) + cx``, ``a = u - 0.5``, weights ``1 - |x0 + dx - a|``),
so both keep the same taps; the sums differ by float rounding only (their order differs;
``tests/render/test_rasterize_fast.py`` checks the two against each other). The result does
not depend on the chunking or on the number of threads: the z-buffers are a min, the
counts integers, and the bags hold each pixel's taps in point order.

Passes 1-2 run in parts of the points (pass 3 in parts of the pixels) on
:data:`stylize3d_core.threads.THREADS` threads (the kernels release
the GIL); with ``should_stop``, each pass runs in chunks of points with the check before
each. The kernels are compiled on first use and cached on disk (Numba's ``cache=True``).
Where Numba cannot be imported, :func:`available` is False and the tensor path runs.
"""

from __future__ import annotations

import functools
import math
import warnings
from typing import Callable, Optional

import numpy as np
import torch
import torch.nn.functional as F

from .. import threads as _threads
from ..errors import RenderInterrupted


def _kernels():
    """The compiled kernels (None where Numba is missing or fails to import)."""
    return _threads.compiled(__package__ + "._raster_kernels")


def available() -> bool:
    """Whether the compiled path can run (Numba imports)."""
    return _kernels() is not None


def applies(points_cam: torch.Tensor, features: torch.Tensor, settings, point_size) -> bool:
    """Whether :func:`rasterize_fast` computes this call (else the tensor path does)."""
    return (settings.backend == "auto" and not _FAILED and point_size is None and settings.supersample == 1 and not settings.soft_edges
            and not settings.blend_coverage and features.dtype == torch.float32
            and points_cam.dtype == torch.float32 and features.device.type == "cpu"
            and points_cam.device.type == "cpu" and not (torch.is_grad_enabled() and features.requires_grad)
            and available())


_FAILED = False
"""True after :func:`disable`: the compiled path failed on this machine and every later call takes the tensor
path (``RasterSettings.backend`` "tensor" asks for the tensor path on a single call)."""


def failed() -> bool:
    """Whether the compiled path failed in this process (:func:`disable`)."""
    return _FAILED


def disable(exc: BaseException) -> None:
    """Turn the compiled path off for this process after it failed (a kernel that does not compile or run
    on this machine): a warning names the error once, and every later call takes the tensor path."""
    global _FAILED
    if not _FAILED:
        _FAILED = True
        warnings.warn(f"stylize3d: the rasterizer's compiled path failed ({type(exc).__name__}: {exc}); "
                      "using the tensor path from now on", RuntimeWarning, stacklevel=3)


def rasterize_fast(points_cam: torch.Tensor, features: torch.Tensor, K: torch.Tensor, settings,
                   should_stop: Optional[Callable[[], bool]] = None, chunk_points: Optional[int] = None):
    """(features (H*W, C), weight (H*W,), depth (H*W,), hole (H*W,)) as the tensor path computes them
    (``applies`` must hold; inputs checked by the caller)."""
    k = _kernels()
    H, W = settings.height, settings.width
    n_pix = H * W
    N, C = features.shape
    pc = points_cam.detach().t().contiguous().numpy()  # (3, N): a no-copy view for column-laid points
    Kd = K.detach().to(torch.float32)
    fx, fy, cx, cy = (np.float32(float(v)) for v in (Kd[0, 0], Kd[1, 1], Kd[0, 2], Kd[1, 2]))
    near = np.float32(settings.near_clip)
    tol = np.float32(1.0 + settings.depth_tolerance)  # as the tensor path's float32 products
    strong = np.float32(settings.hole_weight_threshold)
    threads = _threads.threads()
    if should_stop is not None and chunk_points:
        threads = min(threads, int(chunk_points))  # a round holds about chunk_points points in all
    parts = _threads.parts(N, threads)

    f32 = np.zeros(1, np.float32)  # a pass's unused arrays (typed, never touched)
    i64 = np.zeros(1, np.int64)

    def run(mode, arrays):
        """One pass of ``k.splat_pass`` over every part's points (``arrays(t)``: part t's zbuf, zfront, front,
        counts, pos, index, weight): with ``should_stop``, in rounds of at most ``chunk_points`` points
        (shared by the parts; one per part at least), the check before each round; else in one round."""
        longest = max(b - a for a, b in parts)
        step = max(1, longest) if should_stop is None else max(1, int(chunk_points or N or 1) // len(parts))
        for r in range(max(1, -(-longest // step))):
            if should_stop is not None and should_stop():
                raise RenderInterrupted("render stopped while rasterizing")
            jobs = [(t, a + r * step, min(b, a + (r + 1) * step)) for t, (a, b) in enumerate(parts)]
            _threads.run_parts([(k.splat_pass, (pc, a, b, fx, fy, cx, cy, H, W, near, mode, strong, tol) +
                                 tuple(arrays(t))) for t, a, b in jobs if b > a])

    inf = np.float32(np.inf)
    zbuf = [np.full(n_pix, inf, np.float32) for _ in parts]
    zfront = [np.full(n_pix, inf, np.float32) for _ in parts]
    counts = [np.zeros(n_pix, np.int64) for _ in parts]  # every tap: the bags' room, no pass of its own
    run(k.ZBUFFERS, lambda t: (zbuf[t], zfront[t], f32, counts[t], i64, i64, f32))
    zb, zf = functools.reduce(np.minimum, zbuf), functools.reduce(np.minimum, zfront)
    front = np.where(zf < inf, zf, zb)  # (HW,) each pixel's front depth

    total = functools.reduce(np.add, counts)
    offsets = np.zeros(n_pix + 1, np.int64)
    np.cumsum(total, out=offsets[1:])
    E = int(offsets[-1])
    # The fill's scattered writes are most of the rasterizer's time: each tap's point index and weight
    # go to one slot of 8 bytes, int32 index and float32 weight interleaved (one cache line, not two; int32
    # always fits short of 2**31 taps), split into contiguous arrays by the normalisation's sweep.
    small = E < 2**31 and N < 2**31
    if small:
        slots = np.empty((E, 2), np.int32)
        index, weight = slots[:, 0], slots.view(np.float32)[:, 1]  # strided views of the slots
    else:  # (the kernels' other specialisation, compiled on first use)
        index, weight = np.empty(E, np.int64), np.empty(E, np.float32)
    pos = np.empty((len(parts), n_pix), np.int64)  # part t writes after the slots of parts before it
    end = np.empty((len(parts), n_pix), np.int64)
    start = offsets[:-1].copy()
    for t, c in enumerate(counts):
        pos[t] = start
        start += c
        end[t] = start
    run(k.FILL, lambda t: (f32, f32, front, i64, pos[t], index, weight))

    if should_stop is not None and should_stop():
        raise RenderInterrupted("render stopped while rasterizing")
    # per pixel: the kept taps normalised, the slots of dropped ones (taps behind the front: hidden-layer
    # points, ~15 % at 1 MP) weight 0, so the bags sum the kept taps as before without a pass over the
    # points to count them
    wsum = np.empty(n_pix, np.float32)
    weight_out = np.empty(E, np.float32)
    index_out = np.empty(E, index.dtype)
    _threads.in_parts(lambda a, b: k.normalise(offsets, pos, end, weight, index, strong, wsum, weight_out,
                                               index_out, a, b), n_pix, k=threads)
    index, weight, slots = index_out, weight_out, None  # the interleaved slots are freed before the sums
    table = features.detach()
    table = table if table.is_contiguous() else table.contiguous()
    with torch.no_grad():
        bags = torch.from_numpy(offsets.astype(np.int32) if small else offsets)  # embedding_bag: one index dtype
        out = F.embedding_bag(torch.from_numpy(index), table, bags, mode="sum",
                              per_sample_weights=torch.from_numpy(weight), include_last_offset=True)  # (HW, C)
    wsum_t = torch.from_numpy(wsum)
    hole = wsum_t < settings.hole_weight_threshold
    depth = torch.from_numpy(front)
    return out, wsum_t, torch.where(hole, math.inf, depth), hole
