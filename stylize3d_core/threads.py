"""A small shared thread pool for work that releases the GIL: the compiled rasterizer's passes
(``render/rasterize_fast.py``: contiguous parts of a range, one per thread), the colour transfer's
chunks (``models/colour_transfer.py``), the k-NN grid's queries (``points/neighbours.py``), the IDW
weights (``points/interpolate.py``) and the encoder's neighbour max (``models/encoder.py``). Jobs on
it call Numba, numpy or OpenCV, not PyTorch: a PyTorch call gives its thread an OpenMP team of its own,
and with more OpenMP threads than cores libgomp stops spinning between parallel regions (``embedding_bag``
calls on the pool made every later 256 px preview 1-3 ms slower, 30.2 -> 33.6 ms measured side by side)."""

from __future__ import annotations

import functools
import importlib
import os
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, List, Optional, Tuple

import torch

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


@functools.lru_cache(maxsize=None)
def compiled(module: str):
    """The module of compiled (Numba) kernels named ``module`` (absolute: ``stylize3d_core.render._raster_kernels``),
    imported once; None where Numba is missing or the import fails (the caller's numpy or Open3D path then)."""
    try:
        return importlib.import_module(module)
    except Exception:  # noqa: BLE001 (any failure to import means: no compiled path)
        return None


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

