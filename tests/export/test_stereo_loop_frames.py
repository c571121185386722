"""Stereo eyes, side-by-side and anaglyph frames, boomerang loops, WebP and camera paths by format."""

import numpy as np
import pytest
import torch
from PIL import Image

from stylize3d_core.errors import InputError
from stylize3d_core.export.camera_paths import camera_path_format, read_camera_path, write_camera_path
from stylize3d_core.export.frames import output_kind, write_frames
from stylize3d_core.export.loop import boomerang, boomerang_length
from stylize3d_core.export.stereo import (anaglyph, check_eye_distance, eye_cameras, side_by_side,
                                          stereo_frames)
from stylize3d_core.geometry.camera import Cameras
from stylize3d_core.geometry.trajectories import circle
from stylize3d_core.render.plain import PlainRenderer


def test_eyes_are_apart_along_each_cameras_x_axis():
    yaw = np.eye(4)
    yaw[:3, :3] = [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]  # camera x axis = world -z
    cams = Cameras.create(np.stack([np.eye(4), yaw]), 50.0)
    left, right = eye_cameras(cams, 0.1)
    assert torch.allclose(left.centres()[0], torch.tensor([-0.05, 0, 0], dtype=torch.float64))
    assert torch.allclose(right.centres()[1], torch.tensor([0, 0, -0.05], dtype=torch.float64))
    assert torch.allclose(left.cam_to_world[:, :3, :3], cams.cam_to_world[:, :3, :3])
    with pytest.raises(InputError, match="eye_distance"):
        eye_cameras(cams, 0.0)


def test_layouts():
    lv = np.zeros((4, 6, 3), np.float32)
    rv = np.ones((4, 6, 3), np.float32)
    full = side_by_side(lv, rv, "full")
    assert full.shape == (4, 12, 3) and full[:, :6].max() == 0 and full[:, 6:].min() == 1
    half = side_by_side(lv, rv, "half")
    assert half.shape == (4, 6, 3) and half[:, :3].max() == 0 and half[:, 3:].min() == 1
    ana = anaglyph(np.full((2, 2, 3), 0.9, np.float32), np.full((2, 2, 3), 0.2, np.float32))
    assert np.allclose(ana[..., 0], 0.9) and np.allclose(ana[..., 1:], 0.2)
    with pytest.raises(InputError):
        side_by_side(lv, rv[:, :5])


def test_stereo_frames_show_parallax(photo3d):
    renderer = PlainRenderer(photo3d.points)
    cams = Cameras.identity(photo3d.fov_y_deg)
    (frame,) = stereo_frames(renderer.render, cams, 48, 64, 0.04, "sbs", "full")
    left, right = frame[:, :64], frame[:, 64:]
    red = lambda im: np.nonzero((im[..., 0] > 0.6).any(axis=0))[0].mean()  # column of the near red square
    assert red(left) > red(right) + 0.5  # the left eye sees the near square further right
    with pytest.raises(InputError, match="inside the scene"):
        check_eye_distance(0.5, photo3d.points.xyz, cams, (48, 64))
    assert check_eye_distance(0.01, photo3d.points.xyz, cams, (48, 64)) == 0.01


def test_eye_distance_checked_in_every_frame(photo3d):
    forward = np.tile(np.eye(4), (2, 1, 1))
    forward[1, 2, 3] = 0.3  # the second camera moved up to the near square (at about 1/3)
    cams = Cameras.create(forward, photo3d.fov_y_deg)
    with pytest.raises(InputError, match="camera 1"):
        check_eye_distance(0.05, photo3d.points.xyz, cams, (48, 64))


def test_boomerang():
    frames = [np.full((2, 2, 3), i, np.uint8) for i in range(4)]
    out = [int(f[0, 0, 0]) for f in boomerang(iter(frames))]
    assert out == [0, 1, 2, 3, 2, 1] and len(out) == boomerang_length(4)
    assert [int(f[0, 0, 0]) for f in boomerang(frames[:1])] == [0] and boomerang_length(1) == 1
    with pytest.raises(InputError):
        list(boomerang([np.full((2, 2, 3), np.nan, np.float32)]))


def test_webp_loop_round_trip(tmp_path):
    frames = [np.full((8, 10, 3), 40 * i, np.uint8) for i in range(4)]
    out = write_frames(tmp_path / "l.webp", boomerang(frames), fps=10, n_frames=boomerang_length(4))
    with Image.open(out) as im:
        assert im.n_frames == 6 and im.size == (10, 8) and im.info.get("loop") == 0
        means = []
        for i in range(im.n_frames):
            im.seek(i)
            means.append(np.asarray(im.convert("RGB")).mean())
    assert np.allclose(means, [0, 40, 80, 120, 80, 40], atol=3)
    assert output_kind("a.WEBP") == "webp" and output_kind("a.mp4") == "mp4"
    with pytest.raises(InputError, match="unsupported"):
        output_kind("a.avi")
    with pytest.raises(InputError, match="no frames"):
        write_frames(tmp_path / "e.webp", [], fps=10)
    assert not (tmp_path / "e.webp").exists()


def test_camera_paths_in_both_formats(tmp_path):
    cams = circle(5, fov_y_deg=55.0)
    for fmt in ("stylize3d", "open3d"):
        path = write_camera_path(tmp_path / f"{fmt}.json", cams, fmt=fmt, fps=24, image_size=(48, 64))
        assert camera_path_format(path) == fmt
        back = read_camera_path(path)
        assert torch.allclose(back.cameras.cam_to_world, cams.cam_to_world, atol=1e-9)
        assert torch.allclose(back.cameras.fov_y_deg, cams.fov_y_deg, atol=1e-9)
        assert back.image_size == (48, 64)
        assert back.fps == (24 if fmt == "stylize3d" else None)
    with pytest.raises(InputError):
        write_camera_path(tmp_path / "x.json", cams, fmt="colmap", fps=24, image_size=(48, 64))
    bad = tmp_path / "bad.json"
    bad.write_text('{"class_name": "PinholeCameraTrajectory", "parameters": []}')
    with pytest.raises(InputError, match="zero frames"):
        read_camera_path(bad)
