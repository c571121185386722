"""Camera control math of the viewer (app/viewer/orbit.py): known values, limits, round trips, bad input."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from stylize3d_app.viewer.orbit import (
    HOME, OrbitLimits, OrbitPose, OrbitScene, apply_drag, apply_wheel, cam_to_world, camera_z, clamp_pose,
    dolly, dolly_range, orbit, pan, pose_camera, relative_to, rotation,
)
from stylize3d_core.errors import InputError
from stylize3d_core.geometry.camera import NEAR_DEPTH, Cameras, project, transform_points
from stylize3d_core.geometry.trajectories import circle, static

SCENE = OrbitScene(centre_depth=0.6, near_depth=NEAR_DEPTH)
LIMITS = OrbitLimits()


def project_world(point: np.ndarray, cams: Cameras, hw=(400, 600)) -> np.ndarray:
    """Pixel (u, v) of a world point seen by the single camera ``cams``."""
    p = transform_points(cams.world_to_cam()[0], torch.tensor(point, dtype=torch.float64)[None])
    uv, _ = project(p, cams.intrinsics(*hw, dtype=torch.float64)[0])
    return uv[0].numpy()


def test_home_pose_is_the_input_camera():
    np.testing.assert_allclose(cam_to_world(HOME, SCENE), np.eye(4), atol=1e-12)
    cams = pose_camera(HOME, SCENE, 55.0)
    assert len(cams) == 1 and float(cams.fov_y_deg[0]) == 55.0


def test_rotation_is_orthonormal_known_values():
    R = rotation(90.0, 0.0)
    np.testing.assert_allclose(R @ np.array([0, 0, 1.0]), [1, 0, 0], atol=1e-12)  # +z turns to +x
    R = rotation(0.0, 90.0)
    np.testing.assert_allclose(R @ np.array([0, 0, 1.0]), [0, -1, 0], atol=1e-12)  # +z turns to -y (up)
    rng = np.random.default_rng(0)
    for yaw, pitch in rng.uniform(-40, 40, size=(20, 2)):
        R = rotation(yaw, pitch)
        np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0)


def test_orbit_turns_about_the_centre_and_keeps_looking_at_it():
    pose = orbit(HOME, 8.0, -5.0, SCENE)
    T = cam_to_world(pose, SCENE)
    centre = np.array([0, 0, SCENE.centre_depth])
    assert np.linalg.norm(T[:3, 3] - centre) == pytest.approx(SCENE.centre_depth)  # same distance
    # The optical axis still passes through the centre: it projects to the image centre.
    np.testing.assert_allclose(project_world(centre, pose_camera(pose, SCENE, 60.0)), [300, 200], atol=1e-9)
    # Positive yaw swings the camera to the left (-x), negative pitch lifts it (-y).
    assert T[0, 3] < 0 and T[1, 3] < 0


def test_drag_signs_grab_the_scene():
    # Dragging right: the scene turns right, so a point nearer than the centre moves right on screen.
    near_pt = np.array([0.0, 0.0, 0.4])
    before = project_world(near_pt, pose_camera(HOME, SCENE, 60.0))
    pose = apply_drag(HOME, "orbit", 40, 0, 400, 60.0, SCENE)
    assert pose.yaw_deg == pytest.approx(40 * LIMITS.deg_per_pixel)
    after = project_world(near_pt, pose_camera(pose, SCENE, 60.0))
    assert after[0] > before[0]
    pose = apply_drag(HOME, "orbit", 0, 40, 400, 60.0, SCENE)
    assert pose.pitch_deg == pytest.approx(-40 * LIMITS.deg_per_pixel)
    assert project_world(near_pt, pose_camera(pose, SCENE, 60.0))[1] > before[1]


def test_pan_moves_the_centre_plane_with_the_cursor():
    H, W = 400, 600
    centre = np.array([0.0, 0.0, SCENE.centre_depth])
    pose = apply_drag(HOME, "pan", 12, -7, H, 60.0, SCENE)
    uv = project_world(centre, pose_camera(pose, SCENE, 60.0), (H, W))
    np.testing.assert_allclose(uv, [W / 2 + 12, H / 2 - 7], atol=1e-9)


def test_limits_clamp_every_component():
    big = OrbitPose(yaw_deg=100, pitch_deg=-100, pan_x=5, pan_y=-5, dolly=-10)
    c = clamp_pose(big, SCENE, LIMITS)
    lo, hi = dolly_range(SCENE, LIMITS)
    assert (c.yaw_deg, c.pitch_deg, c.pan_x, c.pan_y) == (LIMITS.max_yaw_deg, -LIMITS.max_pitch_deg,
                                                          LIMITS.max_pan, -LIMITS.max_pan)
    assert c.dolly == pytest.approx(lo) and lo == pytest.approx(LIMITS.min_dolly * SCENE.centre_depth)
    inside = OrbitPose(2.0, -1.0, 0.01, 0.02, 0.03)
    assert clamp_pose(inside, SCENE, LIMITS) == inside
    assert clamp_pose(c, SCENE, LIMITS) == c  # idempotent
    assert orbit(HOME, 1000, 0, SCENE).yaw_deg == LIMITS.max_yaw_deg
    assert pan(HOME, -1, 0, SCENE).pan_x == -LIMITS.max_pan


def test_camera_never_passes_the_near_surface():
    z_max = (1 - LIMITS.near_margin) * SCENE.near_depth
    rng = np.random.default_rng(1)
    for _ in range(300):
        raw = OrbitPose(*rng.uniform(-30, 30, 2), *rng.uniform(-0.5, 0.5, 2), rng.uniform(-1, 2))
        c = clamp_pose(raw, SCENE, LIMITS)
        assert camera_z(c, SCENE) <= z_max + 1e-12
        Cameras.create(cam_to_world(c, SCENE), 60.0)  # a valid, orthonormal pose
    # Wheeling forwards forever stops at the margin.
    pose = HOME
    for _ in range(200):
        pose = apply_wheel(pose, 1, SCENE)
    assert camera_z(pose, SCENE) == pytest.approx(z_max)


def test_wheel_and_dolly_move_along_the_view_axis():
    pose = apply_wheel(HOME, 2, SCENE)
    assert pose.dolly == pytest.approx(2 * LIMITS.dolly_per_tick * SCENE.centre_depth)
    T = cam_to_world(pose, SCENE)
    np.testing.assert_allclose(T[:3, 3], [0, 0, pose.dolly], atol=1e-12)
    assert dolly(pose, -pose.dolly, SCENE).dolly == pytest.approx(0.0)


def test_relative_to_composes_a_trajectory_with_the_view():
    traj = circle(8, fov_y_deg=50.0)
    same = relative_to(HOME, SCENE, traj)
    torch.testing.assert_close(same.cam_to_world, traj.cam_to_world)
    pose = OrbitPose(5.0, 2.0, 0.01, 0.0, 0.02)
    moved = relative_to(pose, SCENE, static(3, fov_y_deg=50.0))
    for i in range(3):
        np.testing.assert_allclose(moved.cam_to_world[i].numpy(), cam_to_world(pose, SCENE), atol=1e-12)
    assert torch.all(moved.fov_y_deg == 50.0)


def test_scene_from_depths():
    z = np.concatenate([np.linspace(1 / 3, 2.0, 1000), [np.nan, np.inf, -1.0, 0.0]])
    s = OrbitScene.from_depths(z)
    assert s.centre_depth == pytest.approx(np.median(np.linspace(1 / 3, 2.0, 1000)))
    assert s.near_depth == pytest.approx(np.percentile(np.linspace(1 / 3, 2.0, 1000), 1))
    with pytest.raises(InputError, match="no finite positive depth"):
        OrbitScene.from_depths(np.array([np.nan, -1.0]))


@pytest.mark.parametrize("kwargs", [dict(centre_depth=0.2, near_depth=0.3), dict(centre_depth=math.nan),
                                    dict(centre_depth=-1.0), dict(centre_depth=1.0, near_depth=0.0)])
def test_bad_scene(kwargs):
    with pytest.raises(InputError):
        OrbitScene(**kwargs)


def test_bad_input():
    with pytest.raises(InputError, match="yaw_deg"):
        OrbitPose(yaw_deg=math.inf)
    with pytest.raises(InputError, match="drag mode"):
        apply_drag(HOME, "spin", 1, 1, 100, 60.0, SCENE)
    with pytest.raises(InputError, match="view_height_px"):
        apply_drag(HOME, "pan", 1, 1, 0, 60.0, SCENE)
    with pytest.raises(InputError, match="fov"):
        pose_camera(HOME, SCENE, 0.0)
    with pytest.raises(InputError, match="near_margin"):
        OrbitLimits(near_margin=1.0)
    with pytest.raises(InputError, match="max_dolly"):
        OrbitLimits(max_dolly=2.0)


def test_limits_come_from_the_library_range():
    from stylize3d_core.geometry.camera_range import CameraRange

    assert LIMITS.camera_range() == CameraRange()  # the viewer's defaults are the library's
    photo_range = CameraRange().scaled(0.25)
    limits = OrbitLimits.from_range(photo_range, deg_per_pixel=0.02, relative=False)
    assert limits.camera_range() == photo_range and limits.deg_per_pixel == 0.02
    c = clamp_pose(OrbitPose(100, 100, 5, 5, 10), SCENE, limits)
    assert (c.yaw_deg, c.pitch_deg, c.pan_x) == (photo_range.max_yaw_deg, photo_range.max_pitch_deg,
                                                 photo_range.max_pan)
    assert c.dolly <= photo_range.max_dolly * SCENE.centre_depth + 1e-12


def test_speeds_relative_to_the_photo_range_cross_it_in_the_same_drag():
    """A photo's range is often a small part of the default one: at the default speeds 200 px of drag
    reach the yaw limit, 15 wheel steps the forward limit and a pan drag the pan limit as far as in the
    default range, whatever the photo's range."""
    from stylize3d_core.geometry.camera_range import CameraRange

    for scale in (1.0, 0.25, 0.06):
        rng = CameraRange().scaled(scale)
        limits = OrbitLimits.from_range(rng)
        assert limits.deg_per_pixel == pytest.approx(0.04 * scale)
        assert limits.pan_gain == pytest.approx(scale) and limits.dolly_per_tick == pytest.approx(0.04 * scale)
        pose = HOME
        for _ in range(199):  # 199 one-pixel moves: not yet at the limit
            pose = apply_drag(pose, "orbit", 1, 0, 500, 60.0, SCENE, limits)
        assert pose.yaw_deg == pytest.approx(rng.max_yaw_deg * 199 / 200)
        assert apply_drag(pose, "orbit", 5, 0, 500, 60.0, SCENE, limits).yaw_deg == pytest.approx(rng.max_yaw_deg)
        wheel = apply_wheel(HOME, 15, SCENE, limits)  # 15 steps: the forward limit (unless the near margin stops it)
        assert wheel.dolly == pytest.approx(min(rng.max_dolly * SCENE.centre_depth,
                                                clamp_pose(replace(HOME, dolly=9.0), SCENE, limits).dolly))
        default_pan = apply_drag(HOME, "pan", 3, 0, 500, 60.0, SCENE, OrbitLimits())
        assert apply_drag(HOME, "pan", 3, 0, 500, 60.0, SCENE, limits).pan_x == pytest.approx(scale * default_pan.pan_x)
    with pytest.raises(InputError, match="pan_gain"):
        OrbitLimits(pan_gain=-1.0)
