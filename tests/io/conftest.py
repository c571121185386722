"""Fixtures that write test images and depth files into ``tmp_path`` (no binaries in the repo)."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path
from typing import Callable

import numpy as np
import pytest
from PIL import Image

# Pillow transposes that turn a photo stored with EXIF orientation N upright
# (as PIL.ImageOps.exif_transpose does), and their inverses, used to build the stored files.
UPRIGHT_OP = {
    2: Image.Transpose.FLIP_LEFT_RIGHT,
    3: Image.Transpose.ROTATE_180,
    4: Image.Transpose.FLIP_TOP_BOTTOM,
    5: Image.Transpose.TRANSPOSE,
    6: Image.Transpose.ROTATE_270,
    7: Image.Transpose.TRANSVERSE,
    8: Image.Transpose.ROTATE_90,
}
STORE_OP = {**UPRIGHT_OP, 6: Image.Transpose.ROTATE_90, 8: Image.Transpose.ROTATE_270}


@pytest.fixture
def quadrants() -> np.ndarray:
    """(48, 64, 3) uint8 upright test image: four flat, distinct colours, so any flip or turn shows."""
    img = np.zeros((48, 64, 3), np.uint8)
    img[:24, :32] = (230, 20, 20)  # top-left red
    img[:24, 32:] = (20, 230, 20)  # top-right green
    img[24:, :32] = (20, 20, 230)  # bottom-left blue
    img[24:, 32:] = (230, 230, 20)  # bottom-right yellow
    return img


@pytest.fixture
def write_image(tmp_path: Path) -> Callable[..., Path]:
    """``write_image(name, array_or_pil, mode=None, **pil_save_kwargs)`` -> path, written with Pillow."""

    def write(name: str, image, mode=None, **kwargs) -> Path:
        im = image if isinstance(image, Image.Image) else Image.fromarray(np.asarray(image), mode)
        path = tmp_path / name
        im.save(path, **kwargs)
        return path

    return write


@pytest.fixture
def write_exif_jpeg(tmp_path: Path) -> Callable[..., Path]:
    """``write_exif_jpeg(name, upright_uint8, orientation=1, focal_35mm=None, exif_ifd=None)`` -> path.

    Stores the pixels so that applying ``orientation`` makes them upright again.
    """

    def write(name: str, upright: np.ndarray, orientation: int = 1, focal_35mm=None, exif_ifd=None) -> Path:
        im = Image.fromarray(upright)
        if orientation != 1:
            im = im.transpose(STORE_OP[orientation])
        exif = Image.Exif()
        exif[0x0112] = orientation
        sub = exif.get_ifd(0x8769)
        if focal_35mm is not None:
            sub[0xA405] = focal_35mm
        sub.update(exif_ifd or {})
        path = tmp_path / name
        im.save(path, exif=exif, quality=95)
        return path

    return write


def png_bytes(width: int, height: int, raw_rows: bytes = b"", bit_depth: int = 8, colour_type: int = 2) -> bytes:
    """A hand-built PNG: IHDR with any size, one IDAT holding zlib(raw_rows), IEND."""

    def chunk(kind: bytes, payload: bytes) -> bytes:
        return struct.pack(">I", len(payload)) + kind + payload + struct.pack(">I", zlib.crc32(kind + payload))

    ihdr = struct.pack(">IIBBBBB", width, height, bit_depth, colour_type, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(raw_rows)) + chunk(b"IEND", b"")


@pytest.fixture
def write_bytes(tmp_path: Path) -> Callable[[str, bytes], Path]:
    """``write_bytes(name, data)`` -> path."""

    def write(name: str, data: bytes) -> Path:
        path = tmp_path / name
        path.write_bytes(data)
        return path

    return write


@pytest.fixture
def make_png_bytes() -> Callable[..., bytes]:
    """The :func:`png_bytes` builder, as a fixture."""
    return png_bytes


@pytest.fixture
def upright_op() -> dict:
    """EXIF orientation -> the Pillow transpose that turns a stored photo upright."""
    return dict(UPRIGHT_OP)
