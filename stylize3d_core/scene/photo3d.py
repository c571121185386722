"""A 3D photo: one photo and its depth turned into a layered, coloured point cloud.

This is everything about a photo that does not depend on the camera or the
style: built once, then rendered from any camera (plain here; stylized by the
model in :mod:`stylize3d_core.models`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Dict, Optional

import numpy as np

from ..checks import check_shape
from ..depth.types import DepthMap
from ..errors import InputError
from ..geometry.camera import DEFAULT_FOV_Y_DEG, check_fov
from ..geometry.camera_range import CameraRange
from .ldi import LDI, LDISettings, build_ldi
from .pointcloud import PointCloud, ldi_to_points


@dataclass(frozen=True)
class Photo3DSettings:
    """How a photo becomes a 3D photo.

    Attributes:
        fov_y_deg: vertical field of view of the photo's camera in degrees; None
            means "from the photo's EXIF focal length if present, else 60" (the
            caller resolves it; :meth:`Photo3D.build` takes None as 60).
        ldi: tearing, hidden-layer and border settings (see :class:`LDISettings`).
    """

    fov_y_deg: Optional[float] = None
    ldi: LDISettings = field(default_factory=LDISettings)

    def __post_init__(self) -> None:
        if self.fov_y_deg is not None:
            check_fov(self.fov_y_deg, "fov_y_deg")


@dataclass(frozen=True)
class Photo3D:
    """A photo lifted to 3D.

    Attributes:
        rgb: (H, W, 3) float32 photo in [0, 1].
        depth: the depth it was built from (aligned with ``rgb``).
        ldi: the layered depth image (scene units, see ``geometry/camera.py``).
        points: one coloured, labelled point per LDI pixel, in world coordinates.
        fov_y_deg: vertical FOV of the photo's camera (world = that camera's frame).
        timings: seconds spent per stage ("ldi", "points").
    """

    rgb: np.ndarray
    depth: DepthMap
    ldi: LDI
    points: PointCloud
    fov_y_deg: float
    timings: Dict[str, float]

    @property
    def size(self) -> tuple:
        """(H, W) of the photo."""
        return self.rgb.shape[:2]

    @property
    def camera_range(self) -> CameraRange:
        """The part of ``settings.ldi.camera_range`` this 3D photo shows without holes
        (``ldi.camera_range``): the viewer's limits for it (``OrbitLimits.from_range``)."""
        return self.ldi.camera_range

    @staticmethod
    def build(rgb: np.ndarray, depth: DepthMap, settings: Photo3DSettings = Photo3DSettings()) -> "Photo3D":
        """Build the LDI and the point cloud of ``rgb`` (H, W, 3) with ``depth`` (H, W)."""
        check_shape(rgb, "photo", (None, None, 3))
        if not isinstance(depth, DepthMap):
            raise InputError("depth", f"expected a DepthMap, got {type(depth).__name__}")
        if depth.shape != rgb.shape[:2]:
            raise InputError(depth.source, f"depth is {depth.shape} but the photo is {rgb.shape[:2]}")
        fov = DEFAULT_FOV_Y_DEG if settings.fov_y_deg is None else settings.fov_y_deg
        t0 = time.perf_counter()
        ldi = build_ldi(rgb, depth, settings.ldi, fov)
        t1 = time.perf_counter()
        points = ldi_to_points(ldi, fov)
        t2 = time.perf_counter()
        return Photo3D(rgb, depth, ldi, points, fov, {"ldi": t1 - t0, "points": t2 - t1})
