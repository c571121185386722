"""The prior falls back to smooth depth when it is unsure, and lifts clear objects with depth varying inside."""

from __future__ import annotations

import numpy as np
import pytest

from stylize3d_core.depth.foreground import is_ground_shape
from stylize3d_core.depth.prior import PriorSettings, estimate_prior
from stylize3d_core.eval.ordinal import ordinal_agreement


def textured(h: int, w: int, seed: int, amount: float = 0.06) -> np.ndarray:
    """(h, w, 1) fine texture (grass, gravel) so the texture-based sky test does not fire."""
    return amount * np.random.default_rng(seed).random((h, w, 1)).astype(np.float32)


def max_step(nearness: np.ndarray) -> float:
    """Largest nearness difference between neighbouring pixels (a depth edge)."""
    return float(max(np.abs(np.diff(nearness, axis=0)).max(), np.abs(np.diff(nearness, axis=1)).max()))


def test_smooth_gradient_gives_smooth_depth_without_steps():
    h, w = 240, 320
    y = np.linspace(0, 1, h, dtype=np.float32)[:, None, None]
    rgb = np.clip(np.concatenate([0.2 + 0.5 * y, 0.5 + 0.3 * y, 0.3 * (1 - y)], axis=2) + textured(h, w, 0, 0.2), 0, 1)
    rgb = np.broadcast_to(rgb, (h, w, 3)).astype(np.float32)
    r = estimate_prior(rgb)
    assert not r.foreground.any()
    assert max_step(r.nearness) < 0.02
    assert np.median(r.depth[-h // 10:]) < np.median(r.depth[: h // 10])  # the bottom is nearer


def ball_on_ground(h: int = 180, w: int = 240):
    rgb = np.empty((h, w, 3), np.float32)
    rgb[:] = (0.55, 0.6, 0.65)
    rgb[100:] = np.clip((0.45, 0.4, 0.3) + textured(h - 100, w, 1), 0, 1)
    yy, xx = np.mgrid[0:h, 0:w]
    disc = (yy - 100) ** 2 + (xx - 120) ** 2 < 40**2
    rgb[disc] = (0.9, 0.15, 0.1)
    return rgb, disc, yy, xx


def test_separated_object_is_lifted_with_depth_varying_inside():
    rgb, disc, yy, xx = ball_on_ground()
    r = estimate_prior(rgb)
    assert r.foreground[disc].mean() > 0.8 and r.foreground[~disc].mean() < 0.15
    ring = ((yy - 100) ** 2 + (xx - 120) ** 2 > 46**2) & ((yy - 100) ** 2 + (xx - 120) ** 2 < 60**2) & (yy < 100)
    assert np.median(r.depth[disc]) < np.median(r.depth[ring])
    # not a flat card: the middle stands out of the outline
    inner = (yy - 100) ** 2 + (xx - 120) ** 2 < 12**2
    rim = disc & ((yy - 100) ** 2 + (xx - 120) ** 2 > 34**2)
    assert np.median(r.depth[inner]) < 0.95 * np.median(r.depth[rim])
    assert np.ptp(r.nearness[disc]) > 0.05


def lake_from_the_air(h: int = 180, w: int = 240):
    """A distinct region running from the top edge to the left edge (an aerial view's lake) in a forest."""
    rgb = np.clip(np.full((h, w, 3), (0.2, 0.45, 0.2), np.float32) + textured(h, w, 2, 0.1), 0, 1)
    yy, xx = np.mgrid[0:h, 0:w]
    lake = xx / w + yy / h < 0.8  # the top-left corner, cut by a diagonal shore
    rgb[lake] = np.clip((0.3, 0.7, 0.85) + textured(h, w, 3, 0.2)[lake], 0, 1)
    return rgb, lake


def test_blob_touching_two_frame_edges_is_not_lifted():
    rgb, lake = lake_from_the_air()
    r = estimate_prior(rgb)
    assert r.foreground[lake].mean() < 0.1
    assert max_step(r.nearness) < 0.05


def test_large_blob_is_not_lifted():
    h, w = 180, 240
    rgb = np.clip(np.full((h, w, 3), 0.5, np.float32) + textured(h, w, 4, 0.1), 0, 1)
    rgb[15:170, 15:225] = np.clip((0.8, 0.2, 0.2) + textured(155, 210, 5), 0, 1)  # 75 % of the photo
    r = estimate_prior(rgb)
    assert r.foreground.mean() < 0.05


def test_ground_shape():
    h, w = 100, 200
    yy, xx = np.mgrid[0:h, 0:w]
    road = (yy > 40) & (np.abs(xx - 100) < (yy - 40) * 1.4)  # a road narrowing to the horizon
    assert is_ground_shape(road)
    person = ((yy - 25) ** 2 + (xx - 100) ** 2 < 15**2) | ((yy > 45) & (np.abs(xx - 100) < 40))  # head, shoulders
    assert not is_ground_shape(person)
    mast = ((yy > 10) & (np.abs(xx - 100) < 5)) | ((yy > 80) & (np.abs(xx - 100) < 90))  # rocket on a pad
    assert not is_ground_shape(mast)


@pytest.mark.parametrize(
    "rgb",
    [
        np.full((64, 64, 3), 0.5, np.float32),  # grey
        np.random.default_rng(5).random((8, 8, 3)).astype(np.float32),  # tiny
        np.random.default_rng(6).random((4, 900, 3)).astype(np.float32),  # wide strip
        np.random.default_rng(7).random((900, 6, 3)).astype(np.float32),  # tall strip
    ],
)
def test_grey_tiny_and_extreme_aspect_give_finite_positive_depth(rgb):
    r = estimate_prior(rgb)
    assert r.depth.shape == rgb.shape[:2]
    assert np.isfinite(r.depth).all() and (r.depth > 0).all()


def test_ordinal_agreement_on_the_motorcycle_pair(motorcycle):
    """Behaviour, not timing: the prior orders at least 76 % of the pairs of the motorcycle's ground truth
    right (0.776 measured; the prior before the confidence gating: 0.760)."""
    left, _, gt = motorcycle
    assert ordinal_agreement(estimate_prior(left).depth, gt, pairs=200_000, margin=1.0, seed=0) > 0.765


def test_ordinal_agreement_measure():
    gt = np.arange(100, dtype=np.float64).reshape(10, 10)
    gt[0, 0] = np.inf  # no ground truth
    assert ordinal_agreement(1.0 / (1.0 + gt), gt) == pytest.approx(1.0)
    assert ordinal_agreement(1.0 + gt, gt) == pytest.approx(0.0)
    assert ordinal_agreement(np.ones((10, 10)), gt) == pytest.approx(0.5)


def test_min_confidence_setting():
    with pytest.raises(Exception):
        PriorSettings(min_confidence=2.0)
    rgb, disc, _, _ = ball_on_ground()  # a sure object: lifted even at the strictest gate
    assert estimate_prior(rgb, PriorSettings(min_confidence=1.0)).foreground[disc].mean() > 0.8
