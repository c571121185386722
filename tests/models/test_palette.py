"""Palette matching: the fit reaches the statistics it can, is the identity where nothing is to be done, and
the map is one affine colour matrix."""

import cv2
import numpy as np
import pytest
import torch

from stylize3d_core.errors import InputError
from stylize3d_core.models.colour_transfer import LabStats
from stylize3d_core.models.palette import apply_palette, fit_palette, palette_target


def _stats(rgb):
    lab = cv2.cvtColor(np.ascontiguousarray(rgb, np.float32).reshape(-1, 1, 3), cv2.COLOR_RGB2Lab).reshape(-1, 3)
    return lab.mean(0), lab.std(0)


def _image(seed=0, h=48, w=64):
    g = np.random.default_rng(seed)
    base = cv2.GaussianBlur(g.random((h, w, 3)).astype(np.float32), (0, 0), 2.0)
    return (0.25 + 0.5 * (base - base.min()) / (base.max() - base.min())).astype(np.float32)


def test_fit_reaches_statistics_an_affine_map_can_make():
    img = _image()
    # the target: the statistics of an affine recolouring of the image itself (reachable, inside the gamut)
    m_true = np.array([[0.8, 0.1, 0.0], [0.05, 0.7, 0.1], [0.0, 0.1, 0.6], [0.1, 0.05, 0.2]], np.float32)
    want = np.hstack([img.reshape(-1, 3), np.ones((img.size // 3, 1), np.float32)]) @ m_true
    mean, std = _stats(want)
    pal = fit_palette(img, LabStats(mean, std), min_lightness_gain=0.0)  # (this one lowers the contrast)
    got_mean, got_std = _stats(apply_palette(torch.from_numpy(img).permute(2, 0, 1), pal.matrix).permute(1, 2, 0).numpy())
    assert np.abs(got_mean - mean).max() < 0.5 and np.abs(got_std - std).max() < 0.5  # L*a*b* units
    assert np.abs(pal.after.mean - mean).max() < 0.5 and np.abs(pal.after.std - std).max() < 0.5
    assert np.abs(pal.before.std - std).max() > 2.0  # it had something to do


def test_own_statistics_give_the_identity_and_apply_known_values():
    img = _image(1)
    mean, std = _stats(img)
    pal = fit_palette(img, LabStats(mean, std))
    assert np.abs(pal.matrix - np.vstack([np.eye(3), np.zeros((1, 3))])).max() < 0.02
    m = np.array([[0.5, 0, 0], [0, 1, 0], [0, 0, 2], [0.1, 0.2, -0.5]], np.float32)
    x = torch.tensor([[[0.2, 0.9]], [[0.4, 0.9]], [[0.7, 0.1]]])  # two pixels (3, 1, 2)
    out = apply_palette(x, m)[:, 0]
    # [rgb, 1] @ m, clamped to [0, 1]: (0.2, 0.4, 0.7) -> (0.2, 0.6, 0.9); (0.9, 0.9, 0.1) -> (0.55, 1.1 -> 1, -0.3 -> 0)
    assert torch.allclose(out, torch.tensor([[0.2, 0.55], [0.6, 1.0], [0.9, 0.0]]))
    with pytest.raises(InputError):
        apply_palette(torch.zeros(4, 2, 2), m)


def test_degenerate_inputs_stay_finite():
    flat = np.full((16, 16, 3), 0.4, np.float32)
    pal = fit_palette(flat, LabStats(np.array([60.0, 20.0, -10.0], np.float32), np.array([10.0, 5.0, 5.0], np.float32)))
    assert np.isfinite(pal.matrix).all()
    out = apply_palette(torch.from_numpy(flat).permute(2, 0, 1), pal.matrix)
    assert torch.isfinite(out).all() and out.min() >= 0 and out.max() <= 1
    nan = np.full((8, 8, 3), np.nan, np.float32)
    ident = np.vstack([np.eye(3), np.zeros((1, 3))])
    assert np.array_equal(fit_palette(nan, pal.target).matrix, ident)  # no finite pixel: the identity
    img = _image(2)
    bad = LabStats(np.array([np.nan, 0, 0], np.float32), np.ones(3, np.float32))
    assert np.array_equal(fit_palette(img, bad).matrix, ident)
    with pytest.raises(InputError):
        fit_palette(img, pal.target, passes=0)


def test_palette_target_interpolates():
    photo = LabStats(np.array([50.0, 10.0, 20.0], np.float32), np.array([20.0, 5.0, 8.0], np.float32))
    style = LabStats(np.array([40.0, -5.0, 0.0], np.float32), np.array([6.0, 15.0, 2.0], np.float32))
    t0 = palette_target(photo, style, 0.0)
    assert np.allclose(t0.mean, photo.mean) and np.allclose(t0.std, photo.std)
    t1 = palette_target(photo, style, 1.0)
    assert np.allclose(t1.mean, style.mean) and np.allclose(t1.std, style.std)
    th = palette_target(photo, style, 0.5)
    assert np.allclose(th.mean, [45.0, 2.5, 10.0]) and np.allclose(th.std, [13.0, 10.0, 5.0])
    with pytest.raises(InputError):
        palette_target(photo, style, 1.5)


def test_a_flatter_style_keeps_the_lightness_contrast():
    img = _image(3)
    mean, std = _stats(img)
    flat = LabStats(np.array([mean[0] - 5, mean[1] + 10, mean[2]], np.float32),
                    np.array([std[0] / 3, std[1] * 1.5, std[2]], np.float32))
    kept = fit_palette(img, flat)
    assert abs(kept.after.std[0] - std[0]) < 0.5  # L* contrast as it was
    assert abs(kept.after.mean[0] - flat.mean[0]) < 0.5 and abs(kept.after.mean[1] - flat.mean[1]) < 0.5
    lowered = fit_palette(img, flat, min_lightness_gain=0.0)
    assert abs(lowered.after.std[0] - flat.std[0]) < 0.5


def test_apply_is_float32_under_a_bfloat16_autocast():
    m = np.vstack([np.eye(3) * 0.5, np.full((1, 3), 0.25)]).astype(np.float32)
    x = torch.rand(3, 4, 5)
    with torch.autocast(device_type="cpu", dtype=torch.bfloat16):
        out = apply_palette(x, m)
    assert out.dtype == torch.float32 and torch.allclose(out, 0.5 * x + 0.25)


def test_more_passes_come_closer_to_the_target():
    """Each pass corrects what the previous map left of the statistics: the distance to the target
    falls with the passes (1 -> 2 -> 8, the default); the image's own statistics keep the identity."""
    img = _image(3)
    target = LabStats(np.array([45.0, 18.0, -12.0], np.float32), np.array([22.0, 14.0, 16.0], np.float32))

    def distance(passes):
        after = fit_palette(img, target, passes=passes).after
        return float(np.abs(after.mean - target.mean).sum() + np.abs(after.std - target.std).sum())

    d1, d2, d8 = distance(1), distance(2), distance(8)
    assert d8 < d2 < d1
    assert d8 < 0.8 * d2  # two passes were far from converged
    own = fit_palette(img, fit_palette(img, target).before)  # the image's own statistics: the identity, at once
    np.testing.assert_allclose(own.matrix, np.vstack([np.eye(3), np.zeros((1, 3))]), atol=2e-3)
