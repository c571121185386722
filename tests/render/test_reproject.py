import numpy as np
import pytest
import torch

from stylize3d_core.errors import InputError
from stylize3d_core.geometry.camera import Cameras
from stylize3d_core.render.rasterize import RasterSettings
from stylize3d_core.render.rasterizer import PointRasterizer
from stylize3d_core.render.reproject import pairwise_consistency, sample_view


def _scene():
    # A dense plane at z = 1 with a colour that is a function of the 3D position.
    g = torch.linspace(-0.8, 0.8, 300)
    y, x = torch.meshgrid(g, g, indexing="ij")
    pts = torch.stack([x, y, torch.ones_like(x)], -1).reshape(-1, 3)
    col = torch.stack([0.5 + 0.4 * torch.sin(3 * pts[:, 0]), 0.5 + 0.4 * torch.cos(2 * pts[:, 1]),
                       0.3 * torch.ones(len(pts))], -1)
    return pts, col


def _cam(x):
    pose = np.eye(4)
    pose[0, 3] = x
    return Cameras.create(pose, 60.0)


def test_samples_reproduce_point_colours():
    pts, col = _scene()
    cam = _cam(0.05)
    fr = PointRasterizer(RasterSettings(64, 64))(pts, col, cam)
    s = sample_view(pts, fr.image, fr.depth, cam)
    assert s.visible.float().mean() > 0.3
    err = (s.colour[s.visible] - col[s.visible]).abs().max()
    assert err < 0.03


def test_consistent_views_have_zero_error_and_inconsistent_ones_do_not():
    pts, col = _scene()
    ca, cb = _cam(-0.05), _cam(0.05)
    ra = PointRasterizer(RasterSettings(64, 64))(pts, col, ca)
    rb = PointRasterizer(RasterSettings(64, 64))(pts, col, cb)
    sa, sb = sample_view(pts, ra.image, ra.depth, ca), sample_view(pts, rb.image, rb.depth, cb)
    l1, rmse, n = pairwise_consistency(sa, sb)
    assert n > 1000 and rmse < 0.02
    # A view whose content is shifted is inconsistent.
    shifted = torch.roll(rb.image, 5, dims=2)
    l1s, rmses, _ = pairwise_consistency(sa, sample_view(pts, shifted, rb.depth, cb))
    assert rmses > 5 * rmse


def test_occluded_points_are_not_visible():
    pts, col = _scene()
    # An occluding card in front of the plane's centre.
    card = pts[(pts[:, 0].abs() < 0.2) & (pts[:, 1].abs() < 0.2)].clone()
    card[:, 2] = 0.5
    allp = torch.cat([pts, card])
    allc = torch.cat([col, torch.zeros(len(card), 3)])
    cam = _cam(0.0)
    fr = PointRasterizer(RasterSettings(64, 64))(allp, allc, cam)
    s = sample_view(allp, fr.image, fr.depth, cam)
    behind = (pts[:, 0].abs() < 0.1) & (pts[:, 1].abs() < 0.1)
    assert not s.visible[: len(pts)][behind].any()
    assert s.visible[len(pts):].float().mean() > 0.9


def test_gradient_reaches_images():
    pts, col = _scene()
    ca, cb = _cam(-0.05), _cam(0.05)
    ra = PointRasterizer(RasterSettings(32, 32))(pts, col, ca)
    img = ra.image.clone().requires_grad_(True)
    s = sample_view(pts, img, ra.depth, ca)
    s2 = sample_view(pts, ra.image.roll(3, 2), ra.depth, ca)
    l1, _, _ = pairwise_consistency(s, s2)
    l1.backward()
    assert img.grad is not None and img.grad.abs().sum() > 0


def test_no_covisible_points_gives_zero():
    pts, col = _scene()
    fr = PointRasterizer(RasterSettings(16, 16))(pts, col, _cam(0.0))
    behind = pts.clone()
    behind[:, 2] = -1.0
    s = sample_view(behind, fr.image, fr.depth, _cam(0.0))
    l1, rmse, n = pairwise_consistency(s, s)
    assert n == 0 and float(l1) == 0.0 and float(rmse) == 0.0


def test_bad_shapes():
    pts, col = _scene()
    with pytest.raises(InputError):
        sample_view(pts, torch.zeros(3, 8, 8), torch.zeros(4, 4), _cam(0.0))
