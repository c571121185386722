"""A small shared thread pool for work that releases the GIL: the compiled rasterizer's passes
(``render/rasterize_fast.py``: contiguous parts of a range, one per thread), the colour transfer's
chunks (``models/colour_transfer.py``), the k-NN grid's queries (``points/neighbours.py``), the IDW
weights (``points/interpolate.py``) and the encoder's neighbour max (``models/encoder.py``). Jobs on
it call Numba, numpy or OpenCV, not PyTorch: a PyTorch call gives its thread an OpenMP team of its own,
and with more OpenMP threads than cores libgomp stops spinning between parallel regions, which slows every
later PyTorch call of the process."""

from __future__ import annotations

import contextlib
import functools
import importlib
import os
import threading
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Callable, Iterator, List, Optional, Tuple

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


@contextlib.contextmanager
def torch_threads(n: Optional[int]) -> Iterator[int]:
    """Run the block with ``n`` torch threads (None or the current count: unchanged), then restore the
    count; yields the count in force. Call it on the thread that runs the torch work: the count is that
    thread's OpenMP setting (and the rasterizer's share of the pool, :func:`threads`)."""
    before = torch.get_num_threads()
    if n is None or int(n) == before:
        yield before
        return
    if int(n) < 1:
        raise ValueError(f"torch_threads: need n >= 1, got {n}")
    torch.set_num_threads(int(n))
    try:
        yield int(n)
    finally:
        torch.set_num_threads(before)


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


def in_parts(job: Callable[[int, int], object], n: int, min_split: int = 1,
             k: Optional[int] = None) -> List[object]:
    """``job(a, b)`` on the :func:`parts` of range(n), ``k`` of them (default :func:`threads`; one below
    ``min_split``), the first in this thread and the rest on the pool; their results in order (a compiled
    kernel's False says it found an input it does not take, for the caller's checked path)."""
    ranges = parts(n, (k or threads()) if n >= min_split else 1)
    results: List[object] = [None] * len(ranges)

    def one(j: int, a: int, b: int) -> None:
        results[j] = job(a, b)

    run_parts([(one, (j, a, b)) for j, (a, b) in enumerate(ranges)])
    return results


def beside(fn: Callable, *args) -> Future:
    """``fn(*args)`` in a new thread of its own, for work beside the caller's that is not a pool job (it may
    itself use the pool, or the caller may be a pool job: pool jobs never wait on each other); the future
    has its result or exception."""
    side = ThreadPoolExecutor(max_workers=1, thread_name_prefix="stylize3d-beside")
    try:
        return side.submit(fn, *args)
    finally:
        side.shutdown(wait=False)


def halves(job: Callable[[int], None], n: int) -> None:
    """``job(i)`` for i in range(n): the first half in this thread, the second in one :func:`beside` it
    (numpy and OpenCV free the GIL on large arrays); each job writes its own rows or slot."""
    rest = beside(lambda: [job(i) for i in range(n // 2, n)])
    try:
        for i in range(n // 2):
            job(i)
    finally:
        rest.result()
