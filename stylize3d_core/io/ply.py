"""Coloured point clouds as binary little-endian PLY files (readable by Open3D, MeshLab, Blender).

The file written by :func:`write_ply`::

    ply
    format binary_little_endian 1.0
    comment stylize3d point cloud
    element vertex N
    property float x
    property float y
    property float z
    property uchar red
    property uchar green
    property uchar blue
    property uchar label        (only when labels are given)
    end_header
    <N packed records of 15 (or 16) bytes>

Coordinates are whatever frame the caller passes (usually the world frame of
:mod:`stylize3d_core.geometry.camera`: the photo's camera, +z forward, y down).
The file is written atomically and read back before it replaces anything
(:func:`stylize3d_core.io.atomic.write_atomically`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Dict, List, NamedTuple, Optional, Tuple

import numpy as np
import torch

from ..errors import ExportError, InputError, PathLike
from .atomic import write_atomically
from .images import to_uint8

_PLY_TYPES: Dict[str, str] = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "<i2", "int16": "<i2", "ushort": "<u2", "uint16": "<u2",
    "int": "<i4", "int32": "<i4", "uint": "<u4", "uint32": "<u4",
    "float": "<f4", "float32": "<f4", "double": "<f8", "float64": "<f8",
}
_MAX_HEADER_BYTES = 64 * 1024


class PlyPointCloud(NamedTuple):
    """A point cloud read from a PLY file.

    Attributes:
        xyz: (N, 3) float32 positions.
        rgb: (N, 3) uint8 colours.
        labels: (N,) integer per-point labels (uint8 in files :func:`write_ply` wrote),
            or None when the file has none.
    """

    xyz: np.ndarray
    rgb: np.ndarray
    labels: Optional[np.ndarray]


def _numpy(x: Any, name: str) -> np.ndarray:
    if isinstance(x, torch.Tensor):
        return x.detach().cpu().numpy()
    if isinstance(x, np.ndarray):
        return x
    raise InputError(name, f"expected a numpy array or a torch tensor, got {type(x).__name__}")


def _colours_u8(rgb: np.ndarray, n: int) -> np.ndarray:
    """(N, 3) uint8 from uint8, or from floats in [0, 1] (clipped, rounded). Input untouched."""
    if rgb.ndim != 2 or rgb.shape != (n, 3):
        raise InputError("rgb", f"expected shape ({n}, 3), got {tuple(rgb.shape)}")
    if rgb.dtype == np.uint8:
        return rgb
    if not np.issubdtype(rgb.dtype, np.floating):
        raise InputError("rgb", f"expected uint8 or float values in [0, 1], got dtype {rgb.dtype}")
    if not np.isfinite(rgb).all():
        raise InputError("rgb", "contains NaN or infinite values")
    return to_uint8(rgb)  # (N, 3)


def write_ply(path: PathLike, xyz: Any, rgb: Any, *, labels: Optional[Any] = None) -> Path:
    """Write a coloured point cloud as binary little-endian PLY, atomically.

    Args:
        path: destination ``*.ply``.
        xyz: (N, 3) finite positions, N >= 1 (numpy or torch; stored as float32).
        rgb: (N, 3) colours, uint8 or float in [0, 1] (clipped).
        labels: optional (N,) integer labels in [0, 255], stored as a uchar ``label`` property.
    Returns:
        The destination path.
    """
    dest = Path(path)
    if dest.suffix.lower() != ".ply":
        raise InputError(dest, "a point cloud file must end in .ply")
    p = _numpy(xyz, "xyz")
    if p.ndim != 2 or p.shape[1] != 3:
        raise InputError("xyz", f"expected shape (N, 3), got {tuple(p.shape)}")
    n = p.shape[0]
    if n == 0:
        raise InputError("xyz", "the point cloud is empty")
    if not (np.issubdtype(p.dtype, np.floating) or np.issubdtype(p.dtype, np.integer)):
        raise InputError("xyz", f"expected numbers, got dtype {p.dtype}")
    if not np.isfinite(p).all():
        raise InputError("xyz", "contains NaN or infinite values")
    if float(np.abs(p).max()) > float(np.finfo(np.float32).max):
        raise InputError("xyz", "values too large for float32")
    p32 = p.astype(np.float32)  # (N, 3)
    c = _colours_u8(_numpy(rgb, "rgb"), n)
    fields: List[Tuple[str, str]] = [("x", "<f4"), ("y", "<f4"), ("z", "<f4"),
                                     ("red", "u1"), ("green", "u1"), ("blue", "u1")]
    lab = None
    if labels is not None:
        lab = _numpy(labels, "labels")
        if lab.shape != (n,):
            raise InputError("labels", f"expected shape ({n},), got {tuple(lab.shape)}")
        if not np.issubdtype(lab.dtype, np.integer) or (lab.size and (lab.min() < 0 or lab.max() > 255)):
            raise InputError("labels", "expected integers in [0, 255]")
        fields.append(("label", "u1"))
    rec = np.empty(n, dtype=np.dtype(fields))  # packed records
    rec["x"], rec["y"], rec["z"] = p32[:, 0], p32[:, 1], p32[:, 2]
    rec["red"], rec["green"], rec["blue"] = c[:, 0], c[:, 1], c[:, 2]
    if lab is not None:
        rec["label"] = lab
    names = {"<f4": "float", "u1": "uchar"}
    header = ["ply", "format binary_little_endian 1.0", "comment stylize3d point cloud", f"element vertex {n}"]
    header += [f"property {names[t]} {name}" for name, t in fields] + ["end_header"]
    head = ("\n".join(header) + "\n").encode("ascii")

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as fh:
            fh.write(head)
            fh.write(rec.tobytes())

    def verify(tmp: Path) -> None:  # read back: the header parses and announces the records that are there
        data = tmp.read_bytes()
        try:
            count, dtype, offset = _parse_header(tmp, data)
        except InputError as e:
            raise ExportError(f"{dest}: the written point cloud does not read back ({e.problem})") from None
        if count != n or dtype != rec.dtype or len(data) != offset + rec.nbytes:
            raise ExportError(f"{dest}: the written point cloud is incomplete ({len(data)} of "
                              f"{len(head) + rec.nbytes} bytes)")

    write_atomically(dest, "point cloud", write, verify=verify, size=len(head) + rec.nbytes)
    return dest


def _parse_header(src: Path, data: bytes) -> Tuple[int, np.dtype, int]:
    """(vertex count, vertex record dtype, offset of the binary data) of a PLY file."""
    if not data.startswith(b"ply\n") and not data.startswith(b"ply\r\n"):
        raise InputError(src, "not a PLY file (it does not start with 'ply')")
    end = data.find(b"end_header", 0, _MAX_HEADER_BYTES)
    if end < 0:
        raise InputError(src, "PLY header has no 'end_header' line")
    offset = data.index(b"\n", end) + 1
    try:
        lines = data[:end].decode("ascii").splitlines()[1:]
    except UnicodeDecodeError:
        raise InputError(src, "PLY header is not ASCII text") from None
    fmt = None
    count = None
    fields: List[Tuple[str, str]] = []
    element = None
    for line in lines:
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format":
            fmt = " ".join(words[1:])
        elif words[0] == "element":
            if element == "vertex":
                break  # the vertex block comes first; later elements are not read
            if len(words) != 3 or not words[2].isdigit():
                raise InputError(src, f"malformed PLY element line {line!r}")
            element = words[1]
            if element != "vertex":
                raise InputError(src, f"the first PLY element must be 'vertex', got {element!r}")
            count = int(words[2])
        elif words[0] == "property" and element == "vertex":
            if len(words) != 3 or words[1] == "list":
                raise InputError(src, f"unsupported vertex property {line!r} (only scalar properties)")
            if words[1] not in _PLY_TYPES:
                raise InputError(src, f"unknown PLY type in {line!r}")
            fields.append((words[2], _PLY_TYPES[words[1]]))
        else:
            raise InputError(src, f"unexpected PLY header line {line!r}")
    if fmt != "binary_little_endian 1.0":
        raise InputError(src, f"only binary little-endian PLY files are supported, got format {fmt!r}")
    if count is None:
        raise InputError(src, "PLY header has no vertex element")
    names = [f for f, _ in fields]
    if len(set(names)) != len(names):
        raise InputError(src, "PLY header repeats a vertex property")
    return count, np.dtype(fields), offset


def read_ply(path: PathLike) -> PlyPointCloud:
    """Read a binary little-endian PLY point cloud with x, y, z and uchar red, green, blue.

    An optional integer ``label`` property is returned as ``labels``; other vertex
    properties and later elements (e.g. faces) are ignored.

    Raises:
        InputError: naming the file and the problem (missing, not PLY, ASCII or
            big-endian, missing properties, truncated data, non-finite positions).
    """
    src = Path(path)
    try:
        data = src.read_bytes()
    except FileNotFoundError:
        raise InputError(src, "file not found") from None
    except OSError as e:
        raise InputError(src, f"cannot read the file: {e}") from None
    count, dtype, offset = _parse_header(src, data)
    need = count * dtype.itemsize
    if len(data) - offset < need:
        raise InputError(src, f"truncated: {count} vertices need {need} bytes, the file has {len(data) - offset}")
    rec = np.frombuffer(data, dtype=dtype, count=count, offset=offset)
    names = dtype.names or ()
    for key in ("x", "y", "z"):
        if key not in names or dtype[key].kind != "f":
            raise InputError(src, f"PLY vertices need a float property {key!r}")
    for key in ("red", "green", "blue"):
        if key not in names or dtype[key] != np.uint8:
            raise InputError(src, f"PLY vertices need a uchar property {key!r}")
    xyz = np.stack([rec["x"], rec["y"], rec["z"]], axis=-1).astype(np.float32)  # (N, 3)
    if not np.isfinite(xyz).all():
        raise InputError(src, "vertex positions contain NaN or infinite values")
    rgb = np.stack([rec["red"], rec["green"], rec["blue"]], axis=-1)  # (N, 3) uint8
    labels = None
    if "label" in names:
        if dtype["label"].kind not in "iu":
            raise InputError(src, "the 'label' property must be an integer type")
        labels = np.array(rec["label"])  # (N,) a copy, in the file's integer type
    return PlyPointCloud(xyz, np.ascontiguousarray(rgb), labels)
