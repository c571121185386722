"""A point cloud as a 3D Gaussian splat ``.ply``, the layout of the 3DGS ecosystem.

3D Gaussian Splatting (Kerbl et al. 2023) stores one Gaussian per vertex of a
binary little-endian PLY; SuperSplat, gsplat-based viewers and the original
SIBR viewer read these properties, all ``float``::

    x y z                position (world frame of geometry/camera.py: +z forward,
                         y down; the same OpenCV / COLMAP convention 3DGS uses)
    nx ny nz             normals, unused by the renderers (written as 0)
    f_dc_0 f_dc_1 f_dc_2 colour as the degree-0 spherical-harmonic coefficient:
                         rgb = 0.5 + SH_C0 * f_dc, so f_dc = (rgb - 0.5) / SH_C0
    opacity              logit of the opacity: alpha = sigmoid(opacity)
    scale_0..2           log of the standard deviations along the Gaussian's axes
    rot_0..3             unit quaternion (w, x, y, z) of the axes

Higher SH bands (``f_rest_*``) are left out: the colour does not depend on
the view (degree 0), which the viewers read as such.

Each point of a 3D photo stands for one pixel of the photo, so its footprint
is the pixel's width at its depth, ``z / f`` (f the photo's focal length in
pixels); the Gaussians are isotropic with standard deviation
``footprint * scale_factor`` (0.6 by default: neighbouring Gaussians, one
footprint apart, overlap enough to leave no gaps).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Dict, NamedTuple, Optional

import numpy as np

from ..checks import check_range
from ..errors import ExportError, InputError, PathLike
from ..geometry.camera import check_fov, focal_from_fov
from ..io.atomic import write_atomically
from ..io.images import read_input_file

SH_C0 = 0.28209479177387814
"""The degree-0 real spherical harmonic, 1 / (2 sqrt(pi))."""

SPLAT_PROPERTIES = ("x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
                    "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3")
"""The vertex properties written, in file order (all float32)."""

MAX_OPACITY = 1.0 - 1e-6
"""Opacities are clipped to [1 - MAX_OPACITY, MAX_OPACITY] so that their logit is finite."""


class SplatCloud(NamedTuple):
    """Gaussians as the viewers see them (decoded from the file's fields).

    Attributes:
        xyz: (N, 3) float32 centres.
        rgb: (N, 3) float32 colours in [0, 1] (from the degree-0 SH coefficient).
        opacity: (N,) float32 in (0, 1).
        scale: (N, 3) float32 standard deviations (> 0).
        rotation: (N, 4) float32 unit quaternions (w, x, y, z).
    """

    xyz: np.ndarray
    rgb: np.ndarray
    opacity: np.ndarray
    scale: np.ndarray
    rotation: np.ndarray


def point_footprints(xyz: np.ndarray, fov_y_deg: float, image_height: int) -> np.ndarray:
    """(N,) float32 width of one photo pixel at each point's depth, ``z / f`` (scene units).

    Args:
        xyz: (N, 3) points in the photo's camera frame (all with z > 0).
        fov_y_deg: the photo's vertical field of view.
        image_height: the photo's height in pixels (the focal length is ``(H / 2) / tan(fov / 2)``).
    """
    p = _points(xyz)
    if isinstance(image_height, bool) or int(image_height) != image_height or image_height < 1:
        raise InputError("image_height", f"must be a positive integer, got {image_height!r}")
    z = p[:, 2].astype(np.float64)
    if (z <= 0).any():
        raise InputError("xyz", "points must lie in front of the photo's camera (z > 0)")
    return (z / focal_from_fov(check_fov(fov_y_deg, "fov_y_deg"), int(image_height))).astype(np.float32)


def _points(xyz: np.ndarray) -> np.ndarray:
    if not isinstance(xyz, np.ndarray) or xyz.ndim != 2 or xyz.shape[1] != 3:
        raise InputError("xyz", f"expected an (N, 3) array, got {getattr(xyz, 'shape', type(xyz).__name__)}")
    if xyz.shape[0] == 0:
        raise InputError("xyz", "the point cloud is empty")
    if not np.isfinite(xyz).all():
        raise InputError("xyz", "contains NaN or infinite values")
    return xyz


def _per_point(value, name: str, n: int, low: float, high: float) -> np.ndarray:
    a = np.broadcast_to(np.asarray(value, dtype=np.float64), (n,)) if np.ndim(value) == 0 else np.asarray(value)
    if a.shape != (n,):
        raise InputError(name, f"expected one value per point, shape ({n},), got {a.shape}")
    if not np.isfinite(a).all() or a.min() < low or a.max() > high:
        raise InputError(name, f"values must be finite and in [{low:g}, {high:g}]")
    return a.astype(np.float64)


def write_splat_ply(path: PathLike, xyz: np.ndarray, rgb: np.ndarray, footprint: np.ndarray, *,
                    scale_factor: float = 0.6, opacity=0.99) -> Path:
    """Write isotropic Gaussians as a 3DGS ``.ply`` (layout in the module docstring), atomically.

    Args:
        path: destination ``*.ply``.
        xyz: (N, 3) finite centres.
        rgb: (N, 3) float colours in [0, 1].
        footprint: (N,) point footprints (:func:`point_footprints`), > 0.
        scale_factor: standard deviation of each Gaussian in footprints, in (0, 10].
        opacity: one opacity in (0, 1] for every point, or (N,) of them.
    Returns:
        The destination path.
    """
    dest = Path(path)
    if dest.suffix.lower() != ".ply":
        raise InputError(dest, "a Gaussian splat file must end in .ply")
    p = _points(xyz)
    n = p.shape[0]
    if not isinstance(rgb, np.ndarray) or rgb.shape != (n, 3) or not np.issubdtype(rgb.dtype, np.floating):
        raise InputError("rgb", f"expected ({n}, 3) float colours in [0, 1]")
    if not np.isfinite(rgb).all():
        raise InputError("rgb", "contains NaN or infinite values")
    fp = _per_point(footprint, "footprint", n, 0.0, math.inf)
    if (fp <= 0).any():
        raise InputError("footprint", "every footprint must be > 0")
    check_range(scale_factor, "scale_factor", 0.0, 10.0)
    if scale_factor <= 0:
        raise InputError("scale_factor", "must be > 0")
    alpha = np.clip(_per_point(opacity, "opacity", n, 1e-6, 1.0), 1.0 - MAX_OPACITY, MAX_OPACITY)
    rec = np.zeros(n, dtype=np.dtype([(name, "<f4") for name in SPLAT_PROPERTIES]))
    rec["x"], rec["y"], rec["z"] = p[:, 0], p[:, 1], p[:, 2]
    dc = (np.clip(rgb.astype(np.float64), 0.0, 1.0) - 0.5) / SH_C0  # (N, 3)
    rec["f_dc_0"], rec["f_dc_1"], rec["f_dc_2"] = dc[:, 0], dc[:, 1], dc[:, 2]
    rec["opacity"] = np.log(alpha / (1.0 - alpha))
    log_scale = np.log(fp * float(scale_factor))
    rec["scale_0"] = rec["scale_1"] = rec["scale_2"] = log_scale
    rec["rot_0"] = 1.0  # identity rotation (w, x, y, z); isotropic Gaussians need no other
    header = ["ply", "format binary_little_endian 1.0", "comment stylize3d 3D Gaussian splat (SH degree 0)",
              f"element vertex {n}", *(f"property float {name}" for name in SPLAT_PROPERTIES), "end_header"]
    head = ("\n".join(header) + "\n").encode("ascii")
    body = rec.tobytes()

    def verify(tmp: Path) -> None:  # the whole file reads back, every Gaussian
        try:
            got = len(read_vertex_properties(tmp)["x"])
        except InputError as e:
            raise ExportError(f"{dest}: the written splat file does not read back ({e.problem})") from e
        if got != n:
            raise ExportError(f"{dest}: the written splat file reads back {got} of {n} Gaussians")

    write_atomically(dest, "Gaussian splat file", lambda tmp: tmp.write_bytes(head + body),
                     verify=verify, size=len(head) + len(body))
    return dest


def read_vertex_properties(path: PathLike) -> Dict[str, np.ndarray]:
    """Every vertex property of a binary little-endian PLY whose only element is ``vertex``,
    as ``{name: (N,) array}`` (enough to check a splat file; not a general PLY reader)."""
    src = Path(path)
    data = read_input_file(src, "PLY")
    end = data.find(b"end_header\n", 0, 64 * 1024)
    if not data.startswith(b"ply\n") or end < 0:
        raise InputError(src, "not a PLY file with a header ending in 'end_header'")
    lines = data[:end].decode("ascii", errors="replace").splitlines()[1:]
    types = {"float": "<f4", "double": "<f8", "uchar": "u1", "int": "<i4", "uint": "<u4"}
    fields = []
    count: Optional[int] = None
    for line in lines:
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format" and words[1:2] != ["binary_little_endian"]:
            raise InputError(src, f"expected a binary little-endian PLY, got {line!r}")
        if words[0] == "element":
            if count is not None or len(words) != 3 or words[1] != "vertex" or not words[2].isdigit():
                raise InputError(src, f"expected one 'element vertex N', got {line!r}")
            count = int(words[2])
        elif words[0] == "property":
            if len(words) != 3 or words[1] not in types:
                raise InputError(src, f"unsupported PLY property {line!r}")
            fields.append((words[2], types[words[1]]))
    if count is None or not fields:
        raise InputError(src, "the PLY header declares no vertices")
    dtype = np.dtype(fields)
    body = data[end + len(b"end_header\n"):]
    if len(body) != count * dtype.itemsize:
        raise InputError(src, f"expected {count} vertices of {dtype.itemsize} bytes, the file holds {len(body)} bytes")
    rec = np.frombuffer(body, dtype=dtype, count=count)
    return {name: rec[name].copy() for name, _ in fields}


def read_splat_ply(path: PathLike) -> SplatCloud:
    """Read a 3DGS ``.ply`` (written by :func:`write_splat_ply` or any 3DGS tool) and decode its fields."""
    props = read_vertex_properties(path)
    missing = [name for name in SPLAT_PROPERTIES if name not in props and not name.startswith("n")]
    if missing:
        raise InputError(path, f"not a Gaussian splat file: missing {', '.join(missing)}")

    def stack(*names: str) -> np.ndarray:
        return np.stack([props[n] for n in names], axis=1).astype(np.float32)

    xyz = stack("x", "y", "z")
    rgb = np.clip(0.5 + SH_C0 * stack("f_dc_0", "f_dc_1", "f_dc_2"), 0.0, 1.0)
    opacity = (1.0 / (1.0 + np.exp(-props["opacity"].astype(np.float64)))).astype(np.float32)
    scale = np.exp(stack("scale_0", "scale_1", "scale_2"))
    rot = stack("rot_0", "rot_1", "rot_2", "rot_3")
    norm = np.linalg.norm(rot, axis=1, keepdims=True)
    rot = rot / np.where(norm > 0, norm, 1.0)
    return SplatCloud(xyz, rgb.astype(np.float32), opacity, scale.astype(np.float32), rot)
