"""PointRasterizer's camera transform in the (3, N) layout: the same points as transform_points (up to rounding)."""

from __future__ import annotations

import math

import torch

from stylize3d_core.geometry.camera import Cameras, transform_points
from stylize3d_core.render.rasterize import RasterSettings
from stylize3d_core.render.rasterizer import PointRasterizer, camera_points, columns


def _pose() -> torch.Tensor:
    pose = torch.eye(4, dtype=torch.float64)
    a = 0.3
    pose[:3, :3] = torch.tensor([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]],
                                dtype=torch.float64)
    pose[:3, 3] = torch.tensor([0.1, -0.2, 0.05], dtype=torch.float64)
    return pose


def test_camera_points_equal_transform_points_in_either_layout():
    g = torch.Generator().manual_seed(0)
    pts = torch.randn(1000, 3, generator=g, dtype=torch.float64)
    T = _pose()
    want = transform_points(T, pts)
    for given in (pts, columns(pts), columns(pts)[:600]):
        got = camera_points(T, given)
        assert got.shape == given.shape
        torch.testing.assert_close(got, want[:given.shape[0]], rtol=0, atol=1e-12)
        assert got[:, 0].is_contiguous()  # each coordinate's column is contiguous


def test_columns_keeps_values_and_a_prefix_keeps_the_layout():
    pts = torch.arange(12, dtype=torch.float32).view(4, 3)
    c = columns(pts)
    assert torch.equal(c, pts) and c.stride() == (1, 4)
    assert c[:2].t().stride() == (4, 1)


def test_rasterizer_gives_the_same_frame_from_either_layout():
    g = torch.Generator().manual_seed(1)
    pts = torch.randn(500, 3, generator=g) * 0.3 + torch.tensor([0.0, 0.0, 2.0])
    feats = torch.rand(500, 4, generator=g)
    cam = Cameras.create(_pose(), 50.0)
    rast = PointRasterizer(RasterSettings(height=24, width=32))
    a, b = rast(pts, feats, cam), rast(columns(pts), feats, cam)
    torch.testing.assert_close(a.image, b.image, rtol=0, atol=1e-5)  # the transform rounds per layout
    assert (a.hole != b.hole).sum() <= 1
