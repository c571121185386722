"""Sample rendered views at the projections of 3D points, with a visibility test.

The basis of the multi-view consistency loss (training) and of the consistency
metric (evaluation): a point seen by two views should have the same colour in
both. A point is *visible* in a view when it projects inside the image, lies in
front of the camera, and is not behind the view's front surface (its depth is
within a relative tolerance of the z-buffer at that pixel).

Sampling is bilinear with pixel centres at +0.5 (``grid_sample`` with
``align_corners=False`` uses exactly that convention) and differentiable with
respect to the images.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
import torch.nn.functional as F

from ..checks import check_shape
from ..errors import InputError
from ..geometry.camera import Cameras, project, transform_points


class ViewSamples(NamedTuple):
    """Colours of N points in one view.

    Attributes:
        colour: (N, C) bilinearly sampled image values (0 where not visible).
        visible: (N,) bool.
    """

    colour: torch.Tensor
    visible: torch.Tensor


def sample_view(
    points_world: torch.Tensor,
    image: torch.Tensor,
    zbuffer: torch.Tensor,
    camera: Cameras,
    depth_tolerance: float = 0.02,
) -> ViewSamples:
    """Sample ``image`` (C, H, W) at the projections of ``points_world`` (N, 3).

    Args:
        points_world: (N, 3) points in world coordinates.
        image: (C, H, W) rendered view (gradients flow to it).
        zbuffer: (H, W) front-most depth of that view (``Fragments.depth``; +inf at holes).
        camera: the single camera that rendered the view.
        depth_tolerance: relative depth band for the visibility test (as the rasterizer's).
    """
    check_shape(points_world, "points_world", (None, 3))
    check_shape(image, "image", (None, None, None))
    H, W = image.shape[1:]
    check_shape(zbuffer, "zbuffer", (H, W))
    if len(camera) != 1:
        raise InputError("camera", f"expected one camera, got {len(camera)}")
    dtype = image.dtype
    w2c = camera.world_to_cam()[0].to(dtype)
    K = camera.intrinsics(H, W, dtype=dtype)[0]
    pts = transform_points(w2c, points_world.to(dtype))  # (N, 3)
    uv, z = project(pts, K)  # (N, 2), (N,)
    inside = (z > 1e-6) & (uv[:, 0] >= 0) & (uv[:, 0] < W) & (uv[:, 1] >= 0) & (uv[:, 1] < H)
    inside &= torch.isfinite(uv).all(dim=1)
    uv_safe = torch.where(inside[:, None], uv, torch.zeros_like(uv))
    col = uv_safe[:, 0].long().clamp(0, W - 1)
    row = uv_safe[:, 1].long().clamp(0, H - 1)
    front = zbuffer[row, col].to(dtype)  # (N,)
    visible = inside & torch.isfinite(front) & (z <= front * (1.0 + depth_tolerance))
    grid = torch.stack([uv_safe[:, 0] / W * 2 - 1, uv_safe[:, 1] / H * 2 - 1], dim=-1)  # (N, 2)
    sampled = F.grid_sample(
        image.unsqueeze(0), grid.view(1, 1, -1, 2), mode="bilinear", padding_mode="border", align_corners=False
    )[0, :, 0].transpose(0, 1)  # (N, C)
    sampled = torch.where(visible[:, None], sampled, torch.zeros_like(sampled))
    return ViewSamples(sampled, visible)


def pairwise_consistency(samples_a: ViewSamples, samples_b: ViewSamples) -> tuple:
    """Mean L1 and RMSE of the colour difference over points visible in both views.

    Returns ``(l1, rmse, count)``; ``l1`` and ``rmse`` are 0-dim tensors (0 when
    no point is visible in both) and ``count`` the number of co-visible points.
    """
    both = samples_a.visible & samples_b.visible  # (N,)
    n = int(both.sum())
    if n == 0:
        zero = samples_a.colour.sum() * 0.0
        return zero, zero, 0
    d = samples_a.colour[both] - samples_b.colour[both]  # (n, C)
    l1 = d.abs().mean()
    rmse = torch.sqrt((d**2).sum(dim=1).mean() / d.shape[1])
    return l1, rmse, n
