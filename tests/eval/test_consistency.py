"""Tests of the multi-view consistency metric (warp through the point cloud, RMSE, feature distance)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from stylize3d_core.errors import InputError
from stylize3d_core.eval.consistency import (
    ConsistencySettings,
    consistency_metrics,
    long_range_pairs,
    short_range_pairs,
    view_geometry,
    warp_view,
)
from stylize3d_core.geometry.camera import Cameras
from stylize3d_core.geometry.trajectories import circle
from stylize3d_core.render.plain import PlainRenderer, PlainRenderSettings
from stylize3d_core.scene.pointcloud import PointCloud

H = W = 64
CARD = 0.15  # half-size of the card at z = 0.5


def _grid(lo, hi, n, z):
    g = np.linspace(lo, hi, n, dtype=np.float32)
    y, x = np.meshgrid(g, g, indexing="ij")
    return np.stack([x, y, np.full_like(x, z)], -1).reshape(-1, 3)


def _texture(xyz):
    # Smooth colours that are a function of the 3D position (period ~10 px at 64^2).
    x, y = xyz[:, 0], xyz[:, 1]
    return np.stack([0.5 + 0.3 * np.sin(12 * x), 0.5 + 0.3 * np.cos(10 * y), 0.45 + 0.3 * np.sin(7 * (x + y))],
                    -1).astype(np.float32)


def _cloud(card: bool) -> PointCloud:
    xyz = _grid(-0.9, 0.9, 330, 1.0)
    rgb = _texture(xyz)
    if card:
        c = _grid(-CARD, CARD, 80, 0.5)
        xyz = np.concatenate([xyz, c])
        rgb = np.concatenate([rgb, np.tile(np.float32([[0.9, 0.1, 0.1]]), (len(c), 1))])
    return PointCloud(xyz, rgb, np.zeros(len(xyz), np.uint8), (H, W), 60.0)


@pytest.fixture(scope="module")
def wall():
    return _cloud(card=False)


@pytest.fixture(scope="module")
def card_scene():
    return _cloud(card=True)


def _cams(xs):
    c2w = np.tile(np.eye(4), (len(xs), 1, 1))
    c2w[:, 0, 3] = xs
    return Cameras.create(c2w, 60.0)


def _frames(cloud, cams):
    return list(PlainRenderer(cloud).frames(cams, H, W))


def test_pair_helpers():
    assert short_range_pairs(4) == [(0, 1), (1, 2), (2, 3)]
    assert short_range_pairs(1) == [] and short_range_pairs(0) == []
    assert long_range_pairs(10) == [(0, 7), (1, 8), (2, 9)]
    assert long_range_pairs(10, gap=3)[:2] == [(0, 3), (1, 4)] and len(long_range_pairs(10, gap=3)) == 7
    assert long_range_pairs(5) == []
    for bad in (dict(n_frames=-1), dict(n_frames=3, gap=0), dict(n_frames=2.5), dict(n_frames=True)):
        with pytest.raises(InputError):
            long_range_pairs(**bad)


def test_static_camera_pair_has_zero_error(card_scene):
    cams = _cams([0.02, 0.02])
    frames = _frames(card_scene, cams)
    res = consistency_metrics(card_scene.xyz, frames, cams, [(0, 1), (1, 0), (0, 0)])
    assert all(n > 0.9 * H * W for n in res.n_covisible)
    assert res.rmse < 1e-5 and max(res.per_pair_rmse) < 1e-5
    assert res.feature_distance < 1e-6
    assert res.pairs == ((0, 1), (1, 0), (0, 0))


def test_known_constant_offset_gives_that_rmse(wall):
    cams = _cams([0.0, 0.0])
    a = _frames(wall, cams[:1])[0]
    assert a.min() > 0.1 and a.max() < 0.85
    res = consistency_metrics(torch.from_numpy(wall.xyz), [a, a + 0.1], cams, [(0, 1)])
    assert res.rmse == pytest.approx(0.1, abs=1e-5)
    assert res.feature_distance > 0


def test_consistent_frames_beat_noisy_and_colour_shifted_frames(wall):
    cams = circle(8, x=0.03, y=0.03, z=(0.0, 0.05))
    frames = _frames(wall, cams)
    pairs = short_range_pairs(8) + long_range_pairs(8, gap=4)
    ok = consistency_metrics(wall.xyz, frames, cams, pairs)
    rng = np.random.default_rng(0)
    noisy = [np.clip(f + rng.normal(0, 0.05, f.shape), 0, 1).astype(np.float32) for f in frames]
    shifted = [np.clip(f + 0.08 * np.float32(rng.choice([-1, 1], 3)), 0, 1).astype(np.float32) for f in frames]
    bad_noise = consistency_metrics(wall.xyz, noisy, cams, pairs)
    bad_shift = consistency_metrics(wall.xyz, shifted, cams, pairs)
    assert min(ok.n_covisible) > 0.8 * H * W
    assert ok.rmse < 0.02
    assert bad_noise.rmse > 0.04 and bad_shift.rmse > 0.06
    assert ok.rmse < bad_noise.rmse / 2 and ok.rmse < bad_shift.rmse / 2
    assert ok.feature_distance < bad_noise.feature_distance and ok.feature_distance < bad_shift.feature_distance
    assert np.isfinite(ok.per_pair_feature_distance).all()


def _occluded_in_source(xs_src, xs_dst):
    """Analytic: for each target pixel, where its ray (were it to hit the wall) crosses the card plane
    from the source camera (cx, cy), and where the target's own ray crosses it (dx, dy)."""
    f = (H / 2) / np.tan(np.radians(30.0))
    v, u = np.meshgrid(np.arange(H) + 0.5, np.arange(W) + 0.5, indexing="ij")
    X = (u - W / 2) / f + xs_dst  # wall point (z = 1) in world
    Y = (v - H / 2) / f
    # The ray from the source centre (xs_src, 0, 0) to the wall point crosses z = 0.5 at the midpoint.
    cx, cy = (xs_src + X) / 2, Y / 2
    dx, dy = (u - W / 2) / f * 0.5 + xs_dst, (v - H / 2) / f * 0.5
    hidden = (np.abs(cx) < CARD) & (np.abs(cy) < CARD)
    in_src = np.abs(f * (X - xs_src)) < W / 2 - 1  # the wall point projects inside the source view
    return hidden, in_src, (dx, dy), (cx, cy)


def test_warp_mask_excludes_disoccluded_pixels(card_scene):
    src, dst = -0.06, 0.06
    cams = _cams([src, dst])
    # Silhouettes not blended: a blended edge pixel mixes card and wall, no one surface point the warp carries.
    frames = list(PlainRenderer(card_scene, PlainRenderSettings(blend_coverage=False)).frames(cams, H, W))
    pts = torch.from_numpy(card_scene.xyz)
    g0, g1 = view_geometry(pts, cams[0], H, W), view_geometry(pts, cams[1], H, W)
    image0 = torch.from_numpy(frames[0]).permute(2, 0, 1)
    warp = warp_view(image0, g0, cams[0], g1, cams[1])
    mask = warp.mask.numpy()
    hidden, in_src, (dx, dy), (cx, cy) = _occluded_in_source(src, dst)
    # A margin of 1.5 px (at the card's depth) around the card's edges, where splats bleed.
    margin = 1.5 * 0.5 / ((H / 2) / np.tan(np.radians(30.0)))
    wall_in_dst = (np.abs(dx) > CARD + margin) | (np.abs(dy) > CARD + margin)
    surely_hidden = wall_in_dst & hidden & (np.abs(cx) < CARD - margin) & (np.abs(cy) < CARD - margin)
    surely_seen = wall_in_dst & in_src & ((np.abs(cx) > CARD + margin) | (np.abs(cy) > CARD + margin))
    assert surely_hidden.sum() > 50  # the test scene has a real disocclusion
    assert not mask[surely_hidden].any()
    assert mask[surely_seen].mean() > 0.97
    # Co-visible pixels carry the source's colour of the same surface point: the error there is small.
    res = consistency_metrics(pts, frames, cams, [(0, 1)])
    assert res.n_covisible[0] == int(mask.sum())
    assert res.rmse < 0.03
    assert np.allclose(warp.image.numpy()[:, ~mask], 0.0)


def test_settings_and_bad_inputs(wall):
    cams = _cams([0.0, 0.01])
    frames = _frames(wall, cams)
    with pytest.raises(InputError):
        consistency_metrics(wall.xyz, frames[:1], cams, [(0, 1)])  # fewer frames than cameras
    with pytest.raises(InputError):
        consistency_metrics(wall.xyz, frames, cams, [(0, 2)])
    with pytest.raises(InputError):
        consistency_metrics(wall.xyz, frames, cams, [])
    bad = frames[1].copy()
    bad[3, 4, 0] = np.nan
    with pytest.raises(InputError):
        consistency_metrics(wall.xyz, [frames[0], bad], cams, [(0, 1)])
    with pytest.raises(InputError):
        consistency_metrics(wall.xyz, [frames[0], (frames[1] * 255).astype(np.uint8)], cams, [(0, 1)])
    with pytest.raises(InputError):
        consistency_metrics(wall.xyz, [frames[0], frames[1][:32]], cams, [(0, 1)])
    with pytest.raises(InputError):
        consistency_metrics(wall.xyz[:, :2], frames, cams, [(0, 1)])
    with pytest.raises(InputError):
        ConsistencySettings(depth_tolerance=-0.1)
    with pytest.raises(InputError):
        ConsistencySettings(feature_stages=(3, 1))
    # Cameras that share no co-visible pixel (the second looks away, behind the scene).
    turned = np.eye(4)
    turned[:3, :3] = np.diag([-1.0, 1.0, -1.0])
    away = Cameras.create(np.stack([np.eye(4), turned]), 60.0)
    with pytest.raises(InputError, match="co-visible"):
        consistency_metrics(wall.xyz, frames, away, [(0, 1)])
    # Inputs are not modified.
    before = [f.copy() for f in frames]
    consistency_metrics(wall.xyz, frames, cams, [(0, 1)])
    assert all(np.array_equal(a, b) for a, b in zip(before, frames))


def _flat_card_scene() -> PointCloud:
    """The card scene with one flat colour per surface (grey wall, red card): a consistent frame of it shows
    exactly those two colours, and a bilinear sample can differ from them only where it reads both."""
    cloud = _cloud(card=True)
    rgb = np.where(cloud.xyz[:, 2:3] < 0.75, np.float32([[0.9, 0.1, 0.1]]), np.float32([[0.4, 0.4, 0.4]]))
    return PointCloud(cloud.xyz, rgb.astype(np.float32), cloud.label, cloud.image_size, cloud.fov_y_deg)


def test_one_surface_warp_counts_only_samples_of_one_surface():
    scene = _flat_card_scene()
    cams = _cams([-0.05, 0.05])
    frames = list(PlainRenderer(scene, PlainRenderSettings(blend_coverage=False)).frames(cams, H, W))
    pts = torch.from_numpy(scene.xyz)
    g0, g1 = view_geometry(pts, cams[0], H, W), view_geometry(pts, cams[1], H, W)
    image0 = torch.from_numpy(frames[0]).permute(2, 0, 1)
    target = torch.from_numpy(frames[1]).permute(2, 0, 1)
    strict = warp_view(image0, g0, cams[0], g1, cams[1])
    loose = warp_view(image0, g0, cams[0], g1, cams[1], one_surface=False)
    s, lo = strict.mask.numpy(), loose.mask.numpy()
    assert not (s & ~lo).any()  # the one-surface test only removes pixels
    dropped = lo & ~s
    assert 10 < dropped.sum() < 0.1 * lo.sum()  # a thin band beside the card's edges
    # The dropped pixels are those whose sample mixes card and wall: the sampled colour is neither.
    sampled = loose.image.numpy()
    red, grey = np.float32([0.9, 0.1, 0.1])[:, None], np.float32([0.4, 0.4, 0.4])[:, None]
    off = np.minimum(np.abs(sampled[:, dropped] - red).max(0), np.abs(sampled[:, dropped] - grey).max(0))
    assert (off > 0.01).mean() > 0.5
    # Kept pixels sample one surface: exactly its flat colour, as the target shows it.
    kept = strict.image.numpy()[:, s]
    assert np.minimum(np.abs(kept - red).max(0), np.abs(kept - grey).max(0)).max() < 1e-4
    err_strict = np.abs(strict.image.numpy() - target.numpy())[:, s].max()
    err_loose = np.abs(loose.image.numpy() - target.numpy())[:, lo].max()
    assert err_strict < 1e-4 < 0.1 < err_loose
    # Far from the card both tests agree.
    far = np.ones((H, W), bool)
    far[8:-8, 8:-8] = False
    np.testing.assert_array_equal(s[far], lo[far])
