"""Camera paths by format: stylize3d's camera-path JSON or Open3D's ``PinholeCameraTrajectory`` JSON.

Both are JSON files; :func:`read_camera_path` tells them apart by their
content (an Open3D trajectory has ``"class_name": "PinholeCameraTrajectory"``),
so ``--camera-path`` takes either. The readers and writers themselves are in
:mod:`stylize3d_core.io.camera_path`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal, Tuple

from ..errors import InputError, PathLike
from ..geometry.camera import Cameras
from ..io.json_files import read_json_file
from ..io.camera_path import (MAX_FRAMES, CameraPath, load_camera_path, load_open3d_trajectory, save_camera_path,
                              save_open3d_trajectory)

PathFormat = Literal["stylize3d", "open3d"]
OPEN3D_CLASS = "PinholeCameraTrajectory"


def camera_path_format(path: PathLike) -> PathFormat:
    """Which format the JSON file ``path`` holds ("open3d" or "stylize3d"; unreadable files are "stylize3d",
    whose reader names the problem)."""
    try:
        doc = read_json_file(path, "camera path")
    except InputError:
        return "stylize3d"
    return "open3d" if isinstance(doc, dict) and doc.get("class_name") == OPEN3D_CLASS else "stylize3d"


def read_camera_path(path: PathLike, *, max_frames: int = MAX_FRAMES) -> CameraPath:
    """Read a stylize3d camera path or an Open3D trajectory (see the module docstring) of at most
    ``max_frames`` frames."""
    if camera_path_format(path) == "open3d":
        return load_open3d_trajectory(path, max_frames=max_frames)
    return load_camera_path(path, max_frames=max_frames)


def write_camera_path(path: PathLike, cameras: Cameras, *, fmt: PathFormat, fps: float,
                      image_size: Tuple[int, int]) -> Path:
    """Write ``cameras`` as ``fmt``: a stylize3d camera path (with ``fps`` and ``image_size``) or an
    Open3D trajectory (intrinsics at ``image_size`` (H, W); Open3D records no fps)."""
    if fmt == "open3d":
        return save_open3d_trajectory(path, cameras, *image_size)
    if fmt == "stylize3d":
        return save_camera_path(path, cameras, fps=fps, image_size=image_size)
    raise InputError("format", f"camera paths are 'stylize3d' or 'open3d', got {fmt!r}")

