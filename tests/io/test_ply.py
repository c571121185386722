import os

import numpy as np
import pytest
import torch

from stylize3d_core.errors import ExportError, InputError
from stylize3d_core.io.ply import PlyPointCloud, read_ply, write_ply

HEADER = (
    b"ply\nformat binary_little_endian 1.0\ncomment stylize3d point cloud\nelement vertex 50\n"
    b"property float x\nproperty float y\nproperty float z\n"
    b"property uchar red\nproperty uchar green\nproperty uchar blue\n"
)


def cloud(n: int = 50, seed: int = 0):
    rng = np.random.default_rng(seed)
    xyz = rng.normal(size=(n, 3)).astype(np.float32)
    rgb = rng.integers(0, 256, size=(n, 3), dtype=np.uint8)
    return xyz, rgb


def test_round_trip_uint8_and_header(tmp_path):
    path = tmp_path / "c.ply"
    xyz, rgb = cloud()
    assert write_ply(path, xyz, rgb) == path
    data = path.read_bytes()
    assert data.startswith(HEADER + b"end_header\n")
    assert len(data) == len(HEADER) + len(b"end_header\n") + 50 * 15
    out = read_ply(path)
    assert isinstance(out, PlyPointCloud) and out.labels is None
    np.testing.assert_array_equal(out.xyz, xyz)
    np.testing.assert_array_equal(out.rgb, rgb)
    assert out.xyz.dtype == np.float32 and out.rgb.dtype == np.uint8
    assert os.listdir(tmp_path) == ["c.ply"]


def test_round_trip_float_colours_labels_and_torch(tmp_path):
    path = tmp_path / "c.ply"
    xyz = torch.tensor([[0.0, 1.0, 2.0], [-1.5, 0.25, 3.0], [1e3, -1e-3, 0.5]], dtype=torch.float64, requires_grad=True)
    rgb = torch.tensor([[0.0, 0.5, 1.0], [-0.2, 1.7, 0.25], [1 / 255, 254.6 / 255, 0.999]])
    write_ply(path, xyz, rgb, labels=np.array([0, 7, 255]))
    out = read_ply(path)
    np.testing.assert_array_equal(out.xyz, xyz.detach().numpy().astype(np.float32))
    np.testing.assert_array_equal(out.rgb, [[0, 128, 255], [0, 255, 64], [1, 255, 255]])
    np.testing.assert_array_equal(out.labels, [0, 7, 255])
    assert b"property uchar label\nend_header\n" in path.read_bytes()[:400]


def test_open3d_reads_our_file(tmp_path):
    import open3d.io as o3io

    xyz, rgb = cloud(200, seed=3)
    for labels in (None, np.arange(200) % 4):
        path = tmp_path / f"c{labels is None}.ply"
        write_ply(path, xyz, rgb, labels=labels)
        pcd = o3io.read_point_cloud(str(path))
        np.testing.assert_array_equal(np.asarray(pcd.points), xyz.astype(np.float64))
        np.testing.assert_array_equal(np.round(np.asarray(pcd.colors) * 255).astype(np.uint8), rgb)


def test_open3d_written_file_reads_back(tmp_path):
    import open3d.geometry as o3g
    import open3d.io as o3io
    import open3d.utility as o3u

    xyz, rgb = cloud(30, seed=5)
    pcd = o3g.PointCloud(o3u.Vector3dVector(xyz.astype(np.float64)))
    pcd.colors = o3u.Vector3dVector(rgb.astype(np.float64) / 255)
    path = tmp_path / "o3d.ply"
    assert o3io.write_point_cloud(str(path), pcd, write_ascii=False)
    out = read_ply(path)
    np.testing.assert_allclose(out.xyz, xyz, rtol=1e-6)
    np.testing.assert_array_equal(out.rgb, rgb)


def test_bad_inputs_leave_nothing(tmp_path):
    path = tmp_path / "c.ply"
    path.write_bytes(b"old")
    xyz, rgb = cloud(4)
    bad = xyz.copy()
    bad[2, 1] = np.nan
    with pytest.raises(InputError, match="xyz.*NaN"):
        write_ply(path, bad, rgb)
    with pytest.raises(InputError, match="float32"):
        write_ply(path, np.full((4, 3), 1e300), rgb)
    with pytest.raises(InputError, match="xyz"):
        write_ply(path, xyz[:, :2], rgb)
    with pytest.raises(InputError, match="empty"):
        write_ply(path, xyz[:0], rgb[:0])
    with pytest.raises(InputError, match="rgb"):
        write_ply(path, xyz, rgb[:3])
    with pytest.raises(InputError, match="rgb.*NaN"):
        write_ply(path, xyz, np.full((4, 3), np.nan))
    with pytest.raises(InputError, match="rgb"):
        write_ply(path, xyz, rgb.astype(np.int64))
    with pytest.raises(InputError, match="labels"):
        write_ply(path, xyz, rgb, labels=np.array([0, 1, 2, 256]))
    with pytest.raises(InputError, match="labels"):
        write_ply(path, xyz, rgb, labels=np.zeros(3, np.uint8))
    with pytest.raises(InputError, match=".ply"):
        write_ply(tmp_path / "c.xyz", xyz, rgb)
    with pytest.raises(InputError, match="xyz"):
        write_ply(path, xyz.tolist(), rgb)
    assert bad[2, 1] != bad[2, 1] and path.read_bytes() == b"old"
    with pytest.raises(ExportError):
        write_ply(tmp_path / "missing" / "c.ply", xyz, rgb)
    assert os.listdir(tmp_path) == ["c.ply"]


def _good_bytes(tmp_path):
    path = tmp_path / "good.ply"
    write_ply(path, *cloud())
    return path.read_bytes()


@pytest.mark.parametrize(
    "mutate, problem",
    [
        (lambda b: b"solid mesh\n" + b, "not a PLY file"),
        (lambda b: b.replace(b"binary_little_endian", b"ascii"), "binary little-endian"),
        (lambda b: b.replace(b"binary_little_endian", b"binary_big_endian"), "binary little-endian"),
        (lambda b: b[:-10], "truncated"),
        (lambda b: b.replace(b"end_header", b"end_hdr___"), "end_header"),
        (lambda b: b.replace(b"property uchar red", b"property uchar rrr"), "'red'"),
        (lambda b: b.replace(b"property float x", b"property float q"), "'x'"),
        (lambda b: b.replace(b"property float x", b"property float y"), "repeats"),
        (lambda b: b.replace(b"property uchar red", b"property blob red"), "unknown PLY type"),
        (lambda b: b.replace(b"element vertex 50", b"element vertex many"), "element"),
        (lambda b: b.replace(b"element vertex 50", b"element face 50"), "'vertex'"),
    ],
)
def test_malformed_files(tmp_path, mutate, problem):
    path = tmp_path / "bad.ply"
    path.write_bytes(mutate(_good_bytes(tmp_path)))
    with pytest.raises(InputError) as e:
        read_ply(path)
    assert str(path) in str(e.value) and problem in str(e.value)


def test_read_rejects_missing_file_and_nan_positions(tmp_path):
    with pytest.raises(InputError, match="not found"):
        read_ply(tmp_path / "nope.ply")
    data = bytearray(_good_bytes(tmp_path))
    start = len(HEADER) + len(b"end_header\n")
    data[start:start + 4] = np.array([np.nan], "<f4").tobytes()
    path = tmp_path / "nan.ply"
    path.write_bytes(bytes(data))
    with pytest.raises(InputError, match="NaN"):
        read_ply(path)
