"""Keyframe camera paths (stylize3d_core/geometry/keyframes.py): through the keyframes, smooth, timed."""

from __future__ import annotations

import numpy as np
import pytest

from stylize3d_core.errors import InputError
from stylize3d_core.geometry.keyframes import (
    Keyframe, KeyframePath, interpolate_keyframes, keyframe_times, quaternion_to_rotation, rotation_to_quaternion,
)


def pose(yaw_deg: float, pitch_deg: float, t) -> np.ndarray:
    a, b = np.radians(yaw_deg), np.radians(pitch_deg)
    Ry = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    Rx = np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
    m = np.eye(4)
    m[:3, :3] = Ry @ Rx
    m[:3, 3] = t
    return m


def three_keyframes(loop: bool = False) -> KeyframePath:
    return KeyframePath((Keyframe(pose(0, 0, [0, 0, 0]), 60.0), Keyframe(pose(10, -4, [0.05, 0.01, 0.1]), 50.0),
                         Keyframe(pose(-6, 3, [-0.04, 0.0, 0.2]), 70.0)), (1.0, 2.0, 1.5), loop)


def test_quaternion_round_trip():
    for yaw, pitch in ((0, 0), (170, 20), (-90, 45), (180, 0)):
        R = pose(yaw, pitch, [0, 0, 0])[:3, :3]
        assert np.allclose(quaternion_to_rotation(rotation_to_quaternion(R)), R, atol=1e-12)


def test_three_keyframes_pass_through_each_keyframe_and_are_smooth():
    kp = three_keyframes()
    fps = 30.0
    cams = interpolate_keyframes(kp, fps)
    assert len(cams) == round(3.0 * fps) + 1 and kp.duration_s == 3.0
    c2w, fov = cams.cam_to_world.numpy(), cams.fov_y_deg.numpy()
    for k, t in zip(kp.keyframes, keyframe_times(kp)):
        i = int(round(t * fps))
        assert np.allclose(c2w[i], k.cam_to_world, atol=1e-9), f"frame {i} is not keyframe at {t} s"
        assert fov[i] == pytest.approx(k.fov_y_deg, abs=1e-9)
    for j in range(len(cams)):  # every frame is a rigid pose
        R = c2w[j, :3, :3]
        assert np.allclose(R.T @ R, np.eye(3), atol=1e-9) and np.linalg.det(R) == pytest.approx(1.0)
    # Smooth: second differences are small and of the order of a spline's (no jumps, no kinks).
    pos = c2w[:, :3, 3]
    d1 = np.linalg.norm(np.diff(pos, axis=0), axis=1)
    d2 = np.linalg.norm(np.diff(pos, 2, axis=0), axis=1)
    assert d2.max() < 0.1 * d1.max() and d2.max() < 2e-3
    rot_d2 = np.abs(np.diff(c2w[:, :3, :3], 2, axis=0)).max()
    assert rot_d2 < 2e-3
    assert np.abs(np.diff(fov, 2)).max() < 0.2
    assert fov.min() >= 50.0 and fov.max() <= 70.0


def test_loop_returns_smoothly_to_the_first_keyframe():
    kp = three_keyframes(loop=True)
    cams = interpolate_keyframes(kp, 20.0)
    assert len(cams) == round(4.5 * 20)
    pos = cams.cam_to_world.numpy()[:, :3, 3]
    wrapped = np.concatenate([pos[-2:], pos[:2]])  # across the end of the loop
    d2 = np.linalg.norm(np.diff(wrapped, 2, axis=0), axis=1)
    assert d2.max() < 2e-3


def test_uneven_timing_and_bad_input():
    one = KeyframePath((Keyframe(np.eye(4), 60.0),), (1.0,))
    assert len(interpolate_keyframes(one, 30)) == 1
    with pytest.raises(InputError, match="durations"):
        KeyframePath((Keyframe(np.eye(4), 60.0),), (1.0, 2.0))
    with pytest.raises(InputError, match="duration"):
        KeyframePath((Keyframe(np.eye(4), 60.0), Keyframe(np.eye(4), 60.0)), (0.0, 1.0))
    with pytest.raises(InputError, match="rigid"):
        Keyframe(np.diag([2.0, 1, 1, 1]), 60.0)
    with pytest.raises(InputError):
        Keyframe(np.eye(4), 500.0)
    with pytest.raises(InputError, match="frames"):
        interpolate_keyframes(KeyframePath(three_keyframes().keyframes, (600, 600, 1)), 1000)
