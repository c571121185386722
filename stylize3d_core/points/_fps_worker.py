"""The farthest-point-sampling worker process (see :mod:`.sampling`).

This file is run by ``python -c`` with its own source, not imported: the process
imports only numpy and fpsample (no torch, no stylize3d_core), so it starts in a
fraction of a second. It reads requests from stdin and answers on its stdout:

* request: four little-endian int64 ``(n_points, n_samples, tree_height, start)``,
  then ``n_points * 3`` float32 coordinates;
* answer: two int64 ``(status, n_bytes)``, then ``n_bytes`` of payload: the
  ``n_samples`` int64 indices (status 0), or an error message (status 1).

It sends one byte ``R`` once its imports are done and exits at the end of stdin
(when its parent closes the pipe or dies), quietly also when its answer meets a
closed pipe (the parent died first). It ignores SIGINT: Ctrl+C in a terminal
reaches the whole process group, and the parent is the one that handles it (a
traceback from this process after the parent's one-line message was seen when
an export was interrupted).
"""

import os
import signal
import struct
import sys

sys.path[:] = [p for p in sys.path if p not in ("", ".")]  # a cwd module must not shadow numpy


def _read_into(stream, view) -> bool:
    """Fill ``view`` (a byte memoryview) from ``stream``; False at the end of the stream."""
    got = 0
    while got < len(view):
        n = stream.readinto(view[got:])
        if not n:
            return False
        got += n
    return True


def main() -> None:
    inp = sys.stdin.buffer
    out = os.fdopen(os.dup(1), "wb", buffering=0)
    os.dup2(2, 1)  # anything printed by a library goes to stderr, never into the answers

    import fpsample
    import numpy as np

    out.write(b"R")
    head = bytearray(32)
    while _read_into(inp, memoryview(head)):
        n_points, n_samples, height, start = struct.unpack("<4q", head)
        pts = np.empty((n_points, 3), dtype=np.float32)
        if not _read_into(inp, memoryview(pts).cast("B")):
            return
        try:
            idx = fpsample.bucket_fps_kdline_sampling(pts, n_samples, height, start_idx=start)
            payload, status = np.ascontiguousarray(idx, dtype=np.int64).tobytes(), 0
        except Exception as e:  # reported to the parent, which runs the sampling itself
            payload, status = repr(e).encode("utf-8", "replace"), 1
        out.write(struct.pack("<2q", status, len(payload)))
        out.write(payload)


if __name__ == "__main__":
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        main()
    except BrokenPipeError:  # the parent is gone: nobody to answer
        os._exit(0)
