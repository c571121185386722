"""How far a camera may leave a 3D photo's input view, and the extreme cameras of that range.

Conventions are those of :mod:`stylize3d_core.geometry.camera` (world = the
photo's camera frame, +z forward, x right, y down, poses are ``cam_to_world``)
and scene units (near depth :data:`~stylize3d_core.geometry.camera.NEAR_DEPTH` = 1/3).

The interactive camera (the viewer's orbit control) is built in two steps:

1. **Pan and dolly** place the camera at ``t0 = (pan_x, pan_y, dolly)`` in the
   photo's frame, still looking along +z (``dolly > 0`` moves forward).
2. **Orbit** turns that camera about the scene centre ``c = (0, 0, centre_depth)``
   by ``R = R_y(yaw) @ R_x(pitch)``: ``cam_to_world = [R | c + R (t0 - c)]``.

A :class:`CameraRange` bounds yaw, pitch, pan and dolly, and keeps the camera
centre at least a margin in front of the near surface. The layered depth image
(:mod:`stylize3d_core.scene.ldi`) is sized from the extreme cameras of a range
(:func:`range_corner_poses`) and of the default trajectories
(:func:`trajectory_extreme_cameras`): its hidden layer and border must cover what
those cameras uncover. Where the photo's geometry would need more than the layer
may hold, the LDI reports the *fraction* of the range it covers
(``LDI.range_scale``) and :meth:`CameraRange.scaled` gives the range it supports.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List, Tuple

import numpy as np

from ..checks import check_range
from .camera import DEFAULT_FOV_Y_DEG, NEAR_DEPTH
from .trajectories import DEFAULT_XY, DEFAULT_Z, dolly_zoom_fov


@dataclass(frozen=True)
class CameraRange:
    """How far the interactive camera may leave the input view.

    Attributes:
        max_yaw_deg: largest turn left/right about the centre, degrees. Default 8.
        max_pitch_deg: largest turn up/down about the centre, degrees. Default 5.
        max_pan: largest sideways/vertical shift in the camera plane, scene units.
            Default 0.1 (30 % of the near depth).
        min_dolly: farthest move backwards, as a fraction of the centre depth (<= 0). Default -0.3.
        max_dolly: farthest move forwards, as a fraction of the centre depth (>= 0). Default 0.6.
        near_margin: the camera centre keeps ``z <= (1 - near_margin) * near_depth``
            (never past the near surface), whatever the other components. Default 0.5.
    """

    max_yaw_deg: float = 8.0
    max_pitch_deg: float = 5.0
    max_pan: float = 0.1
    min_dolly: float = -0.3
    max_dolly: float = 0.6
    near_margin: float = 0.5

    def __post_init__(self) -> None:
        check_range(self.max_yaw_deg, "max_yaw_deg", 0.0, 80.0)
        check_range(self.max_pitch_deg, "max_pitch_deg", 0.0, 80.0)
        check_range(self.max_pan, "max_pan", 0.0, 10.0)
        check_range(self.min_dolly, "min_dolly", -10.0, 0.0)
        check_range(self.max_dolly, "max_dolly", 0.0, 1.0, inclusive=True)
        check_range(self.near_margin, "near_margin", 0.0, 1.0, inclusive=False)

    def scaled(self, scale: float) -> "CameraRange":
        """The range with every motion (yaw, pitch, pan, dolly) multiplied by ``scale`` in [0, 1]."""
        s = check_range(scale, "scale", 0.0, 1.0)
        return CameraRange(self.max_yaw_deg * s, self.max_pitch_deg * s, self.max_pan * s,
                           self.min_dolly * s, self.max_dolly * s, self.near_margin)


def rotation(yaw_deg: float, pitch_deg: float) -> np.ndarray:
    """``R = R_y(yaw) @ R_x(pitch)`` (3, 3) float64, orthonormal with det 1."""
    a, b = math.radians(yaw_deg), math.radians(pitch_deg)
    ry = np.array([[math.cos(a), 0.0, math.sin(a)], [0.0, 1.0, 0.0], [-math.sin(a), 0.0, math.cos(a)]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(b), -math.sin(b)], [0.0, math.sin(b), math.cos(b)]])
    return ry @ rx


def orbit_cam_to_world(yaw_deg: float, pitch_deg: float, pan_x: float, pan_y: float, dolly: float,
                       centre_depth: float) -> np.ndarray:
    """The (4, 4) float64 ``cam_to_world`` of an orbit pose (see the module docstring)."""
    R = rotation(yaw_deg, pitch_deg)  # (3, 3)
    c = np.array([0.0, 0.0, centre_depth])
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = c + R @ (np.array([pan_x, pan_y, dolly]) - c)
    return T


def clamp_dolly(yaw_deg: float, pitch_deg: float, pan_x: float, pan_y: float, dolly: float,
                centre_depth: float, near_depth: float, rng: CameraRange) -> float:
    """``dolly`` in the range's dolly interval, pulled back until the camera centre is at
    least the near margin in front of the near surface (given the other components)."""
    lo, hi = rng.min_dolly * centre_depth, rng.max_dolly * centre_depth
    d = float(np.clip(dolly, lo, hi))
    # The camera's world z grows with dolly at the rate k = R[2, 2] = cos(yaw) cos(pitch) > 0.
    z_max = (1.0 - rng.near_margin) * near_depth
    z = float(orbit_cam_to_world(yaw_deg, pitch_deg, pan_x, pan_y, d, centre_depth)[2, 3])
    if z > z_max:
        k = math.cos(math.radians(yaw_deg)) * math.cos(math.radians(pitch_deg))
        d = max(lo, d - (z - z_max) / k)
    return d


def range_corner_poses(rng: CameraRange, centre_depth: float, near_depth: float = NEAR_DEPTH) -> np.ndarray:
    """The extreme cameras of a range: (K, 4, 4) float64 ``cam_to_world``.

    The sideways and vertical offsets of yaw and pan add up when they push the
    camera the same way (``yaw > 0`` and ``pan_x < 0`` both move it left;
    ``pitch > 0`` and ``pan_y > 0`` both move it down), so the corners are the
    9 combinations of (left, none, right) x (up, none, down) at full yaw, pitch
    and pan, each at the farthest backward and forward dolly (clamped by the
    near margin): 18 cameras (17 when ``max_dolly`` is 0: the input view itself is left out).
    """
    check_range(centre_depth, "centre_depth", 1e-9, math.inf)
    out: List[np.ndarray] = []
    for sx in (-1, 0, 1):
        for sy in (-1, 0, 1):
            yaw, pitch = -sx * rng.max_yaw_deg, sy * rng.max_pitch_deg
            px, py = sx * rng.max_pan, sy * rng.max_pan
            for d in (rng.min_dolly, rng.max_dolly):
                if sx == sy == 0 and d == rng.max_dolly == 0.0:
                    continue
                dz = clamp_dolly(yaw, pitch, px, py, d * centre_depth, centre_depth, near_depth, rng)
                out.append(orbit_cam_to_world(yaw, pitch, px, py, dz, centre_depth))
    return np.stack(out)


def trajectory_extreme_cameras(fov_y_deg: float = DEFAULT_FOV_Y_DEG,
                               subject_depth: float = NEAR_DEPTH) -> Tuple[np.ndarray, np.ndarray]:
    """The extreme cameras of the default trajectories (circle, swing, ken_burns, zoom, dolly_zoom).

    Every default trajectory keeps the identity rotation and moves within
    ``x, y in [-DEFAULT_XY, DEFAULT_XY]``, ``z in DEFAULT_Z``; the dolly zoom also
    widens the FOV as it moves forward. Returns ``(cam_to_world (K, 4, 4),
    fov_y_deg (K,))``: the 8 box corners at the photo's FOV and the dolly zoom's
    forward end at its widened FOV.
    """
    poses, fovs = [], []
    for x in (-DEFAULT_XY, DEFAULT_XY):
        for y in (-DEFAULT_XY, DEFAULT_XY):
            for z in DEFAULT_Z:
                T = np.eye(4)
                T[:3, 3] = (x, y, z)
                poses.append(T)
                fovs.append(fov_y_deg)
    T = np.eye(4)
    T[2, 3] = max(DEFAULT_Z)
    poses.append(T)
    fovs.append(float(dolly_zoom_fov(fov_y_deg, subject_depth, np.array([max(DEFAULT_Z)]))[0]))
    return np.stack(poses), np.asarray(fovs, np.float64)


def _project(points: np.ndarray, world_to_cam: np.ndarray, focal: np.ndarray,
             centre: Tuple[float, float]) -> Tuple[np.ndarray, np.ndarray]:
    """Points (N, 3) seen by K cameras: pixel coordinates (K, N, 2) and depths (K, N)."""
    p = np.matmul(points, world_to_cam[:, :3, :3].transpose(0, 2, 1)) + world_to_cam[:, None, :3, 3]  # (K, N, 3)
    z = np.maximum(p[..., 2], 1e-9)
    uv = p[..., :2] / z[..., None] * focal[:, None, None] + np.asarray(centre)
    return uv, p[..., 2]


def edge_parallax(uv: np.ndarray, z_front: np.ndarray, z_back: np.ndarray, cam_to_world: np.ndarray,
                  fov_y_deg: np.ndarray, photo_size: Tuple[int, int], photo_fov_y_deg: float) -> np.ndarray:
    """How much hidden background each depth edge can uncover, in photo pixels.

    An edge pixel at photo coordinates ``uv`` (N, 2) holds a front surface at
    depth ``z_front`` (N,) before a background at ``z_back`` (N,). A camera that
    moves sees the two points on that ray apart by ``|uv'(front) - uv'(back)|``
    pixels (for a sideways move ``b``: ``b f |1 / z_front - 1 / z_back|``); the
    background there is background the photo did not see, measured here in the
    photo's pixels at the background (divided by the background's magnification
    in the new view). Returns the largest over the K cameras ``cam_to_world``
    (K, 4, 4) with FOVs ``fov_y_deg`` (K,), as (N,) float64.
    """
    h, w = photo_size
    f0 = 0.5 * h / math.tan(math.radians(photo_fov_y_deg) / 2.0)
    rays = np.concatenate([(uv - (w / 2.0, h / 2.0)) / f0, np.ones((uv.shape[0], 1))], axis=1)  # (N, 3)
    w2c = np.linalg.inv(cam_to_world)  # (K, 4, 4)
    focal = 0.5 * h / np.tan(np.radians(np.asarray(fov_y_deg, np.float64)) / 2.0)  # (K,)
    uv_f, _ = _project(rays * z_front[:, None], w2c, focal, (w / 2.0, h / 2.0))
    uv_b, zc_b = _project(rays * z_back[:, None], w2c, focal, (w / 2.0, h / 2.0))
    gap = np.linalg.norm(uv_f - uv_b, axis=-1)  # (K, N) in new-view pixels
    magnification = (focal[:, None] / f0) * z_back[None] / np.maximum(zc_b, 1e-9)  # (K, N)
    return (gap / np.maximum(magnification, 1e-9)).max(axis=0) if len(cam_to_world) else np.zeros(len(uv))


def border_overshoot(side_depths: Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
                     cam_to_world: np.ndarray, fov_y_deg: np.ndarray, photo_size: Tuple[int, int],
                     photo_fov_y_deg: float, samples: int = 9) -> float:
    """How far beyond the photo's frame the cameras see, in photo pixels.

    For each camera (K, 4, 4) with FOV (K,), rendered at the photo's size,
    ``samples`` rays along each side of its frame are cut with the planes at the
    given depths of the photo's matching side (``side_depths`` = depths (D,) found
    along the top, bottom, left and right rows / columns of the photo, e.g. their
    least and largest) and taken back to the photo's pixels; the result is the
    largest distance by which any of them falls outside ``[0, W] x [0, H]``.
    """
    h, w = photo_size
    if not len(cam_to_world):
        return 0.0
    f0 = 0.5 * h / math.tan(math.radians(photo_fov_y_deg) / 2.0)
    t = np.linspace(0.0, 1.0, samples)
    sides = [np.stack([t * w, np.zeros_like(t)], 1), np.stack([t * w, np.full_like(t, h)], 1),
             np.stack([np.zeros_like(t), t * h], 1), np.stack([np.full_like(t, w), t * h], 1)]  # 4 x (S, 2)
    f = 0.5 * h / np.tan(np.radians(np.asarray(fov_y_deg, np.float64)) / 2.0)  # (K,)
    centre = cam_to_world[:, :3, 3]  # (K, 3)
    worst = 0.0
    for uv, depths in zip(sides, side_depths):
        rays = np.concatenate([(uv - (w / 2.0, h / 2.0)), np.zeros((len(uv), 1))], 1)  # (S, 3) / f, plus z = 1
        cam_dirs = rays[None] / f[:, None, None]  # (K, S, 3)
        cam_dirs[..., 2] = 1.0
        d = np.einsum("kij,ksj->ksi", cam_to_world[:, :3, :3], cam_dirs)  # (K, S, 3) world directions
        z = np.asarray(depths, np.float64).reshape(-1)[:, None, None]  # (D, 1, 1)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (z - centre[None, :, None, 2]) / np.where(d[None, ..., 2] > 1e-9, d[None, ..., 2], np.nan)
            s = np.where(s > 0, s, np.nan)  # (D, K, S); NaN: the plane lies behind this camera
            p = centre[None, :, None, :] + d[None] * s[..., None]  # (D, K, S, 3) world points at depth z
            u = p[..., 0] / z * f0 + w / 2.0
            v = p[..., 1] / z * f0 + h / 2.0
            out = np.stack([-u, u - w, -v, v - h])
        if np.isfinite(out).any():
            worst = max(worst, float(np.nanmax(out)))
    return max(worst, 0.0)
