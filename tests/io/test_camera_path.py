import json
import os

import numpy as np
import pytest
import torch

from stylize3d_core.errors import ExportError, InputError
from stylize3d_core.geometry.camera import Cameras, focal_from_fov
from stylize3d_core.geometry.trajectories import circle, dolly_zoom
from stylize3d_core.io.camera_path import (
    FORMAT_TAG,
    CameraPath,
    load_camera_path,
    load_open3d_trajectory,
    save_camera_path,
    save_open3d_trajectory,
)


def rotated_cameras(n: int = 6, seed: int = 0) -> Cameras:
    """Cameras with random rotations, positions and FOVs (exercise every matrix entry)."""
    rng = np.random.default_rng(seed)
    c2w = np.tile(np.eye(4), (n, 1, 1))
    for i in range(n):
        q, r = np.linalg.qr(rng.normal(size=(3, 3)))
        q = q * np.sign(np.diag(r))
        if np.linalg.det(q) < 0:
            q[:, 0] = -q[:, 0]
        c2w[i, :3, :3] = q
        c2w[i, :3, 3] = rng.normal(size=3) * 0.1
    return Cameras(torch.from_numpy(c2w), torch.from_numpy(rng.uniform(20, 100, n)))


def test_json_round_trip_is_exact(tmp_path):
    path = tmp_path / "path.json"
    cams = rotated_cameras()
    assert save_camera_path(path, cams, fps=24, image_size=(480, 640)) == path
    out = load_camera_path(path)
    assert isinstance(out, CameraPath)
    assert torch.equal(out.cameras.cam_to_world, cams.cam_to_world)
    assert torch.equal(out.cameras.fov_y_deg, cams.fov_y_deg)
    assert out.fps == 24.0 and out.image_size == (480, 640)
    assert os.listdir(tmp_path) == ["path.json"]


def test_json_schema_written(tmp_path):
    path = tmp_path / "p.json"
    save_camera_path(path, dolly_zoom(3))
    doc = json.loads(path.read_text())
    assert doc["format"] == FORMAT_TAG and doc["version"] == 1 and doc["fps"] == 30
    assert doc["image_size"] is None and "cam_to_world" in doc["conventions"]
    assert len(doc["frames"]) == 3
    m = doc["frames"][2]["cam_to_world"]
    assert m[2][3] == pytest.approx(0.05) and m[3] == [0.0, 0.0, 0.0, 1.0]  # row-major: translation in column 3
    assert doc["frames"][0]["fov_y_deg"] == 60.0
    out = load_camera_path(path)
    assert out.image_size is None and out.fps == 30.0


def test_save_replaces_existing_file_and_rejects_bad_arguments(tmp_path):
    path = tmp_path / "p.json"
    path.write_text("old")
    save_camera_path(path, circle(4))
    assert len(load_camera_path(path).cameras) == 4
    before = path.read_bytes()
    with pytest.raises(InputError, match="fps"):
        save_camera_path(path, circle(4), fps=0)
    with pytest.raises(InputError, match="image"):
        save_camera_path(path, circle(4), image_size=(0, 10))
    with pytest.raises(InputError, match="cameras"):
        save_camera_path(path, "not cameras")  # type: ignore[arg-type]
    assert path.read_bytes() == before
    with pytest.raises(ExportError):
        save_camera_path(tmp_path / "missing_dir" / "p.json", circle(2))
    assert sorted(os.listdir(tmp_path)) == ["p.json"]


def _valid_doc():
    return {
        "format": FORMAT_TAG, "version": 1, "fps": 30, "image_size": [4, 6],
        "frames": [{"cam_to_world": np.eye(4).tolist(), "fov_y_deg": 60.0}],
    }


_DROP = object()


def _with(**changes):
    """JSON text of a valid file with top-level (or ``frame_*``: frame 0's) keys changed or dropped."""
    doc = _valid_doc()
    for key, value in changes.items():
        target, name = (doc["frames"][0], key[6:]) if key.startswith("frame_") else (doc, key)
        if value is _DROP:
            del target[name]
        else:
            target[name] = value
    return json.dumps(doc)


_SCALED = (np.eye(4) * [2, 1, 1, 1]).tolist()
_REFLECT = np.diag([-1.0, 1, 1, 1]).tolist()


@pytest.mark.parametrize(
    "text, problem",
    [
        ("{not json", "not a valid JSON"),
        ("[1, 2]", "not a stylize3d camera path"),
        (_with(format="something-else"), "not a stylize3d camera path"),
        (_with(version=2), "version"),
        (_with(frames=_DROP), "frames"),
        (_with(fps=_DROP), "fps"),
        (_with(fps=-1), "fps"),
        (_with(image_size=[4]), "image_size"),
        (_with(frames=[]), "zero frames"),
        (_with(frames=[3]), "frame 0"),
        (_with(frame_cam_to_world=np.eye(4)[:3].tolist()), "4 rows of 4"),
        (_with(frame_cam_to_world=[[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 0]]), "4 rows of 4"),
        (_with(frame_cam_to_world="eye"), "4 rows of 4"),
        (_with(frame_cam_to_world=_SCALED), "not a rotation"),
        (_with(frame_cam_to_world=_REFLECT), "not a rotation"),
        (_with(frame_cam_to_world=[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1]]), "last row"),
        (_with(frame_fov_y_deg=0.5), "fov_y_deg"),
        (_with(frame_fov_y_deg=179.0), "fov_y_deg"),
        (_with(frame_fov_y_deg="60"), "fov_y_deg"),
        (_with(frame_fov_y_deg=_DROP), "frame 0: missing key 'fov_y_deg'"),
        (_with(frame_cam_to_world=_DROP), "frame 0: missing key 'cam_to_world'"),
        (_with().replace('"fov_y_deg": 60.0', '"fov_y_deg": NaN'), "non-finite"),
        (_with().replace("[1.0, 0.0, 0.0, 0.0]", "[1.0, 0.0, 0.0, Infinity]"), "non-finite"),
    ],
)
def test_malformed_files_name_the_file_and_the_problem(tmp_path, text, problem):
    path = tmp_path / "bad.json"
    path.write_text(text)
    with pytest.raises(InputError) as e:
        load_camera_path(path)
    assert str(path) in str(e.value) and problem in str(e.value)


def test_missing_and_binary_files(tmp_path):
    with pytest.raises(InputError, match="not found"):
        load_camera_path(tmp_path / "nope.json")
    bad = tmp_path / "bin.json"
    bad.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(InputError, match=str(bad).replace("\\", "\\\\")):
        load_camera_path(bad)


def test_open3d_round_trip(tmp_path):
    import open3d.io as o3io

    path = tmp_path / "traj.json"
    cams = rotated_cameras(5, seed=1)
    assert save_open3d_trajectory(path, cams, height=48, width=65) == path
    assert os.listdir(tmp_path) == ["traj.json"]
    traj = o3io.read_pinhole_camera_trajectory(str(path))
    assert len(traj.parameters) == 5
    p = traj.parameters[2]
    np.testing.assert_allclose(p.extrinsic, cams.world_to_cam()[2].numpy(), atol=1e-12)
    K = p.intrinsic.intrinsic_matrix
    f = focal_from_fov(float(cams.fov_y_deg[2]), 48)
    np.testing.assert_allclose(K, [[f, 0, 32.0], [0, f, 23.5], [0, 0, 1]], rtol=1e-12)
    assert (p.intrinsic.width, p.intrinsic.height) == (65, 48)

    out = load_open3d_trajectory(path)
    assert out.fps is None and out.image_size == (48, 65)
    np.testing.assert_allclose(out.cameras.cam_to_world.numpy(), cams.cam_to_world.numpy(), atol=1e-12)
    np.testing.assert_allclose(out.cameras.fov_y_deg.numpy(), cams.fov_y_deg.numpy(), rtol=1e-12)


def _write_o3d(path, fx, fy, cx, cy, w=64, h=48, extrinsic=None):
    import open3d.camera as o3c
    import open3d.io as o3io

    p = o3c.PinholeCameraParameters()
    p.intrinsic = o3c.PinholeCameraIntrinsic(w, h, fx, fy, cx, cy)
    p.extrinsic = np.eye(4) if extrinsic is None else extrinsic
    t = o3c.PinholeCameraTrajectory()
    t.parameters = [p]
    assert o3io.write_pinhole_camera_trajectory(str(path), t)


def test_open3d_fov_from_fy_and_either_centre_convention(tmp_path):
    path = tmp_path / "t.json"
    _write_o3d(path, 24.0, 24.0, 32.0, 24.0)  # cx = W/2 (pixel centres at +0.5) is accepted too
    out = load_open3d_trajectory(path)
    assert float(out.cameras.fov_y_deg[0]) == pytest.approx(90.0)
    assert torch.equal(out.cameras.cam_to_world[0], torch.eye(4, dtype=torch.float64))


@pytest.mark.parametrize(
    "kwargs, problem",
    [
        (dict(fx=30.0, fy=24.0, cx=31.5, cy=23.5), "square pixels"),
        (dict(fx=24.0, fy=24.0, cx=10.0, cy=23.5), "principal point"),
        (dict(fx=24.0, fy=24.0, cx=31.5, cy=23.5, extrinsic=np.diag([1.0, 2.0, 1.0, 1.0])), "not a rotation"),
        (dict(fx=0.01, fy=0.01, cx=31.5, cy=23.5), "fov_y_deg"),
    ],
)
def test_open3d_unsupported_cameras(tmp_path, kwargs, problem):
    path = tmp_path / "t.json"
    _write_o3d(path, **kwargs)
    with pytest.raises(InputError) as e:
        load_open3d_trajectory(path)
    assert str(path) in str(e.value) and problem in str(e.value)


def test_open3d_malformed_files(tmp_path):
    path = tmp_path / "t.json"
    with pytest.raises(InputError, match="not found"):
        load_open3d_trajectory(path)
    path.write_text("{oops")
    with pytest.raises(InputError, match="not a valid JSON"):
        load_open3d_trajectory(path)
    path.write_text("{}")
    with pytest.raises(InputError, match="zero frames"):
        load_open3d_trajectory(path)
    with pytest.raises(InputError, match=".json"):
        save_open3d_trajectory(tmp_path / "t.txt", circle(2), 48, 64)
    with pytest.raises(InputError, match="image size"):
        save_open3d_trajectory(tmp_path / "t.json", circle(2), 0, 64)
    assert os.listdir(tmp_path) == ["t.json"] and path.read_text() == "{}"
