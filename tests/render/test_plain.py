"""Tests of the plain renderer's point order (stratified: random level prefixes, memory order inside levels)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from stylize3d_core.render.plain import PREVIEW_MIN_POINTS, StratifiedOrder, random_order


@pytest.mark.parametrize("n", [0, 1, 500, 1024, 1025, 50_000])
def test_is_a_permutation_with_boundaries_from_0_to_n(n):
    s = StratifiedOrder(n, seed=3)
    assert torch.equal(s.order.sort().values, torch.arange(n))
    assert s.bounds[0] == 0 and s.bounds[-1] == n
    assert all(a < b for a, b in zip(s.bounds[:-1], s.bounds[1:]))
    if n > PREVIEW_MIN_POINTS:
        assert s.bounds[1] == PREVIEW_MIN_POINTS
        # each level at most 1/8 of what comes before it (rounded up)
        assert all(b - a <= max(1, -(-a // 8)) for a, b in zip(s.bounds[1:-1], s.bounds[2:]))


def test_levels_are_random_subsets_in_memory_order():
    n = 50_000
    s = StratifiedOrder(n, seed=0)
    perm = random_order(n, 0)
    for lo, hi in zip(s.bounds[:-1], s.bounds[1:]):
        level = s.order[lo:hi]
        assert torch.all(level[1:] > level[:-1])  # ascending original index inside the level
        assert torch.equal(level, perm[lo:hi].sort().values)  # the same points as the random order's
    # a prefix at a boundary is spread over the whole cloud, not its beginning
    k = s.prefix(5000)
    hist = np.histogram(s.order[:k].numpy(), bins=10, range=(0, n))[0]
    assert hist.min() > 0.7 * k / 10


def test_prefix_rounds_up_to_a_boundary():
    s = StratifiedOrder(50_000, seed=0)
    for count in (0, 1, 1024, 1025, 3000, 49_999, 50_000, 10**7):
        k = s.prefix(count)
        assert k in s.bounds and k >= min(count, 50_000)
        assert k <= max(PREVIEW_MIN_POINTS, count * 1.125 + 1)
    assert s.prefix(1024) == 1024 and s.prefix(10**7) == 50_000


# ----------------------------------------------------------------------------- stretched splats


def _ramp_photo(h=96, w=128):
    """A textured photo of a steep ramp: from the left edge, each column 0.035 farther in
    normalised disparity (under the 0.04 tear threshold: one surface, no hidden layer), down
    to a flat wall."""
    from stylize3d_core.depth.types import DepthMap
    from stylize3d_core.scene.photo3d import Photo3D, Photo3DSettings

    rng = np.random.default_rng(0)
    rgb = rng.uniform(0.2, 0.8, (h, w, 3)).astype(np.float32)
    nd = np.maximum(1.0 - 0.035 * np.arange(w), 0.2)  # (W,)
    depth = np.broadcast_to(1.0 / nd, (h, w)).astype(np.float32).copy()
    dm = DepthMap(depth, np.ones((h, w), bool), "metric", "test")
    return rgb, Photo3D.build(rgb, dm, Photo3DSettings(fov_y_deg=60.0))


def test_canvas_grid_shape_recognises_an_ldi_cloud_only():
    from stylize3d_core.render.plain import canvas_grid_shape
    from stylize3d_core.scene.pointcloud import PointCloud

    _, p3d = _ramp_photo()
    pc = p3d.points
    assert canvas_grid_shape(pc) == p3d.ldi.canvas_size
    perm = np.random.default_rng(1).permutation(len(pc))
    shuffled = PointCloud(pc.xyz[perm], pc.rgb[perm], pc.label[perm], pc.image_size, pc.fov_y_deg)
    assert canvas_grid_shape(shuffled) is None
    cut = PointCloud(pc.xyz[:-7], pc.rgb[:-7], pc.label[:-7], pc.image_size, pc.fov_y_deg)
    assert canvas_grid_shape(cut) in (None, p3d.ldi.canvas_size)  # only hidden points cut: still a grid
    head = PointCloud(pc.xyz[7:], pc.rgb[7:], pc.label[7:], pc.image_size, pc.fov_y_deg)
    assert canvas_grid_shape(head) is None


def test_stretched_splats_close_the_gaps_of_a_steep_ramp_and_keep_the_home_view():
    from stylize3d_core.geometry.camera import Cameras
    from stylize3d_core.render.plain import PlainRenderer, PlainRenderSettings

    rgb, p3d = _ramp_photo()
    h, w = p3d.size
    plain = PlainRenderer(p3d.points, PlainRenderSettings(stretch_splats=False))
    stretched = PlainRenderer(p3d.points)
    home = Cameras.identity(60.0)
    np.testing.assert_allclose(stretched.render(home, h, w), plain.render(home, h, w), atol=1e-6)
    T = np.eye(4)
    T[:3, 3] = (0.05, 0.0, 0.2)  # forward (the ramp's near end magnifies 2.5x) and sideways
    cam = Cameras.create(T, 60.0)
    before = float(plain.rasterize(cam, h, w).hole.float().mean())
    after = float(stretched.rasterize(cam, h, w).hole.float().mean())
    assert before > 0.005  # the ramp's points spread apart by more than their splats
    assert after < 0.1 * before
