"""Raw depth and disparity files: 16/8-bit PNG, ``.npy``, ``.pfm``, float TIFF, EXR.

:func:`read_depth_values` decodes a file into its values as stored, (H, W)
float64, and a mask of the pixels the file marks as unusable (transparent
pixels of a grey+alpha PNG); nothing else is decided here. What the values
mean -- depth or disparity, which ones are invalid and how they are filled,
the range clamp, resizing to the photo -- is depth policy, applied by
:func:`stylize3d_core.depth.files.load_depth_file`. :func:`read_pfm` /
:func:`write_pfm` and :func:`save_depth_png16` are the format readers and
writers (writes are atomic).

Files are read as stored (no EXIF orientation): a depth map must be written
in the orientation of the upright photo.

EXR is read through OpenCV, which decodes it only when built with OpenEXR and
when the environment variable ``OPENCV_IO_ENABLE_OPENEXR=1`` was set before
OpenCV was first imported; otherwise :func:`read_depth_values` says so. (The
variable is an opt-in security switch, so this module does not set it.)
"""

from __future__ import annotations

import io
import math
import os
import re
from pathlib import Path
from tokenize import TokenError
from typing import Optional, Tuple

import cv2
import numpy as np

from ..checks import check_range
from ..errors import ExportError, InputError, PathLike
from .atomic import atomic_path
from .images import check_png_structure, declared_pixels, read_input_file

MAX_DEPTH_PIXELS = 150_000_000
"""Largest accepted H * W of a depth file (checked on the header for PNG and PFM)."""

SUPPORTED_SUFFIXES = (".png", ".npy", ".pfm", ".tif", ".tiff", ".exr")


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
    """Raw values of a depth/disparity file: ((H, W) float64, (H, W) bool mask of usable pixels or None).

    H and W are at least 1: a file holding no pixels (a 0 x 0 ``.npy``) is an
    InputError naming it, like any other bad file.
    """
    values, mask = _read_values(path)
    if values.size == 0:
        raise InputError(path, f"depth map is empty ({values.shape[0]} x {values.shape[1]} pixels, H x W)")
    return values, mask


def _read_values(path: PathLike) -> Tuple[np.ndarray, Optional[np.ndarray]]:
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
        # a corrupt header can make numpy's header parser raise SyntaxError or tokenize.TokenError
        except (ValueError, OSError, EOFError, SyntaxError, TokenError, RecursionError, MemoryError) as e:
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
    else:  # TIFF: a huge declared size is refused before OpenCV allocates it (Pillow cannot read EXR
        # headers: those go to OpenCV unchecked, under its own limit of 2**30 pixels)
        pixels = declared_pixels(data) or 0
        if pixels > MAX_DEPTH_PIXELS:
            raise InputError(path, f"{suffix.lstrip('.').upper()} declares {pixels:,} pixels, more than {MAX_DEPTH_PIXELS:,}")
    values, mask = _single_channel(_decode_with_opencv(data, path, suffix.lstrip(".").upper()), path)
    if values.dtype.kind not in "fiu":
        raise InputError(path, f"unsupported sample type {values.dtype}")
    return values.astype(np.float64), mask


def save_depth_png16(path: PathLike, depth: np.ndarray, *, scale: Optional[float] = None) -> float:
    """Write a depth map (H, W) as a 16-bit grey PNG storing ``round(depth * scale)``; returns ``scale``.

    Non-finite and non-positive depths are stored as 0 (invalid); valid depths
    are stored as at least 1. With ``scale=None`` the largest valid depth maps to
    65535. Read it back with ``depth.files.load_depth_file(path, scale=1 / returned_scale)``
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
