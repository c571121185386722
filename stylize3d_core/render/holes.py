"""Hole filling for rasterized images: push-pull over an image pyramid.

Push-pull (Gortler et al. 1996, "The Lumigraph"; Grossman & Dally 1998):

* **pull** (down the pyramid): each coarser level holds, per pixel, the sums
  over the 2 x 2 block below it of the weighted colours ``P`` and of the
  weights ``S``; its colour is ``P / S``, the mean of the valid pixels it
  covers. Level 0 has weight 1 at valid pixels, 0 at holes. It stops at 1 x 1.
* **push** (back up): each finer level blends its own colour with the bilinear
  upsampling of the already-filled coarser level,
  ``c = w * c + (1 - w) * up(c')`` with ``w = min(1, S)``, so a valid pixel
  keeps its value, a hole takes the coarse value, and coarse pixels that saw
  no valid pixel at all take theirs from further down.

Every hole is filled from the nearest valid pixels at the scale of the hole.
Cost is linear in the number of pixels (the pyramid adds a third): about 10 ms
for a 3-channel 512 x 512 image on the 2-core CPU. It is used
to render plain 3D photos; the neural decoder handles holes itself.
"""

from __future__ import annotations

from typing import List, Tuple

import torch
import torch.nn.functional as F

from ..checks import check_finite, check_shape
from ..errors import InputError


def _pull(wcolor: torch.Tensor, weight: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
    """2 x 2 sums: (C, H, W), (H, W) -> (C, ceil(H/2), ceil(W/2)), (ceil(H/2), ceil(W/2)).

    Odd sizes are padded with zero weight (the padding adds nothing).
    """
    H, W = weight.shape
    weight = weight.unsqueeze(0)  # (1, H, W)
    if H % 2 or W % 2:
        pad = (0, W % 2, 0, H % 2)
        wcolor, weight = F.pad(wcolor, pad), F.pad(weight, pad)  # (C, H', W'), (1, H', W') even
    return F.avg_pool2d(wcolor, 2) * 4.0, F.avg_pool2d(weight, 2)[0] * 4.0


def _colour(wcolor: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
    """(C, h, w) mean colour ``P / S``; 0 where ``S == 0``."""
    return wcolor / torch.where(weight > 0, weight, torch.ones_like(weight))


def fill_holes(image: torch.Tensor, hole: torch.Tensor) -> torch.Tensor:
    """Fill the hole pixels of an image from their surroundings (push-pull).

    Args:
        image: (C, H, W) floating image; its values at holes are ignored (they
            may be anything, NaN included); at valid pixels they must be finite.
        hole: (H, W) bool, True where the pixel is to be filled.
    Returns:
        (C, H, W) image equal to ``image`` at valid pixels and filled at holes;
        all zeros if every pixel is a hole. Differentiable with respect to ``image``.
    Raises:
        InputError: on wrong shapes or dtypes, or non-finite valid pixels.
    """
    if not isinstance(image, torch.Tensor) or not image.is_floating_point():
        raise InputError("image", "expected a floating-point torch.Tensor")
    if not isinstance(hole, torch.Tensor) or hole.dtype != torch.bool:
        raise InputError("hole", "expected a bool torch.Tensor")
    check_shape(image, "image", (None, None, None))
    check_shape(hole, "hole", tuple(image.shape[1:]))
    valid = ~hole
    zero = torch.zeros((), dtype=image.dtype, device=image.device)
    color = torch.where(valid, image, zero).contiguous()  # (C, H, W)
    # One reduction first; a non-finite sum (NaN, inf or an overflow) is confirmed element-wise.
    with torch.no_grad():
        if not torch.isfinite(color.sum()):
            check_finite(color, "image")
    if not bool(hole.any()):
        return image.clone()
    if bool(hole.all()):
        return color  # all zeros

    # Pull: pyramid of (weighted colour sums, weight sums) down to 1 x 1.
    levels: List[Tuple[torch.Tensor, torch.Tensor]] = [(color, valid.to(image.dtype))]
    while max(levels[-1][1].shape) > 1:
        levels.append(_pull(*levels[-1]))

    # Push: fill each level from the one below it; level 0 only needs the holes.
    filled = _colour(*levels[-1])  # (C, 1, 1)
    for level in range(len(levels) - 2, -1, -1):
        wc, s = levels[level]
        h, w = s.shape
        # The coarse level covers the fine one padded to even size: upsample 2x, then crop.
        up = F.interpolate(filled.unsqueeze(0), scale_factor=2.0, mode="bilinear", align_corners=False)
        up = up[0, :, :h, :w]  # (C, h, w)
        if level == 0:
            return torch.where(valid, image, up)
        a = s.clamp(max=1.0)
        filled = a * _colour(wc, s) + (1.0 - a) * up  # (C, h, w)
    raise AssertionError("unreachable: an image with a valid pixel and a hole has two levels or more")
