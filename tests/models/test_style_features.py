"""StyleEncoder: validation, resizing rules, feature shapes, constant styles."""

from __future__ import annotations

import pytest
import torch

from stylize3d_core.errors import InputError
from stylize3d_core.models.style_features import (
    StyleEncoder,
    StyleEncoderConfig,
    StyleFeatures,
    check_image01,
    resize_style_image,
    style_image_size,
)


@pytest.fixture(scope="module")
def encoder():
    return StyleEncoder()


@pytest.mark.parametrize(
    "hw, expected",
    [
        ((1000, 2000), (256, 512)),  # long side capped, aspect kept
        ((4000, 3000), (512, 384)),
        ((300, 200), (300, 200)),  # already within limits: untouched
        ((20, 40), (64, 128)),  # short side raised to min_side
        ((512, 512), (512, 512)),
    ],
)
def test_style_image_size(hw, expected):
    assert style_image_size(*hw) == expected


def test_resize_keeps_range_and_skips_no_op():
    x = torch.rand(1, 3, 700, 350)
    y = resize_style_image(x)
    assert y.shape == (1, 3, 512, 256) and 0.0 <= float(y.min()) and float(y.max()) <= 1.0
    small = torch.rand(1, 3, 100, 80)
    assert resize_style_image(small) is small
    # antialiased shrink of a fine checkerboard gives mid-grey, not aliasing
    checker = (torch.arange(1024).view(1, -1) + torch.arange(1024).view(-1, 1)) % 2
    y = resize_style_image(checker.float().expand(1, 3, -1, -1))
    assert abs(float(y.mean()) - 0.5) < 0.01 and float(y.std()) < 0.05


def test_encoder_outputs_maps_at_documented_strides():
    encoder = StyleEncoder(StyleEncoderConfig(max_side=128, min_side=32))
    out = encoder(torch.rand(2, 3, 150, 300))
    assert isinstance(out, StyleFeatures)
    assert out.size == (64, 128)
    assert out.strides == (2, 4, 8, 16, 32) == encoder.strides
    assert [m.shape[1] for m in out.maps] == list(encoder.channels) == [16, 24, 40, 112, 320]
    for m, s in zip(out.maps, out.strides):
        assert m.shape == (2, m.shape[1], 64 // s, 128 // s)
        assert torch.isfinite(m).all()
    assert out.maps[3].shape[-2:] == (4, 8)


def test_default_cap_gives_32x32_map_at_stride_16(encoder):
    out = encoder(torch.rand(1, 3, 1024, 640))
    assert out.size == (512, 320) and out.maps[3].shape[-2:] == (32, 20)


@pytest.mark.parametrize("value", [0.0, 0.37, 1.0])
def test_constant_style_is_finite(encoder, value):
    out = encoder(torch.full((1, 3, 128, 96), value))
    for m in out.maps:
        assert torch.isfinite(m).all()


def test_encoder_is_frozen(encoder):
    assert all(not p.requires_grad for p in encoder.parameters())
    encoder.train()
    assert not encoder.extractor.training


@pytest.mark.parametrize(
    "image, match",
    [
        (torch.rand(1, 4, 32, 32), "RGB"),
        (torch.rand(3, 32, 32), "RGB"),
        (torch.rand(1, 3, 0, 32), "empty"),
        (torch.full((1, 3, 8, 8), 2.0), r"\[0, 1\]"),
        (torch.full((1, 3, 8, 8), float("nan")), "NaN"),
        (torch.zeros(1, 3, 8, 8, dtype=torch.uint8), "float"),
    ],
)
def test_bad_images_raise(encoder, image, match):
    with pytest.raises(InputError, match=match):
        encoder(image)


def test_resampling_overshoot_is_clamped_not_rejected():
    x = torch.full((1, 3, 4, 4), 1.0005)
    y = check_image01(x)
    assert float(y.max()) == 1.0 and float(x.max()) > 1.0  # input untouched


def test_bad_config():
    with pytest.raises(InputError):
        StyleEncoderConfig(max_side=32, min_side=64)


def test_constant_style_end_to_end_through_adaattn_is_finite(encoder):
    from stylize3d_core.models.adaattn import AdaAttNStylizer

    torch.manual_seed(0)
    stylizer = AdaAttNStylizer()
    maps = encoder(torch.full((1, 3, 96, 96), 0.5)).maps
    content = torch.randn(64, 256, requires_grad=True)
    out = stylizer(content, maps, alpha=0.8)
    assert torch.isfinite(out).all()
    out.sum().backward()
    assert torch.isfinite(content.grad).all()
