"""Training photos: which ones, their licences, and random crops / flips / colour jitter.

The photos are scikit-image's bundled colour images (``skimage.data``), chosen
for their licence as stated in the ``skimage.data`` docstrings (scikit-image
0.25, ``skimage/data/_fetchers.py``); only public-domain and CC0 images (and one
with "no known copyright restrictions") are used:

==================== ================================================ ======
name                 licence (as scikit-image states it)              split
==================== ================================================ ======
astronaut            public domain (NASA)                             train
coffee               CC0 (photographer Rachel Michetti)               train
rocket               public domain (SpaceX)                           train
hubble_deep_field    public domain (NASA)                             train
retina               CC0 1.0 (Mikael Haggstrom, Wikimedia Commons)    train
immunohistochemistry no known copyright restrictions (CMMI)           train
chelsea              CC0 (photographer Stefan van der Walt)           eval
==================== ================================================ ======

Left out: ``stereo_motorcycle`` (Middlebury 2014; scikit-image states no
licence) and ``colorwheel`` (no licence stated; synthetic). ``assets/samples``
holds JPEG copies of astronaut, chelsea, coffee and rocket, so they add nothing.
Any other photo can be used by giving its file path instead of a name.

scikit-image is a test/training dependency of stylize3d, imported only when a
photo is first loaded.
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass
from typing import Dict, Tuple

import numpy as np

from ..checks import check_range
from ..errors import InputError
from ..io.images import load_image, resize_image

PHOTO_LICENCES: Dict[str, str] = {
    "astronaut": "public domain (NASA)",
    "coffee": "CC0 (photographer Rachel Michetti)",
    "rocket": "public domain (SpaceX)",
    "hubble_deep_field": "public domain (NASA)",
    "retina": "CC0 1.0 (Mikael Haggstrom, Wikimedia Commons)",
    "immunohistochemistry": "no known copyright restrictions (CMMI)",
    "chelsea": "CC0 (photographer Stefan van der Walt)",
}
"""Every scikit-image photo this module loads, with its licence."""

TRAIN_PHOTOS: Tuple[str, ...] = ("astronaut", "coffee", "rocket", "hubble_deep_field", "retina", "immunohistochemistry")
"""Photos of the training split."""

EVAL_PHOTOS: Tuple[str, ...] = ("chelsea",)
"""Photos of the held-out split (no overlap with :data:`TRAIN_PHOTOS`)."""


@functools.lru_cache(maxsize=32)
def load_photo(name: str) -> np.ndarray:
    """A training photo (H, W, 3) float32 in [0, 1] by name (see :data:`PHOTO_LICENCES`) or file path.

    The result is cached and read-only: copy it before modifying it.
    """
    if name in PHOTO_LICENCES:
        try:
            from skimage import data as skdata  # test/training dependency only
        except ImportError as e:
            raise InputError(name, "scikit-image is needed for the training photos (pip install scikit-image)") from e
        a = np.asarray(getattr(skdata, name)())
        if a.ndim != 3 or a.shape[2] < 3 or a.dtype != np.uint8:
            raise InputError(name, f"expected an 8-bit colour image, got {a.dtype} {a.shape}")
        photo = a[..., :3].astype(np.float32) / 255.0
    elif os.path.isfile(name):
        photo = load_image(name, max_size=1024).rgb
    else:
        raise InputError(name, f"not a known training photo ({', '.join(PHOTO_LICENCES)}) nor an existing file")
    photo.setflags(write=False)
    return photo


@dataclass(frozen=True)
class PhotoAugment:
    """Random crop, scale, flip and colour jitter of a training photo."""

    min_crop: float = 0.3
    """Smallest crop, as a fraction of the largest crop of the output's aspect that fits (1 = whole photo)."""
    flip: float = 0.5
    """Probability of a horizontal flip."""
    brightness: float = 0.2
    """Colours are multiplied by a factor in [1 - b, 1 + b]."""
    contrast: float = 0.2
    """Deviation from the mean grey is scaled by a factor in [1 - c, 1 + c]."""
    saturation: float = 0.3
    """Deviation from each pixel's grey is scaled by a factor in [1 - s, 1 + s]."""
    min_std: float = 0.03
    """A crop whose colour standard deviation is below this (e.g. the black around the
    retina) is redrawn, up to 8 times."""

    def __post_init__(self) -> None:
        check_range(self.min_crop, "min_crop", 0.01, 1.0)
        check_range(self.flip, "flip", 0.0, 1.0)
        check_range(self.brightness, "brightness", 0.0, 0.9)
        check_range(self.contrast, "contrast", 0.0, 0.9)
        check_range(self.saturation, "saturation", 0.0, 1.0)
        check_range(self.min_std, "min_std", 0.0, 0.5)


def random_crop(
    photo: np.ndarray, rng: np.random.Generator, size: Tuple[int, int], min_crop: float
) -> Tuple[np.ndarray, str]:
    """A random crop of ``photo`` with the aspect of ``size``, resized to ``size`` (h, w).

    Returns the (h, w, 3) float32 crop and a description ``"y0,x0,ch,cw"`` of it.
    """
    H, W = photo.shape[:2]
    h, w = size
    fit = min(H / h, W / w)  # largest crop of the output's aspect: (fit * h, fit * w)
    scale = fit * math.sqrt(rng.uniform(min_crop**2, 1.0))  # uniform in area
    ch, cw = max(1, min(H, int(round(h * scale)))), max(1, min(W, int(round(w * scale))))
    y0, x0 = int(rng.integers(0, H - ch + 1)), int(rng.integers(0, W - cw + 1))
    crop = resize_image(np.ascontiguousarray(photo[y0 : y0 + ch, x0 : x0 + cw]), (h, w))
    return crop, f"{y0},{x0},{ch},{cw}"


def colour_jitter(image: np.ndarray, rng: np.random.Generator, aug: PhotoAugment) -> np.ndarray:
    """Brightness, contrast and saturation jitter of (h, w, 3) in [0, 1]; returns a new array."""
    x = image * rng.uniform(1.0 - aug.brightness, 1.0 + aug.brightness)
    grey = x @ np.array([0.299, 0.587, 0.114], np.float32)  # (h, w)
    x = grey[..., None] + (x - grey[..., None]) * rng.uniform(1.0 - aug.saturation, 1.0 + aug.saturation)
    mean = float(grey.mean())
    x = mean + (x - mean) * rng.uniform(1.0 - aug.contrast, 1.0 + aug.contrast)
    return np.clip(x, 0.0, 1.0).astype(np.float32)


def augmented_photo(
    name: str, rng: np.random.Generator, size: Tuple[int, int], aug: PhotoAugment = PhotoAugment()
) -> Tuple[np.ndarray, str]:
    """A random crop / scale / flip / colour jitter of the photo ``name``.

    Returns:
        (h, w, 3) float32 image in [0, 1], and a description of where it came from.
    """
    photo = load_photo(name)
    for _ in range(8):
        crop, where = random_crop(photo, rng, size, aug.min_crop)
        if float(crop.std()) >= aug.min_std:
            break
    flipped = rng.random() < aug.flip
    if flipped:
        crop = np.ascontiguousarray(crop[:, ::-1])
    out = colour_jitter(crop, rng, aug)
    return out, f"{os.path.basename(name)} crop {where}{' flipped' if flipped else ''}"
