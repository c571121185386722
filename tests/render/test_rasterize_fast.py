"""The compiled inference path of the rasterizer against its tensor path and the reference."""

from __future__ import annotations

import math
from dataclasses import replace
import warnings

import pytest
import torch

from stylize3d_core import threads as threads_module
from stylize3d_core.errors import InputError, RenderInterrupted
from stylize3d_core.render import rasterize_fast
from stylize3d_core.render.rasterize import RasterSettings, rasterize_points
from stylize3d_core.geometry.camera import intrinsics_from_fov
from stylize3d_core.render.rasterize_reference import rasterize_points_reference

pytestmark = pytest.mark.skipif(not rasterize_fast.available(), reason="Numba is not installed")


def random_scene(H, W, N, C, seed, dtype=torch.float32):
    """Two depth layers a little apart, points off the image, coincident, behind, at the camera, NaN, inf."""
    g = torch.Generator().manual_seed(seed)
    K = intrinsics_from_fov(50.0, H, W, dtype=dtype)
    z = torch.where(torch.rand(N, generator=g) < 0.6, 1.0 + 0.01 * torch.rand(N, generator=g),
                    1.8 + 0.05 * torch.rand(N, generator=g)).to(dtype)
    u = (torch.rand(N, generator=g) * (W + 4) - 2).to(dtype)
    v = (torch.rand(N, generator=g) * (H + 4) - 2).to(dtype)
    pts = torch.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], dim=1)
    pts[:5] = pts[5:10]
    pts[10, 2], pts[11, 2], pts[12, 0], pts[13, 1] = -1.0, 0.0, math.nan, math.inf
    return pts, torch.randn(N, C, generator=g, dtype=dtype), K


def _both(pts, feats, K, settings, monkeypatch, **kw):
    with torch.inference_mode():
        assert rasterize_fast.applies(pts, feats, settings, None)
        fast = rasterize_points(pts, feats, K, settings, **kw)
        slow = rasterize_points(pts, feats, K, replace(settings, backend="tensor"), **kw)
    return fast, slow


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("channels", [3, 35])
def test_compiled_path_matches_the_tensor_path_and_the_reference(seed, channels, monkeypatch):
    H, W = 19, 23
    pts, feats, K = random_scene(H, W, 250, channels, seed=seed, dtype=torch.float32)
    settings = RasterSettings(H, W)
    fast, slow = _both(pts, feats, K, settings, monkeypatch)
    assert torch.equal(fast.hole, slow.hole)  # the same taps pass the same float32 tests
    assert torch.equal(fast.depth, slow.depth)  # a min: order-free
    torch.testing.assert_close(fast.weight, slow.weight, rtol=1e-6, atol=1e-6)  # sums in another order
    torch.testing.assert_close(fast.image, slow.image, rtol=1e-5, atol=1e-5)
    assert fast.image.shape == (channels, H, W) and fast.image.permute(1, 2, 0).is_contiguous()
    ref = rasterize_points_reference(pts, feats, K, settings)
    assert torch.equal(fast.hole, ref.hole)
    torch.testing.assert_close(fast.image, ref.image.float(), rtol=1e-4, atol=1e-4)
    assert torch.isfinite(fast.image).all() and not torch.isnan(fast.depth).any()
    assert fast.hole.any() and not fast.hole.all()  # the scene has both
    assert torch.isinf(fast.depth[fast.hole]).all()


def test_known_values_one_point_between_four_pixels():
    K = torch.tensor([[10.0, 0, 2.0], [0, 10.0, 2.0], [0, 0, 1]])
    # u = v = 1.75 -> a = b = 1.25: pixels (1, 1) 0.5625, (1, 2) 0.1875, (2, 1) 0.1875, (2, 2) 0.0625
    pts = torch.tensor([[-0.025, -0.025, 1.0]])
    feats = torch.tensor([[2.0, -1.0]])
    with torch.inference_mode():
        frags = rasterize_points(pts, feats, K, RasterSettings(4, 4))
    expected = torch.zeros(4, 4)
    expected[1, 1], expected[1, 2], expected[2, 1], expected[2, 2] = 0.5625, 0.1875, 0.1875, 0.0625
    torch.testing.assert_close(frags.weight, expected)
    covered = expected > 0
    assert torch.equal(~frags.hole, covered)
    torch.testing.assert_close(frags.image[0][covered], torch.full((4,), 2.0))
    torch.testing.assert_close(frags.image[1][covered], torch.full((4,), -1.0))
    assert (frags.image[:, ~covered] == 0).all() and (frags.depth[covered] == 1.0).all()


def test_nearer_surface_hides_the_one_behind_and_empty_clouds():
    K = torch.tensor([[10.0, 0, 2.0], [0, 10.0, 2.0], [0, 0, 1]])
    pts = torch.tensor([[0.0, 0.0, 1.0], [0.0, 0.0, 3.0], [0.0, 0.0, -1.0], [math.nan, 0.0, 1.0]])
    feats = torch.tensor([[1.0], [5.0], [7.0], [9.0]])
    with torch.inference_mode():
        frags = rasterize_points(pts, feats, K, RasterSettings(4, 4))
        empty = rasterize_points(pts[:0], feats[:0], K, RasterSettings(4, 4))
    assert float(frags.image[0, 1, 1]) == 1.0 and float(frags.depth[1, 1]) == 1.0
    assert empty.hole.all() and (empty.image == 0).all() and torch.isinf(empty.depth).all()


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("chunk", [1, 50, 10_000])
def test_result_does_not_depend_on_chunks_or_threads(threads, chunk, monkeypatch):
    H, W = 15, 12
    pts, feats, K = random_scene(H, W, 700, 6, seed=4, dtype=torch.float32)
    settings = RasterSettings(H, W)
    with torch.inference_mode():
        one = rasterize_points(pts, feats, K, settings)
        monkeypatch.setattr(threads_module, "THREADS", threads)
        calls = []
        chunked = rasterize_points(pts, feats, K, settings, chunk_points=chunk,
                                   should_stop=lambda: calls.append(1) and False)
    for a, b in zip(one, chunked):
        assert torch.equal(a, b)  # to the bit
    assert len(calls) >= 2 * -(-700 // min(chunk, 700))  # each of the two passes over the points checks per chunk


def test_stop_is_honoured_inside_the_compiled_passes():
    pts, feats, K = random_scene(15, 12, 700, 6, seed=4, dtype=torch.float32)
    for n in (0, 3, 12):
        calls = []
        with torch.inference_mode(), pytest.raises(RenderInterrupted):
            rasterize_points(pts, feats, K, RasterSettings(15, 12), chunk_points=50,
                             should_stop=lambda: calls.append(1) or len(calls) > n)
        assert len(calls) == n + 1


def test_the_tensor_path_keeps_what_the_compiled_one_does_not_take():
    pts, feats, K = random_scene(9, 8, 100, 4, seed=1, dtype=torch.float32)
    s = RasterSettings(9, 8)
    size = torch.full((100,), 0.01)
    assert rasterize_fast.applies(pts, feats, s, None)
    assert not rasterize_fast.applies(pts, feats, s, size)  # grown splats
    assert not rasterize_fast.applies(pts, feats, RasterSettings(9, 8, supersample=2), None)
    assert not rasterize_fast.applies(pts, feats, RasterSettings(9, 8, soft_edges=True), None)
    assert not rasterize_fast.applies(pts.double(), feats.double(), s, None)  # float64 computes in float64
    grad = feats.clone().requires_grad_(True)
    assert not rasterize_fast.applies(pts, grad, s, None)  # training: the tensor path's gradient
    with torch.no_grad():
        assert rasterize_fast.applies(pts, grad, s, None)


def test_a_failing_compiled_path_falls_back_to_the_tensor_path(monkeypatch):
    pts, feats, K = random_scene(11, 13, 300, 4, seed=9)
    settings = RasterSettings(11, 13)
    with torch.inference_mode():
        slow = rasterize_points(pts, feats, K, replace(settings, backend="tensor"))
        monkeypatch.setattr(rasterize_fast, "_FAILED", False)  # restored after the test

        def broken(*args, **kwargs):
            raise RuntimeError("no LLVM here")

        monkeypatch.setattr(rasterize_fast, "rasterize_fast", broken)
        with pytest.warns(RuntimeWarning, match="no LLVM here"):
            frags = rasterize_points(pts, feats, K, settings)
        assert rasterize_fast.failed() and not rasterize_fast.applies(pts, feats, settings, None)
        for a, b in zip(frags, slow):
            assert torch.equal(a, b)  # the tensor path's result
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            rasterize_points(pts, feats, K, settings)  # no second warning: the path stays off


def test_the_backend_is_a_setting():
    pts, feats, K = random_scene(9, 8, 200, 3, seed=4)
    with torch.inference_mode():
        assert rasterize_fast.applies(pts, feats, RasterSettings(9, 8), None)
        assert not rasterize_fast.applies(pts, feats, RasterSettings(9, 8, backend="tensor"), None)
    with pytest.raises(InputError, match="backend: must be one of auto, tensor"):
        RasterSettings(9, 8, backend="gpu")
