"""Colour transfer of the points' colours towards a style: known statistics, strength, edge cases."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch

from stylize3d_core.errors import InputError
from stylize3d_core.models.colour_transfer import (
    MAX_GAIN, ColourTransfer, LabStats, gamut_map, lab_stats, mix_stats, transfer_colours,
)


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
    style_img = (0.2 + 0.6 * g.random((40, 40, 3)) * np.array([1.0, 0.8, 0.6])).astype(np.float32)
    style = lab_stats(style_img)
    out = transfer_colours(photo, style, 1.0)
    got = lab_stats(out.numpy())
    np.testing.assert_allclose(got.mean, style.mean, atol=0.5)
    np.testing.assert_allclose(got.std, style.std, rtol=0.05, atol=0.3)
    # a style of less lightness contrast takes the photo's mean lightness but keeps its contrast
    flat_style = lab_stats((0.45 + 0.05 * g.random((40, 40, 3))).astype(np.float32))
    kept = lab_stats(transfer_colours(photo, flat_style, 1.0).numpy())
    assert abs(kept.mean[0] - flat_style.mean[0]) < 0.5
    assert kept.std[0] == pytest.approx(lab_stats(photo.numpy()).std[0], rel=0.05)
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
    # seeded: on ~2 % of random photos L* clipped at black moves the mean past the tolerance
    out = transfer_colours(torch.rand(50, 3, generator=torch.Generator().manual_seed(0)), const_style)
    lab_out = lab_stats(out.numpy())
    assert torch.isfinite(out).all() and (lab_out.std[1:] < 1.0).all()  # the style's one hue (lightness kept)
    np.testing.assert_allclose(lab_out.mean, const_style.mean, atol=2.5)  # L* clipped at black
    nan_style = LabStats(np.array([np.nan, 0, 0], np.float32), np.array([np.inf, 1, 1], np.float32))
    assert torch.isfinite(transfer_colours(torch.rand(50, 3), nan_style)).all()
    assert transfer_colours(torch.zeros(0, 3), style).shape == (0, 3)


def test_mix_stats():
    a = LabStats(np.zeros(3, np.float32), np.ones(3, np.float32))
    b = LabStats(np.full(3, 10.0, np.float32), np.full(3, 3.0, np.float32))
    m = mix_stats(a, b, 0.25)
    np.testing.assert_allclose(m.mean, 2.5)
    np.testing.assert_allclose(m.std, 1.5)


def test_gamut_map_keeps_lightness_and_hue_and_fits_srgb():
    from stylize3d_core.models.colour_transfer import _linear_rgb, gamut_map

    g = np.random.default_rng(6)
    lab = g.uniform([0, -127, -127], [100, 127, 127], (5000, 3)).astype(np.float32)
    out = gamut_map(lab)
    lin = _linear_rgb(out)
    assert ((lin > -1e-3) & (lin < 1 + 1e-3)).all()  # every colour is an sRGB colour
    np.testing.assert_array_equal(out[:, 0], lab[:, 0])  # lightness kept
    chroma_in, chroma_out = np.hypot(lab[:, 1], lab[:, 2]), np.hypot(out[:, 1], out[:, 2])
    assert (chroma_out <= chroma_in + 1e-4).all()
    moved = chroma_out > 1.0
    hue_in = np.arctan2(lab[moved, 2], lab[moved, 1])
    hue_out = np.arctan2(out[moved, 2], out[moved, 1])
    assert np.abs(np.angle(np.exp(1j * (hue_in - hue_out)))).max() < 1e-3  # hue kept
    # in-gamut colours are untouched; our linear conversion matches OpenCV's
    rgb = g.random((500, 1, 3)).astype(np.float32)
    inside = _lab(rgb)
    np.testing.assert_array_equal(gamut_map(inside), inside)
    lin_ref = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4).reshape(-1, 3)
    np.testing.assert_allclose(_linear_rgb(inside), lin_ref, atol=5e-3)
    # a white rim asked to take a saturated hue stays (nearly) white, not cyan
    white = gamut_map(np.array([[99.0, -40.0, -40.0]], np.float32))
    assert np.hypot(white[0, 1], white[0, 2]) < 10.0


def test_linear_rgb_inverts_opencv_lab_inside_the_gamut():
    from stylize3d_core.models.colour_transfer import _linear_rgb

    rgb = np.random.default_rng(5).random((5000, 3), dtype=np.float32)
    lab = cv2.cvtColor(rgb.reshape(-1, 1, 3), cv2.COLOR_RGB2Lab).reshape(-1, 3)
    srgb_to_linear = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    np.testing.assert_allclose(_linear_rgb(lab), srgb_to_linear, atol=6e-3)  # OpenCV rounds its constants


def test_transfer_does_not_depend_on_the_order_of_the_points():
    rng = np.random.default_rng(6)
    rgb = torch.from_numpy(rng.random((20000, 3), dtype=np.float32))
    style = LabStats(np.array([40.0, 30.0, -20.0], np.float32), np.array([25.0, 30.0, 30.0], np.float32))
    perm = torch.from_numpy(rng.permutation(20000))
    a = ColourTransfer(rgb)(style, 0.7)
    b = ColourTransfer(rgb[perm])(style, 0.7)
    assert torch.equal(a[perm], b)


def test_chunks_on_threads_give_the_same_colours(monkeypatch):
    """Many colours are mapped in chunks on a thread pool: the same colours as one pass, bit for bit."""
    import stylize3d_core.models.colour_transfer as ct

    g = np.random.default_rng(5)
    photo = torch.from_numpy(g.random((10_001, 3)).astype(np.float32))  # saturated ones too: gamut mapping
    style = LabStats(np.array([55.0, 35.0, -30.0], np.float32), np.array([25.0, 40.0, 30.0], np.float32))
    monkeypatch.setattr(ct, "_CHUNK", 1 << 20)
    whole = ColourTransfer(photo)(style, 0.9)
    monkeypatch.setattr(ct, "_CHUNK", 999)  # 11 chunks, the last one short
    chunked = ColourTransfer(photo)(style, 0.9)
    assert torch.equal(whole, chunked)


def test_statistics_in_chunks_match_one_pass(monkeypatch):
    """The photo's L*a*b* statistics are combined from chunks computed on threads: the float64 one-pass
    mean and std of the same colours (to float32 rounding), and the same colours whatever the chunking."""
    import stylize3d_core.models.colour_transfer as ct

    g = np.random.default_rng(8)
    photo = torch.from_numpy(g.random((30_001, 3)).astype(np.float32) ** 2)
    lab = ct._to_lab(photo.numpy())
    monkeypatch.setattr(ct, "_CHUNK", 1000)  # 31 chunks, the last one short
    chunked = ColourTransfer(photo)
    np.testing.assert_array_equal(chunked._lab, lab)
    np.testing.assert_allclose(chunked.stats.mean, lab.mean(0, dtype=np.float64), rtol=1e-6)
    np.testing.assert_allclose(chunked.stats.std, lab.std(0, dtype=np.float64), rtol=1e-6)
    monkeypatch.setattr(ct, "_CHUNK", 1 << 20)
    whole = ColourTransfer(photo)
    np.testing.assert_allclose(whole.stats.std, chunked.stats.std, rtol=1e-6)
    flat = ColourTransfer(torch.full((5000, 3), 0.25))
    assert (flat.stats.std == 0).all()
    empty = ColourTransfer(torch.zeros(0, 3))
    assert empty._lab.shape == (0, 3) and (empty.stats.mean == 0).all() and (empty.stats.std == 0).all()


@pytest.mark.parametrize("strength", [1.0, 0.37])
def test_compiled_map_gives_the_numpy_reference_colours_bit_for_bit(strength, monkeypatch):
    """The compiled colour map (Numba: affine map, clip, gamut bisection in one pass) against the numpy lines
    it replaces, on colours that cover the gamut's faces: bright, saturated styles push many out of it."""
    import stylize3d_core.models.colour_transfer as ct

    if ct._kernels() is None:
        pytest.skip("Numba does not import here: only the numpy path runs")
    g = np.random.default_rng(11)
    photo = torch.from_numpy(np.concatenate([g.random((40_000, 3)), np.eye(3), np.zeros((1, 3)), np.ones((1, 3))])
                             .astype(np.float32))
    styles = [LabStats(np.array([60.0, 40.0, -50.0], np.float32), np.array([30.0, 40.0, 40.0], np.float32)),
              LabStats(np.array([95.0, -5.0, 90.0], np.float32), np.array([2.0, 1.0, 50.0], np.float32)),
              LabStats(np.array([5.0, 0.0, 0.0], np.float32), np.array([80.0, 90.0, 90.0], np.float32))]
    fast, ref = ColourTransfer(photo), ColourTransfer(photo)
    ref.compiled = False
    mapped = []

    def counting_gamut_map(lab, steps):  # the reference's colours, counting those outside the gamut
        out = gamut_map(lab, steps)
        mapped.append(int((out != lab).any(axis=1).sum()))
        return out

    monkeypatch.setattr(ct, "gamut_map", counting_gamut_map)
    for style in styles:
        assert torch.equal(fast(style, strength), ref(style, strength))
    assert sum(mapped) > 1000  # the bisection ran on many colours
