import math

import numpy as np
import pytest
import torch

from stylize3d_core.errors import InputError
from stylize3d_core.geometry.camera import (
    Cameras,
    focal_from_fov,
    intrinsics_from_fov,
    invert_pose,
    pixel_centres,
    project,
    transform_points,
    unproject,
    unproject_depth_map,
)


def random_pose(seed: int) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    q, _ = torch.linalg.qr(torch.randn(3, 3, generator=g, dtype=torch.float64))
    if torch.det(q) < 0:
        q[:, 0] = -q[:, 0]
    T = torch.eye(4, dtype=torch.float64)
    T[:3, :3] = q
    T[:3, 3] = torch.randn(3, generator=g, dtype=torch.float64)
    return T


def test_intrinsics_known_values():
    K = intrinsics_from_fov(90.0, 100, 200, dtype=torch.float64)
    # tan(45 deg) = 1, so f = H / 2.
    assert K[0, 0].item() == pytest.approx(50.0)
    assert K[1, 1].item() == pytest.approx(50.0)
    assert K[0, 2].item() == 100.0 and K[1, 2].item() == 50.0
    assert focal_from_fov(60.0, 512) == pytest.approx(256 / math.tan(math.radians(30)))


def test_pixel_centres_at_half():
    uv = pixel_centres(2, 3)
    assert uv.shape == (2, 3, 2)
    assert uv[0, 0].tolist() == [0.5, 0.5]
    assert uv[1, 2].tolist() == [2.5, 1.5]


def test_vertical_fov_spans_image_height():
    # A point on the top edge of the vertical FOV projects to v = 0.
    K = intrinsics_from_fov(60.0, 480, 640, dtype=torch.float64)
    y = -math.tan(math.radians(30.0))
    uv, z = project(torch.tensor([[0.0, y, 1.0]], dtype=torch.float64), K)
    assert uv[0, 1].item() == pytest.approx(0.0, abs=1e-9)
    assert uv[0, 0].item() == pytest.approx(320.0)


def test_project_unproject_round_trip():
    K = intrinsics_from_fov(55.0, 37, 53, dtype=torch.float64)
    depth = torch.rand(37, 53, dtype=torch.float64) * 5 + 0.1
    pts = unproject_depth_map(depth, K)
    uv, z = project(pts.reshape(-1, 3), K)
    assert torch.allclose(uv, pixel_centres(37, 53, torch.float64).reshape(-1, 2), atol=1e-9)
    assert torch.allclose(z, depth.reshape(-1))
    # explicit pixel: centre pixel of an odd-width image lies on the optical axis in x
    p = unproject(torch.tensor([26.5, 18.5], dtype=torch.float64), torch.tensor(2.0, dtype=torch.float64), K)
    assert p[0].item() == pytest.approx(0.0) and p[1].item() == pytest.approx(0.0) and p[2].item() == 2.0


def test_project_behind_camera_is_finite():
    K = intrinsics_from_fov(60.0, 10, 10)
    uv, z = project(torch.tensor([[1.0, 1.0, 0.0], [1.0, 1.0, -2.0]]), K)
    assert torch.isfinite(uv).all()
    assert (z <= 0).all()


def test_invert_pose_and_transform():
    T = random_pose(0)
    Ti = invert_pose(T)
    assert torch.allclose(T @ Ti, torch.eye(4, dtype=torch.float64), atol=1e-12)
    pts = torch.randn(10, 3, dtype=torch.float64)
    assert torch.allclose(transform_points(Ti, transform_points(T, pts)), pts, atol=1e-12)


def test_cameras_batch_and_world_to_cam():
    poses = torch.stack([random_pose(i) for i in range(3)])
    cams = Cameras.create(poses, 50.0)
    assert len(cams) == 3
    assert cams.fov_y_deg.tolist() == [50.0, 50.0, 50.0]
    assert torch.allclose(cams.world_to_cam() @ cams.cam_to_world, torch.eye(4, dtype=torch.float64).expand(3, 4, 4))
    assert len(cams[1]) == 1 and torch.equal(cams[1].cam_to_world[0], poses[1])
    assert len(cams[-1]) == 1 and torch.equal(cams[-1].cam_to_world[0], poses[2])
    assert cams.intrinsics(10, 20).shape == (3, 3, 3)
    assert torch.equal(Cameras.identity().cam_to_world[0], torch.eye(4, dtype=torch.float64))


@pytest.mark.parametrize(
    "pose, fov",
    [
        (torch.full((1, 4, 4), float("nan")), 60.0),
        (torch.eye(4).unsqueeze(0) * 2, 60.0),  # not a rotation
        (torch.eye(4).unsqueeze(0), 0.0),
        (torch.eye(4).unsqueeze(0), 180.0),
        (torch.eye(3).unsqueeze(0), 60.0),
    ],
)
def test_cameras_reject_bad_input(pose, fov):
    with pytest.raises(InputError):
        Cameras.create(pose, fov)


def test_intrinsics_reject_bad_size_and_fov():
    with pytest.raises(InputError):
        intrinsics_from_fov(60.0, 0, 10)
    with pytest.raises(InputError, match="fov"):
        intrinsics_from_fov(float("nan"), 10, 10)


def test_cameras_from_numpy():
    cams = Cameras.create(np.eye(4), np.array([45.0]))
    assert cams.cam_to_world.dtype == torch.float64 and len(cams) == 1
