"""Render a plain (unstylized) 3D photo: rasterize point colours, fill pinholes.

The stylized path decodes rasterized features with the model's U-Net instead;
this path shows the photo's own colours and is the baseline the stylization is
compared with.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator, Tuple

import numpy as np
import torch

from ..checks import check_range
from ..errors import InputError
from ..geometry.camera import Cameras
from ..scene.pointcloud import PointCloud
from .holes import fill_holes
from .rasterize import RasterSettings
from .rasterizer import PointRasterizer


@dataclass(frozen=True)
class PlainRenderSettings:
    """Options of :class:`PlainRenderer`.

    Attributes:
        supersample: 1 (default) or 2. 2 rasterizes at twice the size and
            averages down: smoother when the camera moves away (minification),
            but magnified surfaces leave pinholes that the hole filling blurs, so
            1 is the better default for the short camera moves of a 3D photo.
        depth_tolerance: relative depth band of the front surface (see RasterSettings).
    """

    supersample: int = 1
    depth_tolerance: float = 0.02

    def __post_init__(self) -> None:
        if self.supersample not in (1, 2):
            raise InputError("supersample", f"must be 1 or 2, got {self.supersample!r}")
        check_range(self.depth_tolerance, "depth_tolerance", 0.0, 1.0)


def frame_size(photo_size: Tuple[int, int], long_side: int, *, even: bool = True) -> Tuple[int, int]:
    """(H, W) of output frames whose long side is ``long_side`` and aspect is the photo's.

    With ``even`` (default) both sides are rounded to even numbers, as H.264 in
    yuv420p needs.
    """
    if int(long_side) != long_side or not 16 <= long_side <= 8192:
        raise InputError("size", f"must be an integer from 16 to 8192, got {long_side!r}")
    h, w = photo_size
    scale = long_side / max(h, w)
    step = 2 if even else 1
    H = max(step, int(round(h * scale / step)) * step)
    W = max(step, int(round(w * scale / step)) * step)
    return H, W


class PlainRenderer:
    """Renders a point cloud's colours from any camera. Holds the points as tensors.

    Runs on whatever thread calls it (torch releases the GIL in its kernels).
    """

    def __init__(self, points: PointCloud, settings: PlainRenderSettings = PlainRenderSettings()) -> None:
        t = points.to_tensors()
        self._xyz = t.xyz  # (N, 3)
        self._rgb = t.rgb  # (N, 3)
        self.settings = settings

    def render(self, camera: Cameras, height: int, width: int) -> np.ndarray:
        """One frame (H, W, 3) float32 in [0, 1] seen by the single camera ``camera``."""
        raster = RasterSettings(
            height=int(height), width=int(width),
            depth_tolerance=self.settings.depth_tolerance, supersample=self.settings.supersample,
        )
        with torch.inference_mode():
            frags = PointRasterizer(raster)(self._xyz, self._rgb, camera)
            image = fill_holes(frags.image, frags.hole).clamp_(0.0, 1.0)  # (3, H, W), never NaN
        return image.permute(1, 2, 0).contiguous().numpy()

    def frames(self, cameras: Cameras, height: int, width: int) -> Iterator[np.ndarray]:
        """Lazily render one frame per camera (for streaming into a video writer)."""
        for i in range(len(cameras)):
            yield self.render(cameras[i], height, width)
