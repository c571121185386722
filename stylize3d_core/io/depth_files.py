"""Depth and disparity maps from files: 16/8-bit PNG, ``.npy``, ``.pfm``, float TIFF, EXR.

:func:`load_depth_file` turns a file into a :class:`~stylize3d_core.depth.types.DepthMap`:

* **Values.** ``kind="depth"``: depth = value * ``scale`` (the map's kind is
  "metric": in the file's unit times ``scale``). ``kind="disparity"``:
  depth = 1 / (value * ``scale``) (kind "relative"); a zero disparity means
  infinitely far, which has no finite depth, so it counts as invalid and is filled.
* **Invalid values** -- NaN, inf, zero, negative (and, in a grey+alpha PNG,
  transparent pixels) -- get ``valid=False`` and take the depth of the
  *nearest* valid pixel. Nearest-valid never blends a foreground and a
  background value into a "flying" depth between them, as averaging or
  diffusion would at a depth edge. Fewer than :data:`MIN_VALID_FRACTION` valid
  pixels is an error.
* **Range.** Valid depths are clamped to [median / 1e3, median * 1e3], so
  max / min <= :data:`MAX_DEPTH_RATIO` = 1e6: a stray near-zero disparity
  cannot put one point a million times farther than the rest of the scene.
* **Resizing** to the photo's (H, W): see :func:`resize_depth`.

Files are read as stored (no EXIF orientation): a depth map must be written
in the orientation of the upright photo.

EXR is read through OpenCV, which decodes it only when built with OpenEXR and
when the environment variable ``OPENCV_IO_ENABLE_OPENEXR=1`` was set before
OpenCV was first imported; otherwise :func:`load_depth_file` says so. (The
variable is an opt-in security switch, so this module does not set it.)
"""

from __future__ import annotations

import io
import math
import os
import re
from pathlib import Path
from typing import Literal, Optional, Tuple

import cv2
import numpy as np

from ..checks import check_choice, check_range
from ..depth.types import DepthMap
from ..errors import ExportError, InputError, PathLike
from .atomic import atomic_path
from .images import check_png_structure, read_input_file

MIN_VALID_FRACTION = 0.01
"""Smallest accepted fraction of valid pixels in a depth file."""

MAX_DEPTH_RATIO = 1e6
"""Largest max/min ratio of valid depths; values beyond median * or / sqrt(ratio) are clamped."""

MAX_DEPTH_PIXELS = 150_000_000
"""Largest accepted H * W of a depth file (checked on the header for PNG and PFM)."""

ASPECT_TOLERANCE = 0.02
"""Largest relative difference of aspect ratio between a depth map and the photo it is resized to."""

EDGE_RATIO = 1.1
"""Neighbouring depths whose ratio exceeds this count as a depth edge when resizing (no blending there)."""

SUPPORTED_SUFFIXES = (".png", ".npy", ".pfm", ".tif", ".tiff", ".exr")

_FLOAT_SAFE = (1e-30, 1e30)  # depth range that float32 holds with full precision, inverses included


# ---------------------------------------------------------------------------- PFM


def read_pfm(path: PathLike) -> np.ndarray:
    """Read a PFM file: (H, W) float32 for 'Pf' (grey), (H, W, 3) for 'PF' (colour); top row first.

    The header is ``Pf|PF``, ``W H``, then a scale whose *sign* gives the byte order
    (negative: little-endian); its magnitude is ignored, as most writers store 1.
    Rows are stored bottom-to-top.
    """
    data = read_input_file(path, "PFM")
    m = re.match(rb"(P[fF])\s+(\d+)\s+(\d+)\s+(\S+?)(\r\n|\s)", data[:512])
    if m is None:
        raise InputError(path, "not a PFM file (expected a 'Pf'/'PF', width, height, scale header)")
    channels = 3 if m.group(1) == b"PF" else 1
    w, h = int(m.group(2)), int(m.group(3))
    try:
        endian_scale = float(m.group(4))
    except ValueError as e:
        raise InputError(path, f"PFM scale {m.group(4)!r} is not a number") from e
    if w < 1 or h < 1 or not math.isfinite(endian_scale) or endian_scale == 0:
        raise InputError(path, f"bad PFM header: size {w} x {h}, scale {endian_scale}")
    if w * h > MAX_DEPTH_PIXELS:
        raise InputError(path, f"PFM is {w} x {h} pixels, more than {MAX_DEPTH_PIXELS}")
    count = w * h * channels
    body = data[m.end():]
    if len(body) < 4 * count:
        raise InputError(path, f"PFM file is truncated: {len(body)} bytes of data, expected {4 * count}")
    dtype = np.dtype("<f4" if endian_scale < 0 else ">f4")
    rows = np.frombuffer(body, dtype, count=count).reshape(h, w, channels)  # bottom row first
    out = rows[::-1].astype(np.float32)  # (H, W, C), top row first, native byte order
    return out[..., 0] if channels == 1 else out


def write_pfm(path: PathLike, data: np.ndarray, *, little_endian: bool = True) -> None:
    """Write (H, W) or (H, W, 3) floats as PFM (atomically); NaN and inf are stored as they are."""
    a = np.asarray(data)
    if a.dtype.kind not in "fiu" or not (a.ndim == 2 or (a.ndim == 3 and a.shape[2] in (1, 3))):
        raise InputError("data", f"expected a numeric array (H, W) or (H, W, 3), got {a.dtype} {a.shape}")
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    h, w = a.shape[:2]
    header = f"{'Pf' if a.ndim == 2 else 'PF'}\n{w} {h}\n{-1.0 if little_endian else 1.0}\n".encode("ascii")
    body = np.ascontiguousarray(a[::-1], dtype="<f4" if little_endian else ">f4").tobytes()
    with atomic_path(path) as tmp:
        tmp.write_bytes(header + body)


# ---------------------------------------------------------------------------- readers


def _single_channel(a: np.ndarray, source: PathLike) -> Tuple[np.ndarray, Optional[np.ndarray]]:
    """(values (H, W), mask of usable pixels or None) from a decoded image (H, W[, C]) in OpenCV order."""
    if a.ndim == 2:
        return a, None
    if a.ndim == 3 and a.shape[2] == 1:
        return a[..., 0], None
    if a.ndim == 3 and a.shape[2] in (3, 4):
        colour = a[..., :3]
        if not (np.array_equal(colour[..., 0], colour[..., 1]) and np.array_equal(colour[..., 0], colour[..., 2])):
            raise InputError(source, "depth image has 3 different colour channels; expected a single-channel "
                                     "(grey) depth or disparity map, not a colour-mapped visualisation")
        return colour[..., 0], (a[..., 3] > 0 if a.shape[2] == 4 else None)
    raise InputError(source, f"expected a single-channel depth image, got shape {a.shape}")


def _decode_with_opencv(data: bytes, source: PathLike, what: str) -> np.ndarray:
    try:
        a = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    except cv2.error as e:
        raise InputError(source, f"could not decode the {what} file ({str(e).strip()})") from e
    if a is None:
        raise InputError(source, f"could not decode the {what} file (corrupt or unsupported variant)")
    return a


def exr_unavailable_reason() -> Optional[str]:
    """None if this OpenCV can read EXR, else why not (in words)."""
    line = next((l for l in cv2.getBuildInformation().splitlines() if "OpenEXR:" in l), "")
    if line.split(":", 1)[-1].strip().upper().startswith("NO"):
        return "this OpenCV build has no OpenEXR support; convert the depth to .pfm, .npy or 16-bit .png"
    if os.environ.get("OPENCV_IO_ENABLE_OPENEXR", "").strip().lower() not in ("1", "true", "on", "yes"):
        return ("OpenCV reads EXR only when the environment variable OPENCV_IO_ENABLE_OPENEXR=1 is set "
                "before it is imported; set it and restart, or convert the depth to .pfm or .npy")
    return None


def read_depth_values(path: PathLike) -> Tuple[np.ndarray, Optional[np.ndarray]]:
    """Raw values of a depth/disparity file: ((H, W) float64, (H, W) bool mask of usable pixels or None)."""
    suffix = Path(path).suffix.lower()
    if suffix not in SUPPORTED_SUFFIXES:
        raise InputError(path, f"unsupported depth file type {suffix!r}; expected one of {', '.join(SUPPORTED_SUFFIXES)}")
    if suffix == ".pfm":
        values, mask = _single_channel(read_pfm(path), path)
        return values.astype(np.float64), mask
    data = read_input_file(path, "depth")
    if suffix == ".exr":
        reason = exr_unavailable_reason()
        if reason is not None:
            raise InputError(path, f"cannot read EXR: {reason}")
    if suffix == ".npy":
        try:
            a = np.load(io.BytesIO(data), allow_pickle=False)
        except (ValueError, OSError, EOFError) as e:
            raise InputError(path, f"not a valid .npy array file ({e})") from e
        if not isinstance(a, np.ndarray) or a.dtype.kind not in "fiu":
            raise InputError(path, f"expected a numeric (float or integer) array, got {getattr(a, 'dtype', type(a))}")
        if a.ndim == 3 and a.shape[0] == 1:
            a = a[0]
        if a.ndim == 3 and a.shape[2] != 1 or a.ndim not in (2, 3):
            raise InputError(path, f"expected a 2-D array (H, W) or a single channel (H, W, 1), got shape {a.shape}")
        return (a[..., 0] if a.ndim == 3 else a).astype(np.float64), None
    if suffix == ".png":
        header = check_png_structure(data, path)
        if header.width * header.height > MAX_DEPTH_PIXELS:
            raise InputError(path, f"PNG is {header.width} x {header.height} pixels, more than {MAX_DEPTH_PIXELS}")
    values, mask = _single_channel(_decode_with_opencv(data, path, suffix.lstrip(".").upper()), path)
    if values.dtype.kind not in "fiu":
        raise InputError(path, f"unsupported sample type {values.dtype}")
    return values.astype(np.float64), mask


# ---------------------------------------------------------------------------- filling and resizing


def fill_nearest(values: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Give every invalid pixel the value of its nearest valid pixel (Euclidean, 5x5 chamfer).

    Args:
        values: (H, W) float; only entries where ``valid`` is True are read.
        valid: (H, W) bool with at least one True.
    Returns:
        (H, W) float32, equal to ``values`` where valid.
    """
    if valid.all():
        return values.astype(np.float32)
    zeros_at_valid = np.where(valid, 0, 255).astype(np.uint8)
    _, labels = cv2.distanceTransformWithLabels(zeros_at_valid, cv2.DIST_L2, 5, labelType=cv2.DIST_LABEL_PIXEL)
    lut = np.zeros(int(labels.max()) + 1, np.float32)  # label of each valid pixel -> its value
    lut[labels[valid]] = values[valid]
    return lut[labels]


def resize_depth(depth: np.ndarray, valid: np.ndarray, size_hw: Tuple[int, int], source: PathLike):
    """Resize a filled depth map (H, W) and its mask to the photo's ``size_hw`` without flying pixels.

    The mask uses nearest-neighbour. Depth is interpolated as *disparity*
    (1/depth is linear across a plane in the image), with area averaging when
    shrinking and bilinear when enlarging -- except at depth edges: where the
    source pixels that feed an output pixel differ by more than
    :data:`EDGE_RATIO`, the output takes the nearest source pixel instead, so a
    foreground and a background are never averaged into a point floating
    between them. Aspect ratios differing by more than :data:`ASPECT_TOLERANCE`
    raise InputError.

    Returns:
        (depth (h, w) float32, valid (h, w) bool).
    """
    h0, w0 = depth.shape
    h, w = int(size_hw[0]), int(size_hw[1])
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


# ---------------------------------------------------------------------------- public API


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


def save_depth_png16(path: PathLike, depth: np.ndarray, *, scale: Optional[float] = None) -> float:
    """Write a depth map (H, W) as a 16-bit grey PNG storing ``round(depth * scale)``; returns ``scale``.

    Non-finite and non-positive depths are stored as 0 (invalid); valid depths
    are stored as at least 1. With ``scale=None`` the largest valid depth maps to
    65535. Read it back with ``load_depth_file(path, scale=1 / returned_scale)``
    (quantisation error at most ``0.5 / scale``).
    """
    if Path(path).suffix.lower() != ".png":
        raise InputError(path, "a 16-bit depth map must be written to a .png file")
    a = np.asarray(depth)
    if a.ndim != 2 or a.dtype.kind not in "fiu":
        raise InputError("depth", f"expected a numeric (H, W) array, got {a.dtype} {a.shape}")
    a = a.astype(np.float64)
    valid = np.isfinite(a) & (a > 0)
    if not valid.any():
        raise InputError("depth", "no finite positive depth to store")
    if scale is None:
        scale = 65535.0 / float(a[valid].max())
    scale = check_range(scale, "scale", 0.0, float("inf"), inclusive=False)
    stored = np.rint(np.where(valid, a, 0.0) * scale)
    if stored.max() > 65535:
        raise InputError("scale", f"depth * scale reaches {stored.max():.0f}, more than 16 bits hold (65535)")
    q = np.where(valid, np.maximum(stored, 1), 0).astype(np.uint16)
    ok, buf = cv2.imencode(".png", q)
    if not ok:
        raise ExportError(f"{os.fspath(path)}: OpenCV could not encode the depth PNG")
    with atomic_path(path) as tmp:
        tmp.write_bytes(buf.tobytes())
    return scale
