"""Camera paths on disk: stylize3d's own JSON, and Open3D's ``PinholeCameraTrajectory`` JSON.

stylize3d camera-path schema (``format`` ``"stylize3d-camera-path"``, ``version`` 1)::

    {
      "format": "stylize3d-camera-path",
      "version": 1,
      "conventions": "...",            # free text, for people; ignored when loading
      "fps": 30,                       # frames per second, > 0
      "image_size": [480, 640],        # [height, width] in pixels, or null
      "frames": [                      # at least one
        {"cam_to_world": [[r00, r01, r02, tx],
                          [r10, r11, r12, ty],
                          [r20, r21, r22, tz],
                          [0,   0,   0,   1 ]],   # 4 rows of 4 numbers (row-major)
         "fov_y_deg": 60.0},           # vertical FOV in degrees
        ...
      ]
    }

The conventions are those of :mod:`stylize3d_core.geometry.camera`: poses are
``cam_to_world`` (camera -> world), the camera looks along +z with x right and
y down, and the world frame is the input photo's camera. Numbers are written
with Python's shortest round-tripping repr, so saving and loading is exact.

Open3D trajectories store ``extrinsic = world_to_cam`` and pinhole intrinsics at
one image size, with Open3D's pixel convention (pixel centres at integer
coordinates, so the principal point of a centred camera is ``(W/2 - 0.5, H/2 - 0.5)``).
Open3D is imported lazily (``open3d.camera`` and ``open3d.io`` only).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, List, Optional, Tuple

import numpy as np
import torch

from ..errors import ExportError, InputError, PathLike
from ..geometry.camera import MAX_FOV_DEG, MIN_FOV_DEG, Cameras, focal_from_fov
from .atomic import write_atomically
from .json_files import read_json_file

FORMAT_TAG = "stylize3d-camera-path"
FORMAT_VERSION = 1
CONVENTIONS = (
    "cam_to_world: 4x4 camera-to-world pose, a list of 4 rows (row-major); camera looks along +z, "
    "x right, y down (OpenCV); world frame = the input photo's camera; fov_y_deg: vertical field of "
    "view in degrees; image_size: [height, width]"
)
ROTATION_TOL = 1e-6
"""Largest deviation of ``R^T R`` from the identity (and of ``det R`` from 1) a pose may have."""


@dataclass(frozen=True)
class CameraPath:
    """A camera path read from a file.

    Attributes:
        cameras: the B cameras (see :class:`Cameras`).
        fps: frames per second, or None where the file does not record it (Open3D).
        image_size: ``(height, width)`` in pixels, or None where the file has none.
    """

    cameras: Cameras
    fps: Optional[float]
    image_size: Optional[Tuple[int, int]]


def _check_size(h: Any, w: Any, source: str) -> Tuple[int, int]:
    ok = all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 1 for v in (h, w))
    if not ok:
        raise InputError(source, f"image size must be two positive integers [height, width], got {[h, w]!r}")
    return (int(h), int(w))


def _check_image_size(image_size: Any, source: str) -> Optional[Tuple[int, int]]:
    if image_size is None:
        return None
    if not isinstance(image_size, (list, tuple)) or len(image_size) != 2:
        raise InputError(source, f"image_size must be [height, width] or null, got {image_size!r}")
    return _check_size(image_size[0], image_size[1], source)


def _check_fps(fps: Any, source: str) -> float:
    if isinstance(fps, bool) or not isinstance(fps, (int, float, np.integer, np.floating)):
        raise InputError(source, f"fps must be a number, got {fps!r}")
    value = _as_float(fps)
    if not (math.isfinite(value) and value > 0):
        raise InputError(source, f"fps must be a finite number > 0, got {_short(fps)}")
    return value


def _as_float(v: Any) -> float:
    """``float(v)``, or inf for an integer too large for a float (so range checks refuse it)."""
    try:
        return float(v)
    except OverflowError:
        return math.inf


def _short(v: Any) -> str:
    text = repr(v)
    return text if len(text) <= 40 else f"{text[:20]}...({len(text)} characters)"


def _rigid_problem(T: np.ndarray) -> Optional[str]:
    """Why the (4, 4) matrix ``T`` is not a rigid transform, or None."""
    if not np.isfinite(T).all():
        return "contains NaN or infinite values"
    if not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0], atol=ROTATION_TOL, rtol=0.0):
        return f"last row must be [0, 0, 0, 1], got {T[3].tolist()}"
    R = T[:3, :3]
    err = float(np.abs(R.T @ R - np.eye(3)).max())
    if err > ROTATION_TOL or abs(float(np.linalg.det(R)) - 1.0) > ROTATION_TOL:
        return f"rotation part is not a rotation (|R^T R - I| = {err:.3g}, det = {float(np.linalg.det(R)):.6g})"
    return None


def _check_fov_value(fov: Any, where: str, source: str) -> float:
    if isinstance(fov, bool) or not isinstance(fov, (int, float)):
        raise InputError(source, f"{where}: fov_y_deg must be a number, got {fov!r}")
    value = _as_float(fov)
    if not (math.isfinite(value) and MIN_FOV_DEG <= value <= MAX_FOV_DEG):
        raise InputError(source, f"{where}: fov_y_deg must be in [{MIN_FOV_DEG:g}, {MAX_FOV_DEG:g}], got {_short(fov)}")
    return value


def _check_cameras(cameras: Any) -> Cameras:
    if not isinstance(cameras, Cameras):
        raise InputError("cameras", f"must be a Cameras batch, got {type(cameras).__name__}")
    if len(cameras) == 0:
        raise InputError("cameras", "the batch is empty; a camera path needs at least one frame")
    return cameras


def save_camera_path(
    path: PathLike, cameras: Cameras, *, fps: float = 30, image_size: Optional[Tuple[int, int]] = None
) -> Path:
    """Write ``cameras`` as a stylize3d camera-path JSON file (schema in the module docstring), atomically.

    Args:
        path: destination, usually ``*.json``.
        cameras: B >= 1 cameras.
        fps: frames per second of the video the path is meant for. Default 30 (public code).
        image_size: ``(height, width)`` to record, or None.
    Returns:
        The destination path.
    """
    _check_cameras(cameras)
    fps_v = _check_fps(fps, "fps")
    size = _check_image_size(image_size, "image_size")
    c2w = cameras.cam_to_world.detach().to(torch.float64).cpu().numpy()  # (B, 4, 4)
    fovs = cameras.fov_y_deg.detach().to(torch.float64).cpu().numpy()  # (B,)
    doc = {
        "format": FORMAT_TAG,
        "version": FORMAT_VERSION,
        "conventions": CONVENTIONS,
        "fps": int(fps_v) if float(fps_v).is_integer() else fps_v,
        "image_size": None if size is None else list(size),
        "frames": [{"cam_to_world": m.tolist(), "fov_y_deg": float(f)} for m, f in zip(c2w, fovs)],
    }
    text = json.dumps(doc, indent=1, allow_nan=False)
    dest = Path(path)
    data = text.encode("utf-8")

    def verify(tmp: Path) -> None:
        if tmp.read_bytes() != data:
            raise ExportError(f"{dest}: the written camera path does not read back as written")

    return write_atomically(dest, "camera path", lambda tmp: tmp.write_bytes(data), verify=verify, size=len(data))


MAX_FRAMES = 10_000
"""Most frames a camera-path file may hold by default (5.5 min at 30 fps); ``max_frames`` raises it."""
def _check_frame_count(n: int, fps: Optional[float], max_frames: int, source: Path) -> None:
    if n > max_frames:
        length = f" ({n / fps / 60:.1f} min at {fps:g} fps)" if fps else ""
        raise InputError(source, f"the camera path has {n:,} frames{length}, more than the limit of "
                                 f"{max_frames:,}; split it, or raise the limit (max_frames, --max-frames)")


def load_camera_path(path: PathLike, *, max_frames: int = MAX_FRAMES) -> CameraPath:
    """Read a stylize3d camera-path JSON file.

    Args:
        path: the file.
        max_frames: most frames accepted (default :data:`MAX_FRAMES`).
    Raises:
        InputError: naming the file and the problem when it is missing, too large,
            not JSON (or nested too deeply, or with numbers that do not fit a float),
            not a stylize3d camera path of a known version, has more than
            ``max_frames`` frames, or holds a bad frame (wrong matrix shape,
            non-finite numbers, non-rigid pose, FOV out of range).
    """
    src = Path(path)
    doc = read_json_file(src, "camera path")
    if not isinstance(doc, dict) or doc.get("format") != FORMAT_TAG:
        got = doc.get("format") if isinstance(doc, dict) else type(doc).__name__
        raise InputError(src, f"not a stylize3d camera path (expected \"format\": \"{FORMAT_TAG}\", got {got!r})")
    if doc.get("version") != FORMAT_VERSION:
        raise InputError(src, f"unsupported camera-path version {doc.get('version')!r} (this reads {FORMAT_VERSION})")
    for key in ("fps", "frames"):
        if key not in doc:
            raise InputError(src, f"missing key {key!r}")
    fps = _check_fps(doc["fps"], str(src))
    size = _check_image_size(doc.get("image_size"), str(src))
    frames = doc["frames"]
    if not isinstance(frames, list) or len(frames) == 0:
        raise InputError(src, "'frames' must be a non-empty list (the path has zero frames)")
    _check_frame_count(len(frames), fps, max_frames, src)
    mats: List[np.ndarray] = []
    fovs: List[float] = []
    for i, fr in enumerate(frames):
        where = f"frame {i}"
        if not isinstance(fr, dict):
            raise InputError(src, f"{where}: must be an object with cam_to_world and fov_y_deg")
        for key in ("cam_to_world", "fov_y_deg"):
            if key not in fr:
                raise InputError(src, f"{where}: missing key {key!r}")
        m = fr["cam_to_world"]
        shape_ok = isinstance(m, list) and len(m) == 4 and all(isinstance(r, list) and len(r) == 4 for r in m)
        if not shape_ok or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for r in m for v in r):
            raise InputError(src, f"{where}: cam_to_world must be 4 rows of 4 numbers")
        T = np.asarray(m, dtype=np.float64)  # (4, 4)
        problem = _rigid_problem(T)
        if problem is not None:
            raise InputError(src, f"{where}: cam_to_world {problem}")
        mats.append(T)
        fovs.append(_check_fov_value(fr["fov_y_deg"], where, str(src)))
    cams = Cameras(torch.from_numpy(np.stack(mats)), torch.tensor(fovs, dtype=torch.float64))
    return CameraPath(cams, fps, size)


def save_open3d_trajectory(path: PathLike, cameras: Cameras, height: int, width: int) -> Path:
    """Write ``cameras`` as an Open3D ``PinholeCameraTrajectory`` JSON file, atomically.

    Each frame gets ``extrinsic = world_to_cam`` and the intrinsics of its FOV at
    ``(height, width)`` in Open3D's pixel convention (``cx = W/2 - 0.5``, ``cy = H/2 - 0.5``).

    Args:
        path: destination; must end in ``.json`` (Open3D picks the format by extension).
    """
    import open3d.camera as o3c  # lazy: keeps importing this module cheap
    import open3d.io as o3io

    _check_cameras(cameras)
    h, w = _check_size(height, width, "image size")
    dest = Path(path)
    if dest.suffix.lower() != ".json":
        raise InputError(dest, "an Open3D camera trajectory must be a .json file")
    w2c = cameras.world_to_cam().detach().to(torch.float64).cpu().numpy()  # (B, 4, 4)
    params = []
    for E, fov in zip(w2c, cameras.fov_y_deg.tolist()):
        f = focal_from_fov(fov, h)
        p = o3c.PinholeCameraParameters()
        p.intrinsic = o3c.PinholeCameraIntrinsic(w, h, f, f, w / 2.0 - 0.5, h / 2.0 - 0.5)
        p.extrinsic = np.ascontiguousarray(E)
        params.append(p)
    traj = o3c.PinholeCameraTrajectory()
    traj.parameters = params
    def write(tmp: Path) -> None:
        if not o3io.write_pinhole_camera_trajectory(str(tmp), traj):
            raise ExportError(f"{dest}: Open3D could not write the camera trajectory (disk full or not writable?)")

    def verify(tmp: Path) -> None:
        try:
            doc = json.loads(tmp.read_text(encoding="utf-8"))
            ok = len(doc["parameters"]) == len(params)
        except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError):
            ok = False
        if not ok:
            raise ExportError(f"{dest}: the written camera trajectory is incomplete or unreadable")

    return write_atomically(dest, "camera trajectory", write, verify=verify)


def load_open3d_trajectory(path: PathLike, *, max_frames: int = MAX_FRAMES) -> CameraPath:
    """Read an Open3D ``PinholeCameraTrajectory`` JSON file.

    The vertical FOV of each frame comes from ``fy`` and the image height,
    ``fov = 2 atan((H / 2) / fy)``. stylize3d cameras have square pixels and a
    centred principal point, so a file whose ``fx != fy`` or whose principal
    point is more than half a pixel off centre is rejected rather than approximated.

    Returns:
        A :class:`CameraPath` with ``fps = None`` (Open3D does not record it) and
        the (common) image size of the frames.
    """
    import open3d.io as o3io  # lazy

    src = Path(path)
    if not src.is_file():
        raise InputError(src, "file not found")
    doc = read_json_file(src, "camera trajectory")  # bounded before Open3D's own parser sees it
    params = doc.get("parameters") if isinstance(doc, dict) else None
    if not params:
        raise InputError(src, "not an Open3D PinholeCameraTrajectory, or it has zero frames")
    if not isinstance(params, list) or not all(isinstance(p, dict) for p in params):
        raise InputError(src, "not an Open3D PinholeCameraTrajectory (expected an object whose 'parameters' "
                              "is a list of camera objects)")
    _check_frame_count(len(params), None, max_frames, src)
    try:
        traj = o3io.read_pinhole_camera_trajectory(str(src))
    except RuntimeError as e:  # Open3D's JSON reader: a value of the wrong type
        raise InputError(src, f"not an Open3D PinholeCameraTrajectory ({e})") from None
    if len(traj.parameters) == 0:
        raise InputError(src, "not an Open3D PinholeCameraTrajectory, or it has zero frames")
    mats: List[np.ndarray] = []
    fovs: List[float] = []
    size: Optional[Tuple[int, int]] = None
    for i, p in enumerate(traj.parameters):
        where = f"frame {i}"
        h, w = int(p.intrinsic.height), int(p.intrinsic.width)
        K = np.asarray(p.intrinsic.intrinsic_matrix, dtype=np.float64)  # (3, 3)
        if h < 1 or w < 1:
            raise InputError(src, f"{where}: image size must be positive, got {(h, w)}")
        if size is None:
            size = (h, w)
        elif size != (h, w):
            raise InputError(src, f"{where}: image size {(h, w)} differs from frame 0's {size}")
        if not np.isfinite(K).all() or K[1, 1] <= 0:
            raise InputError(src, f"{where}: intrinsic matrix must be finite with fy > 0")
        fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
        if abs(fx - fy) > 1e-6 * fy:
            raise InputError(src, f"{where}: fx = {fx:g} and fy = {fy:g} differ; only square pixels are supported")
        if abs(cx - (w / 2.0 - 0.5)) > 0.5 + 1e-6 or abs(cy - (h / 2.0 - 0.5)) > 0.5 + 1e-6:
            raise InputError(
                src, f"{where}: principal point ({cx:g}, {cy:g}) is off centre for a {w}x{h} image; "
                "only centred principal points are supported"
            )
        E = np.asarray(p.extrinsic, dtype=np.float64)  # (4, 4) world_to_cam
        problem = _rigid_problem(E)
        if problem is not None:
            raise InputError(src, f"{where}: extrinsic {problem}")
        c2w = np.eye(4)
        c2w[:3, :3] = E[:3, :3].T
        c2w[:3, 3] = -E[:3, :3].T @ E[:3, 3]
        fov = math.degrees(2.0 * math.atan(0.5 * h / fy))
        mats.append(c2w)
        fovs.append(_check_fov_value(fov, where, str(src)))
    cams = Cameras(torch.from_numpy(np.stack(mats)), torch.tensor(fovs, dtype=torch.float64))
    return CameraPath(cams, None, size)
