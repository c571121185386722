"""Tests of the point rasterizer: known values, the slow reference, gradients, bad inputs."""

from __future__ import annotations

import math

import pytest
import torch

from stylize3d_core.errors import InputError, RenderInterrupted
from stylize3d_core.geometry.camera import Cameras, intrinsics_from_fov, transform_points
from stylize3d_core.render import PointRasterizer, RasterSettings, rasterize_points
from stylize3d_core.render.rasterize_reference import rasterize_points_reference

from raster_cases import F64, assert_matches_reference, assert_no_nan, random_scene, scene, simple_K


@pytest.fixture(params=["fast", "reference"])
def raster(request):
    """Known-value tests run on both implementations."""
    return rasterize_points if request.param == "fast" else rasterize_points_reference


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
