"""The decoder's colour transform: the constant transform equals the general path, known values."""

from __future__ import annotations

import pytest
import torch

from stylize3d_core.models import decoder as decoder_module
from stylize3d_core.models.decoder import DecoderConfig, UNetDecoder, apply_colour_transform, constant_transform

CFG = DecoderConfig(in_channels=8 + 3, width=16, transform_channels=3, transform_gain=1.0 / 16)


def _inputs(h, w, seed=0, c=11):
    g = torch.Generator().manual_seed(seed)
    mask = (torch.rand(1, 1, h, w, generator=g) > 0.2).float()
    feats = torch.randn(1, c, h, w, generator=g)
    feats[:, -3:] = torch.rand(1, 3, h, w, generator=g)
    return feats * mask, mask


def _random_head(dec: UNetDecoder) -> None:
    with torch.no_grad():
        dec.transform.weight.normal_(0.0, 0.05)
        dec.transform.bias.normal_(0.0, 0.1)


def test_constant_transform_equals_the_general_path():
    """A zero-weight head: inference takes its bias as one transform; grad mode runs the head; same output."""
    torch.manual_seed(1)
    dec = UNetDecoder(CFG).eval()
    feats, mask = _inputs(17, 9, seed=1)
    for bias in ([1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0], [0.5, 0.2, 0, 0, 1, 0, 0.1, 0, 0.3, 0.05, -0.1, 0]):
        with torch.no_grad():
            dec.transform.weight.zero_()
            dec.transform.bias.copy_(torch.tensor(bias, dtype=torch.float32))
        assert constant_transform(dec.transform) is not None
        with torch.enable_grad():
            general = dec(feats, mask)  # runs the head and upsamples its field
        with torch.inference_mode():
            fast = dec(feats, mask)
        torch.testing.assert_close(fast, general.detach(), rtol=0, atol=1e-6)
    _random_head(dec)
    assert constant_transform(dec.transform) is None


def test_one_pixel_coefficients_are_one_transform_known_values():
    g = torch.Generator().manual_seed(4)
    rgb, d, m = torch.rand(2, 3, 5, 7, generator=g), torch.rand(2, 3, 5, 7, generator=g), torch.rand(2, 1, 5, 7,
                                                                                                      generator=g)
    a = torch.tensor([[0.5, 0.2, 0.0], [0.0, 1.0, 0.0], [0.1, 0.0, 0.3]])
    off = torch.tensor([0.05, -0.1, 0.0])
    coeff = torch.cat([a.reshape(9), off]).reshape(1, 12, 1, 1)
    want = (rgb + m * (torch.einsum("ij,bjhw->bihw", a, d - rgb) + off[None, :, None, None])).clamp(0, 1)
    torch.testing.assert_close(apply_colour_transform(rgb.clone(), d, m, coeff, (8, 8)), want, rtol=0, atol=1e-6)
    ident = torch.tensor(decoder_module.IDENTITY_TRANSFORM).reshape(1, 12, 1, 1)
    with torch.no_grad():  # in place on rgb (the decoder's own tensor)
        out = apply_colour_transform(rgb.clone(), d, m, ident, (5, 7))
    torch.testing.assert_close(out, (rgb + m * (d - rgb)).clamp(0, 1), rtol=0, atol=1e-6)
