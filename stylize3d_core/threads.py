"""A small shared thread pool for work that releases the GIL: the compiled rasterizer's passes
(``render/rasterize_fast.py``: contiguous parts of a range, one per thread), the colour transfer's
chunks (``models/colour_transfer.py``) and weighted sums of table rows (:func:`embedding_bag_sum`: the
rasterizer's splat sums and the 3-NN upsampling, ``points/interpolate.py``)."""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, List, Optional, Tuple

import torch
import torch.nn.functional as F

THREADS = max(1, min(4, os.cpu_count() or 1))
"""Threads of the pool (the rasterizer uses at most torch's thread count of them)."""

_POOL: Optional[ThreadPoolExecutor] = None
_LOCK = threading.Lock()


def pool() -> ThreadPoolExecutor:
    global _POOL
    with _LOCK:
        if _POOL is None:
            _POOL = ThreadPoolExecutor(THREADS, thread_name_prefix="stylize3d-kernel")
        return _POOL


def threads() -> int:
    """Threads a call may use: :data:`THREADS`, at most torch's thread count."""
    return max(1, min(THREADS, torch.get_num_threads()))


def parts(n: int, k: int) -> List[Tuple[int, int]]:
    """k contiguous ranges covering range(n) (empty ones dropped; one (0, 0) if n == 0)."""
    bounds = [n * i // k for i in range(k + 1)]
    return [(a, b) for a, b in zip(bounds[:-1], bounds[1:]) if b > a] or [(0, 0)]


def run_parts(jobs: List[Tuple[Callable, tuple]]) -> None:
    """Run ``fn(*args)`` for each job, the first in this thread and the rest on the pool."""
    if not jobs:
        return
    futures = [pool().submit(fn, *args) for fn, args in jobs[1:]]
    fn, args = jobs[0]
    try:
        fn(*args)
    finally:
        for f in futures:
            f.result()


PARALLEL_BAG_TAPS = 1 << 16
"""Below this many (index, weight) taps :func:`embedding_bag_sum` runs one call (the pool costs more)."""

BAG_CHUNK = 1 << 16
"""Bags :func:`embedding_bag_sum` sums per call on a thread (its result copied out while in the cache)."""


def embedding_bag_sum(index: torch.Tensor, table: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
    """``F.embedding_bag(index, table, mode="sum", per_sample_weights=weight)``, the bags split into
    contiguous parts summed on the pool's threads.

    PyTorch's CPU kernel of a weighted sum runs on one thread (1.7M bags of 3 rows of 35 channels: 0.47 s
    on this 2-core machine; in two parts 0.12-0.2 s). Each bag is summed by the same kernel in the same
    order whatever part it falls in, so the result is bit-identical to one call. Inference only: under
    autograd (a table or weights that require grad) it is the one call, whose backward PyTorch provides.
    (The rasterizer's bags, of varying size over a table in random order, gained nothing in parts: its
    sums are bound by memory, not by the one thread.)

    Args:
        index: (B, K) long rows of ``table``, K per bag.
        table: (M, C) rows.
        weight: (B, K) weights, the table's dtype.
    """
    k = threads()
    grad = torch.is_grad_enabled() and (table.requires_grad or weight.requires_grad)
    if k == 1 or index.numel() < PARALLEL_BAG_TAPS or grad:
        return F.embedding_bag(index, table, mode="sum", per_sample_weights=weight)
    out = torch.empty(index.shape[0], table.shape[1], dtype=table.dtype)
    inference, grad_on = torch.is_inference_mode_enabled(), torch.is_grad_enabled()

    def job(a: int, b: int) -> None:  # on a thread of the pool, in the caller's (thread-local) modes
        with torch.inference_mode(inference), torch.set_grad_enabled(grad_on):
            for c in range(a, b, BAG_CHUNK):  # in chunks: the temporaries stay small (no second (B, C) tensor)
                d = min(b, c + BAG_CHUNK)
                out[c:d].copy_(F.embedding_bag(index[c:d], table, mode="sum", per_sample_weights=weight[c:d]))

    run_parts([(job, r) for r in parts(index.shape[0], k)])
    return out
