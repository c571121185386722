"""Split-resolution decoding and the constant colour transform: known values, equality with the full path,
interruption, bad inputs."""

from __future__ import annotations

import math

import pytest
import torch

from stylize3d_core.errors import InputError, RenderInterrupted
from stylize3d_core.geometry.camera import Cameras
from stylize3d_core.models import decoder as decoder_module
from stylize3d_core.models.adaattn import AdaAttNConfig
from stylize3d_core.models.decoder import (DecoderConfig, UNetDecoder, apply_colour_transform, constant_transform,
                                           identity_transform, pool_features, upsample_to)
from stylize3d_core.models.encoder import EncoderConfig
from stylize3d_core.models.scene_geometry import prepare_geometry
from stylize3d_core.models.stylize3d import ModelConfig, Stylize3DModel
from stylize3d_core.render.rasterize import RasterSettings
from stylize3d_core.render.rasterizer import PointRasterizer

CFG = DecoderConfig(in_channels=8 + 3, width=16, transform_channels=3, transform_gain=1.0 / 16)


def _inputs(h, w, seed=0, c=11):
    g = torch.Generator().manual_seed(seed)
    mask = (torch.rand(1, 1, h, w, generator=g) > 0.2).float()
    feats = torch.randn(1, c, h, w, generator=g)
    feats[:, -3:] = torch.rand(1, 3, h, w, generator=g)
    return feats * mask, mask


class Counter:
    def __init__(self, stop_at=None) -> None:
        self.calls, self.stop_at = 0, stop_at

    def __call__(self) -> bool:
        self.calls += 1
        return self.stop_at is not None and self.calls >= self.stop_at


def _random_head(dec: UNetDecoder) -> None:
    with torch.no_grad():
        dec.transform.weight.normal_(0.0, 0.05)
        dec.transform.bias.normal_(0.0, 0.1)


@pytest.mark.parametrize("head", ["identity", "random"])
def test_detail_at_the_decoding_size_is_the_plain_decoder(head):
    """With the detail colours and coverage at the features' own size nothing is upsampled: the same output."""
    torch.manual_seed(0)
    dec = UNetDecoder(CFG).eval()
    if head == "random":
        _random_head(dec)
    feats, mask = _inputs(13, 22)
    with torch.inference_mode():
        ref = dec(feats, mask)
        out = dec(feats, mask, detail=(feats[:, -3:], mask))
    torch.testing.assert_close(out, ref, rtol=0, atol=1e-6)


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


def test_split_decoding_shows_the_full_size_colours_and_fills_holes_from_the_small_decode():
    torch.manual_seed(2)
    dec = UNetDecoder(CFG).eval()
    identity_transform(dec.transform, False)
    small, small_mask = _inputs(9, 14, seed=5)
    g = torch.Generator().manual_seed(6)
    colours = torch.rand(1, 3, 18, 28, generator=g)
    coverage = (torch.rand(1, 1, 18, 28, generator=g) > 0.3).float()
    with torch.inference_mode():
        zero = dec(small, small_mask, detail=(colours, coverage))  # zero transform: the small decode upsampled
        torch.testing.assert_close(zero, upsample_to(dec(small, small_mask), (18, 28)), rtol=0, atol=1e-6)
        identity_transform(dec.transform)
        out = dec(small, small_mask, detail=(colours, coverage))
    assert out.shape == (1, 3, 18, 28)
    covered, holes = coverage[0, 0] == 1, coverage[0, 0] == 0
    torch.testing.assert_close(out[:, :, covered], colours[:, :, covered], rtol=0, atol=1e-6)
    torch.testing.assert_close(out[:, :, holes], zero[:, :, holes], rtol=0, atol=1e-6)


def _unet_by_hand(dec: UNetDecoder, small: torch.Tensor, mask: torch.Tensor):
    """The U-Net's last-conv output (cropped to the input's size) and its transform coefficients, computed
    layer by layer without the decoder's forward: the reference the split path is checked against."""
    h, w = small.shape[-2:]
    x = decoder_module._assemble(small, mask, 2**dec.config.levels, True, None)
    skips = []
    for skip, down in zip(dec.skips, dec.downs):
        skips.append(skip(x))
        x = down(x)
    coeff = dec.transform(x * dec.config.transform_gain)
    for i in reversed(range(dec.config.levels)):
        x = dec.ups[i](x, skips[i])
    return dec.out_rgb(torch.relu(dec.out_conv(x)))[..., :h, :w], coeff


def test_split_decoding_with_a_varying_head_upsamples_the_field_over_the_frame():
    """A head that depends on the features: the field is upsampled to the small frame, cropped, then to the
    output size (one smooth field over the frame's extent); a constant detail frame gives its known value."""
    torch.manual_seed(3)
    dec = UNetDecoder(CFG).eval()
    _random_head(dec)
    small, small_mask = _inputs(9, 14, seed=7)
    colours, coverage = torch.full((1, 3, 27, 42), 0.5), torch.ones(1, 1, 27, 42)
    with torch.inference_mode():
        out = dec(small, small_mask, detail=(colours, coverage))
        # the same from the parts: the U-Net's rgb and its coefficients, computed by hand
        y, coeff = _unet_by_hand(dec, small, small_mask)
        rgb = torch.sigmoid(y)
        field = upsample_to(upsample_to(coeff, (12, 16))[..., :9, :14], (27, 42))
        a = field[:, :9].reshape(1, 3, 3, 27, 42)
        rgb = upsample_to(rgb, (27, 42))
        want = (rgb + torch.einsum("bijhw,bjhw->bihw", a, colours - rgb) + field[:, 9:]).clamp(0, 1)
    torch.testing.assert_close(out, want, rtol=0, atol=1e-5)


@pytest.fixture()
def small_strips(monkeypatch):
    monkeypatch.setattr(decoder_module, "STRIP_MACS", 20_000)


def test_split_decoding_stops_and_strips_equal_the_whole(small_strips):
    torch.manual_seed(4)
    dec = UNetDecoder(CFG).eval()
    _random_head(dec)
    small, small_mask = _inputs(19, 26, seed=8)
    g = torch.Generator().manual_seed(9)
    detail = (torch.rand(1, 3, 38, 52, generator=g), (torch.rand(1, 1, 38, 52, generator=g) > 0.2).float())
    with torch.inference_mode():
        ref = dec(small, small_mask, detail=detail)
        total = Counter()
        out = dec(small, small_mask, should_stop=total, detail=detail)
        assert total.calls > 20
        torch.testing.assert_close(out, ref, rtol=0, atol=1e-6)
        last = Counter(total.calls)
        with pytest.raises(RenderInterrupted):
            dec(small, small_mask, should_stop=last, detail=detail)
        assert last.calls == total.calls


def test_split_decoding_bad_inputs():
    dec = UNetDecoder(CFG).eval()
    small, mask = _inputs(8, 8)
    with pytest.raises(InputError, match="detail colours"):
        dec(small, mask, detail=(torch.rand(1, 4, 16, 16), torch.ones(1, 1, 16, 16)))
    with pytest.raises(InputError, match="detail coverage"):
        dec(small, mask, detail=(torch.rand(1, 3, 16, 16), torch.ones(1, 1, 16, 15)))
    bad = torch.rand(1, 3, 16, 16)
    bad[0, 1, 2, 3] = math.nan
    with pytest.raises(InputError, match="NaN"):
        dec(small, mask, detail=(bad, torch.ones(1, 1, 16, 16)))
    plain = UNetDecoder(DecoderConfig(in_channels=11, width=16)).eval()
    with pytest.raises(InputError, match="colour transform"):
        plain(small, mask, detail=(torch.rand(1, 3, 16, 16), torch.ones(1, 1, 16, 16)))


TINY = ModelConfig(
    name="lite", encoder=EncoderConfig(stem_channels=8, stage_channels=(16, 32)),
    stylizer=AdaAttNConfig(content_channels=32, hidden=16, value_channels=16, qk_channels=8),
    raster_channels=8, decoder=DecoderConfig(in_channels=8 + 3, width=16, transform_channels=3,
                                             transform_gain=1 / 16), detail_channels=3,
)


def test_pool_features_known_values():
    """Blocks of s x s: the mean of the covered pixels; covered when any is; odd sizes pad with holes."""
    cover = torch.tensor([[1, 0, 0, 0, 1], [1, 0, 0, 0, 0], [0, 0, 1, 1, 1]], dtype=torch.float32)[None, None]
    feats = torch.arange(15, dtype=torch.float32).view(1, 1, 3, 5).repeat(1, 2, 1, 1) * cover
    feats[:, 1] *= -1
    pooled, mask = pool_features(feats, cover, 2)
    assert pooled.shape == (1, 2, 2, 3) and mask.shape == (1, 1, 2, 3)
    want = torch.tensor([[(0 + 5) / 2, 0.0, 4.0], [0.0, (12 + 13) / 2, 14.0]])
    torch.testing.assert_close(pooled[0, 0], want)
    torch.testing.assert_close(pooled[0, 1], -want)
    torch.testing.assert_close(mask[0, 0], torch.tensor([[1.0, 0.0, 1.0], [0.0, 1.0, 1.0]]))
    nhwc = feats.contiguous(memory_format=torch.channels_last)
    out, _ = pool_features(nhwc, cover, 2)
    torch.testing.assert_close(out, pooled)
    assert pool_features(feats, cover, 1)[0] is feats


def test_render_view_split_resolution(cloud, small_strips):
    """decode_scale 2: covered pixels show the full-size colours, the fragments are the frame's; the
    stoppable path gives the same frame and stops; bad scales and models without the transform are refused."""
    pts, fov = cloud
    torch.manual_seed(0)
    model = Stylize3DModel(TINY).eval()
    geom = prepare_geometry(pts.xyz, pts.rgb, fov, (40, 48), TINY.neighbourhood)
    cam = Cameras.identity(fov)
    with torch.inference_mode():
        dense = model.dense_features(model.encode(geom), geom)
        rgb, frags = model.render_view(dense, geom.xyz, cam, 47, 63, decode_scale=2)
        assert rgb.shape == (3, 47, 63) and torch.isfinite(rgb).all()
        whole = PointRasterizer(RasterSettings(height=47, width=63))(geom.xyz, dense, cam)
        torch.testing.assert_close(frags.image, whole.image, rtol=0, atol=0)
        covered = ~whole.hole
        torch.testing.assert_close(rgb[:, covered], whole.image[-3:].clamp(0, 1)[:, covered], rtol=0, atol=1e-6)
        full = model.render_view(dense, geom.xyz, cam, 47, 63)[0]
        assert (rgb - full).abs().amax(dim=0)[covered].max() <= 1e-6  # only holes differ from decode_scale 1
        total = Counter()
        stopped = model.render_view(dense, geom.xyz, cam, 47, 63, should_stop=total, decode_scale=2)[0]
        torch.testing.assert_close(stopped, rgb, rtol=0, atol=1e-6)
        with pytest.raises(RenderInterrupted):
            model.render_view(dense, geom.xyz, cam, 47, 63, should_stop=Counter(total.calls), decode_scale=2)
    for bad in (0, 9, 1.5, True):
        with pytest.raises(InputError, match="decode_scale"):
            model.render_view(dense, geom.xyz, cam, 24, 32, decode_scale=bad)
    plain_cfg = ModelConfig(name="lite", encoder=TINY.encoder, stylizer=TINY.stylizer, raster_channels=8,
                            decoder=DecoderConfig(in_channels=11, width=16), detail_channels=3)
    plain = Stylize3DModel(plain_cfg).eval()
    with torch.inference_mode(), pytest.raises(InputError, match="colour transform"):
        plain.render_view(plain.dense_features(plain.encode(geom), geom), geom.xyz, cam, 24, 32, decode_scale=2)


@pytest.mark.parametrize("head", ["identity", "random"])
def test_split_decoding_upsamples_the_texture_residual(head):
    """The texture residual is one of the U-Net's outputs: decoded at the small size and upsampled, then
    added on covered pixels (constant-transform and general paths alike)."""
    torch.manual_seed(3)
    cfg = DecoderConfig(in_channels=8 + 3, width=16, transform_channels=3, transform_gain=1.0 / 16,
                        texture_channels=3)
    dec = UNetDecoder(cfg).eval()
    if head == "random":
        _random_head(dec)
    with torch.no_grad():
        dec.out_rgb.weight[3:].normal_(0.0, 0.3)
        dec.out_rgb.bias[3:].normal_(0.0, 0.2)
    small, small_mask = _inputs(9, 14, seed=7)
    g = torch.Generator().manual_seed(8)
    colours = torch.rand(1, 3, 18, 28, generator=g)
    coverage = (torch.rand(1, 1, 18, 28, generator=g) > 0.3).float()
    with torch.inference_mode():
        out = dec(small, small_mask, detail=(colours, coverage))
        # the reference: the small decode's outputs by hand, upsampled, then the general transform
        y, coeff = _unet_by_hand(dec, small, small_mask)
        rgb = upsample_to(torch.sigmoid(y[:, :3]), (18, 28))
        tex = upsample_to(0.5 * torch.tanh(y[:, 3:]), (18, 28))
        coeff = upsample_to(coeff, (12, 16))[..., :9, :14]
        want = apply_colour_transform(rgb, colours, coverage, coeff, (18, 28), texture=tex)
    torch.testing.assert_close(out, want, rtol=0, atol=1e-5)
    assert not torch.equal(out, dec(small, small_mask, detail=(colours, coverage * 0)))  # covered pixels differ
