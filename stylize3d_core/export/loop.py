"""Boomerang loops: the frames forward, then back, so a loop plays without a jump.

For frames ``f0 .. f(n-1)`` the loop is ``f0 .. f(n-1), f(n-2) .. f1``
(2n - 2 frames): neither end is shown twice in a row, so a player that
repeats the loop (GIF, WebP, an MP4 set to loop) moves smoothly back and
forth. One frame stays one frame. The forward frames are kept (as uint8) to
be played back, so no view is rendered twice.
"""

from __future__ import annotations

from typing import Iterable, Iterator, List

import numpy as np

from ..io.images import rgb_to_uint8


def boomerang_length(n_frames: int) -> int:
    """How many frames the boomerang of ``n_frames`` frames has: ``2 n - 2`` (1 for 1)."""
    n = int(n_frames)
    return 1 if n == 1 else 2 * n - 2


def boomerang(frames: Iterable[np.ndarray]) -> Iterator[np.ndarray]:
    """Yield ``frames`` (each (H, W, 3), uint8 or float in [0, 1]) forward, then back (see the module docstring)."""
    kept: List[np.ndarray] = []
    for i, frame in enumerate(frames):
        f = rgb_to_uint8(frame, f"frame {i}")
        kept.append(f)
        yield f
    for f in reversed(kept[1:-1]):
        yield f
