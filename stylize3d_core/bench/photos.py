"""Bench inputs: the sample photo resized to a pixel count (1 MP for the targets, 0.25-4 MP for scaling)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Optional

import numpy as np


def photo_at_megapixels(megapixels: float, folder: Path, photo: Optional[str] = None) -> Path:
    """Write ``photo`` (default the shipped sample) resized to about ``megapixels`` MP as a PNG in ``folder``.

    Upscaled with bicubic, shrunk with area interpolation; the aspect ratio is kept and
    both sides are at least 16 pixels."""
    import cv2

    from ..errors import InputError
    from ..io.images import load_image, save_image
    from ..resources import sample_photo

    if not (megapixels > 0 and math.isfinite(megapixels)):
        raise InputError("megapixels", f"must be a positive number, got {megapixels!r}")
    rgb = load_image(str(photo or sample_photo()), max_size=8192).rgb
    h, w = rgb.shape[:2]
    scale = math.sqrt(megapixels * 1e6 / (h * w))
    size = (max(16, round(w * scale)), max(16, round(h * scale)))
    big = cv2.resize(rgb, size, interpolation=cv2.INTER_CUBIC if scale > 1 else cv2.INTER_AREA)
    path = Path(folder) / f"photo_{megapixels:g}mp.png"
    save_image(path, np.clip(big, 0, 1))
    return path
