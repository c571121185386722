"""Keyframe camera paths: a few cameras and the time between them, interpolated smoothly (pure math).

A :class:`KeyframePath` holds keyframes (pose ``cam_to_world`` and vertical FOV,
conventions of :mod:`stylize3d_core.geometry.camera`) and the seconds from each
keyframe to the next; :func:`interpolate_keyframes` samples it at ``fps`` into
:class:`~stylize3d_core.geometry.camera.Cameras`, as the keyframe editors of
nerfstudio and nerfview do:

* positions and FOVs: a non-uniform Catmull-Rom spline (Barry-Goldman form)
  with the keyframes' times as knots, so it passes through every keyframe, is
  C1 and does not overshoot on uneven timing as a uniform spline does;
* orientations: the same spline on unit quaternions (signs aligned to the
  previous keyframe, the shorter way round), renormalised: through every
  keyframe's orientation and smooth;
* ends: an open path reflects its end keyframes (phantom knots); a loop wraps
  around and the last keyframe leads back to the first in ``durations_s[-1]``.

An open path of K keyframes lasts ``sum(durations_s[:K-1])`` and has
``round(duration * fps) + 1`` frames (the first and last are the end
keyframes); a loop lasts ``sum(durations_s)`` and has ``round(duration * fps)``
frames (the first keyframe is not repeated at the end).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence, Tuple

import numpy as np

from ..checks import check_range
from ..errors import InputError
from .camera import Cameras, check_fov

MAX_KEYFRAME_FRAMES = 100_000
"""Most frames :func:`interpolate_keyframes` makes (a guard against a typo in a duration or the fps)."""


@dataclass(frozen=True)
class Keyframe:
    """One keyframe: ``cam_to_world`` (4, 4) float64 and the vertical FOV in degrees."""

    cam_to_world: np.ndarray
    fov_y_deg: float

    def __post_init__(self) -> None:
        m = np.asarray(self.cam_to_world, dtype=np.float64)
        if m.shape != (4, 4) or not np.isfinite(m).all():
            raise InputError("keyframe", f"cam_to_world must be a finite 4x4 matrix, got shape {m.shape}")
        R = m[:3, :3]
        if np.abs(R.T @ R - np.eye(3)).max() > 1e-5 or abs(np.linalg.det(R) - 1.0) > 1e-5:
            raise InputError("keyframe", "cam_to_world must be a rigid pose (a rotation and a translation)")
        object.__setattr__(self, "cam_to_world", m)
        object.__setattr__(self, "fov_y_deg", check_fov(float(self.fov_y_deg), "keyframe fov"))


@dataclass(frozen=True)
class KeyframePath:
    """Keyframes, the seconds from each to the next, and whether the path loops.

    Attributes:
        keyframes: at least one :class:`Keyframe`.
        durations_s: one per keyframe, each in (0, 600] seconds: the time from keyframe i to i+1
            (for a loop, the last one leads back to the first; for an open path it is kept for when
            a keyframe is added after it).
        loop: the path returns to its first keyframe.
    """

    keyframes: Tuple[Keyframe, ...]
    durations_s: Tuple[float, ...]
    loop: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "keyframes", tuple(self.keyframes))
        object.__setattr__(self, "durations_s", tuple(float(d) for d in self.durations_s))
        if len(self.keyframes) < 1:
            raise InputError("keyframes", "a path needs at least one keyframe")
        if len(self.durations_s) != len(self.keyframes):
            raise InputError("keyframes", f"{len(self.keyframes)} keyframes need {len(self.keyframes)} durations, "
                             f"got {len(self.durations_s)}")
        for d in self.durations_s:
            check_range(d, "keyframe duration (s)", 1e-3, 600.0)

    @property
    def duration_s(self) -> float:
        """Length of the path in seconds."""
        d = self.durations_s if self.loop else self.durations_s[:-1]
        return float(sum(d))


def rotation_to_quaternion(R: np.ndarray) -> np.ndarray:
    """(3, 3) rotation -> unit quaternion (w, x, y, z), w >= 0."""
    R = np.asarray(R, dtype=np.float64)
    t = np.trace(R)
    if t > 0:
        s = 2.0 * np.sqrt(t + 1.0)
        q = np.array([0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s])
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(max(1e-300, 1.0 + R[i, i] - R[j, j] - R[k, k]))
        q = np.empty(4)
        q[0] = (R[k, j] - R[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (R[j, i] + R[i, j]) / s
        q[1 + k] = (R[k, i] + R[i, k]) / s
    q /= np.linalg.norm(q)
    return q if q[0] >= 0 else -q


def quaternion_to_rotation(q: np.ndarray) -> np.ndarray:
    """Quaternion (w, x, y, z) (normalised here) -> (3, 3) rotation."""
    w, x, y, z = np.asarray(q, dtype=np.float64) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def _catmull_rom(p: np.ndarray, knots: np.ndarray, t: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """Barry-Goldman non-uniform Catmull-Rom: control values ``p`` (C, D) at ``knots`` (C,) (see
    :func:`_controls`), evaluated at times ``t`` (T,) in segments ``seg`` (T,); segment s runs from
    control s+1 to control s+2."""
    i = seg + 1
    t0, t1, t2, t3 = knots[i - 1], knots[i], knots[i + 1], knots[i + 2]
    p0, p1, p2, p3 = p[i - 1], p[i], p[i + 1], p[i + 2]

    def lerp(a, b, ta, tb):
        w = ((t - ta) / (tb - ta))[:, None]
        return a + w * (b - a)

    a1 = lerp(p0, p1, t0, t1)
    a2 = lerp(p1, p2, t1, t2)
    a3 = lerp(p2, p3, t2, t3)
    b1 = lerp(a1, a2, t0, t2)
    b2 = lerp(a2, a3, t1, t3)
    return lerp(b1, b2, t1, t2)


def _controls(values: np.ndarray, times: np.ndarray, loop: bool, period: float) -> Tuple[np.ndarray, np.ndarray]:
    """Control values and knots with one phantom before and two after the K keyframes (+ the loop's return)."""
    if loop:
        v = np.concatenate([values[-1:], values, values[:2]])
        k = np.concatenate([times[-1:] - period, times, times[:2] + period])
        return v, k
    if len(values) == 1:
        return np.repeat(values, 4, axis=0), np.array([times[0] - 1, times[0], times[0] + 1, times[0] + 2])
    first = 2 * values[0] - values[1]
    last = 2 * values[-1] - values[-2]
    v = np.concatenate([first[None], values, last[None], last[None]])
    k = np.concatenate([[2 * times[0] - times[1]], times, [2 * times[-1] - times[-2]], [3 * times[-1] - 2 * times[-2]]])
    return v, k


def keyframe_times(path: KeyframePath) -> np.ndarray:
    """Time (s) of each keyframe from the start of the path."""
    return np.concatenate([[0.0], np.cumsum(path.durations_s[:-1])])


def interpolate_keyframes(path: KeyframePath, fps: float) -> Cameras:
    """Sample ``path`` at ``fps`` frames per second into cameras (see the module docstring)."""
    check_range(fps, "fps", 1e-3, 1000.0)
    K = len(path.keyframes)
    period = path.duration_s
    n = int(round(period * fps)) + (0 if path.loop else 1)
    if K == 1 or period <= 0:
        n = 1
    if n > MAX_KEYFRAME_FRAMES:
        raise InputError("keyframes", f"{period:g} s at {fps:g} fps is {n} frames, more than {MAX_KEYFRAME_FRAMES}")
    mats = np.stack([k.cam_to_world for k in path.keyframes])  # (K, 4, 4)
    fovs = np.array([k.fov_y_deg for k in path.keyframes])
    if n == 1:
        return Cameras.create(mats[:1], fovs[:1])
    times = keyframe_times(path)  # (K,)
    quats = np.stack([rotation_to_quaternion(m[:3, :3]) for m in mats])
    for i in range(1, K):  # the shorter way round
        if np.dot(quats[i], quats[i - 1]) < 0:
            quats[i] = -quats[i]
    values = np.concatenate([mats[:, :3, 3], fovs[:, None], quats], axis=1)  # (K, 8)
    ctrl, knots = _controls(values, times, path.loop, period)
    if path.loop:  # align the wrapped quaternions with their neighbours
        for i in range(1, len(ctrl)):
            if np.dot(ctrl[i, 4:], ctrl[i - 1, 4:]) < 0:
                ctrl[i, 4:] = -ctrl[i, 4:]
    t = np.arange(n, dtype=np.float64) / float(fps)
    if not path.loop:
        t[-1] = times[-1]  # exactly the last keyframe, whatever the rounding of n
    n_seg = K if path.loop else K - 1
    seg_starts = np.concatenate([times, [period]]) if path.loop else times
    seg = np.clip(np.searchsorted(seg_starts, t, side="right") - 1, 0, n_seg - 1)
    out = _catmull_rom(ctrl, knots, t, seg)  # (n, 8)
    c2w = np.tile(np.eye(4), (n, 1, 1))
    c2w[:, :3, 3] = out[:, :3]
    for j in range(n):
        c2w[j, :3, :3] = quaternion_to_rotation(out[j, 4:])
    fov = np.clip(out[:, 3], min(fovs), max(fovs))  # a spline of FOVs may overshoot a little: keep it in range
    return Cameras.create(c2w, fov)


def keyframes_from_cameras(cameras: Cameras, durations_s: Sequence[float], loop: bool = False) -> KeyframePath:
    """A :class:`KeyframePath` with one keyframe per camera of ``cameras``."""
    c2w = cameras.cam_to_world.detach().double().cpu().numpy()
    fov = cameras.fov_y_deg.detach().double().cpu().numpy()
    return KeyframePath(tuple(Keyframe(m, float(f)) for m, f in zip(c2w, fov)), tuple(durations_s), loop)


def keyframes_to_cameras(path: KeyframePath) -> Cameras:
    """The keyframes themselves as cameras (one per keyframe)."""
    return Cameras.create(np.stack([k.cam_to_world for k in path.keyframes]),
                          np.array([k.fov_y_deg for k in path.keyframes]))


__all__ = [
    "Keyframe", "KeyframePath", "interpolate_keyframes", "keyframe_times", "keyframes_from_cameras",
    "keyframes_to_cameras", "rotation_to_quaternion", "quaternion_to_rotation", "MAX_KEYFRAME_FRAMES",
]
