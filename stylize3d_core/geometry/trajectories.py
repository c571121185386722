"""Camera trajectories for novel-view videos: pure functions returning a :class:`Cameras` batch.

Conventions are those of :mod:`stylize3d_core.geometry.camera`: poses are
``cam_to_world``, the world frame is the input photo's camera (+z forward, x
right, y down), and the scene is normalised so its near depth is
:data:`~stylize3d_core.geometry.camera.NEAR_DEPTH` = 1/3, so an amplitude of
0.02 is 6 % of the near depth in every scene.

As in the paper's public code, a trajectory moves the camera **position** over
time and keeps the identity rotation: the camera always looks along +z. Writing
a video from the cameras is a separate step (:mod:`stylize3d_core.io.video`).

Range arguments (``x``, ``y``, ``z`` of :func:`ken_burns`, ``z`` everywhere) are
``(start, end)`` pairs; a single number ``a`` means ``(-a, a)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Dict, Literal, Tuple, Union, get_args

import numpy as np
import torch

from ..checks import check_choice
from ..errors import InputError
from .camera import DEFAULT_FOV_Y_DEG, MAX_FOV_DEG, MIN_FOV_DEG, NEAR_DEPTH, Cameras, check_fov

Range = Union[float, Tuple[float, float]]

DEFAULT_N_FRAMES = 90
"""Frames per trajectory in the public code (3 s at 30 fps)."""

DEFAULT_XY = 0.02
"""Sideways / vertical amplitude in the public code (scene units, near depth = 1/3)."""

DEFAULT_Z = (0.0, 0.05)
"""Forward motion in the public code: from the photo's camera to 0.05 forward."""

SUBJECT_MARGIN = 1e-3
"""Closest a dolly-zoom camera may come to its subject plane (scene units)."""


def _check_n_frames(n_frames: int) -> int:
    if isinstance(n_frames, bool) or not isinstance(n_frames, (int, np.integer)) or n_frames < 1:
        raise InputError("n_frames", f"must be an integer >= 1, got {n_frames!r}")
    return int(n_frames)


def _finite(value: float, name: str) -> float:
    v = float(value)
    if not math.isfinite(v):
        raise InputError(name, f"must be finite, got {value!r}")
    return v


def _as_range(value: Range, name: str) -> Tuple[float, float]:
    """``(start, end)`` from a pair, or ``(-a, a)`` from a single number ``a``."""
    if isinstance(value, (int, float, np.floating, np.integer)):
        a = _finite(value, name)
        return (-a, a)
    pair = tuple(value)
    if len(pair) != 2:
        raise InputError(name, f"must be a number or a (start, end) pair, got {value!r}")
    return (_finite(pair[0], name), _finite(pair[1], name))


def _as_amplitude(value: Range, name: str) -> float:
    if not isinstance(value, (int, float, np.floating, np.integer)):
        raise InputError(name, f"must be a single amplitude for this trajectory, got {value!r}")
    return _finite(value, name)


def _cameras(positions: np.ndarray, fov_y_deg: Union[float, np.ndarray]) -> Cameras:
    """Cameras at ``positions`` (B, 3) with the identity rotation and FOV(s) in degrees."""
    n = positions.shape[0]
    c2w = np.tile(np.eye(4), (n, 1, 1))  # (B, 4, 4)
    c2w[:, :3, 3] = positions
    fov = np.broadcast_to(np.asarray(fov_y_deg, dtype=np.float64), (n,)).copy()  # (B,)
    return Cameras(torch.from_numpy(c2w), torch.from_numpy(fov))


def _lerp(rng: Tuple[float, float], n: int) -> np.ndarray:
    return np.linspace(rng[0], rng[1], n)  # (B,)


def circle(
    n_frames: int = DEFAULT_N_FRAMES,
    x: float = DEFAULT_XY,
    y: float = DEFAULT_XY,
    z: Range = DEFAULT_Z,
    fov_y_deg: float = DEFAULT_FOV_Y_DEG,
) -> Cameras:
    """Two loops of an ellipse in x/y while moving forward and back once in z.

    With ``t = linspace(-2, 2, n_frames)``: ``x(t) = cos(pi t) * x``,
    ``y(t) = sin(pi t) * y``, ``z(t) = (cos(pi t / 2) + 1) / 2 * (z1 - z0) + z0``
    (``z0`` at both ends, ``z1`` in the middle).

    Returns:
        ``n_frames`` cameras, identity rotation, constant FOV.
    """
    n = _check_n_frames(n_frames)
    ax, ay = _as_amplitude(x, "x"), _as_amplitude(y, "y")
    z0, z1 = _as_range(z, "z")
    fov = check_fov(fov_y_deg, "fov_y_deg")
    t = np.linspace(-2.0, 2.0, n)  # (B,)
    pos = np.stack(
        [np.cos(np.pi * t) * ax, np.sin(np.pi * t) * ay, (np.cos(np.pi * t / 2) + 1) / 2 * (z1 - z0) + z0], axis=-1
    )  # (B, 3)
    return _cameras(pos, fov)


def swing(
    n_frames: int = DEFAULT_N_FRAMES,
    x: float = DEFAULT_XY,
    z: Range = DEFAULT_Z,
    fov_y_deg: float = DEFAULT_FOV_Y_DEG,
) -> Cameras:
    """:func:`circle` with no vertical motion: the camera swings left-right twice."""
    return circle(n_frames, x=x, y=0.0, z=z, fov_y_deg=fov_y_deg)


def ken_burns(
    n_frames: int = DEFAULT_N_FRAMES,
    x: Range = DEFAULT_XY,
    y: Range = DEFAULT_XY,
    z: Range = DEFAULT_Z,
    fov_y_deg: float = DEFAULT_FOV_Y_DEG,
) -> Cameras:
    """A straight line from ``(x0, y0, z0)`` to ``(x1, y1, z1)`` at constant speed.

    The defaults go from (-0.02, -0.02, 0) to (0.02, 0.02, 0.05).
    """
    n = _check_n_frames(n_frames)
    rx, ry, rz = _as_range(x, "x"), _as_range(y, "y"), _as_range(z, "z")
    fov = check_fov(fov_y_deg, "fov_y_deg")
    pos = np.stack([_lerp(rx, n), _lerp(ry, n), _lerp(rz, n)], axis=-1)  # (B, 3)
    return _cameras(pos, fov)


def zoom(n_frames: int = DEFAULT_N_FRAMES, z: Range = DEFAULT_Z, fov_y_deg: float = DEFAULT_FOV_Y_DEG) -> Cameras:
    """Straight forward along +z: :func:`ken_burns` with ``x = y = 0``."""
    return ken_burns(n_frames, x=(0.0, 0.0), y=(0.0, 0.0), z=z, fov_y_deg=fov_y_deg)


def dolly_zoom_fov(fov_y_deg: float, subject_depth: float, dz: np.ndarray) -> np.ndarray:
    """FOV (degrees) that keeps a plane at ``subject_depth`` the same size after moving ``dz`` forward.

    The plane's visible half-height is ``tan(fov / 2) * d``; from ``dz`` closer it
    lies at distance ``d - dz``, so ``fov' = 2 atan(tan(fov / 2) * d / (d - dz))``.

    Args:
        fov_y_deg: FOV at ``dz = 0``.
        subject_depth: ``d`` > 0, depth of the subject plane in the world frame.
        dz: (B,) forward offsets of the camera, each ``< d``.
    Returns:
        (B,) FOVs in degrees.
    """
    half = math.tan(math.radians(fov_y_deg) / 2.0)
    fov = np.degrees(2.0 * np.arctan(half * subject_depth / (subject_depth - dz)))  # (B,)
    return np.where(dz == 0, fov_y_deg, fov)  # exact where the camera has not moved


def dolly_zoom(
    n_frames: int = DEFAULT_N_FRAMES,
    z: Range = DEFAULT_Z,
    fov_y_deg: float = DEFAULT_FOV_Y_DEG,
    subject_depth: float = NEAR_DEPTH,
) -> Cameras:
    """Move along +z as :func:`zoom` while the FOV changes so the subject keeps its size.

    The subject is the plane at depth ``subject_depth`` (default: the scene's
    near depth, i.e. the foreground); moving forward widens the FOV, so the
    background appears to recede while the subject stays put.

    Raises:
        InputError: if a camera reaches the subject plane (``d - dz <= SUBJECT_MARGIN``)
            or a FOV leaves ``[MIN_FOV_DEG, MAX_FOV_DEG]``.
    """
    n = _check_n_frames(n_frames)
    rz = _as_range(z, "z")
    fov = check_fov(fov_y_deg, "fov_y_deg")
    d = _finite(subject_depth, "subject_depth")
    if d <= SUBJECT_MARGIN:
        raise InputError("subject_depth", f"must be > {SUBJECT_MARGIN} (in front of the camera), got {subject_depth!r}")
    dz = _lerp(rz, n)  # (B,)
    closest = d - float(dz.max())
    if closest <= SUBJECT_MARGIN:
        raise InputError(
            "z",
            f"the camera moves to z = {float(dz.max()):g}, reaching the subject plane at depth {d:g}; "
            f"keep z below {d - SUBJECT_MARGIN:g} or move the subject farther",
        )
    fovs = dolly_zoom_fov(fov, d, dz)  # (B,)
    lo, hi = float(fovs.min()), float(fovs.max())
    if lo < MIN_FOV_DEG or hi > MAX_FOV_DEG:
        raise InputError(
            "dolly_zoom",
            f"the field of view would range over [{lo:.3g}, {hi:.3g}] degrees, outside the allowed "
            f"[{MIN_FOV_DEG:g}, {MAX_FOV_DEG:g}]; use a smaller z range or a farther subject",
        )
    pos = np.stack([np.zeros(n), np.zeros(n), dz], axis=-1)  # (B, 3)
    return _cameras(pos, fovs)


def static(n_frames: int = DEFAULT_N_FRAMES, fov_y_deg: float = DEFAULT_FOV_Y_DEG) -> Cameras:
    """The photo's own camera, repeated ``n_frames`` times."""
    n = _check_n_frames(n_frames)
    return _cameras(np.zeros((n, 3)), check_fov(fov_y_deg, "fov_y_deg"))


TrajectoryName = Literal["circle", "swing", "ken_burns", "zoom", "dolly_zoom", "static"]

TRAJECTORIES: Dict[str, Callable[..., Cameras]] = {
    "circle": circle,
    "swing": swing,
    "ken_burns": ken_burns,
    "zoom": zoom,
    "dolly_zoom": dolly_zoom,
    "static": static,
}
"""Every trajectory by name (the names of :data:`TrajectoryName`)."""


@dataclass(frozen=True)
class TrajectorySettings:
    """Which trajectory to make and its parameters; each field applies where the trajectory uses it.

    Attributes:
        name: one of :data:`TrajectoryName`. Default ``"circle"`` (the paper's demo videos).
        n_frames: number of cameras, >= 1. Default 90 (3 s at 30 fps, as the public code).
        x: sideways amplitude (circle, swing) or ``(start, end)`` range (ken_burns;
            a number ``a`` means ``(-a, a)``). Default 0.02 (public code).
        y: vertical amplitude (circle) or range (ken_burns). Default 0.02 (public code).
        z: forward ``(start, end)`` range for every moving trajectory. Default
            ``(0.0, 0.05)`` (public code).
        fov_y_deg: vertical FOV in degrees (dolly_zoom: the FOV at ``z = 0``). Default 60.
        subject_depth: depth of the plane a dolly zoom keeps at constant size.
            Default :data:`NEAR_DEPTH` = 1/3, the normalised foreground depth.
    """

    name: TrajectoryName = "circle"
    n_frames: int = DEFAULT_N_FRAMES
    x: Range = DEFAULT_XY
    y: Range = DEFAULT_XY
    z: Range = DEFAULT_Z
    fov_y_deg: float = DEFAULT_FOV_Y_DEG
    subject_depth: float = NEAR_DEPTH


def make_trajectory(settings: TrajectorySettings) -> Cameras:
    """The cameras of the trajectory ``settings`` describes."""
    name = check_choice(settings.name, "trajectory", get_args(TrajectoryName))
    s = settings
    if name == "circle":
        return circle(s.n_frames, x=s.x, y=s.y, z=s.z, fov_y_deg=s.fov_y_deg)
    if name == "swing":
        return swing(s.n_frames, x=s.x, z=s.z, fov_y_deg=s.fov_y_deg)
    if name == "ken_burns":
        return ken_burns(s.n_frames, x=s.x, y=s.y, z=s.z, fov_y_deg=s.fov_y_deg)
    if name == "zoom":
        return zoom(s.n_frames, z=s.z, fov_y_deg=s.fov_y_deg)
    if name == "dolly_zoom":
        return dolly_zoom(s.n_frames, z=s.z, fov_y_deg=s.fov_y_deg, subject_depth=s.subject_depth)
    return static(s.n_frames, fov_y_deg=s.fov_y_deg)
