"""The keyframe editor's operations on a :class:`~stylize3d_core.geometry.keyframes.KeyframePath` (pure).

Each function returns a new path (paths are immutable); None stands for "no
keyframe yet". The window's keyframe panel calls them and keeps the result in
``ViewState.keyframes``; :func:`~stylize3d_core.geometry.keyframes.interpolate_keyframes`
turns the path into the export's cameras.
"""

from __future__ import annotations

from dataclasses import replace
from typing import List, Optional

import numpy as np

from stylize3d_core.errors import InputError
from stylize3d_core.geometry.camera import Cameras
from stylize3d_core.geometry.keyframes import Keyframe, KeyframePath

DEFAULT_DURATION_S = 2.0
"""Seconds from a new keyframe to the next one."""


def _check_index(path: Optional[KeyframePath], index: int) -> KeyframePath:
    if path is None or not 0 <= index < len(path.keyframes):
        n = 0 if path is None else len(path.keyframes)
        raise InputError("keyframe", f"no keyframe {index + 1} (the path has {n})")
    return path


def add_keyframe(path: Optional[KeyframePath], camera: Cameras, duration_s: float = DEFAULT_DURATION_S,
                 after: Optional[int] = None) -> KeyframePath:
    """``path`` with the camera (a batch of one) as a new keyframe after ``after`` (default: at the end)."""
    key = Keyframe(camera.cam_to_world[0].detach().double().cpu().numpy(), float(camera.fov_y_deg[0]))
    keys: List[Keyframe] = [] if path is None else list(path.keyframes)
    durations: List[float] = [] if path is None else list(path.durations_s)
    at = len(keys) if after is None else max(0, min(len(keys), after + 1))
    keys.insert(at, key)
    durations.insert(at, float(duration_s))
    return KeyframePath(tuple(keys), tuple(durations), False if path is None else path.loop)


def delete_keyframe(path: Optional[KeyframePath], index: int) -> Optional[KeyframePath]:
    """``path`` without keyframe ``index`` (None once the last one is gone)."""
    p = _check_index(path, index)
    keys = p.keyframes[:index] + p.keyframes[index + 1:]
    if not keys:
        return None
    return KeyframePath(keys, p.durations_s[:index] + p.durations_s[index + 1:], p.loop)


def move_keyframe(path: Optional[KeyframePath], index: int, delta: int) -> KeyframePath:
    """``path`` with keyframe ``index`` moved ``delta`` places (clamped to the ends); its duration goes with it."""
    p = _check_index(path, index)
    to = max(0, min(len(p.keyframes) - 1, index + int(delta)))
    keys, durations = list(p.keyframes), list(p.durations_s)
    keys.insert(to, keys.pop(index))
    durations.insert(to, durations.pop(index))
    return KeyframePath(tuple(keys), tuple(durations), p.loop)


def set_keyframe_fov(path: Optional[KeyframePath], index: int, fov_y_deg: float) -> KeyframePath:
    """``path`` with keyframe ``index``'s vertical FOV set."""
    p = _check_index(path, index)
    keys = list(p.keyframes)
    keys[index] = Keyframe(keys[index].cam_to_world, float(fov_y_deg))
    return replace(p, keyframes=tuple(keys))


def set_keyframe_duration(path: Optional[KeyframePath], index: int, seconds: float) -> KeyframePath:
    """``path`` with the time from keyframe ``index`` to the next set."""
    p = _check_index(path, index)
    durations = list(p.durations_s)
    durations[index] = float(seconds)
    return KeyframePath(p.keyframes, tuple(durations), p.loop)


def set_loop(path: Optional[KeyframePath], loop: bool) -> Optional[KeyframePath]:
    """``path`` looping back to its first keyframe, or not."""
    return None if path is None else replace(path, loop=bool(loop))


def keyframe_labels(path: Optional[KeyframePath]) -> List[str]:
    """One line per keyframe for the editor's list: number, FOV, time to the next."""
    if path is None:
        return []
    n = len(path.keyframes)
    out = []
    for i, (k, d) in enumerate(zip(path.keyframes, path.durations_s)):
        last = i == n - 1
        tail = "" if last and not path.loop else f", {d:g} s to {'the first' if last else 'next'}"
        x, y, z = np.round(k.cam_to_world[:3, 3], 3)
        out.append(f"{i + 1}: fov {k.fov_y_deg:.0f}, at ({x:g}, {y:g}, {z:g}){tail}")
    return out
