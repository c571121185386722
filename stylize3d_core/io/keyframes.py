"""Keyframe camera paths on disk, as stylize3d camera-path JSON (:mod:`stylize3d_core.io.camera_path`).

A keyframe file *is* a camera-path file whose frames are the keyframes, with
one more top-level key that :func:`~stylize3d_core.io.camera_path.load_camera_path`
ignores::

    "keyframes": {"durations_s": [2.0, 1.5, 2.0], "loop": false}

so every tool that reads camera paths reads it (as the keyframes alone), and
:func:`load_keyframes` reads any camera path as keyframes (one second apart,
open, when the block is missing). The interpolated path itself is written with
:func:`~stylize3d_core.io.camera_path.save_camera_path`.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Optional, Tuple

from ..errors import ExportError, InputError, PathLike
from ..geometry.keyframes import KeyframePath, keyframes_from_cameras, keyframes_to_cameras
from .atomic import atomic_path
from .camera_path import CONVENTIONS, FORMAT_TAG, FORMAT_VERSION, load_camera_path
from .json_files import read_json_file

KEYFRAMES_KEY = "keyframes"
DEFAULT_DURATION_S = 1.0


def save_keyframes(path: PathLike, keyframes: KeyframePath, *, fps: float = 30,
                   image_size: Optional[Tuple[int, int]] = None) -> Path:
    """Write ``keyframes`` as a camera-path JSON file with the timing block (atomically)."""
    if not (isinstance(fps, (int, float)) and math.isfinite(fps) and fps > 0):
        raise InputError("fps", f"must be a positive number, got {fps!r}")
    cams = keyframes_to_cameras(keyframes)
    doc = {
        "format": FORMAT_TAG,
        "version": FORMAT_VERSION,
        "conventions": CONVENTIONS,
        "fps": int(fps) if float(fps).is_integer() else float(fps),
        "image_size": None if image_size is None else [int(image_size[0]), int(image_size[1])],
        "frames": [{"cam_to_world": m.tolist(), "fov_y_deg": float(f)}
                   for m, f in zip(cams.cam_to_world.numpy(), cams.fov_y_deg.numpy())],
        KEYFRAMES_KEY: {"durations_s": list(keyframes.durations_s), "loop": bool(keyframes.loop)},
    }
    dest = Path(path)
    try:
        with atomic_path(dest) as tmp:
            tmp.write_text(json.dumps(doc, indent=1, allow_nan=False), encoding="utf-8")
    except ExportError:
        raise
    except OSError as e:
        raise ExportError(f"{dest}: could not write the keyframes: {e}") from e
    return dest


def load_keyframes(path: PathLike) -> Tuple[KeyframePath, float]:
    """Read a keyframe file (or any stylize3d camera path) -> (keyframes, fps).

    Raises:
        InputError: naming the file, for everything :func:`load_camera_path` refuses and for a bad
            timing block (not an object, wrong number of durations, a duration out of range).
    """
    src = Path(path)
    cp = load_camera_path(src)  # validates the file, the poses and the FOVs
    doc = read_json_file(src, "keyframe file")
    block = doc.get(KEYFRAMES_KEY)
    n = len(cp.cameras)
    if block is None:
        durations, loop = [DEFAULT_DURATION_S] * n, False
    else:
        if not isinstance(block, dict) or not isinstance(block.get("durations_s"), list):
            raise InputError(src, f"{KEYFRAMES_KEY!r} must be an object with a list 'durations_s'")
        durations, loop = block["durations_s"], block.get("loop", False)
        if not isinstance(loop, bool):
            raise InputError(src, f"{KEYFRAMES_KEY}.loop must be true or false, got {loop!r}")
        if not all(isinstance(d, (int, float)) and not isinstance(d, bool) for d in durations):
            raise InputError(src, f"{KEYFRAMES_KEY}.durations_s must be numbers")
    try:
        kp = keyframes_from_cameras(cp.cameras, durations, loop)
    except InputError as e:
        raise InputError(src, e.problem) from None
    return kp, float(cp.fps if cp.fps is not None else 30.0)


__all__ = ["save_keyframes", "load_keyframes", "KEYFRAMES_KEY"]
