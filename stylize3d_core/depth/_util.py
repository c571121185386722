"""Small image helpers shared by the depth sources (not part of the public API)."""

from __future__ import annotations

from typing import Tuple

import cv2
import numpy as np

from ..checks import check_finite, check_shape
from ..errors import InputError


def check_rgb(rgb: np.ndarray, name: str = "rgb") -> np.ndarray:
    """Validate a photo (H, W, 3) and return a float32 copy clipped to [0, 1].

    Raises :class:`InputError` for a wrong shape, a non-float dtype, NaN/inf,
    or an image smaller than 2x2. The argument is never modified.
    """
    if not isinstance(rgb, np.ndarray):
        raise InputError(name, f"expected a numpy array (H, W, 3), got {type(rgb).__name__}")
    check_shape(rgb, name, (None, None, 3))
    if not np.issubdtype(rgb.dtype, np.floating):
        raise InputError(name, f"expected float values in [0, 1], got dtype {rgb.dtype}")
    check_finite(rgb, name)
    if rgb.shape[0] < 2 or rgb.shape[1] < 2:
        raise InputError(name, f"image too small: {rgb.shape[:2]}")
    return np.clip(rgb, 0.0, 1.0).astype(np.float32)




def resize_long_side(img: np.ndarray, long_side: int) -> np.ndarray:
    """Downscale ``img`` (H, W, ...) so that its longer side is at most ``long_side`` (area filter).

    Images already small enough are returned unchanged (not copied).
    """
    h, w = img.shape[:2]
    scale = long_side / max(h, w)
    if scale >= 1.0:
        return img
    size = (max(1, round(w * scale)), max(1, round(h * scale)))
    return cv2.resize(img, size, interpolation=cv2.INTER_AREA)


def resize_to(img: np.ndarray, shape: Tuple[int, int], *, nearest: bool = False) -> np.ndarray:
    """Resize ``img`` (h, w, ...) to ``shape`` = (H, W) (linear, or nearest-neighbour)."""
    if img.shape[:2] == tuple(shape):
        return img
    interp = cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR
    return cv2.resize(img, (int(shape[1]), int(shape[0])), interpolation=interp)


def nearness_to_depth(nearness: np.ndarray, far_ratio: float) -> np.ndarray:
    """Map nearness (H, W) in [0, 1] (1 = nearest) to depth in [1, far_ratio], float32.

    Nearness is treated as an inverse depth: ``depth = 1 / (1/far_ratio + (1 - 1/far_ratio) * n)``.
    """
    inv_far = 1.0 / far_ratio
    n = np.clip(np.nan_to_num(nearness, nan=0.0), 0.0, 1.0)
    return (1.0 / (inv_far + (1.0 - inv_far) * n)).astype(np.float32)


def normalise_percentiles(x: np.ndarray, lo_q: float = 2.0, hi_q: float = 98.0) -> np.ndarray:
    """Map the [lo_q, hi_q] percentile range of ``x`` to [0, 1], clipped; constant -> zeros."""
    lo, hi = np.percentile(x, [lo_q, hi_q])
    if not np.isfinite(hi - lo) or hi - lo < 1e-8:
        return np.zeros(x.shape, np.float32)
    return np.clip((x - lo) / (hi - lo), 0.0, 1.0).astype(np.float32)
