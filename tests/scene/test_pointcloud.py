"""Tests of the LDI point cloud (stylize3d_core/scene/pointcloud.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from stylize3d_core.errors import InputError
from stylize3d_core.geometry.camera import NEAR_DEPTH, intrinsics_from_fov, project, unproject_depth_map
from stylize3d_core.scene.ldi import BORDER, INPAINTED, ORIGINAL, build_ldi
from stylize3d_core.scene.pointcloud import PointCloud, PointTensors, ldi_to_points


def plane_ldi(h=48, w=64, z=2.5):
    rgb = np.random.default_rng(0).random((h, w, 3)).astype(np.float32)
    return build_ldi(rgb, np.full((h, w), z, np.float32))


def square_ldi(size=96, lo=30, hi=70):
    depth = np.full((size, size), 3.0, np.float32)
    depth[lo:hi, lo:hi] = 1.0
    rgb = np.zeros((size, size, 3), np.float32)
    rgb[..., 2] = 1.0
    rgb[lo:hi, lo:hi] = [1.0, 0.0, 0.0]
    return build_ldi(rgb, depth)


def test_plane_points_known_values():
    ldi = plane_ldi()
    h, w = ldi.photo_size
    hc, wc = ldi.canvas_size
    p = ldi.pad
    pc = ldi_to_points(ldi, 60.0)
    assert len(pc) == hc * wc and pc.image_size == (h, w) and pc.fov_y_deg == 60.0
    np.testing.assert_allclose(pc.xyz[:, 2], NEAR_DEPTH, rtol=1e-6)  # on the plane z = const
    f = (h / 2) / math.tan(math.radians(30.0))
    z = NEAR_DEPTH
    for i, j in [(0, 0), (p, p), (p + 3, p + 5), (hc - 1, wc - 1), (p + h - 1, p + w // 2)]:
        u, v = j - p + 0.5, i - p + 0.5
        want = [(u - w / 2) / f * z, (v - h / 2) / f * z, z]
        np.testing.assert_allclose(pc.xyz[i * wc + j], want, rtol=1e-5, atol=1e-7)
        np.testing.assert_array_equal(pc.rgb[i * wc + j], ldi.rgb[i, j])
    border = pc.select(BORDER)
    assert len(border) == hc * wc - h * w > 0
    np.testing.assert_allclose(border.xyz[:, 2], NEAR_DEPTH, rtol=1e-6)  # the plane's depth
    # border points lie outside the photo's view, photo points inside
    K = intrinsics_from_fov(60.0, h, w)
    uv_b, _ = project(torch.from_numpy(border.xyz), K)
    outside = (uv_b[:, 0] < 0) | (uv_b[:, 0] > w) | (uv_b[:, 1] < 0) | (uv_b[:, 1] > h)
    assert bool(outside.all())
    assert len(pc.select(INPAINTED)) == 0


def test_photo_points_match_camera_unproject():
    ldi = square_ldi()
    h, w = ldi.photo_size
    pc = ldi_to_points(ldi, 45.0)
    K = intrinsics_from_fov(45.0, h, w, dtype=torch.float64)
    ref = unproject_depth_map(torch.from_numpy(ldi.depth[ldi.photo_region]).double(), K)  # (H, W, 3)
    orig = pc.select(ORIGINAL)
    assert len(orig) == h * w
    np.testing.assert_allclose(orig.xyz, ref.reshape(-1, 3).numpy(), rtol=1e-5, atol=1e-7)
    # round trip: projecting them back gives the pixel centres
    uv, z = project(torch.from_numpy(orig.xyz).double(), K)
    v, u = np.mgrid[:h, :w]
    np.testing.assert_allclose(uv[:, 0].numpy(), (u + 0.5).ravel(), atol=1e-3)
    np.testing.assert_allclose(uv[:, 1].numpy(), (v + 0.5).ravel(), atol=1e-3)


def test_hidden_points_lie_on_the_same_rays_behind():
    ldi = square_ldi()
    pc = ldi_to_points(ldi, 60.0)
    hc, wc = ldi.canvas_size
    n0 = hc * wc
    hidden = pc.select(INPAINTED)
    assert len(hidden) == int(ldi.hidden_mask.sum()) > 0
    assert len(pc) == ldi.num_points == n0 + len(hidden)
    # layer 1 follows layer 0, in row-major order of the hidden mask
    rows, cols = np.nonzero(ldi.hidden_mask)
    front = pc.xyz[rows * wc + cols]  # (M, 3) layer-0 points on the same pixels
    back = pc.xyz[n0:]
    np.testing.assert_allclose(back[:, :2] / back[:, 2:], front[:, :2] / front[:, 2:], atol=1e-6)
    assert (back[:, 2] > front[:, 2]).all()
    np.testing.assert_allclose(back[:, 2], 3.0 * ldi.depth_scale, rtol=1e-3)  # on the wall
    assert (hidden.rgb[:, 0] < 0.02).all() and (hidden.rgb[:, 2] > 0.98).all()  # blue, never red
    np.testing.assert_array_equal(pc.label[n0:], INPAINTED)


def test_select_and_to_tensors():
    ldi = square_ldi()
    pc = ldi_to_points(ldi, 60.0)
    counts = [len(pc.select(lab)) for lab in (ORIGINAL, INPAINTED, BORDER)]
    assert sum(counts) == len(pc)
    both = pc.select(ORIGINAL, INPAINTED)
    assert len(both) == counts[0] + counts[1]
    assert set(np.unique(both.label).tolist()) == {ORIGINAL, INPAINTED}
    t = pc.to_tensors()
    assert isinstance(t, PointTensors)
    assert t.xyz.shape == (len(pc), 3) and t.xyz.dtype == torch.float32
    assert t.rgb.shape == (len(pc), 3) and t.rgb.dtype == torch.float32
    assert t.label.shape == (len(pc),) and t.label.dtype == torch.uint8
    with pytest.raises(InputError):
        pc.select(7)


def test_partly_covering_silhouette_points_move_and_keep_their_opacity():
    """A red square on blue whose right column covers 0.3 of its pixels (anti-aliased): those points sit
    0.35 px left of their pixel centres (towards the square) with opacity 2 a / (1 + a) and the square's
    colour; every other point is at its centre and opaque, but the column's ends, which the depth gives
    the square though they are the wall's colour (the least share); select and to_tensors keep the
    opacities."""
    size, lo, hi = 96, 30, 70
    depth = np.full((size, size), 3.0, np.float32)
    depth[lo:hi, lo:hi + 1] = 1.0  # the depth edge includes the partly covered column
    rgb = np.zeros((size, size, 3), np.float32)
    rgb[..., 2] = 1.0
    rgb[lo:hi, lo:hi] = [1.0, 0.0, 0.0]
    rgb[lo + 2:hi - 2, hi] = 0.3 * np.float32([1.0, 0.0, 0.0]) + 0.7 * np.float32([0.0, 0.0, 1.0])
    ldi = build_ldi(rgb, depth)
    h, w = ldi.photo_size
    pc = ldi_to_points(ldi, 45.0)
    assert pc.alpha is not None and pc.alpha.dtype == np.float32 and pc.alpha.shape == (len(pc),)
    K = intrinsics_from_fov(45.0, h, w, dtype=torch.float64)
    orig = pc.select(ORIGINAL)
    uv, _ = project(torch.from_numpy(orig.xyz).double(), K)
    uv = uv.numpy().reshape(h, w, 2)
    v, u = np.mgrid[:h, :w]
    shift = uv - np.stack([u + 0.5, v + 0.5], axis=2)  # (H, W, 2)
    alpha = orig.alpha.reshape(h, w)
    column = (slice(lo + 2, hi - 2), hi)
    np.testing.assert_allclose(shift[column][:, 0], -0.35, atol=1e-3)  # (1 - 0.3) / 2 towards the square
    np.testing.assert_allclose(shift[column][:, 1], 0.0, atol=1e-3)
    np.testing.assert_allclose(alpha[column], 2 * 0.3 / 1.3, atol=1e-4)
    np.testing.assert_allclose(orig.rgb.reshape(h, w, 3)[column], np.broadcast_to([1.0, 0.0, 0.0], (hi - lo - 4, 3)), atol=1e-4)
    # the column's ends are the wall's blue at the square's depth: drawn at the least share
    ends = (np.array([lo, lo + 1, hi - 2, hi - 1]), hi)
    np.testing.assert_allclose(alpha[ends], 2 * 0.1 / 1.1, atol=1e-4)
    np.testing.assert_allclose(np.hypot(shift[ends][:, 0], shift[ends][:, 1]), 0.45, atol=1e-3)  # (corners: diagonally)
    assert (shift[ends][:, 0] < -0.3).all()
    rest = np.ones((h, w), bool)
    rest[lo:hi, hi] = False
    assert np.abs(shift[rest]).max() < 1e-3 and (alpha[rest] == 1.0).all()
    assert (pc.select(INPAINTED).alpha == 1.0).all()
    assert torch.equal(pc.to_tensors().alpha, torch.from_numpy(pc.alpha))
    with pytest.raises(InputError, match="alpha"):
        PointCloud(pc.xyz, pc.rgb, pc.label, pc.image_size, pc.fov_y_deg, np.zeros(len(pc), np.float32))


def test_points_are_finite_and_colours_in_range():
    ldi = square_ldi()
    pc = ldi_to_points(ldi, 90.0)
    assert np.isfinite(pc.xyz).all() and np.isfinite(pc.rgb).all()
    assert (pc.rgb >= 0).all() and (pc.rgb <= 1).all()
    assert (pc.xyz[:, 2] > 0).all()


@pytest.mark.parametrize("fov", [0.0, 180.0, float("nan")])
def test_bad_fov_raises(fov):
    with pytest.raises(InputError):
        ldi_to_points(plane_ldi(), fov)


def test_bad_ldi_raises():
    with pytest.raises(InputError):
        ldi_to_points({"depth": np.ones((4, 4))}, 60.0)


def test_point_cloud_validation():
    xyz = np.zeros((5, 3), np.float32)
    rgb = np.zeros((5, 3), np.float32)
    label = np.zeros(5, np.uint8)
    PointCloud(xyz, rgb, label, (4, 4), 60.0)
    with pytest.raises(InputError):
        PointCloud(xyz[:, :2], rgb, label, (4, 4), 60.0)
    with pytest.raises(InputError):
        PointCloud(xyz, rgb[:4], label, (4, 4), 60.0)
    with pytest.raises(InputError):
        PointCloud(xyz.astype(np.float64), rgb, label, (4, 4), 60.0)
    bad = xyz.copy()
    bad[0, 0] = np.nan
    with pytest.raises(InputError):
        PointCloud(bad, rgb, label, (4, 4), 60.0)
    with pytest.raises(InputError):
        PointCloud(xyz, rgb, np.full(5, 9, np.uint8), (4, 4), 60.0)
    with pytest.raises(InputError):
        PointCloud(xyz, rgb, label, (0, 4), 60.0)
    with pytest.raises(InputError):
        PointCloud(xyz, rgb, label, (4, 4), 200.0)
