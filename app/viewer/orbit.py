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
from stylize3d_core.geometry.camera_range import CameraRange, clamp_dolly, orbit_cam_to_world
from stylize3d_core.geometry.camera_range import rotation as rotation  # re-exported

_RANGE = CameraRange()

DragMode = Literal["orbit", "pan"]


@dataclass(frozen=True)
class OrbitLimits:
    """How far the camera may leave the input view, and how fast input moves it.

    The range fields mirror :class:`~stylize3d_core.geometry.camera_range.CameraRange`
    (the library's definition, which the layered depth image is sized for; a
    photo's ``Photo3D.camera_range`` is the part of it the photo shows cleanly:
    pass it to :meth:`from_range`).

    Attributes:
        max_yaw_deg, max_pitch_deg, max_pan, min_dolly, max_dolly, near_margin:
            see :class:`~stylize3d_core.geometry.camera_range.CameraRange` (same defaults).
        deg_per_pixel: orbit degrees per pixel of mouse drag. Default 0.04 (8 degrees in 200 px).
        dolly_per_tick: forward move per wheel step, as a fraction of the centre depth. Default 0.04.
        pan_gain: a pan drag moves the camera this many times the distance that keeps the centre plane
            under the cursor. Default 1.
    """

    max_yaw_deg: float = _RANGE.max_yaw_deg
    max_pitch_deg: float = _RANGE.max_pitch_deg
    max_pan: float = _RANGE.max_pan
    min_dolly: float = _RANGE.min_dolly
    max_dolly: float = _RANGE.max_dolly
    near_margin: float = _RANGE.near_margin
    deg_per_pixel: float = 0.04
    dolly_per_tick: float = 0.04
    pan_gain: float = 1.0

    def __post_init__(self) -> None:
        self.camera_range()  # validates the range fields
        check_range(self.deg_per_pixel, "deg_per_pixel", 0.0, 10.0)
        check_range(self.dolly_per_tick, "dolly_per_tick", 0.0, 1.0)
        check_range(self.pan_gain, "pan_gain", 0.0, 100.0)

    def camera_range(self) -> CameraRange:
        """The range part of these limits."""
        return CameraRange(self.max_yaw_deg, self.max_pitch_deg, self.max_pan, self.min_dolly,
                           self.max_dolly, self.near_margin)

    @staticmethod
    def from_range(rng: CameraRange, *, relative: bool = True, **speeds: float) -> "OrbitLimits":
        """Limits of the range ``rng`` (e.g. a photo's ``Photo3D.camera_range``); ``speeds`` may set
        ``deg_per_pixel``, ``dolly_per_tick`` and ``pan_gain`` (default: the class defaults).

        ``relative`` (default): the speeds are those of the default range (``CameraRange()``) and are
        scaled by ``rng``'s size against it (yaw, dolly and pan each by its own limit), so the same drag
        or wheel steps cross the same share of any photo's range: 200 px of drag from the input view to
        the yaw limit, 15 wheel steps to the forward limit, at the default speeds. A photo's range is
        often a small part of the default one (0.06-0.25 of it on the bundled samples): at fixed speeds
        12-50 px of drag reached its limit, and the rest of a drag changed nothing. ``relative=False``
        keeps the speeds as given."""
        if relative:
            base = OrbitLimits(**speeds)
            speeds = dict(deg_per_pixel=base.deg_per_pixel * _ratio(rng.max_yaw_deg, _RANGE.max_yaw_deg),
                          dolly_per_tick=base.dolly_per_tick * _ratio(rng.max_dolly, _RANGE.max_dolly),
                          pan_gain=base.pan_gain * _ratio(rng.max_pan, _RANGE.max_pan))
        return OrbitLimits(rng.max_yaw_deg, rng.max_pitch_deg, rng.max_pan, rng.min_dolly,
                           rng.max_dolly, rng.near_margin, **speeds)


def _ratio(value: float, default: float) -> float:
    """``value / default`` (0 where the default range has no extent)."""
    return float(value) / float(default) if default > 0 else 0.0


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


def cam_to_world(pose: OrbitPose, scene: OrbitScene) -> np.ndarray:
    """The (4, 4) float64 ``cam_to_world`` of ``pose`` (see the module docstring)."""
    return orbit_cam_to_world(pose.yaw_deg, pose.pitch_deg, pose.pan_x, pose.pan_y, pose.dolly, scene.centre_depth)


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
    dz = clamp_dolly(yaw, pitch, px, py, pose.dolly, scene.centre_depth, scene.near_depth, limits.camera_range())
    return OrbitPose(yaw, pitch, px, py, dz)


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
    camera ``limits.pan_gain`` times as far as keeps the centre plane under the cursor
    (``centre_depth / f`` scene units per pixel, ``f`` the focal length in pixels).
    """
    if mode == "orbit":
        k = limits.deg_per_pixel
        return orbit(pose, k * dx_px, -k * dy_px, scene, limits)
    if mode == "pan":
        if view_height_px <= 0:
            raise InputError("view_height_px", f"must be > 0, got {view_height_px!r}")
        f = 0.5 * view_height_px / math.tan(math.radians(check_fov(fov_y_deg)) / 2.0)
        s = limits.pan_gain * scene.centre_depth / f
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
