"""Image error measures shared by the evaluation, the benchmarks and the tests.

PSNR is ``10 log10(peak^2 / MSE)`` in dB over the images' values (every channel), in float64;
identical images give ``inf``. A mask restricts it to some pixels; an empty mask gives ``nan``.
"""

from __future__ import annotations

import math
from typing import Optional

import numpy as np


def psnr(a, b, mask: Optional[np.ndarray] = None, peak: float = 1.0) -> float:
    """PSNR (dB) of two images of one shape, (H, W) or (H, W, C) arrays (or tensors, read as arrays);
    ``mask`` (H, W) bool: only those pixels; ``peak``: the largest value (1 for [0, 1] images, 255 for
    8-bit)."""
    x, y = np.asarray(a, np.float64), np.asarray(b, np.float64)
    if x.shape != y.shape:
        raise ValueError(f"psnr: images of different shapes {x.shape} and {y.shape}")
    d = (x - y) ** 2
    if mask is not None:
        m = np.asarray(mask, bool)
        if not m.any():
            return math.nan
        d = d[m]
    mse = float(d.mean())
    return math.inf if mse == 0 else 10.0 * math.log10(peak * peak / mse)


__all__ = ["psnr"]
