"""The library's camera range (geometry/camera_range.py): corners, clamping, parallax and border overshoot."""

from __future__ import annotations

import math

import numpy as np
import pytest

from stylize3d_core.errors import InputError
from stylize3d_core.geometry.camera import NEAR_DEPTH, focal_from_fov
from stylize3d_core.geometry.camera_range import (
    CameraRange, border_overshoot, clamp_dolly, edge_parallax, orbit_cam_to_world, range_corner_poses,
    trajectory_extreme_cameras,
)
from stylize3d_core.geometry.trajectories import DEFAULT_XY, DEFAULT_Z


def test_corners_reach_the_limits_and_respect_the_near_margin():
    rng = CameraRange()
    centre = 1.2
    poses = range_corner_poses(rng, centre, NEAR_DEPTH)
    assert poses.shape == (18, 4, 4)
    z_max = (1 - rng.near_margin) * NEAR_DEPTH
    assert (poses[:, 2, 3] <= z_max + 1e-9).all()
    # the right corner combines full yaw and full pan: x = pan cos(yaw) + centre sin(yaw)
    straight = orbit_cam_to_world(-rng.max_yaw_deg, 0, rng.max_pan, 0, 0.0, centre)
    a = math.radians(rng.max_yaw_deg)
    assert straight[0, 3] == pytest.approx(rng.max_pan * math.cos(a) + centre * math.sin(a))
    assert np.abs(poses[:, 0, 3]).max() >= rng.max_pan
    for T in poses:
        np.testing.assert_allclose(T[:3, :3].T @ T[:3, :3], np.eye(3), atol=1e-12)


def test_scaled_range_and_clamp_dolly():
    rng = CameraRange().scaled(0.5)
    assert rng.max_yaw_deg == 4.0 and rng.max_pan == 0.05 and rng.min_dolly == -0.15 and rng.near_margin == 0.5
    assert CameraRange().scaled(0.0).max_dolly == 0.0
    with pytest.raises(InputError):
        CameraRange().scaled(1.5)
    # forward as far as the range allows, but never past the margin in front of the near surface
    assert clamp_dolly(0, 0, 0, 0, 10.0, 1.0, NEAR_DEPTH, CameraRange()) == pytest.approx(0.5 * NEAR_DEPTH)
    assert clamp_dolly(0, 0, 0, 0, -10.0, 1.0, NEAR_DEPTH, CameraRange()) == pytest.approx(-0.3)
    assert clamp_dolly(0, 0, 0, 0, 0.01, 1.0, NEAR_DEPTH, CameraRange()) == 0.01


def test_edge_parallax_of_a_sideways_move_is_baseline_times_focal_times_inverse_depth_gap():
    size, fov, b = (120, 160), 60.0, 0.03
    f = focal_from_fov(fov, size[0])
    T = np.eye(4)
    T[0, 3] = b
    uv = np.array([[80.0, 60.0], [10.0, 100.0]])
    zf, zb = np.array([1 / 3, 0.5]), np.array([1.0, 2.0])
    got = edge_parallax(uv, zf, zb, T[None], np.array([fov]), size, fov)
    np.testing.assert_allclose(got, b * f * np.abs(1 / zf - 1 / zb), rtol=1e-9)
    assert edge_parallax(uv, zf, zb, np.zeros((0, 4, 4)), np.zeros(0), size, fov).tolist() == [0.0, 0.0]


def test_border_overshoot_of_a_sideways_move():
    size, fov, b, z = (120, 160), 60.0, 0.02, 0.5
    f = focal_from_fov(fov, size[0])
    T = np.eye(4)
    T[0, 3] = b
    sides = tuple(np.array([z]) for _ in range(4))
    assert border_overshoot(sides, T[None], np.array([fov]), size, fov) == pytest.approx(b * f / z)
    assert border_overshoot(sides, np.eye(4)[None], np.array([fov]), size, fov) == pytest.approx(0.0, abs=1e-9)
    # a wider FOV sees beyond every side
    assert border_overshoot(sides, np.eye(4)[None], np.array([70.0]), size, fov) > 1.0


def test_trajectory_extremes_span_the_default_box_and_the_dolly_zoom():
    poses, fovs = trajectory_extreme_cameras(60.0)
    assert poses.shape == (9, 4, 4) and fovs.shape == (9,)
    assert np.abs(poses[:, 0, 3]).max() == DEFAULT_XY and poses[:, 2, 3].max() == max(DEFAULT_Z)
    assert fovs.max() > 60.0 and fovs.min() == 60.0
