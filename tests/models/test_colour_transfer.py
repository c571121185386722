"""Colour transfer of the points' colours towards a style: known statistics, strength, edge cases."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch

from stylize3d_core.errors import InputError
from stylize3d_core.models.colour_transfer import MAX_GAIN, ColourTransfer, LabStats, lab_stats, mix_stats, transfer_colours


def _lab(rgb: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(rgb.reshape(-1, 1, 3).astype(np.float32), cv2.COLOR_RGB2Lab).reshape(-1, 3)


def test_lab_stats_match_opencv_and_accept_images_and_tensors():
    g = np.random.default_rng(0)
    img = g.random((20, 30, 3)).astype(np.float32)
    lab = _lab(img)
    s = lab_stats(img)
    np.testing.assert_allclose(s.mean, lab.mean(0), rtol=1e-5, atol=1e-4)
    np.testing.assert_allclose(s.std, lab.std(0), rtol=1e-5, atol=1e-4)
    t = lab_stats(torch.from_numpy(img).permute(2, 0, 1))  # (3, h, w)
    np.testing.assert_allclose(t.mean, s.mean, atol=1e-4)


def test_transfer_reaches_the_style_statistics_inside_the_gamut():
    g = np.random.default_rng(1)
    photo = torch.from_numpy((0.3 + 0.4 * g.random((5000, 3))).astype(np.float32))  # mid-tones
    style_img = (0.35 + 0.3 * g.random((40, 40, 3)) * np.array([1.0, 0.8, 0.6])).astype(np.float32)
    style = lab_stats(style_img)
    out = transfer_colours(photo, style, 1.0)
    got = lab_stats(out.numpy())
    np.testing.assert_allclose(got.mean, style.mean, atol=0.5)
    np.testing.assert_allclose(got.std, style.std, rtol=0.05, atol=0.3)
    # each point keeps its place in the distribution: the order of lightness is kept
    l_in, l_out = _lab(photo.numpy())[:, 0], _lab(out.numpy())[:, 0]
    assert np.corrcoef(l_in, l_out)[0, 1] > 0.999


def test_strength_interpolates_and_zero_is_the_identity():
    g = np.random.default_rng(2)
    photo = torch.from_numpy(g.random((3000, 3)).astype(np.float32))
    style = LabStats(np.array([60.0, 20.0, -10.0], np.float32), np.array([10.0, 5.0, 5.0], np.float32))
    ct = ColourTransfer(photo)
    assert torch.equal(ct(style, 0.0), photo)
    half = lab_stats(ct(style, 0.5).numpy()).mean
    full = lab_stats(ct(style, 1.0).numpy()).mean
    base = ct.stats.mean
    np.testing.assert_allclose(half, (base + full) / 2, atol=1.5)
    with pytest.raises(InputError, match="strength"):
        ct(style, 1.5)


def test_flat_photo_flat_style_and_bad_values_stay_finite():
    flat = torch.full((100, 3), 0.5)
    style = lab_stats(np.random.default_rng(3).random((8, 8, 3)).astype(np.float32))
    out = transfer_colours(flat, style)
    assert torch.isfinite(out).all() and out.min() >= 0 and out.max() <= 1
    # the gain is bounded: a near-flat photo is not blown into noise
    noisy = torch.from_numpy((0.5 + 0.001 * np.random.default_rng(4).standard_normal((500, 3))).astype(np.float32))
    spread = lab_stats(transfer_colours(noisy, style).numpy()).std
    assert (spread <= MAX_GAIN * lab_stats(noisy.numpy()).std + 0.1).all()
    const_style = lab_stats(np.full((4, 4, 3), 0.2, np.float32))
    out = transfer_colours(torch.rand(50, 3), const_style)
    assert torch.isfinite(out).all() and float(out.std(0).max()) < 0.02  # the style's one colour
    nan_style = LabStats(np.array([np.nan, 0, 0], np.float32), np.array([np.inf, 1, 1], np.float32))
    assert torch.isfinite(transfer_colours(torch.rand(50, 3), nan_style)).all()
    assert transfer_colours(torch.zeros(0, 3), style).shape == (0, 3)


def test_mix_stats():
    a = LabStats(np.zeros(3, np.float32), np.ones(3, np.float32))
    b = LabStats(np.full(3, 10.0, np.float32), np.full(3, 3.0, np.float32))
    m = mix_stats(a, b, 0.25)
    np.testing.assert_allclose(m.mean, 2.5)
    np.testing.assert_allclose(m.std, 1.5)
