"""Tests of the point rasterizer: known values, the slow reference, gradients, bad inputs."""

from __future__ import annotations

import dataclasses
import math

import pytest
import torch

from stylize3d_core.errors import InputError, RenderInterrupted
from stylize3d_core.geometry.camera import Cameras, intrinsics_from_fov, transform_points
from stylize3d_core.render import Fragments, PointRasterizer, RasterSettings, rasterize_points
from stylize3d_core.render.rasterize_reference import rasterize_points_reference

F64 = torch.float64


@pytest.fixture(params=["fast", "reference"])
def raster(request):
    """Known-value tests run on both implementations."""
    return rasterize_points if request.param == "fast" else rasterize_points_reference


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


# ----------------------------------------------------------------------------- known values


def test_point_at_pixel_centre_lands_on_one_pixel(raster):
    K = simple_K()
    pts, feats = scene(K, [(2.5, 3.5, 2.0)])
    frag = raster(pts, feats, K, RasterSettings(6, 8))
    expected_weight = torch.zeros(6, 8, dtype=F64)
    expected_weight[3, 2] = 1.0
    assert torch.equal(frag.weight, expected_weight)
    assert torch.allclose(frag.image[:, 3, 2], feats[0])
    assert frag.image.abs().sum() == frag.image[:, 3, 2].abs().sum()
    assert frag.depth[3, 2] == 2.0
    assert frag.hole.sum() == 47 and not frag.hole[3, 2]
    assert_no_nan(frag)


def test_point_at_pixel_corner_splits_a_quarter_each(raster):
    K = simple_K()
    pts, feats = scene(K, [(3.0, 2.0, 1.5)])
    frag = raster(pts, feats, K, RasterSettings(6, 8))
    expected_weight = torch.zeros(6, 8, dtype=F64)
    expected_weight[1:3, 2:4] = 0.25
    assert torch.allclose(frag.weight, expected_weight, atol=1e-12)
    for i, j in ((1, 2), (1, 3), (2, 2), (2, 3)):
        assert torch.allclose(frag.image[:, i, j], feats[0])
        assert frag.depth[i, j] == 1.5
    assert frag.hole.sum() == 44


def test_bilinear_weights(raster):
    K = simple_K()
    pts, feats = scene(K, [(2.75, 1.25, 1.0)])  # a = 2.25, b = 0.75
    frag = raster(pts, feats, K, RasterSettings(6, 8))
    assert frag.weight[0, 2].item() == pytest.approx(0.75 * 0.25)
    assert frag.weight[0, 3].item() == pytest.approx(0.25 * 0.25)
    assert frag.weight[1, 2].item() == pytest.approx(0.75 * 0.75)
    assert frag.weight[1, 3].item() == pytest.approx(0.25 * 0.75)
    assert frag.weight.sum().item() == pytest.approx(1.0)


def test_nearer_point_occludes_farther_one(raster):
    K = simple_K()
    pts, feats = scene(K, [(2.5, 3.5, 3.0), (2.5, 3.5, 1.0)])
    frag = raster(pts, feats, K, RasterSettings(6, 8))
    assert torch.allclose(frag.image[:, 3, 2], feats[1])
    assert frag.weight[3, 2] == 1.0 and frag.depth[3, 2] == 1.0


def test_zero_weight_corner_does_not_occlude(raster):
    # The near point sits exactly on the centre of pixel (3, 2): its corners on
    # column 3 have weight 0 and must not hide the far point there.
    K = simple_K()
    pts, feats = scene(K, [(2.5, 3.5, 1.0), (3.75, 3.5, 2.0)])
    frag = raster(pts, feats, K, RasterSettings(6, 8))
    assert frag.weight[3, 3].item() == pytest.approx(0.75) and frag.depth[3, 3] == 2.0
    assert torch.allclose(frag.image[:, 3, 3], feats[1])
    assert frag.weight[3, 2] == 1.0 and torch.allclose(frag.image[:, 3, 2], feats[0])


@pytest.mark.parametrize("soft_edges", [False, True])
@pytest.mark.parametrize("supersample", [1, 2])
def test_faint_tap_of_a_nearer_point_does_not_hide_the_surface_behind(raster, supersample, soft_edges):
    """A near point almost on a pixel centre gives the next column a tap of ~1e-5, below the hole
    threshold: it must neither hide the far surface's own point there nor leave a hole."""
    K = simple_K()
    settings = RasterSettings(6, 8, supersample=supersample, soft_edges=soft_edges)
    # the near point's faint tap lands on column 3 (on its left sub-pixel column at 2x)
    u_near = 2.5 if supersample == 1 else 2.75
    for eps, faint in ((1e-5, True), (2e-2, False)):
        pts, _ = scene(K, [(u_near + eps, 3.5, 1.0), (3.5, 3.5, 2.0), (4.5, 3.5, 2.0)], C=1)
        feats = torch.tensor([[1.0], [0.0], [0.0]], dtype=F64)  # near 1, far 0
        frag = raster(pts, feats, K, settings)
        assert not frag.hole[3, 2] and float(frag.image[0, 3, 2]) == pytest.approx(1.0)
        assert not frag.hole[3, 3]
        if faint:  # the far surface shows, and the z-buffer holds its depth
            assert float(frag.image[0, 3, 3]) == pytest.approx(0.0, abs=1e-3) and float(frag.depth[3, 3]) == 2.0
        else:  # a tap above the threshold still occludes
            assert float(frag.image[0, 3, 3]) == pytest.approx(1.0) and float(frag.depth[3, 3]) == 1.0
        assert_no_nan(frag)


@pytest.mark.parametrize("supersample", [1, 2])
def test_photo_grid_edge_over_a_far_surface_has_no_holes(raster, supersample):
    """An LDI-like layer: a near half-plane and a far plane, one point per pixel centre (with the
    rounding jitter of a real projection, 1e-6 px, rightwards on even rows); the column next to the
    near edge shows the far plane, not a hole."""
    H, W = 5, 8
    K = simple_K(H, W)
    g = torch.Generator().manual_seed(3)
    specs = [(j + 0.5, i + 0.5, 1.0 if j < 4 else 2.0) for i in range(H) for j in range(W)]
    pts, _ = scene(K, specs, C=1)
    jitter = (torch.rand(len(specs), 2, generator=g, dtype=F64) - 0.5) * 2e-6
    jitter[:, 0] = torch.tensor([1e-6 if i % 2 == 0 else -1e-6 for i in range(H) for _ in range(W)], dtype=F64)
    pts[:, :2] += jitter * pts[:, 2:] / K[0, 0]
    feats = torch.tensor([[1.0 if z == 1.0 else 0.0] for _, _, z in specs], dtype=F64)
    frag = raster(pts, feats, K, RasterSettings(H, W, supersample=supersample))
    assert not frag.hole.any()
    assert torch.allclose(frag.image[0, :, :4], torch.ones((), dtype=F64))
    assert torch.allclose(frag.image[0, :, 4:], torch.zeros((), dtype=F64), atol=1e-3)
    assert torch.allclose(frag.depth[:, 4:], torch.full((), 2.0, dtype=F64))


def test_points_within_depth_tolerance_blend(raster):
    K = simple_K()
    pts, feats = scene(K, [(2.5, 3.5, 1.01), (2.5, 3.5, 1.0), (2.5, 3.5, 1.03)])
    frag = raster(pts, feats, K, RasterSettings(6, 8, depth_tolerance=0.02))
    assert torch.allclose(frag.image[:, 3, 2], feats[:2].mean(0))
    assert frag.weight[3, 2] == 2.0 and frag.depth[3, 2] == 1.0


def test_coincident_points_average(raster):
    K = simple_K()
    pts, feats = scene(K, [(4.3, 2.2, 1.0)] * 3)
    frag = raster(pts, feats, K, RasterSettings(6, 8))
    assert torch.allclose(frag.weight.sum(), torch.tensor(3.0, dtype=F64))
    touched = frag.weight > 0
    assert torch.allclose(frag.image[:, touched], feats.mean(0)[:, None].expand(-1, 4))


@pytest.mark.parametrize("spec", [(2.5, 3.5, -1.0), (2.5, 3.5, 0.0), (2.5, 3.5, 5e-4),
                                  (-0.5, 3.5, 1.0), (8.5, 3.5, 1.0), (2.5, -3.0, 1.0), (40.0, 90.0, 2.0)])
def test_culled_points_contribute_nothing(spec, raster):
    K = simple_K()
    pts, feats = scene(K, [spec, (6.5, 0.5, 1.0)])
    frag = raster(pts, feats, K, RasterSettings(6, 8))
    assert frag.weight.sum() == 1.0 and frag.weight[0, 6] == 1.0
    assert frag.image.abs().sum() == frag.image[:, 0, 6].abs().sum()


def test_point_just_outside_reaches_the_border(raster):
    K = simple_K()
    pts, feats = scene(K, [(-0.25, 2.5, 1.0)])  # a = -0.75: a quarter on column 0
    frag = raster(pts, feats, K, RasterSettings(6, 8))
    assert frag.weight[2, 0].item() == pytest.approx(0.25) and frag.weight.sum().item() == pytest.approx(0.25)


def test_hole_threshold(raster):
    K = simple_K()
    pts, feats = scene(K, [(2.6, 3.5, 1.0)])  # weights 0.9 and 0.1
    frag = raster(pts, feats, K, RasterSettings(6, 8, hole_weight_threshold=0.2))
    assert not frag.hole[3, 2] and frag.hole[3, 3]
    assert frag.weight[3, 3].item() == pytest.approx(0.1)
    assert frag.image[:, 3, 3].abs().sum() == 0 and frag.depth[3, 3] == math.inf


def test_supersample_point_at_pixel_centre(raster):
    K = simple_K()
    pts, feats = scene(K, [(2.5, 3.5, 2.0)])
    frag = raster(pts, feats, K, RasterSettings(6, 8, supersample=2))
    assert frag.weight[3, 2].item() == pytest.approx(1.0) and frag.weight.sum().item() == pytest.approx(1.0)
    assert torch.allclose(frag.image[:, 3, 2], feats[0]) and frag.depth[3, 2] == 2.0


def test_supersample_visibility_splatting(raster):
    # A far point on the sub-pixel right next to a near one is hidden (the gaps between
    # a near surface's splats must not let the background through) ...
    K = simple_K()
    pts, feats = scene(K, [(0.25, 0.25, 1.0), (0.75, 0.25, 2.0)])
    ss = raster(pts, feats, K, RasterSettings(6, 8, supersample=2))
    assert ss.weight[0, 0].item() == pytest.approx(1.0)
    assert torch.allclose(ss.image[:, 0, 0], feats[0]) and ss.depth[0, 0] == 1.0
    # ... one two sub-pixels away is not, so an output pixel can still mix both surfaces.
    pts, feats = scene(K, [(0.25, 0.25, 1.0), (1.25, 0.25, 2.0), (1.75, 0.25, 2.0)])
    ss = raster(pts, feats, K, RasterSettings(6, 8, supersample=2))
    assert ss.weight[0, 1].item() == pytest.approx(2.0)
    assert torch.allclose(ss.image[:, 0, 1], feats[1:].mean(0))
    plain = raster(pts, feats, K, RasterSettings(6, 8, supersample=1))
    assert torch.allclose(plain.image[:, 0, 0], feats[0])


def test_supersample_hides_a_background_behind_a_magnified_surface(raster):
    # A front surface sampled every 1.6 output pixels (magnified 1.6x) over a dense
    # background: no background colour may show through at 2x supersampling.
    K = simple_K(16, 16)
    front = [(0.3 + 1.6 * i, 0.3 + 1.6 * j, 1.0) for i in range(10) for j in range(10)]
    back = [(0.25 + 0.5 * i, 0.25 + 0.5 * j, 3.0) for i in range(32) for j in range(32)]
    pts, _ = scene(K, front + back, C=1)
    feats = torch.cat([torch.ones(len(front), 1), torch.zeros(len(back), 1)]).to(F64)
    ss = raster(pts, feats, K, RasterSettings(16, 16, supersample=2))
    shown = ~ss.hole[1:14, 1:14]
    assert shown.float().mean() > 0.7
    assert torch.allclose(ss.image[0, 1:14, 1:14][shown], torch.ones((), dtype=F64))
    # At 1x the 2 x 2 splats of the front surface still overlap: no hole, no background.
    plain = raster(pts, feats, K, RasterSettings(16, 16))
    assert not plain.hole.any() and torch.allclose(plain.image, torch.ones((), dtype=F64))


def test_empty_and_all_culled():
    K = simple_K()
    for pts in (torch.zeros(0, 3, dtype=F64), torch.tensor([[0.0, 0.0, -1.0], [math.nan] * 3], dtype=F64)):
        feats = torch.randn(pts.shape[0], 5, dtype=F64, requires_grad=True)
        frag = rasterize_points(pts, feats, K, RasterSettings(6, 8))
        assert frag.image.shape == (5, 6, 8) and frag.image.abs().sum() == 0
        assert frag.hole.all() and torch.isinf(frag.depth).all() and frag.weight.abs().sum() == 0
        frag.image.sum().backward()
        assert feats.grad.shape == feats.shape and feats.grad.abs().sum() == 0


@pytest.mark.parametrize("K", [
    torch.tensor([[1e30, 0, 4], [0, 1e30, 3], [0, 0, 1]], dtype=torch.float32),
    torch.tensor([[1e-30, 0, 4], [0, 1e-30, 3], [0, 0, 1]], dtype=torch.float32),
    torch.tensor([[1e300, 0, 4], [0, 1e300, 3], [0, 0, 1]], dtype=F64),
    torch.tensor([[0.0, 0, 1e20], [0, 0.0, -1e20], [0, 0, 1]], dtype=F64),
    torch.tensor([[-10.0, 0, 4], [0, -10.0, 3], [0, 0, 1]], dtype=F64),
])
def test_extreme_intrinsics_and_positions_give_no_nan(K):
    g = torch.Generator().manual_seed(3)
    pts = torch.randn(200, 3, generator=g) * torch.tensor([1.0, 1.0, 3.0])
    pts[::7] = pts[::7] * 1e30
    pts[::11, 2] = 1e-30
    pts[5] = math.inf
    pts[6] = -math.inf
    pts[7, 0] = math.nan
    feats = torch.randn(200, 4, generator=g)
    frag = rasterize_points(pts, feats, K, RasterSettings(6, 8, supersample=2))
    assert_no_nan(frag)


def test_inputs_are_not_mutated():
    pts, feats, K = random_scene(5, 7, 40, 3, seed=1)
    copies = (pts.clone(), feats.clone(), K.clone())
    rasterize_points(pts, feats, K, RasterSettings(5, 7, supersample=2))
    for a, b in zip((pts, feats, K), copies):
        assert torch.equal(torch.isnan(a), torch.isnan(b)) and torch.equal(a.nan_to_num(), b.nan_to_num())


def test_image_is_channels_last_view():
    pts, feats, K = random_scene(5, 7, 40, 3, seed=2, dtype=torch.float32)
    frag = rasterize_points(pts, feats, K, RasterSettings(5, 7))
    assert frag.image.shape == (3, 5, 7) and frag.image.dtype == torch.float32
    assert frag.image.unsqueeze(0).is_contiguous(memory_format=torch.channels_last)


# ----------------------------------------------------------------------------- against the reference


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


@pytest.mark.parametrize("supersample", [1, 2])
@pytest.mark.parametrize("seed", range(4))
def test_matches_reference_forward_and_backward(supersample, seed):
    H, W = 7, 9
    pts, feats, K = random_scene(H, W, 90, 4, seed)
    settings = RasterSettings(H, W, supersample=supersample)
    fast = assert_matches_reference(pts, feats, K, settings, torch.Generator().manual_seed(seed))
    assert 0 < fast.hole.sum() < H * W  # the scene has both holes and surface


@pytest.mark.parametrize("channels", [3, 20])
def test_inference_matches_the_autograd_path(channels):
    """Inference accumulates per corner (few channels) or in one sort; training through the autograd bags."""
    pts, feats, K = random_scene(11, 13, 300, channels, seed=9)
    settings = RasterSettings(11, 13)
    with torch.inference_mode():
        inf = rasterize_points(pts, feats, K, settings)
    train = rasterize_points(pts, feats.clone().requires_grad_(True), K, settings)
    assert torch.allclose(inf.image, train.image.detach(), atol=1e-12)
    assert torch.equal(inf.hole, train.hole) and torch.equal(inf.weight, train.weight)


def test_float32_matches_reference():
    H, W = 12, 10
    pts, feats, K = random_scene(H, W, 150, 3, seed=7, dtype=torch.float32)
    settings = RasterSettings(H, W)
    fast = rasterize_points(pts, feats, K, settings)
    ref = rasterize_points_reference(pts, feats, K, settings)
    assert torch.allclose(fast.image, ref.image, atol=1e-5)
    assert torch.allclose(fast.weight, ref.weight, atol=1e-5)
    assert torch.equal(fast.hole, ref.hole)


# ----------------------------------------------------------------------------- chunked (interruptible)


@pytest.mark.parametrize("supersample", [1, 2])
@pytest.mark.parametrize("chunk", [1, 7, 64, 1000])
@pytest.mark.parametrize("dtype", [F64, torch.float32])
@pytest.mark.parametrize("channels", [5, 20])  # the per-corner path (<= 16 channels) and the one-sort path
def test_chunked_is_identical_to_one_shot_and_matches_reference(supersample, chunk, dtype, channels):
    H, W = 13, 17
    pts, feats, K = random_scene(H, W, 400, channels, seed=3, dtype=dtype)
    settings = RasterSettings(H, W, supersample=supersample)
    calls = []
    with torch.inference_mode():
        one = rasterize_points(pts, feats, K, settings)
        chunked = rasterize_points(pts, feats, K, settings, chunk_points=chunk,
                                   should_stop=lambda: calls.append(1) and False)
    ref = rasterize_points_reference(pts, feats, K, settings)
    for a, b in zip(one, chunked):
        assert torch.equal(a, b)  # to the bit
    if dtype == F64:  # (float32 rounding can flip a z-buffer test at the tolerance's edge)
        assert torch.allclose(chunked.image, ref.image, atol=1e-12)
        assert torch.equal(chunked.hole, ref.hole)
    # Steps: the point chunks (twice), the weight sums, the kept corners, the pixel bands.
    n_chunks = -(-400 // chunk)
    assert len(calls) >= (2 * n_chunks if chunk < 400 else 1)


def test_chunked_with_gradient_is_identical():
    pts, feats, K = random_scene(9, 11, 200, 3, seed=5)
    settings = RasterSettings(9, 11)
    fa, fb = feats.clone().requires_grad_(True), feats.clone().requires_grad_(True)
    a = rasterize_points(pts, fa, K, settings)
    b = rasterize_points(pts, fb, K, settings, chunk_points=13, should_stop=lambda: False)
    assert torch.equal(a.image, b.image)
    a.image.sum().backward()
    b.image.sum().backward()
    assert torch.equal(fa.grad, fb.grad)


@pytest.mark.parametrize("stop_after", [0, 1, 3, 10, 30])
def test_should_stop_interrupts_between_chunks(stop_after):
    pts, feats, K = random_scene(13, 17, 400, 5, seed=3)
    calls = []

    def should_stop():
        calls.append(1)
        return len(calls) > stop_after

    with pytest.raises(RenderInterrupted):
        rasterize_points(pts, feats, K, RasterSettings(13, 17), chunk_points=16, should_stop=should_stop)
    assert len(calls) == stop_after + 1  # stopped at the first check that said so


def test_empty_cloud_with_chunks():
    K = simple_K()
    frag = rasterize_points(torch.zeros(0, 3, dtype=F64), torch.zeros(0, 2, dtype=F64), K, RasterSettings(6, 8),
                            chunk_points=4, should_stop=lambda: False)
    assert frag.hole.all() and torch.equal(frag.image, torch.zeros(2, 6, 8, dtype=F64))


@pytest.mark.parametrize("chunk", [0, -1, 2.5, True])
def test_bad_chunk_points(chunk):
    pts, feats = scene(simple_K(), [(2.5, 3.5, 2.0)])
    with pytest.raises(InputError, match="chunk_points"):
        rasterize_points(pts, feats, simple_K(), RasterSettings(6, 8), chunk_points=chunk)


@pytest.mark.parametrize("supersample", [1, 2])
def test_gradcheck(supersample):
    pts, feats, K = random_scene(4, 5, 24, 2, seed=11)
    feats.requires_grad_(True)
    settings = RasterSettings(4, 5, supersample=supersample)
    assert torch.autograd.gradcheck(lambda f: rasterize_points(pts, f, K, settings).image, (feats,))


def test_gradient_of_culled_points_is_zero_and_layout_does_not_matter():
    H, W = 6, 7
    pts, feats, K = random_scene(H, W, 50, 3, seed=9)
    feats_t = feats.t().contiguous().requires_grad_(True)  # (C, N): its .t() is a non-contiguous (N, C)
    frag = rasterize_points(pts, feats_t.t(), K, RasterSettings(H, W))
    ref = rasterize_points_reference(pts, feats, K, RasterSettings(H, W))
    assert torch.allclose(frag.image, ref.image, atol=1e-12)
    frag.image.square().sum().backward()
    assert feats_t.grad[:, 8:12].abs().sum() == 0  # behind, at the camera, NaN, inf


# ----------------------------------------------------------------------------- the module


def test_point_rasterizer_matches_function():
    pts, feats, _ = random_scene(6, 8, 60, 3, seed=5)
    pts = pts[12:]  # finite points only
    feats = feats[12:]
    pose = torch.eye(4, dtype=F64)
    angle = 0.1
    pose[:3, :3] = torch.tensor([[math.cos(angle), 0, math.sin(angle)], [0, 1, 0],
                                 [-math.sin(angle), 0, math.cos(angle)]], dtype=F64)
    pose[:3, 3] = torch.tensor([0.05, -0.02, 0.1], dtype=F64)
    cameras = Cameras.create(pose, 50.0)
    settings = RasterSettings(6, 8)
    points_world = transform_points(pose, pts)
    frag = PointRasterizer(settings)(points_world, feats, cameras)
    expected = rasterize_points(pts, feats, intrinsics_from_fov(50.0, 6, 8, dtype=F64), settings)
    assert torch.allclose(frag.image, expected.image, atol=1e-9)
    assert torch.equal(frag.hole, expected.hole)


def test_point_rasterizer_bad_inputs():
    rast = PointRasterizer(RasterSettings(6, 8))
    pts, feats = torch.rand(5, 3), torch.rand(5, 2)
    two = Cameras.create(torch.eye(4).expand(2, 4, 4), 60.0)
    with pytest.raises(InputError, match="one camera"):
        rast(pts, feats, two)
    with pytest.raises(InputError, match="points_world"):
        rast(torch.rand(5, 2), feats, Cameras.identity())
    with pytest.raises(InputError, match="settings"):
        PointRasterizer({"height": 6})


# ----------------------------------------------------------------------------- bad inputs


@pytest.mark.parametrize("kwargs, name", [
    (dict(height=0, width=8), "height"),
    (dict(height=6.0, width=8), "height"),
    (dict(height=True, width=8), "height"),
    (dict(height=6, width=100000), "width"),
    (dict(height=6, width=8, supersample=3), "supersample"),
    (dict(height=6, width=8, depth_tolerance=-0.1), "depth_tolerance"),
    (dict(height=6, width=8, depth_tolerance=math.nan), "depth_tolerance"),
    (dict(height=6, width=8, hole_weight_threshold=0.0), "hole_weight_threshold"),
    (dict(height=6, width=8, near_clip=0.0), "near_clip"),
    (dict(height=6, width=8, near_clip=math.inf), "near_clip"),
])
def test_bad_settings(kwargs, name):
    with pytest.raises(InputError, match=name):
        RasterSettings(**kwargs)


def test_bad_inputs():
    K = simple_K()
    s = RasterSettings(6, 8)
    pts, feats = torch.rand(5, 3, dtype=F64), torch.rand(5, 2, dtype=F64)
    cases = [
        ((torch.rand(5, 2), feats, K, s), "points_cam"),
        ((pts, torch.rand(4, 2), K, s), "features"),
        ((pts, torch.rand(5), K, s), "features"),
        ((pts, torch.rand(5, 0), K, s), "features"),
        ((pts, feats.half(), K, s), "features"),
        ((pts, torch.ones(5, 2, dtype=torch.long), K, s), "features"),
        ((pts, torch.full((5, 2), math.nan), K, s), "features"),
        ((pts, feats, K[:2], s), "K"),
        ((pts, feats, K * math.inf, s), "K"),
        ((pts, feats, K, {"height": 6, "width": 8}), "settings"),
        ((pts.numpy(), feats, K, s), "points_cam"),
    ]
    for args, name in cases:
        with pytest.raises(InputError, match=name):
            rasterize_points(*args)


# ----------------------------------------------------------------------------- grown splats


def footprint(pts: torch.Tensor, K: torch.Tensor, pixels) -> torch.Tensor:
    """Point sizes (N,) that cover ``pixels`` output pixels each in the view of ``K``."""
    return torch.as_tensor(pixels, dtype=pts.dtype).expand(pts.shape[0]) * pts[:, 2] / K[0, 0]


@pytest.mark.parametrize("supersample", [1, 2])
@pytest.mark.parametrize("seed", range(3))
def test_grown_splats_match_reference_forward_and_backward(supersample, seed):
    H, W = 8, 9
    pts, feats, K = random_scene(H, W, 60, 3, seed)
    g = torch.Generator().manual_seed(100 + seed)
    sizes = footprint(pts, K, 0.5 + 3.5 * torch.rand(pts.shape[0], generator=g, dtype=F64))  # 0.5 .. 4 px
    sizes = sizes.nan_to_num(0.01)
    settings = RasterSettings(H, W, supersample=supersample)
    assert_matches_reference(pts, feats, K, settings, g, point_size=sizes)


def test_grown_splat_known_weights_and_unit_footprint_is_bilinear(raster):
    K = simple_K(9, 9)
    pts, feats = scene(K, [(4.5, 4.5, 1.0)], C=1)  # at the centre of pixel (4, 4)
    two = raster(pts, feats, K, RasterSettings(9, 9), point_size=footprint(pts, K, 2.0))
    # tent of half-width 2 at offsets -1, 0, +1 (the +-2 taps weigh 0): 1/4, 1/2, 1/4 per axis
    want = torch.tensor([0.25, 0.5, 0.25], dtype=F64)
    torch.testing.assert_close(two.weight[3:6, 3:6], want[:, None] * want[None])
    assert two.hole.sum() == 81 - 9
    # a footprint of at most one pixel is the bilinear splat
    pts, feats = scene(K, [(4.2, 3.9, 1.0), (6.7, 2.2, 1.5)], C=2)
    plain = raster(pts, feats, K, RasterSettings(9, 9))
    small = raster(pts, feats, K, RasterSettings(9, 9), point_size=footprint(pts, K, 0.7))
    torch.testing.assert_close(plain.weight, small.weight)
    torch.testing.assert_close(plain.image, small.image)


@pytest.mark.parametrize("supersample", [1, 2])
def test_magnified_grid_has_no_holes_with_grown_splats(supersample):
    """A surface whose points land 2.5 px apart (moving in) shows a grid of holes with
    bilinear splats and none with splats grown to the footprint."""
    H, W, step = 40, 40, 2.5
    K = simple_K(H, W, f=30.0)
    coords = torch.arange(-1.0, W + 1, step, dtype=F64)
    uu, vv = torch.meshgrid(coords, coords, indexing="xy")
    specs = [(float(u), float(v), 2.0) for u, v in zip(uu.reshape(-1), vv.reshape(-1))]
    pts, feats = scene(K, specs, C=3)
    settings = RasterSettings(H, W, supersample=supersample)
    plain = rasterize_points(pts, feats, K, settings)
    grown = rasterize_points(pts, feats, K, settings, point_size=footprint(pts, K, step))
    assert plain.hole.float().mean() > 0.2
    assert not grown.hole.any()


@pytest.mark.parametrize("supersample", [1, 2])
@pytest.mark.parametrize("seed", range(2))
def test_soft_edges_match_reference(supersample, seed):
    H, W = 8, 9
    pts, feats, K = random_scene(H, W, 70, 2, seed)
    g = torch.Generator().manual_seed(200 + seed)
    sizes = footprint(pts, K, 0.5 + 2.5 * torch.rand(pts.shape[0], generator=g, dtype=F64)).nan_to_num(0.01)
    settings = RasterSettings(H, W, supersample=supersample, soft_edges=True)
    for size in (None, sizes):
        fast = rasterize_points(pts, feats, K, settings, point_size=size)
        ref = rasterize_points_reference(pts, feats, K, settings, point_size=size)
        assert torch.allclose(fast.image, ref.image, atol=1e-12)
        assert torch.equal(fast.hole, ref.hole)


def test_soft_edges_keep_a_silhouette_from_growing(raster):
    """A grown front splat whose fringe grazes a background pixel hides it by default; with
    soft edges the background pixel keeps its own colour (bilinear splats are unchanged)."""
    K = simple_K(6, 6)
    pts = torch.tensor([point_at(1.5, 2.5, 2.0, K), point_at(3.9, 2.5, 1.0, K)], dtype=F64)  # back, front
    feats = torch.tensor([[0.0], [1.0]], dtype=F64)
    size = footprint(pts, K, torch.tensor([1.0, 2.5], dtype=F64))  # the front covers 2.5 px
    hard = raster(pts, feats, K, RasterSettings(6, 6), point_size=size)
    soft = raster(pts, feats, K, RasterSettings(6, 6, soft_edges=True), point_size=size)
    # pixel (2, 1): the back point's own pixel, 2.4 px from the front point (fringe weight > 0)
    assert float(hard.weight[2, 1]) > 0 and float(hard.image[0, 2, 1]) == pytest.approx(1.0)
    assert float(soft.image[0, 2, 1]) == pytest.approx(0.0)
    assert float(soft.image[0, 2, 3]) == pytest.approx(1.0)  # the front's core pixels stay the front
    plain = raster(pts, feats, K, RasterSettings(6, 6))
    plain_soft = raster(pts, feats, K, RasterSettings(6, 6, soft_edges=True))
    torch.testing.assert_close(plain.image, plain_soft.image)


# ----------------------------------------------------------------------------- chunked grown splats


@pytest.mark.parametrize("supersample", [1, 2])
@pytest.mark.parametrize("chunk", [1, 7, 64, 1000])
@pytest.mark.parametrize("soft_edges", [False, True])
@pytest.mark.parametrize("channels", [3, 20])
@pytest.mark.parametrize("pixels", ["mixed", 0.7])  # grown splats of several tap counts; all bilinear
def test_chunked_grown_splats_are_identical_to_one_shot(supersample, chunk, soft_edges, channels, pixels):
    """A point's taps come from its own footprint, so chunking by points is exact with point sizes too."""
    H, W, N = 13, 17, 400
    pts, feats, K = random_scene(H, W, N, channels, seed=7)
    g = torch.Generator().manual_seed(7)
    px = 0.5 + 3.5 * torch.rand(N, generator=g, dtype=F64) if pixels == "mixed" else pixels
    sizes = footprint(pts, K, px).nan_to_num(0.01)
    settings = RasterSettings(H, W, supersample=supersample, soft_edges=soft_edges)
    calls = []
    with torch.inference_mode():
        one = rasterize_points(pts, feats, K, settings, point_size=sizes)
        chunked = rasterize_points(pts, feats, K, settings, point_size=sizes, chunk_points=chunk,
                                   should_stop=lambda: calls.append(1) and False)
    for a, b in zip(one, chunked):
        assert torch.equal(a, b)  # to the bit
    ref = rasterize_points_reference(pts, feats, K, settings, point_size=sizes)
    assert torch.allclose(chunked.image, ref.image, atol=1e-12)
    assert torch.equal(chunked.hole, ref.hole)
    n_chunks = -(-N // chunk)
    assert len(calls) >= (2 * n_chunks if chunk < N else 1)


@pytest.mark.parametrize("soft_edges", [False, True])
def test_chunked_grown_splats_with_gradient_are_identical(soft_edges):
    pts, feats, K = random_scene(9, 11, 200, 3, seed=5)
    g = torch.Generator().manual_seed(5)
    sizes = footprint(pts, K, 0.5 + 3.5 * torch.rand(200, generator=g, dtype=F64)).nan_to_num(0.01)
    settings = RasterSettings(9, 11, soft_edges=soft_edges)
    fa, fb = feats.clone().requires_grad_(True), feats.clone().requires_grad_(True)
    a = rasterize_points(pts, fa, K, settings, point_size=sizes)
    b = rasterize_points(pts, fb, K, settings, point_size=sizes, chunk_points=13, should_stop=lambda: False)
    for x, y in zip(a, b):
        assert torch.equal(x, y)
    upstream = torch.randn(3, 9, 11, dtype=F64, generator=g)
    (a.image * upstream).sum().backward()
    (b.image * upstream).sum().backward()
    assert torch.equal(fa.grad, fb.grad)


def test_point_rasterizer_takes_point_size_and_should_stop():
    pts, feats, _ = random_scene(6, 8, 60, 3, seed=5)
    pts, feats = pts[12:], feats[12:]  # finite points only
    pose = torch.eye(4, dtype=F64)
    cameras = Cameras.create(pose, 50.0)
    settings = RasterSettings(6, 8, soft_edges=True)
    K = intrinsics_from_fov(50.0, 6, 8, dtype=F64)
    sizes = footprint(pts, K, 2.5)
    frag = PointRasterizer(settings)(pts, feats, cameras, sizes, should_stop=lambda: False)
    expected = rasterize_points(pts, feats, K, settings, point_size=sizes)
    assert torch.allclose(frag.image, expected.image, atol=1e-9)
    assert torch.equal(frag.hole, expected.hole)
    with pytest.raises(RenderInterrupted):
        PointRasterizer(settings)(pts, feats, cameras, sizes, should_stop=lambda: True)


# ----------------------------------------------------------------------------- coverage blending


def test_blend_coverage_antialiases_a_silhouette(raster):
    """A near point 0.3 px past a pixel boundary covers 0.3 of the next pixel (its bilinear weight):
    with blend_coverage that pixel shows 0.3 near over 0.7 of the far surface behind; without it,
    the near surface alone. A pixel with nothing behind shows its front alone either way."""
    K = simple_K()
    pts, _ = scene(K, [(2.5 + 0.3, 3.5, 1.0), (3.5, 3.5, 2.0), (3.5, 1.5, 1.0)], C=1)
    feats = torch.tensor([[1.0], [0.0], [1.0]], dtype=F64)
    size = footprint(pts, K, 1.0)  # one pixel each: bilinear splats, which tile the view
    hard = raster(pts, feats, K, RasterSettings(6, 8), point_size=size)
    soft = raster(pts, feats, K, RasterSettings(6, 8, blend_coverage=True), point_size=size)
    bare = raster(pts, feats, K, RasterSettings(6, 8, blend_coverage=True))  # no sizes: not blended
    assert torch.equal(bare.image, raster(pts, feats, K, RasterSettings(6, 8)).image)
    assert float(hard.image[0, 3, 3]) == pytest.approx(1.0)
    assert float(soft.image[0, 3, 3]) == pytest.approx(0.3)
    assert float(soft.image[0, 3, 2]) == pytest.approx(1.0)  # covered 0.7, nothing behind: the front alone
    assert float(soft.image[0, 1, 3]) == pytest.approx(1.0)  # a lone point
    for frag in (hard, soft):  # the weight, depth and holes are the front's
        assert float(frag.weight[3, 3]) == pytest.approx(0.3) and float(frag.depth[3, 3]) == 1.0
    assert torch.equal(hard.hole, soft.hole)


def test_point_alpha_scales_a_silhouette_points_coverage(raster):
    """A near point at a pixel's centre with opacity 0.4 over a far point: the pixel shows 0.4 of the near
    colour over 0.6 of the far one (blend_coverage with point sizes); opaque, the near colour alone;
    without blend_coverage the opacity is not used. Weight, depth and holes stay the front's."""
    K = simple_K()
    pts, _ = scene(K, [(3.5, 3.5, 1.0), (3.5, 3.5, 2.0), (1.5, 1.5, 1.0)], C=1)
    feats = torch.tensor([[1.0], [0.0], [1.0]], dtype=F64)
    size = footprint(pts, K, 1.0)
    alpha = torch.tensor([0.4, 1.0, 0.5], dtype=F64)
    settings = RasterSettings(6, 8, blend_coverage=True)
    see = raster(pts, feats, K, settings, point_size=size, point_alpha=alpha)
    opaque = raster(pts, feats, K, settings, point_size=size)
    assert float(see.image[0, 3, 3]) == pytest.approx(0.4) and float(opaque.image[0, 3, 3]) == pytest.approx(1.0)
    assert float(see.image[0, 1, 1]) == pytest.approx(1.0)  # nothing behind: the front alone
    assert torch.equal(see.weight, opaque.weight) and torch.equal(see.depth, opaque.depth)
    assert torch.equal(see.hole, opaque.hole)
    hard = RasterSettings(6, 8)
    assert torch.equal(raster(pts, feats, K, hard, point_size=size, point_alpha=alpha).image,
                       raster(pts, feats, K, hard, point_size=size).image)


@pytest.mark.parametrize("bad", [torch.full((3,), 1.5, dtype=F64), torch.full((3,), float("nan"), dtype=F64),
                                 torch.ones(2, dtype=F64), torch.ones(3, dtype=torch.int64)])
def test_point_alpha_is_checked(bad):
    K = simple_K()
    pts, _ = scene(K, [(3.5, 3.5, 1.0), (3.5, 3.5, 2.0), (1.5, 1.5, 1.0)], C=1)
    with pytest.raises(InputError, match="point_alpha"):
        rasterize_points(pts, torch.ones(3, 1, dtype=F64), K, RasterSettings(6, 8, blend_coverage=True),
                         point_size=footprint(pts, K, 1.0), point_alpha=bad)


def test_blend_coverage_keeps_a_magnified_surface_opaque(raster):
    """Grown splats of points 2 px apart (half-width 2) cover their pixels fully: the surface behind
    does not show through, though each pixel's weight is ~1/4."""
    K = simple_K(12, 12)
    front = [(1.0 + 2 * i, 1.0 + 2 * j, 1.0) for i in range(6) for j in range(6)]
    back = [(0.5 + i, 0.5 + j, 3.0) for i in range(12) for j in range(12)]
    pts, _ = scene(K, front + back, C=1)
    feats = torch.cat([torch.ones(len(front), 1), torch.zeros(len(back), 1)]).to(F64)
    size = footprint(pts, K, torch.tensor([2.0] * len(front) + [1.0] * len(back), dtype=F64))
    frag = raster(pts, feats, K, RasterSettings(12, 12, blend_coverage=True), point_size=size)
    inner = (slice(2, 10), slice(2, 10))
    assert float(frag.weight[inner].mean()) < 0.5
    assert torch.allclose(frag.image[0][inner], torch.ones((), dtype=F64))


@pytest.mark.parametrize("spacing,phase", [(1.37, (0.3, 0.6)), (1.5, (0.0, 0.25)), (2.6, (0.45, 0.1))])
def test_blend_coverage_keeps_a_surface_opaque_at_any_magnification_and_phase(raster, spacing, phase):
    """Points ``spacing`` pixels apart with splats of that half-width, at any phase against the pixel grid,
    cover every pixel inside them wholly: the surface behind does not show through as a grid (the tents
    sum to exactly 1; the normalised weights times the half-width squared did not)."""
    K = simple_K(16, 16)
    n = int(14 / spacing)
    front = [(1.0 + phase[0] + spacing * i, 1.0 + phase[1] + spacing * j, 1.0) for i in range(n) for j in range(n)]
    back = [(0.5 + i, 0.5 + j, 3.0) for i in range(16) for j in range(16)]
    pts, _ = scene(K, front + back, C=1)
    feats = torch.cat([torch.ones(len(front), 1), torch.zeros(len(back), 1)]).to(F64)
    size = footprint(pts, K, torch.tensor([spacing] * len(front) + [1.0] * len(back), dtype=F64))
    frag = raster(pts, feats, K, RasterSettings(16, 16, blend_coverage=True), point_size=size)
    lo, hi = int(math.ceil(1.0 + phase[0] + 0.5)), int(1.0 + spacing * (n - 1) - 0.5)
    inner = (slice(lo, hi), slice(lo, hi))
    assert hi - lo >= 6
    assert torch.allclose(frag.image[0][inner], torch.ones((), dtype=F64), atol=1e-9)


@pytest.mark.parametrize("supersample", [1, 2])
@pytest.mark.parametrize("soft_edges", [False, True])
@pytest.mark.parametrize("seed", range(2))
def test_blend_coverage_matches_reference_and_chunks(supersample, soft_edges, seed):
    H, W = 8, 9
    pts, feats, K = random_scene(H, W, 90, 3, seed)
    g = torch.Generator().manual_seed(300 + seed)
    sizes = footprint(pts, K, 0.5 + 3.0 * torch.rand(pts.shape[0], generator=g, dtype=F64)).nan_to_num(0.01)
    settings = RasterSettings(H, W, supersample=supersample, soft_edges=soft_edges, blend_coverage=True)
    blended = 0
    alpha = (0.1 + 0.9 * torch.rand(pts.shape[0], generator=g, dtype=F64)) * (torch.rand(pts.shape[0], generator=g) < 0.5)
    alpha = torch.where(alpha > 0, alpha, 1.0)  # half the points partly opaque
    for size, opacity in ((None, None), (sizes, None), (sizes, alpha)):
        fast = assert_matches_reference(pts, feats, K, settings, g, point_size=size, point_alpha=opacity)
        with torch.inference_mode():
            one = rasterize_points(pts, feats, K, settings, point_size=size, point_alpha=opacity)
            chunked = rasterize_points(pts, feats, K, settings, point_size=size, chunk_points=7,
                                       should_stop=lambda: False, point_alpha=opacity)
        for a, b in zip(one, chunked):
            assert torch.equal(a, b)  # to the bit
        assert torch.allclose(one.image, fast.image, atol=1e-12)  # the inference path too (fast == reference)
        plain = rasterize_points(pts, feats, K, dataclasses.replace(settings, blend_coverage=False), point_size=size)
        blended += int((~torch.isclose(plain.image, fast.image, atol=1e-9)).any(0).sum())
    if supersample == 1:
        assert blended > 0  # some pixels were blended (with point sizes)
    else:  # the sub-pixel z-buffer anti-aliases instead
        assert blended == 0


def test_features_finite_skips_only_the_features_sum_and_gives_the_same_image():
    """``features_finite``: the caller checked the features (a renderer drawing one set frame after frame);
    the image is the checked call's, bit for bit, and every other check still runs."""
    K = simple_K()
    s = RasterSettings(6, 8)
    g = torch.Generator().manual_seed(3)
    pts = torch.rand(40, 3, generator=g, dtype=F64) + torch.tensor([0.0, 0.0, 1.0], dtype=F64)
    feats = torch.rand(40, 4, generator=g, dtype=F64)
    a, b = rasterize_points(pts, feats, K, s), rasterize_points(pts, feats, K, s, features_finite=True)
    assert torch.equal(a.image, b.image) and torch.equal(a.weight, b.weight) and torch.equal(a.hole, b.hole)
    with pytest.raises(InputError, match="features"):  # unchecked by default
        rasterize_points(pts, torch.full((40, 4), math.nan, dtype=F64), K, s)
    with pytest.raises(InputError, match="K"):
        rasterize_points(pts, feats, K * math.inf, s, features_finite=True)
    with pytest.raises(InputError, match="features"):
        rasterize_points(pts, feats[:5], K, s, features_finite=True)
