"""Camera control for the viewer: orbit, pan and dolly about a 3D photo, kept near the input view.

Pure functions on a frozen :class:`OrbitPose`; no GUI, no threads. Conventions
are those of :mod:`stylize3d_core.geometry.camera` (world = the photo's camera
frame, +z forward, x right, y down, poses are ``cam_to_world``, near depth
:data:`~stylize3d_core.geometry.camera.NEAR_DEPTH` = 1/3).

The camera is built in two steps:

1. **Pan and dolly** place the camera at ``t0 = (pan_x, pan_y, dolly)`` in the
   photo's frame, still looking along +z (``dolly > 0`` moves forward).
2. **Orbit** turns that camera about the scene centre ``c = (0, 0, centre_depth)``
   (the photo's median depth on the optical axis) by ``R = R_y(yaw) @ R_x(pitch)``:
   ``cam_to_world = [R | c + R (t0 - c)]``.

Signs follow the "grab the scene" feel: dragging right turns the scene right
(the camera swings left, ``yaw > 0``), dragging down tilts its top towards you
(the camera rises, ``pitch < 0``); a pan drag moves the scene with the cursor.

A 3D photo only holds up near the input view, so every pose is clamped
(:class:`OrbitLimits`): yaw, pitch and pan to small ranges, dolly to a fraction
of the centre depth, and the camera centre never comes closer than a margin to
the near surface (world ``z <= (1 - near_margin) * near_depth``), whatever the
yaw, pitch and pan.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Literal, Tuple

import numpy as np

from stylize3d_core.checks import check_range
from stylize3d_core.errors import InputError
from stylize3d_core.geometry.camera import NEAR_DEPTH, Cameras, check_fov

DragMode = Literal["orbit", "pan"]


@dataclass(frozen=True)
class OrbitLimits:
    """How far the camera may leave the input view.

    Attributes:
        max_yaw_deg: largest turn left/right about the centre, degrees. Default 8 (beyond it
            the torn edges, the inpainted background and the extended border of a single
            photo dominate the view).
        max_pitch_deg: largest turn up/down about the centre, degrees. Default 5.
        max_pan: largest sideways/vertical shift in the camera plane, scene units. Default 0.1
            (30 % of the near depth).
        min_dolly: farthest move backwards, as a fraction of the centre depth (<= 0). Default -0.3.
        max_dolly: farthest move forwards, as a fraction of the centre depth (>= 0). Default 0.6.
        near_margin: the camera centre keeps ``z <= (1 - near_margin) * near_depth``
            (never past the near surface). Default 0.5.
        deg_per_pixel: orbit degrees per pixel of mouse drag. Default 0.04 (8 degrees in 200 px).
        dolly_per_tick: forward move per wheel step, as a fraction of the centre depth. Default 0.04.
    """

    max_yaw_deg: float = 8.0
    max_pitch_deg: float = 5.0
    max_pan: float = 0.1
    min_dolly: float = -0.3
    max_dolly: float = 0.6
    near_margin: float = 0.5
    deg_per_pixel: float = 0.04
    dolly_per_tick: float = 0.04

    def __post_init__(self) -> None:
        check_range(self.max_yaw_deg, "max_yaw_deg", 0.0, 80.0)
        check_range(self.max_pitch_deg, "max_pitch_deg", 0.0, 80.0)
        check_range(self.max_pan, "max_pan", 0.0, 10.0)
        check_range(self.min_dolly, "min_dolly", -10.0, 0.0)
        check_range(self.max_dolly, "max_dolly", 0.0, 1.0, inclusive=True)
        check_range(self.near_margin, "near_margin", 0.0, 1.0, inclusive=False)
        check_range(self.deg_per_pixel, "deg_per_pixel", 0.0, 10.0)
        check_range(self.dolly_per_tick, "dolly_per_tick", 0.0, 1.0)


@dataclass(frozen=True)
class OrbitScene:
    """What the camera control needs to know about a 3D photo (scene units).

    Attributes:
        centre_depth: depth of the orbit centre on the optical axis (the median depth). > near_depth.
        near_depth: depth of the nearest surface. Default NEAR_DEPTH = 1/3 (normalised scenes).
    """

    centre_depth: float
    near_depth: float = NEAR_DEPTH

    def __post_init__(self) -> None:
        for name in ("centre_depth", "near_depth"):
            v = float(getattr(self, name))
            if not math.isfinite(v) or v <= 0:
                raise InputError(name, f"must be a finite depth > 0, got {getattr(self, name)!r}")
        if self.centre_depth < self.near_depth:
            raise InputError("centre_depth", f"must be >= near_depth {self.near_depth:g}, got {self.centre_depth:g}")

    @staticmethod
    def from_depths(z: np.ndarray) -> "OrbitScene":
        """From the depths (N,) of the photo's visible surface: median centre, 1st-percentile near depth."""
        z = np.asarray(z, dtype=np.float64).reshape(-1)
        z = z[np.isfinite(z) & (z > 0)]
        if z.size == 0:
            raise InputError("depth", "no finite positive depth to place the orbit centre")
        near, centre = np.percentile(z, [1.0, 50.0])
        return OrbitScene(centre_depth=float(max(centre, near)), near_depth=float(near))


@dataclass(frozen=True)
class OrbitPose:
    """A camera relative to the input view (all zero = the photo's own camera).

    Attributes:
        yaw_deg: turn about the centre's vertical axis, degrees (> 0: camera to the left).
        pitch_deg: turn about the centre's horizontal axis, degrees (> 0: camera lower).
        pan_x: shift right in the camera plane, scene units.
        pan_y: shift down in the camera plane, scene units.
        dolly: move forwards along the view axis, scene units.
    """

    yaw_deg: float = 0.0
    pitch_deg: float = 0.0
    pan_x: float = 0.0
    pan_y: float = 0.0
    dolly: float = 0.0

    def __post_init__(self) -> None:
        for name in ("yaw_deg", "pitch_deg", "pan_x", "pan_y", "dolly"):
            if not math.isfinite(float(getattr(self, name))):
                raise InputError(name, f"must be finite, got {getattr(self, name)!r}")


HOME = OrbitPose()
"""The input view."""


def rotation(yaw_deg: float, pitch_deg: float) -> np.ndarray:
    """``R = R_y(yaw) @ R_x(pitch)`` (3, 3) float64, orthonormal with det 1."""
    a, b = math.radians(yaw_deg), math.radians(pitch_deg)
    ry = np.array([[math.cos(a), 0.0, math.sin(a)], [0.0, 1.0, 0.0], [-math.sin(a), 0.0, math.cos(a)]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(b), -math.sin(b)], [0.0, math.sin(b), math.cos(b)]])
    return ry @ rx


def cam_to_world(pose: OrbitPose, scene: OrbitScene) -> np.ndarray:
    """The (4, 4) float64 ``cam_to_world`` of ``pose`` (see the module docstring)."""
    R = rotation(pose.yaw_deg, pose.pitch_deg)  # (3, 3)
    c = np.array([0.0, 0.0, scene.centre_depth])
    t0 = np.array([pose.pan_x, pose.pan_y, pose.dolly])
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = c + R @ (t0 - c)
    return T


def camera_z(pose: OrbitPose, scene: OrbitScene) -> float:
    """World z of the camera centre (its depth in the photo's frame)."""
    return float(cam_to_world(pose, scene)[2, 3])


def dolly_range(scene: OrbitScene, limits: OrbitLimits = OrbitLimits()) -> Tuple[float, float]:
    """``(lo, hi)`` dolly in scene units from the limits' fractions of the centre depth."""
    return limits.min_dolly * scene.centre_depth, limits.max_dolly * scene.centre_depth


def clamp_pose(pose: OrbitPose, scene: OrbitScene, limits: OrbitLimits = OrbitLimits()) -> OrbitPose:
    """``pose`` moved to the nearest pose inside ``limits`` (a pose inside is returned unchanged)."""
    yaw = float(np.clip(pose.yaw_deg, -limits.max_yaw_deg, limits.max_yaw_deg))
    pitch = float(np.clip(pose.pitch_deg, -limits.max_pitch_deg, limits.max_pitch_deg))
    px = float(np.clip(pose.pan_x, -limits.max_pan, limits.max_pan))
    py = float(np.clip(pose.pan_y, -limits.max_pan, limits.max_pan))
    lo, hi = dolly_range(scene, limits)
    out = OrbitPose(yaw, pitch, px, py, float(np.clip(pose.dolly, lo, hi)))
    # The camera's world z grows with dolly at the rate k = R[2, 2] = cos(yaw) cos(pitch) > 0:
    # pull the dolly back until the camera is at least the margin in front of the near surface.
    z_max = (1.0 - limits.near_margin) * scene.near_depth
    z = camera_z(out, scene)
    if z > z_max:
        k = math.cos(math.radians(yaw)) * math.cos(math.radians(pitch))
        out = replace(out, dolly=max(lo, out.dolly - (z - z_max) / k))
    return out


def orbit(pose: OrbitPose, d_yaw_deg: float, d_pitch_deg: float, scene: OrbitScene,
          limits: OrbitLimits = OrbitLimits()) -> OrbitPose:
    """Turn about the centre by ``(d_yaw, d_pitch)`` degrees, clamped."""
    return clamp_pose(replace(pose, yaw_deg=pose.yaw_deg + d_yaw_deg, pitch_deg=pose.pitch_deg + d_pitch_deg),
                      scene, limits)


def pan(pose: OrbitPose, dx: float, dy: float, scene: OrbitScene, limits: OrbitLimits = OrbitLimits()) -> OrbitPose:
    """Shift the camera by ``(dx, dy)`` scene units in its plane (x right, y down), clamped."""
    return clamp_pose(replace(pose, pan_x=pose.pan_x + dx, pan_y=pose.pan_y + dy), scene, limits)


def dolly(pose: OrbitPose, dz: float, scene: OrbitScene, limits: OrbitLimits = OrbitLimits()) -> OrbitPose:
    """Move the camera ``dz`` scene units forwards (negative: backwards), clamped."""
    return clamp_pose(replace(pose, dolly=pose.dolly + dz), scene, limits)


def apply_drag(pose: OrbitPose, mode: DragMode, dx_px: float, dy_px: float, view_height_px: float,
               fov_y_deg: float, scene: OrbitScene, limits: OrbitLimits = OrbitLimits()) -> OrbitPose:
    """The pose after a mouse drag of ``(dx, dy)`` pixels (x right, y down) in a view ``view_height_px`` tall.

    ``"orbit"`` turns ``limits.deg_per_pixel`` per pixel; ``"pan"`` moves the
    camera so the centre plane follows the cursor (``centre_depth / f`` scene
    units per pixel, ``f`` the focal length in pixels).
    """
    if mode == "orbit":
        k = limits.deg_per_pixel
        return orbit(pose, k * dx_px, -k * dy_px, scene, limits)
    if mode == "pan":
        if view_height_px <= 0:
            raise InputError("view_height_px", f"must be > 0, got {view_height_px!r}")
        f = 0.5 * view_height_px / math.tan(math.radians(check_fov(fov_y_deg)) / 2.0)
        s = scene.centre_depth / f
        return pan(pose, -s * dx_px, -s * dy_px, scene, limits)
    raise InputError("drag mode", f"must be 'orbit' or 'pan', got {mode!r}")


def apply_wheel(pose: OrbitPose, ticks: float, scene: OrbitScene, limits: OrbitLimits = OrbitLimits()) -> OrbitPose:
    """The pose after ``ticks`` wheel steps (> 0: scroll up = move forwards), clamped."""
    return dolly(pose, ticks * limits.dolly_per_tick * scene.centre_depth, scene, limits)


def pose_camera(pose: OrbitPose, scene: OrbitScene, fov_y_deg: float) -> Cameras:
    """A batch of one :class:`Cameras` for ``pose`` with vertical FOV ``fov_y_deg`` degrees."""
    return Cameras.create(cam_to_world(pose, scene), check_fov(fov_y_deg))


def relative_to(pose: OrbitPose, scene: OrbitScene, cameras: Cameras) -> Cameras:
    """``cameras`` (a trajectory around the input view) moved to start from ``pose``: ``C(pose) @ T_i``."""
    base = np.asarray(cam_to_world(pose, scene))  # (4, 4)
    c2w = cameras.cam_to_world.detach().cpu().numpy()  # (B, 4, 4)
    return Cameras.create(np.einsum("ij,bjk->bik", base, c2w), cameras.fov_y_deg.clone())
