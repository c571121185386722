"""Depth maps from depth and disparity files: the depth policy over the raw readers of ``io.depth_files``.

:func:`load_depth_file` turns a file (16/8-bit PNG, ``.npy``, ``.pfm``, float
TIFF, EXR; decoded by :func:`~stylize3d_core.io.depth_files.read_depth_values`)
into a :class:`~stylize3d_core.depth.types.DepthMap`:

* **Values.** ``kind="depth"``: depth = value * ``scale`` (the map's kind is
  "metric": in the file's unit times ``scale``). ``kind="disparity"``:
  depth = 1 / (value * ``scale``) (kind "relative"); a zero disparity means
  infinitely far, which has no finite depth, so it counts as invalid and is filled.
* **Invalid values** -- NaN, inf, zero, negative (and, in a grey+alpha PNG,
  transparent pixels) -- get ``valid=False`` and take the depth of the
  *nearest* valid pixel (:func:`~.fill.fill_nearest`). Nearest-valid never
  blends a foreground and a background value into a "flying" depth between
  them, as averaging or diffusion would at a depth edge. Fewer than
  :data:`MIN_VALID_FRACTION` valid pixels is an error.
* **Range.** Valid depths are clamped to [median / 1e3, median * 1e3], so
  max / min <= :data:`MAX_DEPTH_RATIO` = 1e6: a stray near-zero disparity
  cannot put one point a million times farther than the rest of the scene.
* **Resizing** to the photo's (H, W): see :func:`resize_depth`.

Files are read as stored (no EXIF orientation): a depth map must be written
in the orientation of the upright photo.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Literal, Optional, Tuple

import cv2
import numpy as np

from ..checks import check_choice, check_range
from ..errors import InputError, PathLike
from ..io.depth_files import read_depth_values
from .fill import fill_nearest
from .types import DepthMap

MIN_VALID_FRACTION = 0.01
"""Smallest accepted fraction of valid pixels in a depth file."""

MAX_DEPTH_RATIO = 1e6
"""Largest max/min ratio of valid depths; values beyond median * or / sqrt(ratio) are clamped."""

ASPECT_TOLERANCE = 0.02
"""Largest relative difference of aspect ratio between a depth map and the photo it is resized to."""

EDGE_RATIO = 1.1
"""Neighbouring depths whose ratio exceeds this count as a depth edge when resizing (no blending there)."""

_FLOAT_SAFE = (1e-30, 1e30)  # depth range that float32 holds with full precision, inverses included


def resize_depth(depth: np.ndarray, valid: np.ndarray, size_hw: Tuple[int, int], source: PathLike):
    """Resize a filled depth map (H, W) and its mask to the photo's ``size_hw`` without flying pixels.

    The mask uses nearest-neighbour. Depth is interpolated as *disparity*
    (1/depth is linear across a plane in the image), with area averaging when
    shrinking and bilinear when enlarging -- except at depth edges: where the
    source pixels that feed an output pixel differ by more than
    :data:`EDGE_RATIO`, the output takes the nearest source pixel instead, so a
    foreground and a background are never averaged into a point floating
    between them. Aspect ratios differing by more than :data:`ASPECT_TOLERANCE`
    raise InputError, and so does an empty depth map or target size (naming ``source``).

    Returns:
        (depth (h, w) float32, valid (h, w) bool).
    """
    h0, w0 = depth.shape
    h, w = int(size_hw[0]), int(size_hw[1])
    if h0 < 1 or w0 < 1:
        raise InputError(source, f"depth map is empty ({h0} x {w0} pixels, H x W); nothing to resize")
    if h < 1 or w < 1:
        raise InputError(source, f"cannot resize the depth map to {h} x {w} pixels (H x W)")
    if (h, w) == (h0, w0):
        return depth, valid
    mismatch = abs(math.log((w0 / h0) / (w / h)))
    if mismatch > ASPECT_TOLERANCE:
        raise InputError(source, f"depth map is {h0} x {w0} (H x W) but the photo is {h} x {w}: their aspect "
                                 f"ratios differ by {100 * mismatch:.1f}% (at most {100 * ASPECT_TOLERANCE:.0f}%)")
    nearest = cv2.INTER_NEAREST_EXACT  # pixel-centre aligned nearest neighbour
    valid_out = cv2.resize(valid.astype(np.uint8), (w, h), interpolation=nearest).astype(bool)
    disparity = (1.0 / depth).astype(np.float32)
    factor = max(h0 / h, w0 / w)
    smooth = cv2.resize(disparity, (w, h), interpolation=cv2.INTER_AREA if factor > 1 else cv2.INTER_LINEAR)
    sharp = cv2.resize(disparity, (w, h), interpolation=nearest)
    radius = math.ceil(factor / 2) + 1 if factor > 1 else 1  # covers the source pixels that feed `smooth`
    kernel = np.ones((2 * radius + 1, 2 * radius + 1), np.uint8)
    spread = cv2.dilate(depth, kernel) / cv2.erode(depth, kernel)  # (H, W) local max / min
    edge = cv2.resize(spread, (w, h), interpolation=nearest) > EDGE_RATIO
    return (1.0 / np.where(edge, sharp, smooth)).astype(np.float32), valid_out


def load_depth_file(
    path: PathLike,
    *,
    kind: Literal["depth", "disparity"] = "depth",
    size: Optional[Tuple[int, int]] = None,
    scale: float = 1.0,
) -> DepthMap:
    """Read a depth or disparity file into a filled :class:`DepthMap` (see the module docstring).

    Args:
        path: .png (8/16-bit grey), .npy, .pfm, .tif/.tiff or .exr.
        kind: "depth" (z values) or "disparity" (inverse depth).
        size: (H, W) of the photo to resize to, or None to keep the file's size.
        scale: multiplies the file's values first (e.g. 0.001 for millimetre PNGs).
    Returns:
        DepthMap with ``kind`` "metric" for depth files, "relative" for disparity files.
    Raises:
        InputError: naming the file, for unreadable files, too few valid values, aspect mismatch.
    """
    check_choice(kind, "kind", ("depth", "disparity"))
    scale = check_range(scale, "scale", 0.0, float("inf"), inclusive=False)
    if size is not None:
        try:
            size = (int(size[0]), int(size[1])) if len(size) == 2 else (0, 0)
        except (TypeError, ValueError) as e:
            raise InputError("size", f"expected (H, W), got {size!r}") from e
        if min(size) < 1:
            raise InputError("size", f"expected a positive (H, W), got {size!r}")
    raw, usable = read_depth_values(path)
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        values = raw * scale
        if kind == "disparity":
            values = 1.0 / np.where(values > 0, values, np.nan)
    valid = np.isfinite(values) & (values > 0)
    if usable is not None:
        valid &= usable
    fraction = float(valid.mean())
    if fraction == 0:
        raise InputError(path, "no valid depth values (every pixel is NaN, infinite, zero or negative)")
    if fraction < MIN_VALID_FRACTION:
        raise InputError(path, f"only {100 * fraction:.2f}% of the pixels hold a valid depth "
                               f"(at least {100 * MIN_VALID_FRACTION:.0f}% needed)")
    median = float(np.median(values[valid]))
    low, high = median / math.sqrt(MAX_DEPTH_RATIO), median * math.sqrt(MAX_DEPTH_RATIO)
    if low < _FLOAT_SAFE[0] or high > _FLOAT_SAFE[1]:
        raise InputError(path, f"depth values around {median:.3g} are too extreme to process; pass a `scale` "
                               "that brings them near 1")
    depth = fill_nearest(np.clip(np.where(valid, values, median), low, high), valid)  # (H, W) float32
    if size is not None:
        depth, valid = resize_depth(depth, valid, size, path)
    return DepthMap(depth, valid, "relative" if kind == "disparity" else "metric", f"file:{Path(path).name} ({kind})")
