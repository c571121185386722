"""U-Net decoder: shapes, range, gradients, odd sizes, supersampling, presets, bad input."""

from __future__ import annotations

import pytest
import torch

from stylize3d_core.errors import InputError
from stylize3d_core.models.decoder import (
    DecoderConfig,
    UNetDecoder,
    IDENTITY_TRANSFORM,
    TEXTURE_SCALE,
    apply_colour_transform,
    identity_transform,
    pad_to_multiple,
    supersample_pool,
)


def _inputs(b, c, h, w, seed=0):
    g = torch.Generator().manual_seed(seed)
    feats = torch.randn(b, c, h, w, generator=g)
    mask = (torch.rand(b, 1, h, w, generator=g) > 0.2).float()
    return feats * mask, mask


@pytest.fixture(scope="module")
def lite():
    torch.manual_seed(0)
    return UNetDecoder(DecoderConfig.lite(in_channels=16))


def test_presets():
    paper, lite = DecoderConfig.paper(), DecoderConfig.lite()
    assert (paper.in_channels, paper.width, paper.levels) == (256, 256, 2)
    assert (lite.in_channels, lite.levels) == (64, 2) and lite.width < paper.width
    assert DecoderConfig.lite(supersample=True).supersample


@pytest.mark.parametrize("config", [DecoderConfig.paper(), DecoderConfig.lite()], ids=["paper", "lite"])
def test_shapes_and_range_both_presets(config):
    dec = UNetDecoder(config)
    feats, mask = _inputs(2, config.in_channels, 24, 32)
    with torch.inference_mode():
        rgb = dec(feats, mask)
    assert rgb.shape == (2, 3, 24, 32) and rgb.is_contiguous()
    assert torch.isfinite(rgb).all() and 0.0 <= float(rgb.min()) and float(rgb.max()) <= 1.0


@pytest.mark.parametrize("h, w", [(37, 53), (1, 1), (5, 130), (31, 32)])
def test_odd_sizes(lite, h, w):
    feats, mask = _inputs(1, 16, h, w)
    rgb = lite(feats, mask)
    assert rgb.shape == (1, 3, h, w) and torch.isfinite(rgb).all()


def test_extreme_inputs_stay_in_range(lite):
    feats, mask = _inputs(1, 16, 16, 16)
    with torch.no_grad():
        rgb = lite(feats * 1e6, mask)
    assert torch.isfinite(rgb).all() and 0.0 <= float(rgb.min()) and float(rgb.max()) <= 1.0


def test_gradients_reach_parameters_and_input(lite):
    feats, mask = _inputs(1, 16, 20, 20)
    feats.requires_grad_(True)
    lite.zero_grad()
    lite(feats, mask).mean().backward()
    assert feats.grad is not None and torch.isfinite(feats.grad).all() and feats.grad.abs().sum() > 0
    for name, p in lite.named_parameters():
        assert p.grad is not None and p.grad.abs().sum() > 0, name


def test_gradcheck_float64_tiny_decoder():
    torch.manual_seed(1)
    dec = UNetDecoder(DecoderConfig(in_channels=2, width=8, levels=2, channels_last=False)).double()
    g = torch.Generator().manual_seed(2)
    feats = torch.randn(1, 2, 5, 6, dtype=torch.float64, generator=g, requires_grad=True)
    mask = torch.ones(1, 1, 5, 6, dtype=torch.float64)
    assert torch.autograd.gradcheck(lambda f: dec(f, mask), (feats,))


def test_channels_last_matches_contiguous(lite):
    other = UNetDecoder(DecoderConfig(in_channels=16, width=lite.config.width, channels_last=False))
    other.load_state_dict(lite.state_dict())
    feats, mask = _inputs(1, 16, 24, 20)
    with torch.inference_mode():
        torch.testing.assert_close(lite(feats, mask), other(feats, mask), rtol=1e-4, atol=1e-5)


def test_batch_items_are_independent(lite):
    feats, mask = _inputs(2, 16, 16, 24)
    with torch.inference_mode():
        both = lite(feats, mask)
        torch.testing.assert_close(both[1:], lite(feats[1:], mask[1:]), rtol=1e-4, atol=1e-5)


def test_padding_does_not_leak_into_the_crop_size(lite):
    # The decoder pads 18x18 to 20x20 internally; its output must equal that of an
    # explicitly zero-padded (hole) input, cropped.
    feats, mask = _inputs(1, 16, 18, 18)
    with torch.inference_mode():
        a = lite(feats, mask)
        b = lite(pad_to_multiple(feats, 4), pad_to_multiple(mask, 4))[..., :18, :18]
    torch.testing.assert_close(a, b)


def test_pad_to_multiple():
    x = torch.ones(1, 2, 5, 8)
    y = pad_to_multiple(x, 4)
    assert y.shape == (1, 2, 8, 8) and float(y[..., 5:, :].abs().sum()) == 0.0
    assert pad_to_multiple(x[..., :4, :], 4).shape == (1, 2, 4, 8)


def test_supersample_pool_known_values():
    feats = torch.tensor([[[[4.0, 8.0, 1.0, 1.0], [2.0, 6.0, 1.0, 1.0]]]])  # (1, 1, 2, 4)
    mask = torch.tensor([[[[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]]]])
    pooled, cover = supersample_pool(feats, mask)
    torch.testing.assert_close(pooled, torch.tensor([[[[5.0, 0.0]]]]))  # mean of covered 4 and 6; empty block 0
    torch.testing.assert_close(cover, torch.tensor([[[[0.5, 0.0]]]]))
    with pytest.raises(InputError, match="even"):
        supersample_pool(torch.ones(1, 1, 3, 4), torch.ones(1, 1, 3, 4))


def test_supersampled_decoder_halves_the_size():
    torch.manual_seed(0)
    dec = UNetDecoder(DecoderConfig.lite(in_channels=8, supersample=True))
    feats, mask = _inputs(1, 8, 2 * 19, 2 * 26)
    rgb = dec(feats, mask)
    assert rgb.shape == (1, 3, 19, 26) and torch.isfinite(rgb).all()


def test_bad_inputs(lite):
    feats, mask = _inputs(1, 16, 8, 8)
    with pytest.raises(InputError, match="features"):
        lite(feats[:, :8], mask)
    with pytest.raises(InputError, match="mask"):
        lite(feats, mask[..., :4])
    bad = feats.clone()
    bad[0, 0, 0, 0] = float("nan")
    with pytest.raises(InputError, match="NaN"):
        lite(bad, mask)
    with pytest.raises(InputError, match="width"):
        DecoderConfig(width=30)
    with pytest.raises(InputError, match="levels"):
        DecoderConfig(levels=0)


def test_colour_transform_known_values():
    """out = clamp(rgb + m (A (d - rgb) + b)) with a constant A and b, fractional coverage."""
    g = torch.Generator().manual_seed(3)
    rgb = torch.rand(2, 3, 5, 7, generator=g)
    d = torch.rand(2, 3, 5, 7, generator=g)
    m = torch.rand(2, 1, 5, 7, generator=g)
    a = torch.tensor([[0.5, 0.2, 0.0], [0.0, 1.0, 0.0], [0.1, 0.0, 0.3]])
    off = torch.tensor([0.05, -0.1, 0.0])
    coeff = torch.cat([a.reshape(9), off]).reshape(1, 12, 1, 1).expand(2, 12, 2, 2)  # constant field
    out = apply_colour_transform(rgb, d, m, coeff, (8, 8))
    want = rgb + m * (torch.einsum("ij,bjhw->bihw", a, d - rgb) + off[None, :, None, None])
    torch.testing.assert_close(out, want.clamp(0, 1), rtol=0, atol=1e-6)


@pytest.mark.parametrize("supersample,h,w", [(False, 13, 22), (True, 10, 14)])
def test_colour_transform_head_identity_zero_and_sizes(supersample, h, w):
    torch.manual_seed(1)
    cfg = DecoderConfig(in_channels=8 + 3, width=16, transform_channels=3, supersample=supersample,
                        transform_gain=1.0 / 16)
    dec = UNetDecoder(cfg).eval()
    assert dec.transform.bias.tolist() == list(IDENTITY_TRANSFORM)  # a new decoder starts at the identity
    identity_transform(dec.transform, False)
    plain = UNetDecoder(DecoderConfig(in_channels=8 + 3, width=16, supersample=supersample)).eval()
    plain.load_state_dict({k: v for k, v in dec.state_dict().items() if not k.startswith("transform.")})
    s = 2 if supersample else 1
    feats, mask = _inputs(1, 11, h * s, w * s)
    feats[:, -3:] = feats[:, -3:].abs().clamp(max=1) * mask
    with torch.no_grad():
        zero = dec(feats, mask)
        torch.testing.assert_close(zero, plain(feats, mask), rtol=0, atol=1e-6)  # zero head: the U-Net
        identity_transform(dec.transform)
        ident = dec(feats, mask)
    assert ident.shape == (1, 3, h, w)
    if supersample:
        colours, cover = supersample_pool(feats[:, -3:], mask)
    else:
        colours, cover = feats[:, -3:], mask
    full = cover[:, 0] == 1
    torch.testing.assert_close(ident[:, :, full[0]], colours[:, :, full[0]], rtol=0, atol=1e-5)
    holes = cover[:, 0] == 0
    torch.testing.assert_close(ident[:, :, holes[0]], zero[:, :, holes[0]], rtol=0, atol=1e-6)


def test_colour_transform_config_checks():
    with pytest.raises(InputError, match="transform_channels"):
        DecoderConfig(in_channels=8, transform_channels=2)
    with pytest.raises(InputError, match="transform_channels"):
        DecoderConfig(in_channels=3, width=16, transform_channels=3)
    assert DecoderConfig.lite(in_channels=35, transform_channels=3).transform_gain == pytest.approx(1 / 48)
    with pytest.raises(InputError, match="transform_gain"):
        DecoderConfig(in_channels=8, transform_channels=3, transform_gain=0.0)


def test_texture_residual_known_values():
    """The residual r is added where points cover the pixel, scaled by the coverage, before the clamp."""
    g = torch.Generator().manual_seed(4)
    rgb, d = torch.rand(1, 3, 4, 6, generator=g), torch.rand(1, 3, 4, 6, generator=g)
    m = torch.rand(1, 1, 4, 6, generator=g)
    r = (torch.rand(1, 3, 4, 6, generator=g) - 0.5) * 0.4
    coeff = torch.tensor(IDENTITY_TRANSFORM).reshape(1, 12, 1, 1)
    out = apply_colour_transform(rgb, d, m, coeff, (4, 8), texture=r)
    torch.testing.assert_close(out, (rgb + m * (d - rgb + r)).clamp(0, 1), rtol=0, atol=1e-6)
    assert torch.equal(apply_colour_transform(rgb, d, m, coeff, (4, 8), texture=torch.zeros_like(r)),
                       apply_colour_transform(rgb, d, m, coeff, (4, 8)))


def test_texture_residual_starts_at_zero_and_gets_gradients_where_the_identity_hides_the_unet():
    """A new head changes nothing; with the identity transform the U-Net's RGB gets no gradient on
    fully covered pixels, the residual does (the way texture reaches covered pixels)."""
    torch.manual_seed(2)
    cfg = DecoderConfig(in_channels=8 + 3, width=16, transform_channels=3, texture_channels=3,
                        transform_gain=1.0 / 16)
    dec = UNetDecoder(cfg)
    assert dec.out_rgb.out_channels == 6 and not dec.out_rgb.weight[3:].any() and not dec.out_rgb.bias[3:].any()
    plain = UNetDecoder(DecoderConfig(in_channels=8 + 3, width=16, transform_channels=3, transform_gain=1.0 / 16))
    state = {k: (v[:3] if k.startswith("out_rgb.") else v) for k, v in dec.state_dict().items()}
    plain.load_state_dict(state)
    feats = torch.rand(1, 11, 12, 16)
    mask = torch.ones(1, 1, 12, 16)
    with torch.no_grad():
        torch.testing.assert_close(dec.eval()(feats, mask), plain.eval()(feats, mask), rtol=0, atol=0)
    dec.train()
    target = torch.rand(1, 3, 12, 16)
    ((dec(feats, mask) - target) ** 2).mean().backward()
    assert dec.out_rgb.weight.grad[:3].abs().max() == 0  # rgb is replaced by the colours everywhere
    assert dec.out_rgb.weight.grad[3:].abs().max() > 0
    with torch.no_grad():  # a large residual is bounded by TEXTURE_SCALE before the clamp
        dec.out_rgb.bias[3:].fill_(50.0)
        out = dec.eval()(feats * 0.5, mask)
    torch.testing.assert_close(out, (feats[:, -3:] * 0.5 + TEXTURE_SCALE).clamp(0, 1), rtol=0, atol=1e-5)


def test_texture_residual_config_checks():
    with pytest.raises(InputError, match="texture_channels"):
        DecoderConfig(in_channels=11, width=16, texture_channels=3)  # needs the colour transform
    with pytest.raises(InputError, match="texture_channels"):
        DecoderConfig(in_channels=11, width=16, transform_channels=3, texture_channels=1)
    assert DecoderConfig.lite(in_channels=35, transform_channels=3, texture_channels=3).texture_channels == 3


def test_bfloat16_decoding_is_float32_out_and_close_to_float32():
    torch.manual_seed(1)
    dec = UNetDecoder(DecoderConfig.lite(in_channels=16, transform_channels=3, texture_channels=3))
    feats, mask = _inputs(1, 16, 40, 36)
    with torch.inference_mode():
        ref = dec(feats, mask)
        out = dec(feats, mask, bfloat16=True)
        stopped = dec(feats, mask, lambda: False, bfloat16=True)  # the strips run under the autocast too
    assert out.dtype == torch.float32 and out.shape == ref.shape and torch.isfinite(out).all()
    err = (out - ref).abs()
    assert 0 < float(err.max()) < 0.03 and float(err.mean()) < 4e-3  # bfloat16's 8-bit mantissa, not another image
    torch.testing.assert_close(stopped, out, rtol=0, atol=2e-2)


def test_bfloat16_decoding_is_for_inference_only(lite):
    feats, mask = _inputs(1, 16, 8, 8)
    with pytest.raises(InputError, match="bfloat16"):
        lite(feats, mask, bfloat16=True)


def test_native_bfloat16_reads_the_cpu_probes_and_survives_their_absence(monkeypatch):
    from stylize3d_core.models import decoder

    def probes(bf16, amx):
        monkeypatch.setattr(torch.cpu, "_is_avx512_bf16_supported", lambda: bf16, raising=False)
        monkeypatch.setattr(torch.cpu, "_is_amx_tile_supported", lambda: amx, raising=False)
        decoder.native_bfloat16.cache_clear()
        return decoder.native_bfloat16()

    try:
        assert probes(False, False) is False
        assert probes(True, False) is True and probes(False, True) is True
        monkeypatch.delattr(torch.cpu, "_is_avx512_bf16_supported")  # a torch without the probe
        decoder.native_bfloat16.cache_clear()
        assert decoder.native_bfloat16() is False
    finally:
        monkeypatch.undo()
        decoder.native_bfloat16.cache_clear()
