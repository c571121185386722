"""Fuzz targets: the parsers that read user files, fed arbitrary bytes.

Each target takes one input (bytes), writes it to a file and calls the parser.
A parser may refuse the input only with :class:`InputError`; any other
exception is a crash (atheris reports it and saves the input). The first byte
of some inputs picks the format or the entry point (see each target), so one
corpus covers several readers.

Run by ``run_fuzz.py`` (atheris, coverage-guided) and replayed by ``test_fuzz.py``.
"""

from __future__ import annotations

import atexit
import shutil
import tempfile
from pathlib import Path
from typing import Callable, Dict

from stylize3d_core.errors import InputError

_DIR = Path(tempfile.mkdtemp(prefix="stylize3d-fuzz-"))
atexit.register(shutil.rmtree, _DIR, ignore_errors=True)
MAX_LEN = 16 * 1024
"""Longest input the fuzzer generates (and replays)."""


def _file(name: str, data: bytes) -> Path:
    path = _DIR / name
    path.write_bytes(data)
    return path


def camera_path(data: bytes) -> None:
    """Byte 0 % 4 == 3: an Open3D PinholeCameraTrajectory; else a stylize3d camera path. Rest: the JSON file."""
    from stylize3d_core.io.camera_path import load_camera_path, load_open3d_trajectory

    if not data:
        return
    path = _file("path.json", data[1:])
    if data[0] % 4 == 3:
        load_open3d_trajectory(path)
    else:
        load_camera_path(path)


DEPTH_SUFFIXES = (".png", ".npy", ".pfm", ".tiff")


def depth_file(data: bytes) -> None:
    """Byte 0 % 4 picks PNG16 / NPY / PFM / TIFF; the rest is the depth file."""
    from stylize3d_core.io.depth_files import read_depth_values

    if not data:
        return
    read_depth_values(_file("depth" + DEPTH_SUFFIXES[data[0] % 4], data[1:]))


def phone_jpeg(data: bytes) -> None:
    """The bytes are a phone JPEG: XMP packets, GDepth data, a Dynamic Depth container."""
    from stylize3d_core.depth.phone_xmp import has_embedded_depth, read_embedded_depth

    has_embedded_depth(data)
    read_embedded_depth(data, "photo.jpg")


def checkpoint(data: bytes) -> None:
    """Byte 0 % 2 == 1: the model-configuration JSON of a checkpoint's metadata; else a whole checkpoint file."""
    from stylize3d_core.models.checkpoint import config_from_json, load_checkpoint

    if not data:
        return
    if data[0] % 2 == 1:
        config_from_json(data[1:].decode("utf-8", "replace"), "checkpoint.safetensors")
    else:
        load_checkpoint(_file("checkpoint.safetensors", data[1:]))


TARGETS: Dict[str, Callable[[bytes], None]] = {
    "camera_path": camera_path, "depth_file": depth_file, "phone_jpeg": phone_jpeg, "checkpoint": checkpoint,
}


KNOWN_OPEN: Dict[str, tuple] = {}
"""Exception types per target that are known, reported crashes; the fuzzer keeps going past them."""


def run_one(target: str, data: bytes, *, known_open: bool = True) -> None:
    """Run ``target`` on ``data``; an InputError is the parser refusing the input (fine).

    With ``known_open`` the exceptions listed in :data:`KNOWN_OPEN` are let through too.
    """
    allowed = (InputError,) + (KNOWN_OPEN.get(target, ()) if known_open else ())
    try:
        TARGETS[target](data)
    except allowed:
        pass
