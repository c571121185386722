"""Shared cases of the rasterizer tests (``tests/render/test_rasterize*.py``; tests/support is on pytest's path)."""

from __future__ import annotations

import math

import torch

from stylize3d_core.geometry.camera import intrinsics_from_fov
from stylize3d_core.render import Fragments, rasterize_points
from stylize3d_core.render.rasterize_reference import rasterize_points_reference

F64 = torch.float64


def simple_K(H: int = 6, W: int = 8, f: float = 10.0, dtype=F64) -> torch.Tensor:
    return torch.tensor([[f, 0.0, W / 2], [0.0, f, H / 2], [0.0, 0.0, 1.0]], dtype=dtype)


def point_at(u: float, v: float, z: float, K: torch.Tensor) -> list:
    """Camera-frame point that projects to pixel coordinates (u, v) at depth z."""
    return [(u - float(K[0, 2])) / float(K[0, 0]) * z, (v - float(K[1, 2])) / float(K[1, 1]) * z, z]


def scene(K, specs, C=3, seed=0, dtype=F64):
    """Points from (u, v, z) triples and random features."""
    pts = torch.tensor([point_at(u, v, z, K) for u, v, z in specs], dtype=dtype).reshape(-1, 3)
    feats = torch.randn(len(specs), C, generator=torch.Generator().manual_seed(seed), dtype=dtype)
    return pts, feats


def random_scene(H, W, N, C, seed, dtype=F64):
    """Two depth layers (occlusions), duplicated points, and points to cull."""
    g = torch.Generator().manual_seed(seed)
    K = intrinsics_from_fov(55.0, H, W, dtype=dtype)
    front = torch.rand(N, generator=g) < 0.5
    z = torch.where(front, 1.0 + 0.015 * torch.rand(N, generator=g), 2.0 + 0.03 * torch.rand(N, generator=g))
    u = torch.rand(N, generator=g) * (W + 3) - 1.5
    v = torch.rand(N, generator=g) * (H + 3) - 1.5
    z, u, v = z.to(dtype), u.to(dtype), v.to(dtype)
    pts = torch.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], dim=1)
    pts[:4] = pts[4:8]  # coincident points
    pts[8, 2] = -1.0  # behind the camera
    pts[9, 2] = 0.0  # at the camera
    pts[10, 0] = math.nan
    pts[11, 1] = math.inf
    feats = torch.randn(N, C, generator=g, dtype=dtype)
    return pts, feats, K


def assert_no_nan(frag: Fragments) -> None:
    assert torch.isfinite(frag.image).all()
    assert torch.isfinite(frag.weight).all()
    assert not torch.isnan(frag.depth).any()
    assert torch.isinf(frag.depth[frag.hole]).all() and torch.isfinite(frag.depth[~frag.hole]).all()




def assert_matches_reference(pts, feats, K, settings, generator, point_size=None, point_alpha=None):
    """The fast rasterizer equals the reference in every output and in the features' gradient (float64);
    returns the fast fragments."""
    feats_a = feats.clone().requires_grad_(True)
    feats_b = feats.clone().requires_grad_(True)
    fast = rasterize_points(pts, feats_a, K, settings, point_size=point_size, point_alpha=point_alpha)
    ref = rasterize_points_reference(pts, feats_b, K, settings, point_size=point_size, point_alpha=point_alpha)
    assert torch.allclose(fast.image, ref.image, atol=1e-12)
    assert torch.allclose(fast.weight, ref.weight, atol=1e-12)
    assert torch.equal(fast.depth, ref.depth) and torch.equal(fast.hole, ref.hole)
    upstream = torch.randn(tuple(fast.image.shape), dtype=F64, generator=generator)
    (fast.image * upstream).sum().backward()
    (ref.image * upstream).sum().backward()
    assert torch.allclose(feats_a.grad, feats_b.grad, atol=1e-12)
    return fast

