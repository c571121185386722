import math
from dataclasses import FrozenInstanceError
from typing import get_args

import numpy as np
import pytest
import torch

from stylize3d_core.errors import InputError
from stylize3d_core.geometry.camera import NEAR_DEPTH, Cameras, project, transform_points
from stylize3d_core.geometry.trajectories import (
    TRAJECTORIES,
    TrajectoryName,
    TrajectorySettings,
    circle,
    dolly_zoom,
    dolly_zoom_fov,
    ken_burns,
    make_trajectory,
    static,
    swing,
    zoom,
)


def positions(cams: Cameras) -> np.ndarray:
    return cams.centres().numpy()


def assert_identity_rotation(cams: Cameras) -> None:
    R = cams.cam_to_world[:, :3, :3]
    assert torch.equal(R, torch.eye(3, dtype=torch.float64).expand_as(R))
    assert torch.equal(cams.cam_to_world[:, 3], torch.tensor([0, 0, 0, 1.0], dtype=torch.float64).expand(len(cams), 4))


@pytest.mark.parametrize("name", sorted(TRAJECTORIES))
def test_every_trajectory_frame_count_dtype_rotation(name):
    for n in (1, 2, 90):
        cams = TRAJECTORIES[name](n_frames=n)
        assert isinstance(cams, Cameras) and len(cams) == n
        assert cams.cam_to_world.dtype == torch.float64 and cams.fov_y_deg.dtype == torch.float64
        assert_identity_rotation(cams)
        assert torch.isfinite(cams.cam_to_world).all()


def test_registry_matches_literal_names():
    assert set(TRAJECTORIES) == set(get_args(TrajectoryName))


def test_circle_known_values():
    cams = circle(90)
    np.testing.assert_allclose(positions(cams)[0], [0.02, 0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(positions(cams)[-1], [0.02, 0.0, 0.0], atol=1e-15)
    # t = -2, -1, 0, 1, 2
    p = positions(circle(5, x=0.02, y=0.03, z=(0.0, 0.05)))
    np.testing.assert_allclose(p[:, 0], [0.02, -0.02, 0.02, -0.02, 0.02], atol=1e-15)
    np.testing.assert_allclose(p[:, 1], 0.0, atol=1e-15)
    np.testing.assert_allclose(p[:, 2], [0.0, 0.025, 0.05, 0.025, 0.0], atol=1e-15)
    # t = -1.5: y = sin(-1.5 pi) * y = +y, x = 0
    p9 = positions(circle(9, x=0.02, y=0.03))
    np.testing.assert_allclose(p9[1], [0.0, 0.03, (math.cos(-0.75 * math.pi) + 1) / 2 * 0.05], atol=1e-15)
    assert torch.all(circle(7, fov_y_deg=45).fov_y_deg == 45.0)


def test_circle_z_range_reversed_and_scalar():
    p = positions(circle(5, z=(0.1, -0.1)))
    np.testing.assert_allclose(p[:, 2], [0.1, 0.0, -0.1, 0.0, 0.1], atol=1e-15)
    # a single number a means (-a, a)
    np.testing.assert_allclose(positions(circle(5, z=0.1))[:, 2], [-0.1, 0.0, 0.1, 0.0, -0.1], atol=1e-15)


def test_swing_has_no_vertical_motion():
    p = positions(swing(90))
    assert np.all(p[:, 1] == 0.0)
    np.testing.assert_allclose(p[:, [0, 2]], positions(circle(90))[:, [0, 2]], atol=0)


def test_ken_burns_endpoints_and_linearity():
    p = positions(ken_burns(11, x=(-0.02, 0.03), y=0.01, z=(0.0, 0.05)))
    np.testing.assert_allclose(p[0], [-0.02, -0.01, 0.0], atol=1e-15)
    np.testing.assert_allclose(p[-1], [0.03, 0.01, 0.05], atol=1e-15)
    np.testing.assert_allclose(np.diff(p, axis=0), np.diff(p, axis=0)[:1].repeat(10, 0), atol=1e-15)
    np.testing.assert_allclose(positions(ken_burns(3))[-1], [0.02, 0.02, 0.05], atol=1e-15)


def test_zoom_moves_only_forward():
    p = positions(zoom(5, z=(0.0, 0.08)))
    np.testing.assert_allclose(p, [[0, 0, 0], [0, 0, 0.02], [0, 0, 0.04], [0, 0, 0.06], [0, 0, 0.08]], atol=1e-15)


def test_static_is_identity():
    cams = static(4, fov_y_deg=50)
    assert torch.equal(cams.cam_to_world, torch.eye(4, dtype=torch.float64).expand(4, 4, 4))
    assert torch.all(cams.fov_y_deg == 50.0)


def _project_world(cams: Cameras, point: torch.Tensor, h: int, w: int) -> np.ndarray:
    """(B, 2) pixel positions of one world point in every camera."""
    Ks = cams.intrinsics(h, w, dtype=torch.float64)
    w2c = cams.world_to_cam()
    out = []
    for i in range(len(cams)):
        uv, z = project(transform_points(w2c[i], point[None]), Ks[i])
        assert z.item() > 0
        out.append(uv[0].numpy())
    return np.stack(out)


def test_dolly_zoom_keeps_subject_size_and_moves_background():
    h, w = 240, 320
    d = 0.5
    cams = dolly_zoom(15, z=(0.0, 0.15), fov_y_deg=60, subject_depth=d)
    np.testing.assert_allclose(positions(cams), positions(zoom(15, z=(0.0, 0.15))), atol=0)
    assert cams.fov_y_deg[0] == pytest.approx(60.0)
    assert torch.all(torch.diff(cams.fov_y_deg) > 0)  # moving in widens the view
    # a subject-plane point at the bottom edge of frame 0, and one off-centre
    edge = torch.tensor([0.0, math.tan(math.radians(30)) * d, d], dtype=torch.float64)
    uv = _project_world(cams, edge, h, w)
    np.testing.assert_allclose(uv[:, 1], h / 2 + h / 2, atol=1e-9)
    np.testing.assert_allclose(uv[:, 0], w / 2, atol=1e-9)
    other = torch.tensor([0.1, -0.07, d], dtype=torch.float64)
    uv = _project_world(cams, other, h, w)
    np.testing.assert_allclose(uv, uv[:1].repeat(len(cams), 0), atol=1e-9)
    # a background point moves towards the centre
    bg = torch.tensor([0.3, 0.2, 3 * d], dtype=torch.float64)
    uvb = _project_world(cams, bg, h, w)
    assert np.all(np.diff(uvb[:, 0]) < 0) and uvb[0, 0] - uvb[-1, 0] > 5.0


def test_dolly_zoom_fov_formula_and_defaults():
    fov = dolly_zoom_fov(60.0, 1.0, np.array([0.0, 0.5]))
    np.testing.assert_allclose(fov, [60.0, math.degrees(2 * math.atan(math.tan(math.radians(30)) * 2))])
    cams = dolly_zoom()
    assert len(cams) == 90
    np.testing.assert_allclose(cams.fov_y_deg.numpy(), dolly_zoom_fov(60.0, NEAR_DEPTH, np.linspace(0, 0.05, 90)))


def test_dolly_zoom_rejects_reaching_the_subject_and_extreme_fov():
    with pytest.raises(InputError, match="subject plane"):
        dolly_zoom(10, z=(0.0, 0.5), subject_depth=0.5)
    with pytest.raises(InputError, match="subject plane"):
        dolly_zoom(10, z=(0.0, 0.6), subject_depth=0.5)
    with pytest.raises(InputError, match="field of view"):
        dolly_zoom(10, z=(0.0, 0.45), fov_y_deg=150, subject_depth=0.5)
    with pytest.raises(InputError, match="field of view"):  # moving far back narrows below 1 degree
        dolly_zoom(10, z=(0.0, -100.0), fov_y_deg=10, subject_depth=0.5)
    with pytest.raises(InputError, match="subject_depth"):
        dolly_zoom(10, subject_depth=0.0)
    with pytest.raises(InputError, match="subject_depth"):
        dolly_zoom(10, subject_depth=float("nan"))


@pytest.mark.parametrize("bad", [0, -1, 2.5, True, "3"])
def test_n_frames_must_be_positive_int(bad):
    with pytest.raises(InputError, match="n_frames"):
        circle(bad)
    with pytest.raises(InputError, match="n_frames"):
        make_trajectory(TrajectorySettings("static", n_frames=bad))


def test_bad_amplitudes_and_fov():
    with pytest.raises(InputError, match="x"):
        circle(5, x=(0.0, 0.02))
    with pytest.raises(InputError, match="y"):
        circle(5, y=float("inf"))
    with pytest.raises(InputError, match="z"):
        ken_burns(5, z=(0.0, 0.1, 0.2))
    with pytest.raises(InputError, match="z"):
        zoom(5, z=(0.0, float("nan")))
    with pytest.raises(InputError, match="fov_y_deg"):
        static(5, fov_y_deg=180)


def test_settings_defaults_and_make_trajectory():
    s = TrajectorySettings()
    assert (s.name, s.n_frames, s.x, s.y, s.z, s.fov_y_deg, s.subject_depth) == (
        "circle", 90, 0.02, 0.02, (0.0, 0.05), 60.0, NEAR_DEPTH)
    with pytest.raises(FrozenInstanceError):
        s.n_frames = 3  # type: ignore[misc]
    for name in TRAJECTORIES:
        a = make_trajectory(TrajectorySettings(name, n_frames=12, fov_y_deg=50))
        b = TRAJECTORIES[name](n_frames=12, fov_y_deg=50)
        assert torch.equal(a.cam_to_world, b.cam_to_world) and torch.equal(a.fov_y_deg, b.fov_y_deg)
    kb = make_trajectory(TrajectorySettings("ken_burns", n_frames=3, x=(0.0, 0.1), y=0.0, z=(0.0, 0.0)))
    np.testing.assert_allclose(positions(kb)[-1], [0.1, 0.0, 0.0])


def test_unknown_name_lists_valid_ones():
    with pytest.raises(InputError) as e:
        make_trajectory(TrajectorySettings("spiral"))  # type: ignore[arg-type]
    for name in TRAJECTORIES:
        assert name in str(e.value)
