"""The benchmarks' test photos: the bundled samples and a few real photos from scikit-image.

Imports the library only when called (``stylize3d_core.io.images``), so a script
can choose which checkout's library it runs first.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterator, Tuple

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[2]

SKIMAGE_PHOTOS = ("stereo_motorcycle", "camera", "coins")
"""Real photos shipped with scikit-image (not in the repository's samples)."""


def test_photos(size: int) -> Iterator[Tuple[str, np.ndarray]]:
    """(name, (H, W, 3) float32 photo in [0, 1] with long side ``size``)."""
    from stylize3d_core.io.images import load_image

    for path in sorted((ROOT / "assets" / "samples").glob("*.jpg")):
        yield path.stem, load_image(str(path), max_size=size).rgb
    import skimage.data

    for name in SKIMAGE_PHOTOS:
        img = getattr(skimage.data, name)()
        img = img[0] if isinstance(img, tuple) else img  # a stereo pair: the left view
        img = np.repeat(img[..., None], 3, axis=2) if img.ndim == 2 else img[..., :3]
        scale = size / max(img.shape[:2])
        img = cv2.resize(img, (round(img.shape[1] * scale), round(img.shape[0] * scale)),
                         interpolation=cv2.INTER_AREA)
        yield name, img.astype(np.float32) / 255.0


def estimate_depth(source, rgb: np.ndarray):
    """The ``DepthMap`` that the depth ``source`` gives the photo array ``rgb``."""
    from stylize3d_core.io.images import load_image_array

    return source.estimate(load_image_array(rgb, max_size=max(rgb.shape[:2]))).depth_map
