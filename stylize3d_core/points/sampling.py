"""Farthest point sampling (FPS).

FPS picks ``n`` of ``N`` points one at a time, each time the point farthest from
those already picked. The result covers the cloud evenly: its *coverage radius*
(the largest distance from any point to its nearest pick) is within a factor 2
of the best possible for ``n`` picks.

We run the bucket-based FPS of the ``fpsample`` package (the "QuickFPS"
algorithm), which keeps a k-d tree of buckets and updates only the buckets a new pick
can affect. It gives exactly the textbook FPS sequence (checked against
:func:`stylize3d_core.points.reference.farthest_point_sample_reference` in the
tests), at 300k -> 75k points in 0.3-0.6 s and 1M -> 250k in 2-3 s on the
project's 2-core CPU, where the textbook O(N n) loop would take minutes.

Two quirks of fpsample 1.0.2 are handled here:

* its ``start_idx`` indexes the points in the k-d tree's internal order, so the
  first pick is a deterministic function of the points and ``start`` but not
  necessarily point ``start`` itself;
* once every point coincides with a pick (coverage radius 0: the cloud has
  fewer distinct positions than ``n``), it repeats indices. We keep indices
  distinct by filling those slots with the unpicked points in ascending order,
  which is what the textbook loop does when it never re-picks a point.

fpsample holds Python's GIL for the whole call (0.6-0.8 s for a photo's 300k
points), which would freeze every other Python thread: a viewer's window while
its worker prepares a photo, or the k-NN search that :func:`prepare_geometry`
runs beside the next level's sampling. So clouds of at least
:data:`PROCESS_MIN_POINTS` points are sampled in a small worker process
(:mod:`._fps_worker`: numpy and fpsample only, started once and kept), with the
same call and so the same indices. Any failure of that process falls back to the
call in this process, with a warning. :func:`set_fps_process` turns the worker
off (so does the environment variable ``STYLIZE3D_FPS_PROCESS=0``);
:func:`start_fps_process` starts it early, so that the first sampling does not
wait for its imports.
"""

from __future__ import annotations

import atexit
import math
import os
import select
import struct
import subprocess
import sys
import threading
import warnings
from pathlib import Path
from typing import Optional

import fpsample
import numpy as np
import torch

from ..checks import check_finite, check_shape
from ..errors import InputError
from .neighbours import check_count


PROCESS_MIN_POINTS = 32768
"""Clouds from this size up are sampled in the worker process (smaller ones take
under ~30 ms, less than the round trip is worth)."""

_WORKER_SOURCE = Path(__file__).with_name("_fps_worker.py")


class _Worker:
    """One fpsample worker process, shared by all threads (requests take turns)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._proc: Optional[subprocess.Popen] = None
        self._ready = False
        self.enabled = os.environ.get("STYLIZE3D_FPS_PROCESS", "1").strip().lower() not in ("0", "false", "no", "off")

    def start(self) -> None:
        """Start the process if it is not running (returns at once; its imports run meanwhile)."""
        with self._lock:
            self._spawn()

    def _spawn(self) -> None:
        if self._proc is not None:
            if self._proc.poll() is None:
                return
            self._stop()  # it ended (killed?): close its pipes and start a new one
        env = dict(os.environ)
        # numpy and fpsample where this process found them, whatever sys.path tricks brought them here
        found = [str(Path(m.__file__).resolve().parent.parent) for m in (np, fpsample)]
        env["PYTHONPATH"] = os.pathsep.join(dict.fromkeys(found + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p]))
        self._proc = subprocess.Popen(
            [sys.executable, "-c", _WORKER_SOURCE.read_text(encoding="utf-8")],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env, bufsize=0)
        self._ready = False

    def wait_ready(self, timeout: float = 60.0) -> bool:
        """Start the process if needed and wait until its imports are done (True; False if it is disabled,
        failed or did not answer within ``timeout`` seconds: the first sampling then waits or falls back)."""
        if not self.enabled:
            return False
        with self._lock:
            try:
                self._spawn()
                return self._await_ready(timeout)
            except (OSError, EOFError, ValueError):
                self._stop()
                return False

    def _await_ready(self, timeout: Optional[float] = None) -> bool:
        """Read the worker's ready byte unless read already (lock held): False if none came within
        ``timeout`` seconds (None: wait); EOFError if the process answered anything else or ended."""
        if self._ready:
            return True
        if timeout is not None:
            readable, _, _ = select.select([self._proc.stdout], [], [], timeout)
            if not readable:
                return False
        if self._read(1) != b"R":
            raise EOFError("the worker process did not start")
        self._ready = True
        return True

    def _write(self, view: memoryview) -> None:
        while len(view):
            view = view[self._proc.stdin.write(view):]  # an unbuffered pipe may take part of it

    def _read(self, n: int) -> bytes:
        data = bytearray()
        while len(data) < n:
            chunk = self._proc.stdout.read(n - len(data))  # blocks without the GIL
            if not chunk:
                raise EOFError("the worker process ended")
            data += chunk
        return bytes(data)

    def sample(self, pts: np.ndarray, n_samples: int, height: int, start: int) -> np.ndarray:
        """fpsample's indices for ``pts`` (N, 3) float32, computed in the worker."""
        with self._lock:
            try:
                self._spawn()
                self._await_ready()
                self._write(memoryview(struct.pack("<4q", pts.shape[0], n_samples, height, start)))
                self._write(memoryview(np.ascontiguousarray(pts)).cast("B"))
                status, n_bytes = struct.unpack("<2q", self._read(16))
                payload = self._read(n_bytes)
            except (OSError, EOFError, ValueError) as e:
                self._stop()
                raise RuntimeError(f"farthest point sampling worker failed: {e}") from e
        if status != 0:
            raise RuntimeError(f"farthest point sampling worker failed: {payload.decode('utf-8', 'replace')}")
        return np.frombuffer(payload, dtype=np.int64).copy()

    def _stop(self) -> None:
        proc, self._proc, self._ready = self._proc, None, False
        if proc is None:
            return
        for stream in (proc.stdin, proc.stdout):
            try:
                stream.close()
            except OSError:
                pass
        try:
            proc.wait(timeout=2)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()

    def stop(self) -> None:
        """End the process (the next large sampling starts a new one).

        If a sampling is under way in another thread (a daemon thread at interpreter exit), the process is
        killed rather than waited for: that thread's sampling then falls back to its own process."""
        if self._lock.acquire(timeout=0.5):
            try:
                self._stop()
            finally:
                self._lock.release()
        elif self._proc is not None:
            self._proc.kill()


_WORKER = _Worker()
atexit.register(_WORKER.stop)


def set_fps_process(enabled: bool) -> None:
    """Sample large clouds in the worker process (True, the default) or in this process (False)."""
    _WORKER.enabled = bool(enabled)
    if not enabled:
        _WORKER.stop()


def start_fps_process() -> None:
    """Start the worker process now (if it is enabled), so that it is ready when a photo's geometry is prepared."""
    if _WORKER.enabled:
        try:
            _WORKER.start()
        except OSError as e:
            warnings.warn(f"could not start the farthest point sampling worker ({e}); sampling in this process")
            _WORKER.enabled = False


def wait_for_fps_process(timeout: float = 60.0) -> bool:
    """Start the worker process (if enabled) and wait until it is ready to sample (see :meth:`_Worker.wait_ready`)."""
    return _WORKER.wait_ready(timeout)


def _fpsample(pts: np.ndarray, n_samples: int, height: int, start: int) -> np.ndarray:
    """fpsample's bucket FPS, in the worker process for large clouds (see the module docstring)."""
    if _WORKER.enabled and pts.shape[0] >= PROCESS_MIN_POINTS:
        try:
            return _WORKER.sample(pts, n_samples, height, start)
        except RuntimeError as e:
            warnings.warn(f"{e}; sampling in this process from now on")
            _WORKER.enabled = False
    return np.asarray(fpsample.bucket_fps_kdline_sampling(pts, n_samples, height, start_idx=start), dtype=np.int64)


def _tree_height(n_points: int) -> int:
    """k-d tree height for fpsample's bucket FPS (buckets of 2**h points).

    Measured on the project's CPU: the best height grows with log2(N), about
    log2(N) - 10 (3 below 16k points, 6 at 75k, 8 at 300k, 9 at 1M); fpsample
    needs 1 <= h and 2**h <= N.
    """
    log_n = int(math.floor(math.log2(n_points)))
    return max(1, min(log_n, min(9, max(3, log_n - 10))))


def _make_distinct(idx: np.ndarray, n_points: int) -> np.ndarray:
    """Replace repeated indices (after their first use) by unused ones, ascending."""
    _, first = np.unique(idx, return_index=True)
    if len(first) == len(idx):
        return idx
    keep = np.zeros(len(idx), dtype=bool)
    keep[first] = True
    used = np.zeros(n_points, dtype=bool)
    used[idx] = True
    fill = np.flatnonzero(~used)[: int((~keep).sum())]
    out = idx.copy()
    out[~keep] = fill
    return out


def farthest_point_sample(xyz: torch.Tensor, n_samples: int, start: int = 0) -> torch.Tensor:
    """Indices of ``n_samples`` points of ``xyz`` chosen by farthest point sampling.

    Args:
        xyz: (N, 3) finite points, N >= 1.
        n_samples: how many points to pick, 1 <= n_samples <= N.
        start: seed of the first pick, 0 <= start < N. The result is a
            deterministic function of ``(xyz, n_samples, start)``; see the
            module docstring for how fpsample maps ``start`` to the first pick.

    Returns:
        (n_samples,) long tensor of distinct indices into ``xyz``, in pick order.
        Every prefix of it is itself a farthest point sample.
    """
    check_shape(xyz, "xyz", (None, 3))
    n_points = xyz.shape[0]
    if n_points == 0:
        raise InputError("xyz", "the point cloud is empty")
    if not torch.is_floating_point(xyz):
        raise InputError("xyz", f"expected a floating-point tensor, got {xyz.dtype}")
    check_finite(xyz, "xyz")
    n_samples = check_count(n_samples, "n_samples", 1)
    if n_samples > n_points:
        raise InputError("n_samples", f"must be <= the number of points ({n_points}), got {n_samples}")
    start = check_count(start, "start", 0)
    if start >= n_points:
        raise InputError("start", f"must be < the number of points ({n_points}), got {start}")
    if n_points == 1:
        return torch.zeros(1, dtype=torch.long)

    pts = np.ascontiguousarray(xyz.detach().cpu().numpy(), dtype=np.float32)  # (N, 3)
    idx = _make_distinct(_fpsample(pts, n_samples, _tree_height(n_points), start), n_points)  # (n_samples,)
    return torch.from_numpy(idx)
