"""The decoder's stoppable path: convolutions in strips equal the whole convolution; should_stop stops it."""

from __future__ import annotations

import pytest
import torch
from torch import nn

from stylize3d_core.errors import InputError, RenderInterrupted
from stylize3d_core.geometry.camera import Cameras
from stylize3d_core.models import decoder as decoder_module
from stylize3d_core.models.adaattn import AdaAttNConfig
from stylize3d_core.models.decoder import DecoderConfig, UNetDecoder, conv_in_strips
from stylize3d_core.models.encoder import EncoderConfig
from stylize3d_core.models.scene_geometry import prepare_geometry
from stylize3d_core.models.stylize3d import ModelConfig, Stylize3DModel

CONVS = {
    "3x3": lambda: nn.Conv2d(5, 7, 3, padding=1),
    "3x3 stride 2": lambda: nn.Conv2d(5, 7, 3, stride=2, padding=1),
    "1x1": lambda: nn.Conv2d(5, 7, 1),
    "5x5": lambda: nn.Conv2d(5, 7, 5, padding=2),
    "3x3 no padding": lambda: nn.Conv2d(5, 7, 3),
    "transposed 3x3 stride 2": lambda: nn.ConvTranspose2d(5, 7, 3, stride=2, padding=1, output_padding=1),
    "transposed 4x4 stride 2": lambda: nn.ConvTranspose2d(5, 7, 4, stride=2, padding=1),
}


class Counter:
    """A should_stop that counts its calls and says stop from call ``stop_at`` on (never if None)."""

    def __init__(self, stop_at=None) -> None:
        self.calls, self.stop_at = 0, stop_at

    def __call__(self) -> bool:
        self.calls += 1
        return self.stop_at is not None and self.calls >= self.stop_at


@pytest.mark.parametrize("name", list(CONVS))
@pytest.mark.parametrize("hw", [(1, 1), (2, 3), (17, 9), (32, 20)])
@pytest.mark.parametrize("channels_last", [False, True], ids=["nchw", "nhwc"])
def test_strips_equal_the_whole_convolution(name, hw, channels_last):
    torch.manual_seed(0)
    conv = CONVS[name]()
    x = torch.randn(2, 5, *hw)
    if channels_last:
        x = x.contiguous(memory_format=torch.channels_last)
    if hw[0] < conv.kernel_size[0] and not isinstance(conv, nn.ConvTranspose2d) and conv.padding == (0, 0):
        pytest.skip("no output rows")
    with torch.inference_mode():
        ref = conv(x)
        for max_macs in (1, 700, 10**9):  # one row per strip, a few rows, one strip
            stop = Counter()
            y = conv_in_strips(conv, x, stop, max_macs=max_macs)
            assert y.shape == ref.shape
            assert (y - ref).abs().max().item() <= 1e-6, max_macs
            if hw != (1, 1):  # a 1 x 1 input is both NCHW and NHWC
                assert y.is_contiguous(memory_format=torch.channels_last if channels_last else torch.contiguous_format)
            if max_macs == 1:  # one check per output row
                assert stop.calls == ref.shape[-2]


def test_strips_of_concatenated_inputs_and_activation():
    torch.manual_seed(1)
    conv = nn.Conv2d(6, 4, 3, padding=1)
    a, b = torch.randn(1, 2, 13, 11), torch.randn(1, 4, 13, 11)
    with torch.inference_mode():
        ref = torch.relu(conv(torch.cat([a, b], dim=1)))
        y = conv_in_strips(conv, (a, b), None, torch.relu, max_macs=2000)
    assert (y - ref).abs().max().item() <= 1e-6


def test_strips_refuse_convolutions_they_cannot_split():
    x = torch.randn(1, 4, 8, 8)
    for conv in (nn.Conv2d(4, 4, 3, padding=1, groups=2), nn.Conv2d(4, 4, 3, padding=2, dilation=2),
                 nn.Conv2d(4, 4, 3, padding=1, padding_mode="reflect"), nn.Conv2d(4, 4, 3, padding="same")):
        with pytest.raises(InputError, match="conv_in_strips"):
            conv_in_strips(conv, x)
    with pytest.raises(InputError, match="do not fit"):
        conv_in_strips(nn.Conv2d(5, 4, 3), x)


@pytest.fixture()
def small_strips(monkeypatch):
    """Strips of ~20k multiply-adds, so that a small image is decoded in many strips."""
    monkeypatch.setattr(decoder_module, "STRIP_MACS", 20_000)


@pytest.mark.parametrize("config", [DecoderConfig.lite(in_channels=16), DecoderConfig(in_channels=3, width=16,
                                                                                         levels=3,
                                                                                         channels_last=False)],
                         ids=["lite", "3 levels nchw"])
@pytest.mark.parametrize("hw", [(37, 53), (1, 1), (64, 48)])
def test_stoppable_forward_equals_the_plain_forward(small_strips, config, hw):
    torch.manual_seed(0)
    dec = UNetDecoder(config).eval()
    g = torch.Generator().manual_seed(2)
    feats = torch.randn(1, config.in_channels, *hw, generator=g)
    mask = (torch.rand(1, 1, *hw, generator=g) > 0.2).float()
    with torch.inference_mode():
        ref = dec(feats * mask, mask)
        stop = Counter()
        out = dec(feats * mask, mask, should_stop=stop)
    assert out.shape == ref.shape and out.is_contiguous()
    assert (out - ref).abs().max().item() <= 1e-6
    if hw == (64, 48):
        assert stop.calls > 50  # many strips, one check each


def test_stoppable_forward_with_the_colour_transform_head(small_strips):
    torch.manual_seed(0)
    dec = UNetDecoder(DecoderConfig.lite(in_channels=16, transform_channels=3)).eval()
    with torch.no_grad():  # a head that does something (it starts at zero)
        dec.transform.weight.normal_(0.0, 0.05)
        dec.transform.bias.normal_(0.0, 0.1)
    g = torch.Generator().manual_seed(3)
    feats = torch.rand(1, 16, 37, 53, generator=g)
    mask = (torch.rand(1, 1, 37, 53, generator=g) > 0.2).float()
    with torch.inference_mode():
        ref = dec(feats * mask, mask)
        total = Counter()
        out = dec(feats * mask, mask, should_stop=total)
        assert (out - ref).abs().max().item() <= 1e-6
        last = Counter(total.calls)  # the last check: just before the colour transform
        with pytest.raises(RenderInterrupted):
            dec(feats * mask, mask, should_stop=last)


def test_should_stop_stops_at_the_check_it_is_true(small_strips):
    torch.manual_seed(0)
    dec = UNetDecoder(DecoderConfig.lite(in_channels=16)).eval()
    feats, mask = torch.randn(1, 16, 64, 48), torch.ones(1, 1, 64, 48)
    with torch.inference_mode():
        total = Counter()
        dec(feats, mask, should_stop=total)
        for stop_at in (1, total.calls // 2, total.calls):
            stop = Counter(stop_at)
            with pytest.raises(RenderInterrupted):
                dec(feats, mask, should_stop=stop)
            assert stop.calls == stop_at  # nothing ran past the first True


def test_overflowing_sum_of_finite_features_is_not_an_error():
    dec = UNetDecoder(DecoderConfig.lite(in_channels=4)).eval()
    feats = torch.full((1, 4, 8, 8), 3e38)  # finite, but their sum is inf
    dec._check(feats, torch.ones(1, 1, 8, 8))  # no error
    bad = feats.clone()
    bad[0, 1, 2, 3] = float("inf")
    with pytest.raises(InputError, match="NaN or infinite"):
        dec(bad, torch.ones(1, 1, 8, 8))


TINY = ModelConfig(
    name="lite", encoder=EncoderConfig(stem_channels=8, stage_channels=(16, 32)),
    stylizer=AdaAttNConfig(content_channels=32, hidden=16, value_channels=16, qk_channels=8),
    raster_channels=8, decoder=DecoderConfig(in_channels=8 + 3, width=16), detail_channels=3,
)


def test_render_view_passes_should_stop_to_the_decoder(cloud, small_strips):
    pts, fov = cloud
    torch.manual_seed(0)
    model = Stylize3DModel(TINY).eval()
    geom = prepare_geometry(pts.xyz, pts.rgb, fov, (40, 48), TINY.neighbourhood)
    with torch.inference_mode():
        dense = model.dense_features(model.encode(geom), geom)
        cam = Cameras.identity(fov)
        ref, _ = model.render_view(dense, geom.xyz, cam, 48, 64)
        total = Counter()
        rgb, _ = model.render_view(dense, geom.xyz, cam, 48, 64, should_stop=total)
        assert (rgb - ref).abs().max().item() <= 1e-6
        last = Counter(total.calls)  # the last check is the decoder's (its output layer's last strip)
        with pytest.raises(RenderInterrupted, match="decoder"):
            model.render_view(dense, geom.xyz, cam, 48, 64, should_stop=last)
