"""The decoder's pass-through of covered pixels (``UNetDecoder.passes_covered_colours``): where the colour
transform is the identity and the texture residual zero, inference returns the colours on covered pixels and
decodes only a crop around the others; the result equals the whole U-Net's (the training path, which never
takes the shortcut)."""

from __future__ import annotations

import pytest
import torch

from stylize3d_core.errors import InputError
from stylize3d_core.models.decoder import DecoderConfig, UNetDecoder
from stylize3d_core.models.stylize3d import ModelConfig, Stylize3DModel, settle_pass_through

C = 16


def _decoder(seed: int = 0) -> UNetDecoder:
    """A decoder with a random U-Net (small weights: outputs away from the sigmoid's flat ends), the identity
    transform and a zero texture residual, as the shipped model has them."""
    torch.manual_seed(seed)
    dec = UNetDecoder(DecoderConfig.lite(in_channels=C, transform_channels=3, texture_channels=3)).eval()
    with torch.no_grad():
        for name, p in dec.named_parameters():
            if not name.startswith(("transform.", "out_rgb.")):
                p.add_(torch.randn_like(p) * 0.02)
        dec.out_rgb.weight[:3].normal_(0.0, 0.1)
    assert dec.passes_covered_colours()
    return dec


def _features(h: int, w: int, seed: int = 1) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    f = torch.rand(1, C, h, w, generator=g)
    return f


def _both(dec: UNetDecoder, f: torch.Tensor, m: torch.Tensor):
    with torch.inference_mode():
        fast = dec(f, m)
    with torch.enable_grad():  # the training path: always the whole U-Net
        full = dec(f, m).detach()
    return fast, full


def test_the_new_decoder_passes_colours_and_any_change_of_its_heads_stops_it():
    dec = _decoder()
    for name, index in (("transform.weight", (0, 0, 0, 0)), ("transform.bias", (3,)),
                        ("out_rgb.weight", (4, 0, 0, 0)), ("out_rgb.bias", (5,))):
        d = _decoder()
        with torch.no_grad():
            dict(d.named_parameters())[name][index] += 1e-6
        assert not d.passes_covered_colours(), name
    with torch.no_grad():
        dec.out_rgb.weight[:3].add_(1.0)  # the U-Net's own colours do not matter
    assert dec.passes_covered_colours()
    assert not UNetDecoder(DecoderConfig.lite(in_channels=C)).passes_covered_colours()  # no transform


def test_a_fully_covered_frame_is_its_colours():
    dec = _decoder()
    f = _features(50, 70)
    f[:, -3:] = f[:, -3:] * 1.4 - 0.2  # colours outside [0, 1] are clamped, as the transform clamps them
    fast, full = _both(dec, f, torch.ones(1, 1, 50, 70))
    assert torch.equal(fast, f[:, -3:].clamp(0, 1))
    assert torch.allclose(fast, full, atol=1e-6)
    assert fast.is_contiguous() and fast.dtype == torch.float32


@pytest.mark.parametrize("holes", [
    [(40, 60)],                      # one hole pixel in the middle
    [(0, 0), (1, 1)],                # at the top-left corner
    [(118, 157), (119, 159)],        # at the bottom-right corner, where the U-Net pads the frame
    [(10, 20), (100, 140)],          # far apart: the crop would be most of the frame, the whole is decoded
])
def test_uncovered_pixels_are_decoded_as_the_whole_frame_decodes_them(holes):
    dec = _decoder()
    h, w = 120, 161  # not multiples of the U-Net's grid
    f, m = _features(h, w), torch.ones(1, 1, h, w)
    for r, c in holes:
        m[..., r, c] = 0.0
        f[..., r, c] = 0.0  # what the rasterizer gives a hole
    m[..., holes[0][0], min(w - 1, holes[0][1] + 1)] = 0.5  # a partly covered pixel mixes the U-Net in too
    fast, full = _both(dec, f, m)
    assert torch.allclose(fast, full, atol=2e-6), float((fast - full).abs().max())
    covered = (m == 1).expand_as(fast)
    assert torch.equal(fast[covered], f[:, -3:].clamp(0, 1)[covered])


def test_the_u_net_sees_no_farther_than_the_crops_context():
    # The lite U-Net's output at a pixel depends on its input within 16 pixels (HOLE_CONTEXT keeps 32).
    dec = _decoder()
    h = w = 96
    f, m = _features(h, w), torch.ones(1, 1, h, w)
    m[..., 48, 48] = 0.0
    with torch.enable_grad():
        base = dec(f, m).detach()[..., 48, 48]
        for dist, moves in ((4, True), (17, False), (24, False), (dec.HOLE_CONTEXT, False)):
            g = f.clone()
            g[..., 48 + dist, 48] += 3.0
            g[..., 48, 48 - dist] -= 3.0
            changed = not torch.equal(dec(g, m).detach()[..., 48, 48], base)
            assert changed == moves, dist
    assert dec.HOLE_CONTEXT % 2 ** dec.config.levels == 0


def test_bfloat16_and_batches_take_the_shortcut_too():
    dec = _decoder()
    f, m = _features(40, 52).repeat(2, 1, 1, 1), torch.ones(2, 1, 40, 52)
    m[1, :, 20, 30] = 0.0
    fast, full = _both(dec, f, m)
    assert torch.allclose(fast, full, atol=2e-6)
    with torch.inference_mode():
        low = dec(f, m, bfloat16=True)
    assert low.dtype == torch.float32 and torch.allclose(low, full, atol=0.05)
    assert torch.equal(low[0], f[0, -3:].clamp(0, 1))


def test_settle_pass_through_sets_near_identity_heads_exactly_and_refuses_real_ones():
    torch.manual_seed(0)
    model = Stylize3DModel(ModelConfig.lite()).eval()
    dec = model.decoder
    with torch.no_grad():
        dec.transform.weight.normal_(0.0, 3e-4)
        dec.transform.bias.add_(torch.full((12,), 5e-4))
        dec.out_rgb.weight[3:].normal_(0.0, 3e-4)
    assert not dec.passes_covered_colours()
    settled, gap = settle_pass_through(model)
    assert settled.decoder.passes_covered_colours() and 5e-4 <= gap <= 2e-3
    assert model.decoder.transform.weight.abs().max() > 0  # the original is left as it was
    same = [k for k in model.state_dict() if not k.startswith(("decoder.transform.", "decoder.out_rgb."))]
    assert all(torch.equal(model.state_dict()[k], settled.state_dict()[k]) for k in same)
    with torch.no_grad():
        dec.transform.weight[0, 0] = 0.01
    with pytest.raises(InputError, match="transform weights 0.01"):
        settle_pass_through(model)
