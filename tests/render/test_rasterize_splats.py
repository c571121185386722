"""The rasterizer's grown splats, soft edges and coverage blending: known values, the reference, chunking."""

from __future__ import annotations

import dataclasses
import math

import pytest
import torch

from stylize3d_core.errors import InputError, RenderInterrupted
from stylize3d_core.geometry.camera import Cameras, intrinsics_from_fov
from stylize3d_core.render import PointRasterizer, RasterSettings, rasterize_points
from stylize3d_core.render.rasterize_reference import rasterize_points_reference

from raster_cases import F64, assert_matches_reference, point_at, random_scene, scene, simple_K


@pytest.fixture(params=["fast", "reference"])
def raster(request):
    """Known-value tests run on both implementations."""
    return rasterize_points if request.param == "fast" else rasterize_points_reference


def footprint(pts: torch.Tensor, K: torch.Tensor, pixels) -> torch.Tensor:
    """Point sizes (N,) that cover ``pixels`` output pixels each in the view of ``K``."""
    return torch.as_tensor(pixels, dtype=pts.dtype).expand(pts.shape[0]) * pts[:, 2] / K[0, 0]


def random_footprints(pts: torch.Tensor, K: torch.Tensor, g: torch.Generator, widest: float) -> torch.Tensor:
    """Point sizes (N,) covering a random 0.5 .. ``widest`` output pixels each (drawn from ``g``); points
    behind the camera (a NaN size) get a tiny one."""
    pixels = 0.5 + (widest - 0.5) * torch.rand(pts.shape[0], generator=g, dtype=F64)
    return footprint(pts, K, pixels).nan_to_num(0.01)


@pytest.mark.parametrize("supersample", [1, 2])
@pytest.mark.parametrize("seed", range(3))
def test_grown_splats_match_reference_forward_and_backward(supersample, seed):
    H, W = 8, 9
    pts, feats, K = random_scene(H, W, 60, 3, seed)
    g = torch.Generator().manual_seed(100 + seed)
    sizes = random_footprints(pts, K, g, 4.0)
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
    sizes = random_footprints(pts, K, g, 3.0)
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
    sizes = random_footprints(pts, K, g, 4.0)
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
    sizes = random_footprints(pts, K, g, 3.5)
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
