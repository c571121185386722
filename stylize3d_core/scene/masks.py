"""Foreground masks of a photo, and the points of a 3D photo they select.

A mask is (H, W) bool over the photo, True on the foreground (the person or
object that layered stylization keeps as it is, ``export/layered.py``). It comes
from

* a file (:func:`load_mask_file`): any image Pillow reads (PNG is usual), grey
  or colour, foreground where it is brighter than mid-grey (or, for an image
  with an alpha channel, where it is more than half opaque). Its size must be
  the photo's: the size of the photo file (it is then shrunk with the photo,
  nearest neighbour) or the size the photo was loaded at; anything else is an
  :class:`InputError` naming the mask file and both sizes;
* OpenCV's GrabCut seeded by a rectangle around the foreground
  (:func:`grabcut_mask`), always available;
* an automatic person segmentation (:func:`person_mask`): MediaPipe's selfie
  segmentation network (Apache-2.0), converted once to ONNX by
  ``tools/convert_selfie_segmentation.py`` and shipped as
  ``assets/model/selfie_segmentation.onnx``; run with onnxruntime, offline.
  It is a selfie model: it finds people (best when they fill much of the
  frame) but also marks other large salient foreground objects (a cat's face,
  a cup seen close up) as foreground.

The mask follows the layered depth image (:func:`point_mask`): a layer-0 point
is foreground where the mask is, border points are background, and the hidden
layer -- the background the LDI invents behind the foreground's edges -- is
background too, so it is stylized like the rest of the background when a
moving camera uncovers it.
"""

from __future__ import annotations

import functools
from typing import Tuple

import cv2
import numpy as np
from PIL import Image, UnidentifiedImageError

from ..errors import InputError, PathLike
from ..io.images import to_uint8
from ..resources import _checkout_assets, shipped_location
from .ldi import LDI

GRABCUT_ITERATIONS = 5
"""Iterations of ``cv2.grabCut``."""
PERSON_MODEL = "model/selfie_segmentation.onnx"
"""The person segmentation network inside the shipped data (``stylize3d_assets``)."""
PERSON_THRESHOLD = 0.5
"""A pixel is a person where the network's probability is at least this."""
PERSON_MIN_SIDE = 16
"""The smallest photo side (pixels) :func:`person_mask` accepts."""


def _size_text(hw: Tuple[int, int]) -> str:
    return f"{hw[1]}x{hw[0]}"


def fit_mask(mask: np.ndarray, size: Tuple[int, int], file_size: Tuple[int, int], source: PathLike) -> np.ndarray:
    """``mask`` (h, w) bool as (H, W) = ``size``: kept if it is that size, shrunk (nearest) if it is the photo
    file's size ``file_size``; any other size is an :class:`InputError` naming ``source``."""
    mh, mw = mask.shape
    if (mh, mw) == tuple(size):
        return mask.astype(bool)
    if (mh, mw) == tuple(file_size):
        small = cv2.resize(mask.astype(np.uint8), (size[1], size[0]), interpolation=cv2.INTER_NEAREST)
        return small.astype(bool)
    expected = _size_text(file_size) if tuple(file_size) == tuple(size) else \
        f"{_size_text(file_size)} (the photo file) or {_size_text(size)} (the photo as loaded)"
    raise InputError(source, f"the mask is {mw}x{mh} pixels but the photo is {expected}; "
                             "a mask must have the photo's size")


def load_mask_file(path: PathLike, size: Tuple[int, int], file_size: Tuple[int, int]) -> np.ndarray:
    """The foreground mask (H, W) bool = ``size`` read from ``path`` (see the module docstring)."""
    try:
        with Image.open(path) as im:
            im.load()
            if "A" in im.getbands():
                values = np.asarray(im.getchannel("A"))
            else:
                values = np.asarray(im.convert("L"))
    except FileNotFoundError:
        raise InputError(path, "mask file not found") from None
    except (UnidentifiedImageError, OSError, ValueError) as e:
        raise InputError(path, f"cannot read the mask image: {e}") from None
    mask = fit_mask(values >= 128, size, file_size, path)
    check_mask(mask, path)
    return mask


def check_mask(mask: np.ndarray, source: PathLike) -> np.ndarray:
    """``mask`` if it has both foreground and background, else an :class:`InputError` naming ``source``."""
    if not mask.any():
        raise InputError(source, "the mask has no foreground (every pixel is background)")
    if mask.all():
        raise InputError(source, "the mask has no background (every pixel is foreground): nothing would be "
                                 "stylized")
    return mask


def parse_rect(text: str, name: str = "mask_rect") -> Tuple[int, int, int, int]:
    """"X,Y,W,H" (pixels of the photo file: left, top, width, height) -> a tuple of 4 ints."""
    parts = str(text).replace(" ", "").split(",")
    try:
        x, y, w, h = (int(p) for p in parts)
    except ValueError:
        raise InputError(name, f"expected X,Y,WIDTH,HEIGHT in pixels, e.g. 40,20,200,300; got {text!r}") from None
    if w < 2 or h < 2 or x < 0 or y < 0:
        raise InputError(name, f"the rectangle {text!r} needs x, y >= 0 and a width and height of at least 2")
    return x, y, w, h


def grabcut_mask(rgb: np.ndarray, rect: Tuple[int, int, int, int], *, scale: float = 1.0,
                 name: str = "mask_rect") -> np.ndarray:
    """Foreground (H, W) bool of ``rgb`` (H, W, 3) in [0, 1] by GrabCut inside ``rect`` (x, y, w, h).

    ``rect`` is in the photo file's pixels; ``scale`` (loaded size / file size) takes it to ``rgb``'s.
    The rectangle must leave some of the photo outside it (GrabCut learns the background there).
    """
    h, w = rgb.shape[:2]
    x0, y0, rw, rh = (int(round(v * scale)) for v in rect)
    x1, y1 = min(w, x0 + max(2, rw)), min(h, y0 + max(2, rh))
    if x0 >= w - 1 or y0 >= h - 1 or x1 - x0 < 2 or y1 - y0 < 2:
        raise InputError(name, f"the rectangle {tuple(rect)} lies outside the {int(round(w / scale))}x"
                               f"{int(round(h / scale))} photo")
    if x0 == 0 and y0 == 0 and x1 == w and y1 == h:
        raise InputError(name, "the rectangle covers the whole photo; GrabCut needs background outside it")
    bgr = cv2.cvtColor(to_uint8(rgb), cv2.COLOR_RGB2BGR)
    labels = np.zeros((h, w), np.uint8)
    bgd, fgd = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
    cv2.grabCut(bgr, labels, (x0, y0, x1 - x0, y1 - y0), bgd, fgd, GRABCUT_ITERATIONS, cv2.GC_INIT_WITH_RECT)
    mask = (labels == cv2.GC_FGD) | (labels == cv2.GC_PR_FGD)
    if not mask.any():
        raise InputError(name, f"GrabCut found no foreground inside the rectangle {tuple(rect)}")
    return mask


def point_mask(ldi: LDI, mask: np.ndarray) -> np.ndarray:
    """(N,) bool over the points of :func:`~stylize3d_core.scene.pointcloud.ldi_to_points` (same order):
    layer-0 photo pixels where ``mask`` (H, W) is True; border and hidden-layer points are background."""
    if mask.shape != tuple(ldi.photo_size):
        raise InputError("mask", f"is {_size_text(mask.shape)} but the photo is {_size_text(ldi.photo_size)}")
    canvas = np.zeros(ldi.canvas_size, bool)
    canvas[ldi.photo_region] = mask
    hidden = np.zeros(int(ldi.hidden_mask.sum()), bool)
    return np.concatenate([canvas.ravel(), hidden])


@functools.lru_cache(maxsize=1)
def _person_session():
    """The onnxruntime session of the shipped person network (loaded once per process).

    When the installed data lacks the file (an editable install of an older checkout), this source
    checkout's ``assets/`` is tried, as :func:`~stylize3d_core.resources.assets_location` does.
    """
    import onnxruntime as ort  # imported here: the other mask sources do not need it

    path = shipped_location(PERSON_MODEL)
    checkout = _checkout_assets()
    if not path.is_file() and checkout is not None and (checkout / PERSON_MODEL).is_file():
        path = checkout / PERSON_MODEL
    if not path.is_file():
        raise InputError(path, "the person segmentation model is not installed; reinstall stylize3d")
    options = ort.SessionOptions()
    options.log_severity_level = 3
    try:
        return ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
    except Exception as exc:  # onnxruntime raises its own exception types for a damaged file
        raise InputError(path, f"cannot load the person segmentation model: {exc}") from None


def person_probability(rgb: np.ndarray, name: str = "photo") -> np.ndarray:
    """(H, W) float32 in [0, 1]: the network's probability that each pixel of ``rgb`` is a person.

    ``rgb`` is (H, W, 3) (or (H, W) grey), float in [0, 1] or uint8; it is stretched to the network's
    input (256 x 256, as MediaPipe feeds it) and the output is resized back bilinearly.
    """
    image = np.asarray(rgb)
    if image.ndim == 2:
        image = np.repeat(image[..., None], 3, axis=2)
    if image.ndim != 3 or image.shape[2] != 3:
        raise InputError(name, f"expected an (H, W, 3) RGB image or an (H, W) grey one, got shape {image.shape}")
    h, w = image.shape[:2]
    if min(h, w) < PERSON_MIN_SIDE:
        raise InputError(name, f"is {w}x{h} pixels: too small to find a person in "
                               f"(at least {PERSON_MIN_SIDE} pixels a side)")
    if image.dtype == np.uint8:
        image = image.astype(np.float32) / 255.0
    else:
        image = image.astype(np.float32)
        if not np.isfinite(image).all():
            raise InputError(name, "has NaN or infinite pixel values")
        image = np.clip(image, 0.0, 1.0)
    session = _person_session()
    inp = session.get_inputs()[0]
    net_h, net_w = int(inp.shape[1]), int(inp.shape[2])
    shrink = h > net_h or w > net_w
    x = cv2.resize(image, (net_w, net_h), interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)
    prob = session.run(None, {inp.name: x[None]})[0][0, :, :, 0]
    prob = cv2.resize(prob, (w, h), interpolation=cv2.INTER_LINEAR)
    return np.clip(prob, 0.0, 1.0)


def person_mask(rgb: np.ndarray, name: str = "photo") -> np.ndarray:
    """The people in ``rgb`` as (H, W) bool (see :func:`person_probability` for the input).

    The probability is thresholded at :data:`PERSON_THRESHOLD`, then cleaned with a morphological
    opening (drops specks) and closing (fills pinholes) of about 1 % of the photo's shorter side.
    May be all False (nobody found): :func:`check_mask` turns that into an error where a mask is needed.
    """
    mask = person_probability(rgb, name) >= PERSON_THRESHOLD
    side = min(mask.shape)
    k = max(3, int(round(side * 0.01)) | 1)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))
    m = cv2.morphologyEx(mask.astype(np.uint8), cv2.MORPH_OPEN, kernel)
    m = cv2.morphologyEx(m, cv2.MORPH_CLOSE, kernel)
    return m.astype(bool)
