"""U-Net decoder: rasterized point features + hole mask -> RGB image.

Layout (as in the paper's public code: 2 levels, no normalisation layers)::

    x0 = [features | mask]                        (B, C_in + 1, H, W)
    for each level i = 0 .. levels-1:
        skip_i  = conv1x1(x_i)                    (B, width / 2^(levels - i), H_i, W_i)
        x_{i+1} = lrelu(conv3x3(lrelu(conv3x3 stride 2(x_i))))   (B, width, H_i / 2, W_i / 2)
    y = x_levels
    for i = levels-1 .. 0:
        y = relu(conv_transpose3x3 stride 2(y))   (B, width / 2^(levels - i), H_i, W_i)
        y = relu(conv3x3([y | skip_i]))
    rgb = sigmoid(conv1x1(relu(conv3x3(y))))      (B, 3, H, W), in (0, 1)

**Colour transform** (``transform_channels`` = 3): the last three input
feature channels are the points' own colours ``d`` (the model's detail path).
A 1x1 convolution of the coarsest level ``x_levels`` predicts, per pixel, a
3 x 3 matrix ``A`` and an offset ``b``, upsampled bilinearly to full resolution
(a smooth field), and wherever points cover the pixel (coverage ``m``)::

    out = clamp(rgb + m * (A (d - rgb) + b), 0, 1)

so ``A = I, b = 0`` renders the points' colours exactly (sharp, and consistent
from view to view by construction), ``A = 0, b = 0`` is the plain U-Net output,
and in between the decoder recolours the full-resolution detail with a
locally varying colour transform while it paints texture into ``rgb``. Holes
(``m = 0``) keep the U-Net's inpainting. A new decoder starts at the identity;
:func:`~stylize3d_core.models.stylize3d.add_colour_transform` can also add a zero
head to a trained model, leaving its output unchanged.

The full-resolution layers are narrow (``width / 4`` channels for 2 levels);
the ``width``-channel layers run at 1/2 and 1/4 resolution.

**Sizes.** H and W need not be divisible by ``2**levels``: the input is
zero-padded at the bottom/right (padding counts as holes: features 0, mask 0)
and the output cropped back.

**Supersampling** (``DecoderConfig.supersample``, the public renderer's
anti-aliasing): the rasterizer renders at (2H, 2W); the decoder first averages
each 2 x 2 block of features weighted by the mask (holes do not darken the
average) and takes the mean mask as the coverage channel, then decodes at
(H, W). The supersampled size must be even.

**Speed.** :meth:`DecoderConfig.lite` meets the CPU targets (512^2 frame
<= 0.5 s, 256^2 preview <= 0.1 s on 2 cores; ``benchmarks/bench_decoder.py``).
Run it under ``torch.inference_mode()``; with ``channels_last`` (default) the
weights and activations use NHWC, which oneDNN convolves fastest on CPU.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import List, Tuple

import torch
import torch.nn.functional as F
from torch import nn

from ..checks import check_finite
from ..errors import InputError


@dataclass(frozen=True)
class DecoderConfig:
    """Settings of :class:`UNetDecoder`.

    Attributes:
        in_channels: C of the rasterized feature image, without the mask channel
            (256 for the paper's encoder features).
        width: channels of the coarse levels (public code: 256); the
            full-resolution layers use ``width // 2**levels``.
        levels: number of stride-2 down/up levels (public code: 2).
        negative_slope: slope of the LeakyReLU in the down path (public code: 0.2).
        supersample: inputs come at (2H, 2W) and are mask-weighted-averaged to
            (H, W) before decoding (see the module docstring). Default False.
        channels_last: keep weights/activations in NHWC (faster on CPU). Default True.
        transform_channels: 0, or 3: the last 3 feature channels are RGB colours that the
            colour-transform head recolours (see the module docstring). Default 0.
        transform_gain: the head sees its input scaled by this: with Adam, whose steps are about
            the learning rate per weight whatever the gradient, a gain of 1 / width keeps each step's
            change of the colour matrix near the learning rate instead of ``width`` times it (the
            presets use 1 / width; 1.0 is the layout of the first checkpoints with the transform).
    """

    in_channels: int = 256
    width: int = 256
    levels: int = 2
    negative_slope: float = 0.2
    supersample: bool = False
    channels_last: bool = True
    transform_channels: int = 0
    transform_gain: float = 1.0

    def __post_init__(self) -> None:
        if not 0.0 < self.transform_gain <= 1.0:
            raise InputError("DecoderConfig.transform_gain", f"must be in (0, 1], got {self.transform_gain!r}")
        if self.transform_channels not in (0, 3):
            raise InputError("DecoderConfig.transform_channels", f"must be 0 or 3, got {self.transform_channels!r}")
        if self.transform_channels and self.in_channels <= self.transform_channels:
            raise InputError("DecoderConfig.transform_channels", f"needs in_channels > {self.transform_channels} "
                             f"(learned features before the colours), got {self.in_channels}")
        if self.in_channels < 1:
            raise InputError("DecoderConfig.in_channels", f"must be >= 1, got {self.in_channels}")
        if self.levels < 1:
            raise InputError("DecoderConfig.levels", f"must be >= 1, got {self.levels}")
        if self.width < 2**self.levels or self.width % 2**self.levels:
            raise InputError(
                "DecoderConfig.width", f"must be a positive multiple of 2**levels = {2**self.levels}, got {self.width}"
            )
        if not 0.0 <= self.negative_slope < 1.0:
            raise InputError("DecoderConfig.negative_slope", f"must be in [0, 1), got {self.negative_slope}")

    @classmethod
    def paper(cls, in_channels: int = 256, supersample: bool = False, transform_channels: int = 0) -> "DecoderConfig":
        """The public code's decoder: width 256, 2 levels (seconds per 512^2 frame on a CPU)."""
        return cls(in_channels=in_channels, width=256, levels=2, supersample=supersample,
                   transform_channels=transform_channels, transform_gain=1.0 / 256)

    @classmethod
    def lite(cls, in_channels: int = 64, supersample: bool = False, transform_channels: int = 0) -> "DecoderConfig":
        """CPU decoder for the viewer: width 96 (24 channels at full resolution), 2 levels.

        Chosen with ``benchmarks/bench_decoder.py`` (C_in = 64, widths 64/96/128/192,
        i.e. 16/24/32/48 channels at full resolution) as the widest width that decodes
        512^2 in <= 0.5 s and 256^2 in <= 0.1 s on 2 cores with >= 30 % headroom:
        width 96 took ~230-290 ms at 512^2 and ~37-52 ms at 256^2 in quiet runs,
        width 128 ~340 ms at 512^2 at best (no headroom).
        """
        return cls(in_channels=in_channels, width=96, levels=2, supersample=supersample,
                   transform_channels=transform_channels, transform_gain=1.0 / 96)


def pad_to_multiple(x: torch.Tensor, multiple: int) -> torch.Tensor:
    """Zero-pad (B, C, H, W) at the bottom/right so H and W are multiples of ``multiple``."""
    h, w = x.shape[-2:]
    ph, pw = (-h) % multiple, (-w) % multiple
    return F.pad(x, (0, pw, 0, ph)) if ph or pw else x


def supersample_pool(features: torch.Tensor, mask: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
    """Average 2 x 2 blocks, weighted by the mask: (B, C, 2H, 2W), (B, 1, 2H, 2W) -> (B, C, H, W), (B, 1, H, W).

    A block without any covered sample gets features 0 and coverage 0.
    """
    if features.shape[-2] % 2 or features.shape[-1] % 2:
        raise InputError("features", f"supersampled input needs an even size, got {tuple(features.shape[-2:])}")
    coverage = F.avg_pool2d(mask, 2)  # (B, 1, H, W)
    summed = F.avg_pool2d(features * mask, 2)  # (B, C, H, W); exactly 0 where coverage is 0
    return summed / coverage.clamp_min(1e-6), coverage


IDENTITY_TRANSFORM = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)
"""The colour transform's coefficients (A row by row, then b) that render the colours unchanged."""


def identity_transform(head: nn.Conv2d, identity: bool = True) -> None:
    """Set the transform head to the identity (a new decoder renders the colours it is given) or to zero
    (``identity`` False: the U-Net's own output)."""
    with torch.no_grad():
        head.weight.zero_()
        head.bias.copy_(torch.tensor(IDENTITY_TRANSFORM) if identity else torch.zeros(12))


def apply_colour_transform(rgb: torch.Tensor, colours: torch.Tensor, coverage: torch.Tensor,
                           coefficients: torch.Tensor, padded: Tuple[int, int]) -> torch.Tensor:
    """``clamp(rgb + m (A (d - rgb) + b), 0, 1)`` (see the module docstring).

    rgb, colours ``d``: (B, 3, H, W); coverage ``m``: (B, 1, H, W); coefficients:
    (B, 12, h', w') over the zero-padded frame of size ``padded`` (rows of ``A``
    first, then ``b``): upsampled bilinearly to ``padded``, then cropped to (H, W).
    """
    b, _, h, w = rgb.shape
    full = F.interpolate(coefficients, size=padded, mode="bilinear", align_corners=False)[..., :h, :w]
    a = full[:, :9].reshape(b, 3, 3, h, w)
    delta = colours.to(rgb.dtype) - rgb  # (B, 3, H, W)
    mixed = torch.einsum("bijhw,bjhw->bihw", a, delta) + full[:, 9:]
    return (rgb + coverage * mixed).clamp(0.0, 1.0)


class _Down(nn.Module):
    def __init__(self, c_in: int, c_out: int, slope: float) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(c_in, c_out, 3, stride=2, padding=1)
        self.conv2 = nn.Conv2d(c_out, c_out, 3, padding=1)
        self.slope = slope

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = F.leaky_relu(self.conv1(x), self.slope)
        return F.leaky_relu(self.conv2(x), self.slope)


class _Up(nn.Module):
    def __init__(self, c_in: int, c_out: int) -> None:
        super().__init__()
        self.up = nn.ConvTranspose2d(c_in, c_out, 3, stride=2, padding=1, output_padding=1)
        self.conv = nn.Conv2d(2 * c_out, c_out, 3, padding=1)

    def forward(self, x: torch.Tensor, skip: torch.Tensor) -> torch.Tensor:
        x = F.relu(self.up(x))  # (B, c_out, 2h, 2w)
        return F.relu(self.conv(torch.cat([x, skip], dim=1)))


class UNetDecoder(nn.Module):
    """U-Net decoder (see the module docstring).

    ``forward(features, mask)``: features (B, C_in, H', W'), mask (B, 1, H', W')
    with 1 = covered by points, 0 = hole (fractions allowed), where
    (H', W') = (H, W), or (2H, 2W) with ``supersample``. Returns RGB (B, 3, H, W)
    in (0, 1), contiguous NCHW. Non-finite features raise :class:`InputError`.
    """

    def __init__(self, config: DecoderConfig = DecoderConfig()) -> None:
        super().__init__()
        self.config = config
        n, w = config.levels, config.width
        skip_ch = [w // 2 ** (n - i) for i in range(n)]
        in_ch = [config.in_channels + 1] + [w] * (n - 1)
        self.skips = nn.ModuleList([nn.Conv2d(in_ch[i], skip_ch[i], 1) for i in range(n)])
        self.downs = nn.ModuleList([_Down(in_ch[i], w, config.negative_slope) for i in range(n)])
        self.ups = nn.ModuleList([_Up(2 * skip_ch[i], skip_ch[i]) for i in range(n)])
        self.out_conv = nn.Conv2d(skip_ch[0], skip_ch[0], 3, padding=1)
        self.out_rgb = nn.Conv2d(skip_ch[0], 3, 1)
        self.transform = None
        if config.transform_channels:
            self.transform = nn.Conv2d(w, 12, 1)  # 3 x 3 matrix + offset per pixel, at 1 / 2**levels resolution
            identity_transform(self.transform)
        if config.channels_last:
            self.to(memory_format=torch.channels_last)

    def _check(self, features: torch.Tensor, mask: torch.Tensor) -> None:
        c = self.config.in_channels
        if features.dim() != 4 or features.shape[1] != c:
            raise InputError("features", f"expected shape (B, {c}, H, W), got {tuple(features.shape)}")
        b, _, h, w = features.shape
        if tuple(mask.shape) != (b, 1, h, w):
            raise InputError("mask", f"expected shape ({b}, 1, {h}, {w}), got {tuple(mask.shape)}")
        if h < 1 or w < 1:
            raise InputError("features", f"empty image {h}x{w}")
        check_finite(features, "features")
        check_finite(mask, "mask")

    def forward(self, features: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        self._check(features, mask)
        mask = mask.to(features.dtype)
        if self.config.supersample:
            features, mask = supersample_pool(features, mask)
        h, w = features.shape[-2:]
        colours = features[:, features.shape[1] - self.config.transform_channels:]
        x = pad_to_multiple(torch.cat([features, mask], dim=1), 2**self.config.levels)  # (B, C_in+1, Hp, Wp)
        if self.config.channels_last:
            x = x.contiguous(memory_format=torch.channels_last)
        skips: List[torch.Tensor] = []
        for skip, down in zip(self.skips, self.downs):
            skips.append(skip(x))
            x = down(x)
        coarse = x  # (B, width, Hp / 2**levels, Wp / 2**levels)
        for i in reversed(range(self.config.levels)):
            x = self.ups[i](x, skips[i])
        x = F.relu(self.out_conv(x))
        rgb = torch.sigmoid(self.out_rgb(x))[..., :h, :w]  # (B, 3, H, W)
        if self.transform is not None:
            padded = (coarse.shape[-2] * 2**self.config.levels, coarse.shape[-1] * 2**self.config.levels)
            gain = self.config.transform_gain
            coeff = self.transform(coarse * gain if gain != 1.0 else coarse)
            rgb = apply_colour_transform(rgb, colours, mask, coeff, padded)
        return rgb.contiguous()
