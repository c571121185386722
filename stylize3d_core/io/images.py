"""Read and write photos: JPEG, PNG (8/16-bit, grey, alpha, palette), WebP and TIFF.

Every photo becomes a :class:`LoadedImage`: ``rgb`` (H, W, 3) float32 sRGB values
in [0, 1], upright (the EXIF orientation is applied), shrunk so its long side is
at most ``max_size``; it also keeps the file's bytes and its EXIF orientation, so
that whatever else needs the file (depth embedded by a phone) reads it from
there instead of opening and parsing the file again. EXIF is parsed here only. Anything wrong with a file -- missing, a folder, empty,
not an image, truncated, too small, a decompression bomb, an unsupported pixel
mode -- raises :class:`~stylize3d_core.errors.InputError` naming the file.

Truncation is detected by checking the file structure ourselves (a PNG must
reach its IEND chunk, a JPEG must hold an EOI marker after its first scan), so
the result does not depend on ``PIL.ImageFile.LOAD_TRUNCATED_IMAGES``, which
another library may have switched on.

Pillow does the decoding, except for 16-bit colour PNG/TIFF, which Pillow
reduces to 8 bits: those are decoded by OpenCV so the 16-bit precision is kept.
"""

from __future__ import annotations

import io
import math
import os
import re
import struct
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple, Optional, Tuple

import cv2
import numpy as np
from PIL import Image, UnidentifiedImageError

from ..checks import check_finite, check_range
from ..errors import ExportError, InputError, PathLike
from .atomic import atomic_path

FILM_DIAGONAL_MM = math.hypot(36.0, 24.0)
"""Diagonal of 35 mm film (36 x 24 mm), 43.27 mm: what a "35 mm equivalent" focal length refers to."""

PLAUSIBLE_FOCAL_35MM = (4.0, 2000.0)
"""35 mm-equivalent focal lengths (mm) outside this range are treated as a broken EXIF tag."""

_ORIENTATION_TAG = 0x0112
_EXIF_IFD = 0x8769
_FOCAL_35MM_TAG = 0xA405
_FOCAL_LENGTH_TAG = 0x920A
_FOCAL_PLANE_XRES_TAG, _FOCAL_PLANE_YRES_TAG, _FOCAL_PLANE_UNIT_TAG = 0xA20E, 0xA20F, 0xA210
_PIXEL_X_TAG, _PIXEL_Y_TAG = 0xA002, 0xA003
_FOCAL_PLANE_UNIT_MM = {2: 25.4, 3: 10.0, 4: 1.0, 5: 1e-3}  # inch, cm, mm, micrometre

_RGB_MODES = ("1", "L", "P", "RGB", "RGBX", "CMYK", "YCbCr")
_RGBA_MODES = ("LA", "La", "PA", "RGBA", "RGBa")
_GREY16_MODES = ("I;16", "I;16L", "I;16B", "I;16N", "I")
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@dataclass(frozen=True)
class LoadedImage:
    """A decoded photo.

    Attributes:
        rgb: (H, W, 3) float32 sRGB values in [0, 1], upright, *not* premultiplied by alpha.
        alpha: (H, W) float32 opacity in [0, 1], or None when the file has no alpha channel.
        path: the file it came from, or None for an in-memory array.
        original_size: (H, W) of the upright photo before shrinking to ``max_size``.
        bit_depth: 8 or 16, the precision of the source samples (16 for float arrays).
        focal_35mm: the 35 mm-equivalent focal length from EXIF in mm, or None.
        orientation: the EXIF orientation (1..8) the file was stored with and that
            was applied to make ``rgb`` upright; 1 when the file has none, and for
            an in-memory array. Data stored alongside the pixels in the file's
            orientation (a phone's depth map) is turned upright with
            ``apply_orientation(data, orientation)``.
        data: the file's bytes exactly as read (None for an in-memory array), for
            metadata that is not decoded here, e.g. the XMP in which phones embed a
            depth map; the file is read once, by :func:`load_image`.
        format: the file's format as Pillow names it ("JPEG", "PNG", "MPO", "WEBP",
            "TIFF", ...), or None for an in-memory array.
    """

    rgb: np.ndarray
    alpha: Optional[np.ndarray]
    path: Optional[str]
    original_size: Tuple[int, int]
    bit_depth: int
    focal_35mm: Optional[float]
    orientation: int = 1
    data: Optional[bytes] = field(default=None, repr=False, compare=False)
    format: Optional[str] = None

    def __post_init__(self) -> None:
        if self.orientation not in range(1, 9):
            raise InputError(self.path or "image", f"EXIF orientation must be 1..8, got {self.orientation!r}")

    @property
    def size(self) -> Tuple[int, int]:
        """(H, W) of ``rgb``."""
        return int(self.rgb.shape[0]), int(self.rgb.shape[1])

    def fov_y_deg(self) -> Optional[float]:
        """Vertical field of view from EXIF in degrees; see :func:`fov_y_deg_from_exif`."""
        return fov_y_deg_from_exif(self)


def fov_y_deg_from_exif(loaded: LoadedImage) -> Optional[float]:
    """Vertical FOV (degrees) implied by ``loaded.focal_35mm``, or None if unknown or absurd.

    A 35 mm-equivalent focal length ``f`` means the photo's *diagonal* spans the
    angle that 43.27 mm (the 36 x 24 mm film diagonal) spans at distance ``f``.
    For an upright photo of (H, W) the height then corresponds to
    ``43.27 * H / hypot(H, W)`` mm, so ``fov_y = 2 atan(that / (2 f))``.
    """
    from ..geometry.camera import MAX_FOV_DEG, MIN_FOV_DEG

    f = loaded.focal_35mm
    if f is None or not math.isfinite(f) or not PLAUSIBLE_FOCAL_35MM[0] <= f <= PLAUSIBLE_FOCAL_35MM[1]:
        return None
    h, w = loaded.original_size
    height_mm = FILM_DIAGONAL_MM * h / math.hypot(h, w)
    fov = math.degrees(2.0 * math.atan(height_mm / (2.0 * f)))
    return fov if MIN_FOV_DEG <= fov <= MAX_FOV_DEG else None


# ---------------------------------------------------------------------------- file checks


def read_input_file(path: PathLike, what: str = "image") -> bytes:
    """Return the bytes of a user-given file, or raise InputError (missing, folder, empty, unreadable)."""
    p = Path(path)
    if not p.exists():
        raise InputError(path, f"{what} file not found")
    if p.is_dir():
        raise InputError(path, f"is a folder, not a file ({what} expected)")
    try:
        data = p.read_bytes()
    except OSError as e:
        raise InputError(path, f"cannot read the {what} file: {e.strerror or e}") from e
    if not data:
        raise InputError(path, f"{what} file is empty (0 bytes)")
    return data


class PngHeader(NamedTuple):
    width: int
    height: int
    bit_depth: int
    colour_type: int  # 0 grey, 2 RGB, 3 palette, 4 grey+alpha, 6 RGBA
    has_exif: bool = False  # an eXIf chunk is present


def check_png_structure(data: bytes, source: PathLike) -> PngHeader:
    """Walk a PNG's chunks; raise InputError unless it is complete up to IEND. Returns its IHDR."""
    if not data.startswith(_PNG_SIGNATURE):
        raise InputError(source, "not a PNG file (bad signature)")
    pos, header, has_data, has_exif = len(_PNG_SIGNATURE), None, False, False
    while True:
        if pos + 8 > len(data):
            raise InputError(source, "PNG file is truncated (it ends before its IEND chunk)")
        length, ctype = struct.unpack(">I4s", data[pos : pos + 8])
        end = pos + 12 + length  # length, type, data, CRC
        if end > len(data):
            raise InputError(source, f"PNG file is truncated (chunk {ctype!r} is cut off)")
        if ctype == b"IHDR" and length >= 13:
            header = PngHeader(*struct.unpack(">IIBB", data[pos + 8 : pos + 18]))
        has_data |= ctype == b"IDAT"
        has_exif |= ctype == b"eXIf"
        if ctype == b"IEND":
            break
        pos = end
    if header is None or not has_data:
        raise InputError(source, "corrupt PNG file (no IHDR or no image data)")
    return header._replace(has_exif=has_exif)


def check_jpeg_structure(data: bytes, source: PathLike) -> None:
    """Raise InputError unless a JPEG has its segments intact and an EOI marker after its first scan."""
    if not data.startswith(b"\xff\xd8"):
        raise InputError(source, "not a JPEG file (no SOI marker)")
    pos = 2
    while pos + 4 <= len(data):
        if data[pos] != 0xFF:
            raise InputError(source, f"corrupt JPEG file (no marker at byte {pos})")
        marker = data[pos + 1]
        if marker == 0xFF:  # fill byte
            pos += 1
            continue
        if marker == 0xD9:
            raise InputError(source, "corrupt JPEG file (it ends before any image data)")
        if 0xD0 <= marker <= 0xD7 or marker == 0x01:  # markers without a length
            pos += 2
            continue
        seg_end = pos + 2 + struct.unpack(">H", data[pos + 2 : pos + 4])[0]
        if seg_end > len(data):
            break
        if marker == 0xDA:  # start of scan: entropy-coded data never holds FF D9 (FF is stuffed)
            if data.find(b"\xff\xd9", seg_end) < 0:
                break
            return
        pos = seg_end
    raise InputError(source, "JPEG file is truncated (no end-of-image marker)")


def declared_pixels(data: bytes) -> Optional[int]:
    """Width x height an encoded image's header declares, read by Pillow without decoding; None if Pillow
    cannot read the header (EXR, for one).

    For checking a size before a decoder (OpenCV's) allocates it. An image so large that Pillow refuses it
    as a decompression bomb gives the count from Pillow's error (or 2**31 if the error does not say).
    """
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(io.BytesIO(data)) as im:
                return im.size[0] * im.size[1]
    except Image.DecompressionBombError as e:
        found = re.search(r"\((\d+) pixels\)", str(e))
        return int(found.group(1)) if found else 2**31
    except Exception:  # noqa: BLE001 -- any header Pillow cannot read: the size is unknown
        return None


# ---------------------------------------------------------------------------- decoding


def _exif_info(im: Image.Image, stored_wh: Tuple[int, int], source: PathLike) -> Tuple[int, Optional[float]]:
    """(orientation 1..8, 35 mm-equivalent focal length or None) from a Pillow image's EXIF."""
    try:
        exif = im.getexif()
        sub = exif.get_ifd(_EXIF_IFD)
    except (OSError, ValueError, SyntaxError, struct.error) as e:
        warnings.warn(f"{os.fspath(source)}: ignoring unreadable EXIF data ({e})", stacklevel=3)
        return 1, None
    orientation = exif.get(_ORIENTATION_TAG, 1)
    if orientation not in range(1, 9):
        warnings.warn(f"{os.fspath(source)}: ignoring invalid EXIF orientation {orientation!r}", stacklevel=3)
        orientation = 1

    def num(tag: int) -> Optional[float]:
        value = sub.get(tag)
        try:
            value = float(value) if value is not None else None
        except (TypeError, ValueError, ZeroDivisionError):
            return None
        return value if value is not None and math.isfinite(value) and value > 0 else None

    f35 = num(_FOCAL_35MM_TAG)
    if f35 is None:  # derive it from the focal length and the sensor's pixel pitch
        f, xres, unit = num(_FOCAL_LENGTH_TAG), num(_FOCAL_PLANE_XRES_TAG), sub.get(_FOCAL_PLANE_UNIT_TAG, 2)
        yres = num(_FOCAL_PLANE_YRES_TAG) or xres
        if f is not None and xres is not None and unit in _FOCAL_PLANE_UNIT_MM:
            w_px, h_px = num(_PIXEL_X_TAG) or stored_wh[0], num(_PIXEL_Y_TAG) or stored_wh[1]
            mm = _FOCAL_PLANE_UNIT_MM[unit]
            sensor_diag = math.hypot(w_px / xres * mm, h_px / yres * mm)
            f35 = f * FILM_DIAGONAL_MM / sensor_diag if sensor_diag > 0 else None
    return int(orientation), f35


def apply_orientation(a: np.ndarray, orientation: int) -> np.ndarray:
    """Turn an (H, W, ...) array stored with EXIF ``orientation`` (1..8) upright (returns a copy)."""
    ops = {
        1: lambda x: x,
        2: lambda x: x[:, ::-1],  # mirrored horizontally
        3: lambda x: x[::-1, ::-1],  # rotated 180
        4: lambda x: x[::-1],  # mirrored vertically
        5: lambda x: x.swapaxes(0, 1),  # transposed (main diagonal)
        6: lambda x: np.rot90(x, k=-1),  # needs 90 degrees clockwise
        7: lambda x: x.swapaxes(0, 1)[::-1, ::-1],  # transverse (anti-diagonal)
        8: lambda x: np.rot90(x, k=1),  # needs 90 degrees counter-clockwise
    }
    return np.ascontiguousarray(ops[orientation](a))


def _is_16bit_colour(im: Image.Image, png: Optional[PngHeader]) -> bool:
    """True for files Pillow would reduce to 8 bits: 16-bit RGB(A) PNG or TIFF."""
    if png is not None:
        return png.bit_depth == 16 and png.colour_type in (2, 6)
    if im.format == "TIFF" and im.mode in ("RGB", "RGBA", "RGBX"):
        bits = im.tag_v2.get(258, (8,))
        return max(bits if isinstance(bits, tuple) else (bits,)) == 16
    return False


def _decode_16bit_colour(data: bytes, source: PathLike):
    """Decode a 16-bit colour PNG/TIFF with OpenCV: (RGB (H, W, 3) uint16, alpha (H, W) or None, 16)."""
    a = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if a is None or a.dtype != np.uint16 or a.ndim != 3 or a.shape[2] not in (3, 4):
        raise InputError(source, "corrupt 16-bit colour image (OpenCV could not decode it)")
    alpha = a[..., 3] if a.shape[2] == 4 else None
    return a[..., 2::-1], alpha, 16  # BGR(A) -> RGB


def _pillow_pixels(im: Image.Image, source: PathLike):
    """Samples of a loaded Pillow image: ((H, W, 3) or (H, W) uint8/uint16, alpha or None, bit depth)."""
    mode = im.mode
    if mode == "P" and "transparency" in im.info:
        mode = "PA"
    if mode in _RGB_MODES:
        return np.asarray(im.convert("RGB")), None, 8
    if mode in _RGBA_MODES:
        a = np.asarray(im.convert("RGBA"))
        return a[..., :3], a[..., 3], 8
    if mode in _GREY16_MODES:
        a = np.asarray(im)
        if a.dtype.kind not in "iu" or a.min() < 0 or a.max() > 65535:
            raise InputError(source, f"unsupported pixel mode {im.mode} (values outside 0..65535)")
        return a.astype(np.uint16), None, 16
    raise InputError(source, f"unsupported pixel mode {im.mode!r} (expected grey, RGB, RGBA or palette; 8 or 16 bits)")


def load_image(
    path: PathLike, *, max_size: int = 1024, min_size: int = 32, max_pixels: int = 150_000_000
) -> LoadedImage:
    """Read a photo upright, as float RGB, shrunk so its long side is at most ``max_size``.

    Args:
        path: a JPEG, PNG, WebP or TIFF file (anything else Pillow decodes is accepted too).
        max_size: longest side of the result; larger photos are shrunk with area
            averaging keeping the aspect ratio; smaller ones are never enlarged.
        min_size: smallest accepted short side, of the photo and of the shrunk
            result (a very elongated photo can fail the second test).
        max_pixels: largest accepted H * W, checked on the header before decoding.
            Pillow's own limit (``PIL.Image.MAX_IMAGE_PIXELS``) applies as well.
    Returns:
        a :class:`LoadedImage`.
    Raises:
        InputError: naming the file, for any bad file.
    """
    _check_sizes(max_size, min_size, max_pixels)
    data = read_input_file(path, "image")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            im = Image.open(io.BytesIO(data))
    except (Image.DecompressionBombError, Image.DecompressionBombWarning) as e:
        raise InputError(path, f"image is too large, refused as a possible decompression bomb ({e})") from e
    except UnidentifiedImageError as e:
        raise InputError(path, "not an image file, or a corrupt one (no known image format)") from e
    except (OSError, ValueError, SyntaxError, struct.error) as e:
        raise InputError(path, f"corrupt image file ({e})") from e
    with im:
        file_format = im.format
        w, h = im.size
        if w * h > max_pixels:
            raise InputError(path, f"image is {w} x {h} = {w * h} pixels, more than max_pixels={max_pixels}")
        png = check_png_structure(data, path) if im.format == "PNG" else None
        if im.format in ("JPEG", "MPO"):
            check_jpeg_structure(data, path)
        if _is_16bit_colour(im, png):
            samples, alpha, bits = _decode_16bit_colour(data, path)
        else:
            try:  # decode before reading EXIF: Pillow's getexif() may decode a PNG and hide its errors
                with warnings.catch_warnings():
                    warnings.simplefilter("error", Image.DecompressionBombWarning)
                    im.load()
            except (Image.DecompressionBombError, Image.DecompressionBombWarning) as e:
                raise InputError(path, f"image is too large, refused as a possible decompression bomb ({e})") from e
            except (OSError, ValueError, SyntaxError, struct.error) as e:
                raise InputError(path, f"corrupt or truncated image file ({e})") from e
            samples, alpha, bits = _pillow_pixels(im, path)
        # a PNG without an eXIf chunk has no EXIF (and Pillow would decode it again to look for one)
        orientation, focal = (1, None) if png is not None and not png.has_exif else _exif_info(im, (w, h), path)
    top = np.float32(65535.0 if bits == 16 else 255.0)
    rgb = apply_orientation(samples, orientation).astype(np.float32) / top
    if rgb.ndim == 2:
        rgb = np.repeat(rgb[..., None], 3, axis=2)  # (H, W, 3)
    a = None if alpha is None else apply_orientation(alpha, orientation).astype(np.float32) / top
    return _finish(rgb, a, os.fspath(path), path, bits, focal, max_size, min_size,
                   orientation=orientation, data=data, file_format=file_format)


def load_image_array(
    array: np.ndarray, name: str = "array", *, max_size: int = 1024, min_size: int = 32, max_pixels: int = 150_000_000
) -> LoadedImage:
    """Validate an in-memory photo like :func:`load_image` does a file.

    Args:
        array: (H, W, 3) RGB, (H, W, 4) RGBA, (H, W, 1) or (H, W) grey; uint8
            (0..255), uint16 (0..65535) or float in [0, 1]. Channel order is RGB.
        name: how errors refer to it.
    """
    _check_sizes(max_size, min_size, max_pixels)
    a = np.asarray(array)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if not (a.ndim == 2 or (a.ndim == 3 and a.shape[2] in (3, 4))):
        raise InputError(name, f"expected an image of shape (H, W), (H, W, 3) or (H, W, 4), got {a.shape}")
    if a.shape[0] * a.shape[1] > max_pixels:
        raise InputError(name, f"image has {a.shape[0] * a.shape[1]} pixels, more than max_pixels={max_pixels}")
    if a.dtype == np.uint8:
        x, bits = a.astype(np.float32) / 255.0, 8
    elif a.dtype == np.uint16:
        x, bits = a.astype(np.float32) / 65535.0, 16
    elif a.dtype.kind == "f":
        check_finite(a, name)
        if a.size and (a.min() < -1e-6 or a.max() > 1 + 1e-6):
            raise InputError(name, f"float image values must lie in [0, 1], got [{a.min():.4g}, {a.max():.4g}]")
        x, bits = np.clip(a, 0.0, 1.0).astype(np.float32), 16
    else:
        raise InputError(name, f"unsupported dtype {a.dtype} (expected uint8, uint16 or float)")
    if x.ndim == 2:
        x = np.repeat(x[..., None], 3, axis=2)  # (H, W, 3)
    alpha = np.ascontiguousarray(x[..., 3]) if x.shape[2] == 4 else None
    return _finish(np.ascontiguousarray(x[..., :3]), alpha, None, name, bits, None, max_size, min_size)


def _check_sizes(max_size: int, min_size: int, max_pixels: int) -> None:
    check_range(min_size, "min_size", 1, 1 << 20)
    check_range(max_size, "max_size", min_size, 1 << 20)
    check_range(max_pixels, "max_pixels", 1, float("inf"))


def _finish(rgb, alpha, path, source, bits, focal, max_size, min_size, *,
            orientation: int = 1, data: Optional[bytes] = None, file_format: Optional[str] = None) -> LoadedImage:
    """Check the size, shrink to ``max_size`` (alpha-weighted), build the LoadedImage."""
    h, w = rgb.shape[:2]
    if min(h, w) < min_size:
        raise InputError(source, f"image is too small: {h} x {w} (H x W), the short side must be >= {min_size}")
    s = min(1.0, max_size / max(h, w))
    new_hw = (max(1, round(h * s)), max(1, round(w * s)))
    if min(new_hw) < min_size:
        raise InputError(source, f"image {h} x {w} is too elongated: shrunk to max_size={max_size} "
                                 f"its short side would be below {min_size}")
    if new_hw != (h, w):
        if alpha is None:
            rgb = resize_image(rgb, new_hw)
        else:  # average premultiplied colour so transparent pixels do not bleed in
            a_small = resize_image(alpha, new_hw)  # (h, w)
            premul = resize_image(rgb * alpha[..., None], new_hw)  # (h, w, 3)
            plain = resize_image(rgb, new_hw)
            safe = np.maximum(a_small, 1e-6)[..., None]
            rgb = np.where(a_small[..., None] > 1e-6, np.clip(premul / safe, 0.0, 1.0), plain)
            alpha = a_small
    return LoadedImage(rgb.astype(np.float32, copy=False), alpha, path, (int(h), int(w)), bits, focal,
                       orientation, data, file_format)


# ---------------------------------------------------------------------------- resize / save


def to_uint8(rgb: np.ndarray) -> np.ndarray:
    """Float colours in [0, 1] -> uint8: scaled by 255, rounded to nearest and clipped to [0, 255].

    ``k / 255`` maps back to ``k`` exactly. The caller checks finiteness (NaN has no uint8 value).
    """
    return np.clip(np.rint(np.asarray(rgb, dtype=np.float32) * 255.0), 0, 255).astype(np.uint8)


def rgb_to_uint8(image: np.ndarray, name: str) -> np.ndarray:
    """Check an (H, W, 3) image, uint8 or float in [0, 1], and return it as uint8 (H, W, 3).

    Float values are clipped to [0, 1] and rounded (:func:`to_uint8`); another
    dtype, another shape, NaN or inf is an InputError naming ``name``. The input
    is never modified.
    """
    a = image if isinstance(image, np.ndarray) else np.asarray(image)
    if a.ndim != 3 or a.shape[2] != 3 or a.shape[0] < 1 or a.shape[1] < 1:
        raise InputError(name, f"expected shape (H, W, 3), got {tuple(a.shape)}")
    if a.dtype == np.uint8:
        return np.ascontiguousarray(a)
    if not np.issubdtype(a.dtype, np.floating):
        raise InputError(name, f"expected uint8 or float values in [0, 1], got dtype {a.dtype}")
    if not np.isfinite(a).all():
        raise InputError(name, "contains NaN or infinite values")
    return to_uint8(a)  # (H, W, 3)


def resize_image(rgb: np.ndarray, size_hw: Tuple[int, int]) -> np.ndarray:
    """Resize an image (H, W, C) or (H, W) of values in [0, 1] to ``size_hw``; returns float32, clipped.

    Area averaging when shrinking both sides (no aliasing), bicubic otherwise
    (its overshoot is clipped back into [0, 1]).
    """
    a = np.asarray(rgb)
    if a.ndim not in (2, 3) or a.dtype.kind != "f":
        raise InputError("rgb", f"expected a float array (H, W) or (H, W, C), got {a.dtype} {a.shape}")
    try:
        h, w = int(size_hw[0]), int(size_hw[1])
    except (TypeError, ValueError, IndexError) as e:
        raise InputError("size_hw", f"expected (H, W), got {size_hw!r}") from e
    if h < 1 or w < 1:
        raise InputError("size_hw", f"must be positive, got {(h, w)}")
    if (h, w) == a.shape[:2]:
        return np.clip(a, 0.0, 1.0).astype(np.float32)
    shrink = h <= a.shape[0] and w <= a.shape[1]
    out = cv2.resize(a.astype(np.float32), (w, h), interpolation=cv2.INTER_AREA if shrink else cv2.INTER_CUBIC)
    if a.ndim == 3 and out.ndim == 2:  # OpenCV drops a single channel
        out = out[..., None]
    return np.clip(out, 0.0, 1.0)


_OUTPUT_EXT = {".png": ".png", ".jpg": ".jpg", ".jpeg": ".jpg", ".webp": ".webp"}


def save_image(path: PathLike, rgb: np.ndarray, *, bit_depth: int = 8, quality: int = 95) -> None:
    """Write an image (H, W, 3) RGB or (H, W) grey atomically as PNG, JPEG or WebP (from the suffix).

    Args:
        rgb: float values in [0, 1] (clipped; NaN/inf refused), or uint8/uint16 samples.
        bit_depth: 8, or 16 for a 16-bit PNG.
        quality: JPEG/WebP quality, 1..100.
    Raises:
        InputError: bad array, format or option. ExportError: the file could not be written.
    """
    ext = _OUTPUT_EXT.get(Path(path).suffix.lower())
    if ext is None:
        raise InputError(path, f"unsupported image format {Path(path).suffix!r}; use .png, .jpg or .webp")
    if bit_depth not in (8, 16):
        raise InputError("bit_depth", f"must be 8 or 16, got {bit_depth!r}")
    if bit_depth == 16 and ext != ".png":
        raise InputError(path, "16-bit output needs a .png file")
    check_range(quality, "quality", 1, 100)
    a = np.asarray(rgb)
    if not (a.ndim == 2 or (a.ndim == 3 and a.shape[2] == 3)):
        raise InputError("rgb", f"expected shape (H, W, 3) or (H, W), got {a.shape}")
    if a.dtype == np.uint8 or a.dtype == np.uint16:
        x = a.astype(np.float64) / np.iinfo(a.dtype).max
    elif a.dtype.kind == "f":
        check_finite(a, "rgb")
        x = np.clip(a.astype(np.float64), 0.0, 1.0)
    else:
        raise InputError("rgb", f"unsupported dtype {a.dtype} (expected float, uint8 or uint16)")
    top = 65535 if bit_depth == 16 else 255
    q = np.rint(x * top).astype(np.uint16 if bit_depth == 16 else np.uint8)
    if q.ndim == 3:
        q = np.ascontiguousarray(q[..., ::-1])  # RGB -> BGR for OpenCV
    params = {".jpg": [cv2.IMWRITE_JPEG_QUALITY, int(quality)], ".webp": [cv2.IMWRITE_WEBP_QUALITY, int(quality)]}
    ok, buf = cv2.imencode(ext, q, params.get(ext, []))
    if not ok:
        raise ExportError(f"{os.fspath(path)}: OpenCV could not encode the image as {ext}")
    with atomic_path(path) as tmp:
        tmp.write_bytes(buf.tobytes())
