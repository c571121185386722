"""Style image -> CNN feature maps (the style side of the stylizer and of the losses).

A style image arrives as RGB (B, 3, H, W) in [0, 1] (grey and alpha are
resolved by the image reader). Before the frozen ImageNet extractor
(:class:`~stylize3d_core.models.efficientnet_lite.EfficientNetLiteFeatures` by
default) it is resized, keeping the aspect ratio:

* **long side capped at** ``max_side`` (default 512, antialiased
  downscaling): bounds the cost and the number of attention keys (a 512-pixel
  image gives a 32 x 32 map at stride 16, L = 1024 keys) and matches the scale
  of the style images the network sees in training;
* **short side at least** ``min_side`` (default 64, bilinear upscaling), so the
  deepest (stride 32) map still has 2 x 2 cells.

A constant-colour style gives feature maps with zero spatial variance; every
consumer (AdaAttN, style losses) adds an epsilon to the variance, so nothing
downstream becomes NaN.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple, Optional, Tuple

import torch
import torch.nn.functional as F
from torch import nn

from ..checks import check_finite
from ..errors import InputError
from .efficientnet_lite import EfficientNetLiteFeatures

_RANGE_TOL = 1e-3  # values within this of [0, 1] are clamped (resampling overshoot); beyond it is an error


@dataclass(frozen=True)
class StyleEncoderConfig:
    """Settings of :class:`StyleEncoder`.

    Attributes:
        max_side: long side cap in pixels (default 512; see the module docstring).
        min_side: short side floor in pixels (default 64).
    """

    max_side: int = 512
    min_side: int = 64

    def __post_init__(self) -> None:
        if self.min_side < 1 or self.max_side < self.min_side:
            raise InputError("StyleEncoderConfig", f"need 1 <= min_side <= max_side, got {self.min_side}, {self.max_side}")


class StyleFeatures(NamedTuple):
    """Feature maps of a style image.

    Attributes:
        maps: one (B, C_i, h_i, w_i) map per extractor stage, shallow to deep.
        strides: stride of each map relative to ``size``.
        size: (H, W) of the resized image the maps were computed from.
    """

    maps: Tuple[torch.Tensor, ...]
    strides: Tuple[int, ...]
    size: Tuple[int, int]


def style_image_size(height: int, width: int, max_side: int = 512, min_side: int = 64) -> Tuple[int, int]:
    """Target (H, W) for a style image: long side <= max_side, then short side >= min_side, aspect kept."""
    scale = min(1.0, max_side / max(height, width))
    if min(height, width) * scale < min_side:
        scale = min_side / min(height, width)
    return max(1, round(height * scale)), max(1, round(width * scale))


def check_image01(image: torch.Tensor, name: str = "style image") -> torch.Tensor:
    """Validate an RGB batch (B, 3, H, W) in [0, 1]; returns it (clamped if only off by resampling noise)."""
    if image.dim() != 4 or image.shape[1] != 3:
        raise InputError(name, f"expected RGB of shape (B, 3, H, W), got {tuple(image.shape)}")
    if image.shape[-2] < 1 or image.shape[-1] < 1 or image.shape[0] < 1:
        raise InputError(name, f"image is empty: {tuple(image.shape)}")
    if not image.is_floating_point():
        raise InputError(name, f"expected a float tensor in [0, 1], got {image.dtype}")
    check_finite(image, name)
    lo, hi = float(image.detach().min()), float(image.detach().max())
    if lo < -_RANGE_TOL or hi > 1 + _RANGE_TOL:
        raise InputError(name, f"values must lie in [0, 1], got [{lo:.4g}, {hi:.4g}]")
    return image.clamp(0.0, 1.0) if lo < 0 or hi > 1 else image


def resize_style_image(image: torch.Tensor, max_side: int = 512, min_side: int = 64) -> torch.Tensor:
    """(B, 3, H, W) -> (B, 3, H', W') with :func:`style_image_size`; antialiased when shrinking."""
    h, w = image.shape[-2:]
    th, tw = style_image_size(h, w, max_side, min_side)
    if (th, tw) == (h, w):
        return image
    shrink = th < h or tw < w
    out = F.interpolate(image, size=(th, tw), mode="bilinear", align_corners=False, antialias=shrink)
    return out.clamp(0.0, 1.0)


def encode_style(image: torch.Tensor, extractor: nn.Module, config: StyleEncoderConfig = StyleEncoderConfig()) -> StyleFeatures:
    """Validate, resize and run ``extractor`` (image in [0, 1] -> tuple of maps, with ``.strides``)."""
    image = resize_style_image(check_image01(image), config.max_side, config.min_side)
    maps = tuple(extractor(image))
    return StyleFeatures(maps, tuple(extractor.strides), (int(image.shape[-2]), int(image.shape[-1])))


class StyleEncoder(nn.Module):
    """Frozen style encoder: ``forward(image (B, 3, H, W) in [0, 1]) -> StyleFeatures``.

    Args:
        config: resizing settings.
        extractor: a frozen feature extractor with ``strides`` and ``channels``
            attributes; default :class:`EfficientNetLiteFeatures` (all 5 stages).
    """

    def __init__(self, config: StyleEncoderConfig = StyleEncoderConfig(), extractor: Optional[nn.Module] = None) -> None:
        super().__init__()
        self.config = config
        self.extractor = EfficientNetLiteFeatures() if extractor is None else extractor
        self.channels: Tuple[int, ...] = tuple(self.extractor.channels)
        self.strides: Tuple[int, ...] = tuple(self.extractor.strides)

    def forward(self, image: torch.Tensor) -> StyleFeatures:
        return encode_style(image, self.extractor, self.config)
