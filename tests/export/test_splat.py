"""3D Gaussian splat files: the fields the 3DGS viewers read, decoded back to what was written."""

import numpy as np
import pytest

from stylize3d_core.errors import InputError
from stylize3d_core.export.splat import (SH_C0, SPLAT_PROPERTIES, point_footprints, read_splat_ply,
                                         read_vertex_properties, write_splat_ply)
from stylize3d_core.geometry.camera import focal_from_fov


def test_footprint_is_one_pixel_at_the_points_depth():
    xyz = np.array([[0, 0, 1.0], [0.5, -0.2, 3.0]], np.float32)
    f = focal_from_fov(60.0, 100)
    assert np.allclose(point_footprints(xyz, 60.0, 100), [1 / f, 3 / f], rtol=1e-6)
    with pytest.raises(InputError, match="in front"):
        point_footprints(np.array([[0, 0, -1.0]], np.float32), 60.0, 100)


def test_round_trip_of_every_field(photo3d, tmp_path):
    pts = photo3d.points
    fp = point_footprints(pts.xyz, photo3d.fov_y_deg, photo3d.size[0])
    path = write_splat_ply(tmp_path / "s.ply", pts.xyz, pts.rgb, fp, scale_factor=0.6, opacity=0.9)
    raw = read_vertex_properties(path)
    assert tuple(raw) == SPLAT_PROPERTIES and all(v.dtype == np.float32 for v in raw.values())
    assert np.allclose(raw["f_dc_0"], (pts.rgb[:, 0] - 0.5) / SH_C0, atol=1e-5)
    assert np.allclose(raw["opacity"], np.log(0.9 / 0.1), atol=1e-5)  # logit
    assert np.allclose(raw["scale_1"], np.log(0.6 * fp), atol=1e-5)  # log of the standard deviation
    assert np.all(raw["rot_0"] == 1) and np.all(raw["rot_1"] == 0)
    s = read_splat_ply(path)
    assert np.array_equal(s.xyz, pts.xyz)
    assert np.allclose(s.rgb, pts.rgb, atol=1e-5)
    assert np.allclose(s.opacity, 0.9, atol=1e-6)
    assert np.allclose(s.scale, 0.6 * fp[:, None], rtol=1e-5)
    for v in s:
        assert np.isfinite(v).all()


def test_open3d_reads_the_positions(photo3d, tmp_path):
    import open3d.io as o3io

    pts = photo3d.points
    path = write_splat_ply(tmp_path / "s.ply", pts.xyz, pts.rgb, np.full(len(pts), 0.01))
    cloud = o3io.read_point_cloud(str(path))
    assert np.allclose(np.asarray(cloud.points), pts.xyz, atol=1e-6)


def test_bad_inputs(tmp_path):
    xyz = np.zeros((2, 3), np.float32)
    rgb = np.zeros((2, 3), np.float32)
    with pytest.raises(InputError, match="end in .ply"):
        write_splat_ply(tmp_path / "s.splat", xyz, rgb, np.ones(2))
    with pytest.raises(InputError, match="footprint"):
        write_splat_ply(tmp_path / "s.ply", xyz, rgb, np.zeros(2))
    with pytest.raises(InputError, match="NaN"):
        write_splat_ply(tmp_path / "s.ply", np.full((2, 3), np.nan, np.float32), rgb, np.ones(2))
    not_splat = tmp_path / "plain.ply"
    from stylize3d_core.io.ply import write_ply
    write_ply(not_splat, xyz, rgb)
    with pytest.raises(InputError, match="missing f_dc_0"):
        read_splat_ply(not_splat)
    trunc = tmp_path / "t.ply"
    write_splat_ply(trunc, xyz, rgb, np.ones(2))
    trunc.write_bytes(trunc.read_bytes()[:-5])
    with pytest.raises(InputError, match="expected 2 vertices"):
        read_splat_ply(trunc)


def test_unwritable_destination(tmp_path):
    from stylize3d_core.errors import ExportError

    blocker = tmp_path / "not_a_folder"
    blocker.write_text("x")
    with pytest.raises((ExportError, InputError)):
        write_splat_ply(blocker / "s.ply", np.ones((1, 3), np.float32), np.ones((1, 3), np.float32), np.ones(1))
    assert blocker.read_text() == "x"
