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

    out = clamp(rgb + m * (A (d - rgb) + b + r), 0, 1)

so ``A = I, b = 0`` renders the points' colours exactly (sharp, and consistent
from view to view by construction), ``A = 0, b = 0`` is the plain U-Net output,
and in between the decoder recolours the full-resolution detail with a
locally varying colour transform while it paints texture into ``rgb``. Holes
(``m = 0``) keep the U-Net's inpainting. A new decoder starts at the identity;
:func:`~stylize3d_core.models.stylize3d.add_colour_transform` can also add a zero
head to a trained model, leaving its output unchanged.

**Texture residual** (``texture_channels`` = 3, with the colour transform): the
U-Net's last 1x1 convolution has three more outputs, ``r = TEXTURE_SCALE *
tanh(.)``, added where points cover the pixel (``r`` above; without the head
``r = 0``). The colour transform alone is smooth (it comes from the coarsest
level), so a transform near the identity leaves the U-Net no way to paint
brush strokes onto covered pixels; ``r`` is that way: full-resolution texture
on top of the recoloured detail. Its weights start at zero (the output is the
same as without it); :func:`~stylize3d_core.models.stylize3d.add_texture_residual`
adds it to a trained model.

The full-resolution layers are narrow (``width / 4`` channels for 2 levels);
the ``width``-channel layers run at 1/2 and 1/4 resolution.

**Constant transform:** under ``torch.no_grad``/``inference_mode``, a head whose weights are all zero
(the shipped ``lite`` checkpoint's) gives the same coefficients at every pixel, its bias: the head's
convolution and the full-resolution upsampling of 12 channels are skipped (:func:`constant_transform`).

**Covered pixels pass through:** where the transform head is the constant identity and the texture
residual zero (:meth:`UNetDecoder.passes_covered_colours`; the shipped ``lite`` checkpoint), a pixel the
points cover (mask 1) shows ``d`` whatever the U-Net computes. Under ``torch.no_grad``/``inference_mode`` the
decoder then returns the colours and runs the U-Net only on a crop around the pixels with a mask below 1
(holes, partly covered pixels) with :data:`UNetDecoder.HOLE_CONTEXT` pixels of context, or not at all where
there are none (a full frame of a photo seen from near its own camera usually has none).

**Sizes.** H and W need not be divisible by ``2**levels``: the input is
zero-padded at the bottom/right (padding counts as holes: features 0, mask 0)
and the output cropped back.

**Supersampling** (``DecoderConfig.supersample``, the public renderer's
anti-aliasing): the rasterizer renders at (2H, 2W); the decoder first averages
each 2 x 2 block of features weighted by the mask (holes do not darken the
average) and takes the mean mask as the coverage channel, then decodes at
(H, W). The supersampled size must be even.

**Speed.** :meth:`DecoderConfig.lite` meets the CPU targets (512^2 frame
<= 0.5 s, 256^2 preview <= 0.1 s on 2 cores; ``tests/benchmarks/bench_decoder.py``).
Run it under ``torch.inference_mode()``; with ``channels_last`` (default) the
weights and activations use NHWC, which oneDNN convolves fastest on CPU.
``forward(..., bfloat16=True)`` (inference) runs the U-Net's convolutions under a bfloat16
autocast (the heads in float32) and returns float32: on a CPU with native bfloat16 (AVX-512
BF16 / AMX, :func:`native_bfloat16`) a 512x342 frame decodes ~2.4x faster (``bench floor``),
55-61 dB PSNR from float32 (``bench speed``); without it bfloat16 is emulated and slower.

**Stopping** (``forward(..., should_stop=)``, the viewer's full frames): a
768x512 frame takes ~1-2 s on one CPU thread, its largest single layer ~0.25 s.
With ``should_stop`` every convolution runs in horizontal strips of output rows
(:func:`conv_in_strips`, each strip reads the input rows its kernel reaches: the
1-row halo of a 3x3 convolution, zero padding only at the image's own edges) of at
most :data:`STRIP_MACS` multiply-adds, ~10-20 ms, and ``should_stop()`` is checked
before each strip; True stops with :class:`~stylize3d_core.errors.RenderInterrupted`.
The strips give the unstripped result up to float rounding (within 1e-6,
``tests/models/test_decoder_interrupt.py``). Without ``should_stop`` nothing changes.
"""

from __future__ import annotations

import contextlib
import functools
from dataclasses import dataclass
from typing import Callable, List, Optional, Tuple

import torch
import torch.nn.functional as F
from torch import nn

from ..checks import check_finite
from ..errors import InputError, RenderInterrupted

StopCheck = Optional[Callable[[], bool]]


@functools.lru_cache(maxsize=None)
def native_bfloat16() -> bool:
    """True where this CPU computes bfloat16 natively (AVX-512 BF16 or AMX tiles), so that oneDNN's
    bfloat16 convolutions beat float32 ones; False elsewhere (emulated: several times slower)."""
    try:
        cpu = torch.cpu
        return bool(torch.backends.mkldnn.is_available() and
                    (cpu._is_avx512_bf16_supported() or cpu._is_amx_tile_supported()))
    except (AttributeError, RuntimeError):  # an older or newer torch without these probes: assume not
        return False


STRIP_MACS = 120_000_000
"""Multiply-adds per strip of :func:`conv_in_strips` (~10-20 ms on one CPU thread)."""


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
        texture_channels: 0, or 3: the texture residual ``r`` added on covered pixels (see the module
            docstring); needs the colour transform. Default 0.
    """

    in_channels: int = 256
    width: int = 256
    levels: int = 2
    negative_slope: float = 0.2
    supersample: bool = False
    channels_last: bool = True
    transform_channels: int = 0
    transform_gain: float = 1.0
    texture_channels: int = 0

    def __post_init__(self) -> None:
        if self.texture_channels not in (0, 3):
            raise InputError("DecoderConfig.texture_channels", f"must be 0 or 3, got {self.texture_channels!r}")
        if self.texture_channels and not self.transform_channels:
            raise InputError("DecoderConfig.texture_channels", "the texture residual is added with the colour "
                                                               "transform: needs transform_channels 3")
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
    def paper(cls, in_channels: int = 256, supersample: bool = False, transform_channels: int = 0,
              texture_channels: int = 0) -> "DecoderConfig":
        """The public code's decoder: width 256, 2 levels (seconds per 512^2 frame on a CPU)."""
        return cls(in_channels=in_channels, width=256, levels=2, supersample=supersample,
                   transform_channels=transform_channels, transform_gain=1.0 / 256, texture_channels=texture_channels)

    @classmethod
    def lite(cls, in_channels: int = 64, supersample: bool = False, transform_channels: int = 0,
             texture_channels: int = 0) -> "DecoderConfig":
        """CPU decoder for the viewer: width 48 (12 channels at full resolution), 2 levels, about 20k
        multiply-adds per output pixel.

        The width is the narrowest that keeps the quality figures of ``docs/quality.md``, so a preview and a
        full frame fit the viewer's time targets on a 2-core CPU without native bfloat16 (``bench targets``).
        A narrower decoder is distilled from a wider one and trained on (``tools/distill_decoder.py``). The
        full-resolution layers gain least from a narrower width: their cost is mostly memory traffic.
        """
        return cls(in_channels=in_channels, width=48, levels=2, supersample=supersample,
                   transform_channels=transform_channels, transform_gain=1.0 / 48, texture_channels=texture_channels)


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


TEXTURE_SCALE = 0.5
"""The texture residual's range: ``r`` in (-TEXTURE_SCALE, TEXTURE_SCALE) per channel."""

IDENTITY_TRANSFORM = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)
"""The colour transform's coefficients (A row by row, then b) that render the colours unchanged."""


def identity_transform(head: nn.Conv2d, identity: bool = True) -> None:
    """Set the transform head to the identity (a new decoder renders the colours it is given) or to zero
    (``identity`` False: the U-Net's own output)."""
    with torch.no_grad():
        head.weight.zero_()
        head.bias.copy_(torch.tensor(IDENTITY_TRANSFORM) if identity else torch.zeros(12))


def _stop(should_stop: StopCheck) -> None:
    if should_stop is not None and should_stop():
        raise RenderInterrupted("render stopped inside the decoder")


def conv_in_strips(conv: nn.Module, x, should_stop: StopCheck = None,
                   act: Optional[Callable[[torch.Tensor], torch.Tensor]] = None,
                   max_macs: Optional[int] = None) -> torch.Tensor:
    """``act(conv(x))`` (``conv(x)`` without ``act``) computed in horizontal strips of output rows, with
    ``should_stop()`` checked before each strip (True raises :class:`RenderInterrupted`).

    ``conv`` is an ``nn.Conv2d`` or ``nn.ConvTranspose2d`` (zero padding, no groups, no dilation).
    ``x``: (B, C_in, H, W), or a sequence of tensors (B, C_i, H, W) that ``conv`` reads concatenated
    along the channels (concatenated strip by strip: the whole is never built).
    Each strip convolves the input rows its output rows reach -- the kernel's halo
    (one row each side for a 3x3 kernel), padded with zeros only where the image ends --
    so the result equals ``conv(x)`` up to float rounding. A strip holds at most
    ``max_macs`` multiply-adds (default :data:`STRIP_MACS`; at least one output row). The output has the memory format of
    (the first) ``x`` (NHWC stays NHWC).
    """
    if not isinstance(conv, (nn.Conv2d, nn.ConvTranspose2d)) or conv.groups != 1 or \
            tuple(conv.dilation) != (1, 1) or conv.padding_mode != "zeros" or isinstance(conv.padding, str):
        raise InputError("conv_in_strips", f"needs a plain Conv2d or ConvTranspose2d, got {conv!r}")
    xs_all = [x] if isinstance(x, torch.Tensor) else list(x)
    if sum(t.shape[1] for t in xs_all) != conv.in_channels or len({t.shape[-2:] for t in xs_all}) != 1:
        raise InputError("conv_in_strips", f"inputs of shapes {[tuple(t.shape) for t in xs_all]} do not fit {conv!r}")
    transposed = isinstance(conv, nn.ConvTranspose2d)
    (kh, kw), (sh, sw), (ph, pw) = conv.kernel_size, conv.stride, conv.padding
    first = xs_all[0]
    b, (h_in, w_in) = first.shape[0], first.shape[-2:]
    if transposed:
        oph, opw = conv.output_padding
        h_out = (h_in - 1) * sh - 2 * ph + kh + oph
        w_out = (w_in - 1) * sw - 2 * pw + kw + opw
        per_row = b * w_out * conv.in_channels * conv.out_channels * kh * kw // (sh * sw)
    else:
        h_out = (h_in + 2 * ph - kh) // sh + 1
        w_out = (w_in + 2 * pw - kw) // sw + 1
        per_row = b * w_out * conv.in_channels * conv.out_channels * kh * kw
    per_row = max(per_row, 16 * b * w_in * conv.in_channels)  # memory-bound layers (1x1): ~16 MACs per value read
    rows = max(1, int((STRIP_MACS if max_macs is None else max_macs) // max(1, per_row)))
    nhwc = first.is_contiguous(memory_format=torch.channels_last) and first.stride(1) == 1  # (1 x 1: either)
    out = torch.empty((b, conv.out_channels, h_out, w_out), dtype=first.dtype, device=first.device,
                      memory_format=torch.channels_last if nhwc else torch.contiguous_format)

    def rows_of(r0: int, r1: int) -> torch.Tensor:
        parts = [t[:, :, r0:r1] for t in xs_all]
        return parts[0] if len(parts) == 1 else torch.cat(parts, dim=1)

    for o0 in range(0, h_out, rows):
        _stop(should_stop)
        o1 = min(h_out, o0 + rows)
        if transposed:
            # output row o = i * sh - ph + k: input rows i0..i1 reach output rows o0..o1-1
            i0 = max(0, -(-(o0 + ph - kh + 1) // sh))
            i1 = min(h_in - 1, (o1 - 1 + ph) // sh)
            y = F.conv_transpose2d(rows_of(i0, i1 + 1), conv.weight, None, (sh, sw), (0, pw), (0, opw))
            a, z = o0 - i0 * sh + ph, o1 - i0 * sh + ph  # the strip's rows in y (no input row reaches y's tail)
            if z > y.shape[-2]:
                y = F.pad(y, (0, 0, 0, z - y.shape[-2]))
            y = y[:, :, a:z]
            if conv.bias is not None:
                y = y + conv.bias.view(1, -1, 1, 1)
        else:
            # output row o reads padded rows o * sh .. o * sh + kh - 1, i.e. input rows - ph
            r0, r1 = o0 * sh - ph, (o1 - 1) * sh - ph + kh
            top, bottom = max(0, -r0), max(0, r1 - h_in)
            xs = rows_of(max(0, r0), min(h_in, r1))
            if top or bottom:
                xs = F.pad(xs, (0, 0, top, bottom))
            y = F.conv2d(xs, conv.weight, conv.bias, (sh, sw), (0, pw))
        out[:, :, o0:o1].copy_(y if act is None else act(y))
    return out


def _layer(conv: nn.Module, x: torch.Tensor, should_stop: StopCheck,
           act: Optional[Callable[[torch.Tensor], torch.Tensor]] = None) -> torch.Tensor:
    """``act(conv(x))``: at once without ``should_stop``, else in strips (:func:`conv_in_strips`)."""
    if should_stop is None:
        y = conv(x)
        return y if act is None else act(y)
    return conv_in_strips(conv, x, should_stop, act)


def _assemble(features: torch.Tensor, mask: torch.Tensor, multiple: int, channels_last: bool,
              should_stop: StopCheck, dtype: Optional[torch.dtype] = None) -> torch.Tensor:
    """``[features | mask]`` zero-padded to a multiple of ``multiple`` (B, C + 1, Hp, Wp), NHWC with
    ``channels_last``, in ``dtype`` (default the features'); with ``should_stop``, copied in strips of
    rows with a check before each."""
    b, c, h, w = features.shape
    hp, wp = h + (-h) % multiple, w + (-w) % multiple
    x = torch.empty((b, c + 1, hp, wp), dtype=dtype or features.dtype, device=features.device,
                    memory_format=torch.channels_last if channels_last else torch.contiguous_format)
    if hp > h or wp > w:  # the padding: holes (features 0, mask 0)
        x[:, :, h:].zero_()
        x[:, :, :h, w:].zero_()
    # one allocation, the padding zeroed, the rest copied once; in strips with a check before each when
    # stoppable (a copy costs ~1/20 of a multiply-add's budget)
    rows = h if should_stop is None else max(1, STRIP_MACS // (20 * b * (c + 1) * w))
    for r0 in range(0, h, rows):
        _stop(should_stop)
        r1 = min(h, r0 + rows)
        x[:, :c, r0:r1, :w].copy_(features[:, :, r0:r1])
        x[:, c:, r0:r1, :w].copy_(mask[:, :, r0:r1])
    return x


def zero_texture(out_rgb: nn.Conv2d) -> None:
    """Zero the texture residual's rows of the U-Net's last convolution (outputs 3 onwards): ``r = 0``."""
    with torch.no_grad():
        out_rgb.weight[3:].zero_()
        out_rgb.bias[3:].zero_()


def apply_colour_transform(rgb: torch.Tensor, colours: torch.Tensor, coverage: torch.Tensor,
                           coefficients: torch.Tensor, padded: Tuple[int, int],
                           texture: Optional[torch.Tensor] = None) -> torch.Tensor:
    """``clamp(rgb + m (A (d - rgb) + b + r), 0, 1)`` (see the module docstring).

    rgb, colours ``d``: (B, 3, H, W); coverage ``m``: (B, 1, H, W); coefficients:
    (B, 12, h', w') over the zero-padded frame of size ``padded`` (rows of ``A``
    first, then ``b``): upsampled bilinearly to ``padded``, then cropped to (H, W);
    ``texture`` ``r``: (B, 3, H, W) or None (0).
    Coefficients of size (B, 12, 1, 1) are one transform for the whole frame
    (:func:`constant_transform`): no upsampling, and ``A = I, b = 0`` is ``rgb + m (d - rgb)``.
    """
    b, _, h, w = rgb.shape
    if coefficients.shape[-2:] == (1, 1):
        return _apply_constant_transform(rgb, colours, coverage, coefficients[:, :, 0, 0], texture)
    full = F.interpolate(coefficients, size=padded, mode="bilinear", align_corners=False)[..., :h, :w]
    a = full[:, :9].reshape(b, 3, 3, h, w)
    delta = colours.to(rgb.dtype) - rgb  # (B, 3, H, W)
    mixed = torch.einsum("bijhw,bjhw->bihw", a, delta) + full[:, 9:]
    if texture is not None:
        mixed = mixed + texture.to(rgb.dtype)
    return (rgb + coverage * mixed).clamp(0.0, 1.0)


def constant_transform(head: nn.Conv2d) -> Optional[torch.Tensor]:
    """The head's coefficients (1, 12, 1, 1) when they do not depend on the features (its weights are all
    zero, as in a new decoder and the shipped ``lite`` checkpoint: the bias alone), else None."""
    if head.weight.count_nonzero() != 0:
        return None
    return head.bias.detach().view(1, -1, 1, 1)


def _apply_constant_transform(rgb: torch.Tensor, colours: torch.Tensor, coverage: torch.Tensor,
                              coefficients: torch.Tensor, texture: Optional[torch.Tensor] = None) -> torch.Tensor:
    """:func:`apply_colour_transform` with one transform (B, 12) for the whole frame."""
    b = rgb.shape[0]
    delta = colours.to(rgb.dtype) - rgb  # (B, 3, H, W)
    coefficients = coefficients.to(rgb.dtype).expand(b, -1)
    identity = torch.tensor(IDENTITY_TRANSFORM, dtype=rgb.dtype, device=rgb.device)
    if not bool((coefficients == identity).all()):
        delta = torch.einsum("bij,bjhw->bihw", coefficients[:, :9].reshape(b, 3, 3), delta) \
            + coefficients[:, 9:, None, None]
    if texture is not None:
        delta = delta + texture.to(rgb.dtype)
    if torch.is_grad_enabled():
        return (rgb + coverage * delta).clamp(0.0, 1.0)
    return rgb.addcmul_(coverage, delta).clamp_(0.0, 1.0)  # rgb is the decoder's own new tensor


class _Down(nn.Module):
    def __init__(self, c_in: int, c_out: int, slope: float) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(c_in, c_out, 3, stride=2, padding=1)
        self.conv2 = nn.Conv2d(c_out, c_out, 3, padding=1)
        self.slope = slope

    def forward(self, x: torch.Tensor, should_stop: StopCheck = None) -> torch.Tensor:
        lrelu = lambda t: F.leaky_relu(t, self.slope)  # noqa: E731
        x = _layer(self.conv1, x, should_stop, lrelu)
        return _layer(self.conv2, x, should_stop, lrelu)


class _Up(nn.Module):
    def __init__(self, c_in: int, c_out: int) -> None:
        super().__init__()
        self.up = nn.ConvTranspose2d(c_in, c_out, 3, stride=2, padding=1, output_padding=1)
        self.conv = nn.Conv2d(2 * c_out, c_out, 3, padding=1)

    def forward(self, x: torch.Tensor, skip: torch.Tensor, should_stop: StopCheck = None) -> torch.Tensor:
        x = _layer(self.up, x, should_stop, F.relu)  # (B, c_out, 2h, 2w)
        if should_stop is None:
            return F.relu(self.conv(torch.cat([x, skip], dim=1)))
        return conv_in_strips(self.conv, (x, skip), should_stop, F.relu)  # concatenated strip by strip


class UNetDecoder(nn.Module):
    """U-Net decoder (see the module docstring).

    ``forward(features, mask)``: features (B, C_in, H', W'), mask (B, 1, H', W')
    with 1 = covered by points, 0 = hole (fractions allowed), where
    (H', W') = (H, W), or (2H, 2W) with ``supersample``. Returns RGB (B, 3, H, W)
    in (0, 1), contiguous NCHW. Non-finite features raise :class:`InputError`.
    ``should_stop`` (optional): checked between layers and between the strips of
    each convolution (see the module docstring); True raises :class:`RenderInterrupted`.
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
        self.out_rgb = nn.Conv2d(skip_ch[0], 3 + config.texture_channels, 1)  # RGB, then the texture residual
        if config.texture_channels:
            zero_texture(self.out_rgb)
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
        for t, name in ((features, "features"), (mask, "mask")):
            if not torch.isfinite(t.sum()):  # a sum is finite when every value is (one pass, no (B, C, H, W) bools)
                check_finite(t, name)

    def forward(self, features: torch.Tensor, mask: torch.Tensor, should_stop: StopCheck = None, *,
                bfloat16: bool = False, runtime=None) -> torch.Tensor:
        """``bfloat16``: decode under a CPU bfloat16 autocast (inference; see the module docstring);
        the result is float32 either way.

        ``runtime``: the caller's choice of another runtime for the U-Net (inference, float32), any object
        whose ``run_or_none(x, should_stop)`` takes the assembled NHWC input and returns (``y``,
        ``coefficients`` or None), or None where it could not run (this frame then decodes in torch); the
        caller makes it (``models/decoder_onnx.onnx_unet``: ONNX Runtime, the same outputs up to float
        rounding, faster on CPUs without native bfloat16). Everything around it (padding, crop, heads,
        colour transform) is this method's."""
        if bfloat16 and torch.is_grad_enabled():
            raise InputError("bfloat16", "bfloat16 decoding is for inference (run under torch.inference_mode())")
        if runtime is not None and (bfloat16 or torch.is_grad_enabled()):
            raise InputError("runtime", "the ONNX Runtime U-Net is for float32 inference (under "
                                        "torch.inference_mode(), without bfloat16)")
        self._check(features, mask)
        mask = mask.to(features.dtype)
        if self._covered_pass_through():
            return self._decode_uncovered(features, mask, should_stop, bfloat16)
        if self.config.supersample:
            features, mask = supersample_pool(features, mask)
        h, w = features.shape[-2:]
        colours = features[:, -self.config.transform_channels:] if self.transform is not None else None
        # bfloat16: the U-Net's convolutions under the autocast, from an input assembled in bfloat16;
        # its outputs back in float32 for the heads (sigmoid, tanh, the per-pixel colour matrices)
        amp = torch.autocast("cpu", dtype=torch.bfloat16) if bfloat16 else contextlib.nullcontext()
        unet = None
        if runtime is not None:
            x = _assemble(features, mask, 2**self.config.levels, True, should_stop)  # NHWC, as the graph takes it
            unet = runtime.run_or_none(x, should_stop)  # None: it failed, and this frame decodes in torch
        if unet is not None:
            y, coefficients = unet
            padded = tuple(x.shape[-2:])
            y = y[..., :h, :w]
            if self.transform is not None and coefficients is None:
                coefficients = constant_transform(self.transform)
        else:
            y, coefficients, padded = self._unet(features, mask, should_stop, bfloat16, amp)
        # the heads on planar memory: a channel slice of channels-last memory is strided, where sigmoid and
        # tanh run unvectorised (tanh of 3 of 6 channels at 272x272: 2.5 ms against 0.4 ms planar)
        y = y.contiguous()
        rgb = torch.sigmoid(y[:, :3])  # (B, 3, H, W)
        texture = TEXTURE_SCALE * torch.tanh(y[:, 3:]) if self.config.texture_channels else None
        if self.transform is not None:
            _stop(should_stop)
            rgb = apply_colour_transform(rgb, colours, mask, coefficients, padded, texture)
        return rgb.contiguous()

    def passes_covered_colours(self) -> bool:
        """Whether a covered pixel (mask 1) shows its points' colours ``d`` unchanged whatever the U-Net
        computes: the colour transform's head is the constant identity (zero weights, the identity as its
        bias) and the texture residual is zero (zero weights and bias), so ``out = rgb + 1 * (d - rgb) = d``.
        The U-Net is then needed only where the mask is below 1 (see :meth:`forward`)."""
        head = self.transform
        if head is None or head.weight.count_nonzero() != 0:
            return False
        if not torch.equal(head.bias.detach(), torch.tensor(IDENTITY_TRANSFORM, dtype=head.bias.dtype)):
            return False
        rows = self.out_rgb
        return bool(rows.weight[3:].count_nonzero() == 0 and rows.bias[3:].count_nonzero() == 0)

    def _covered_pass_through(self) -> bool:
        """Whether :meth:`forward` decodes only the uncovered pixels: inference, no supersampling, and
        :meth:`passes_covered_colours`. Those pixels always take the torch U-Net (a crop's size changes from
        frame to frame, and torch is the faster runtime for small ones)."""
        return not torch.is_grad_enabled() and not self.config.supersample and self.passes_covered_colours()

    HOLE_CONTEXT = 32
    """Pixels of context kept around the uncovered pixels when only they are decoded (a multiple of
    ``2**levels``): the lite U-Net's output at a pixel depends on its input within 16 pixels (two stride-2
    levels of 3 x 3 convolutions; ``tests/models/test_decoder_pass_through.py`` checks it), so a crop with
    this margin decodes its uncovered pixels as the whole frame does, up to float rounding."""
    CROP_FRACTION = 0.5
    """Above this share of the frame the crop around the uncovered pixels is not worth it: the whole frame
    is decoded."""

    def _decode_uncovered(self, features: torch.Tensor, mask: torch.Tensor, should_stop: StopCheck,
                          bfloat16: bool) -> torch.Tensor:
        """:meth:`forward` where :meth:`passes_covered_colours` holds: the colours where the mask is 1; the
        U-Net (on the smallest grid-aligned crop holding every uncovered pixel and
        :data:`HOLE_CONTEXT` pixels around them, or the whole frame) where it is below 1."""
        colours = features[:, -self.config.transform_channels:]
        out = colours.clamp(0.0, 1.0).contiguous()
        uncovered = (mask < 1.0).any(dim=0)[0]  # (H, W), over the batch
        if not bool(uncovered.any()):
            _stop(should_stop)
            return out
        h, w = uncovered.shape
        rows = torch.nonzero(uncovered.any(dim=1)).flatten()
        cols = torch.nonzero(uncovered.any(dim=0)).flatten()
        step, margin = 2 ** self.config.levels, self.HOLE_CONTEXT
        r0 = max(0, int(rows[0]) - margin) // step * step  # the grid's phase kept: the crop decodes as the frame
        c0 = max(0, int(cols[0]) - margin) // step * step
        r1, c1 = min(h, int(rows[-1]) + 1 + margin), min(w, int(cols[-1]) + 1 + margin)
        if (r1 - r0) * (c1 - c0) > self.CROP_FRACTION * h * w:
            r0, c0, r1, c1 = 0, 0, h, w
        y, coefficients, padded = self._unet(features[..., r0:r1, c0:c1], mask[..., r0:r1, c0:c1], should_stop,
                                             bfloat16, torch.autocast("cpu", dtype=torch.bfloat16) if bfloat16
                                             else contextlib.nullcontext())
        rgb = torch.sigmoid(y.contiguous()[:, :3])
        _stop(should_stop)
        m = mask[..., r0:r1, c0:c1]
        crop = apply_colour_transform(rgb, colours[..., r0:r1, c0:c1], m, coefficients, padded)  # no texture
        window = out[..., r0:r1, c0:c1]
        window.copy_(torch.where(m < 1.0, crop, window))  # covered pixels keep their colours exactly
        return out

    def _unet(self, features: torch.Tensor, mask: torch.Tensor, should_stop: StopCheck, bfloat16: bool,
              amp) -> Tuple[torch.Tensor, Optional[torch.Tensor], Tuple[int, int]]:
        """The U-Net in torch: its last convolution's output cropped to (H, W) (B, 3 + texture, H, W), the
        transform head's coefficients (None without the head) and the padded size (Hp, Wp)."""
        h, w = features.shape[-2:]
        with amp:
            x = _assemble(features, mask, 2**self.config.levels, self.config.channels_last, should_stop,
                          torch.bfloat16 if bfloat16 else None)  # (B, C_in+1, Hp, Wp)
            padded = tuple(x.shape[-2:])
            skips: List[torch.Tensor] = []
            for skip, down in zip(self.skips, self.downs):
                skips.append(_layer(skip, x, should_stop))
                x = down(x, should_stop)
            coarse = x  # (B, width, Hp / 2**levels, Wp / 2**levels)
            for i in reversed(range(self.config.levels)):
                x = self.ups[i](x, skips[i], should_stop)
            x = _layer(self.out_conv, x, should_stop, F.relu)
            y = _layer(self.out_rgb, x, should_stop)[..., :h, :w].to(features.dtype)  # (B, 3 + texture, H, W)
            coefficients = None
            if self.transform is not None:
                coefficients = None if torch.is_grad_enabled() else constant_transform(self.transform)
                if coefficients is None:
                    gain = self.config.transform_gain
                    coefficients = _layer(self.transform, coarse * gain if gain != 1.0 else coarse,
                                          should_stop).to(features.dtype)
        return y, coefficients, padded

