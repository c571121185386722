"""``PointRasterizer``: a thin module over :func:`~stylize3d_core.render.rasterize.rasterize_points`.

It takes world points and one camera (conventions in
:mod:`stylize3d_core.geometry.camera`), moves the points into the camera frame
with ``Cameras.world_to_cam()``, builds ``K`` with ``Cameras.intrinsics(H, W)``
and rasterizes.
"""

from __future__ import annotations

from typing import Callable, Optional, Tuple

import torch
from torch import nn

from ..checks import check_shape
from ..errors import InputError
from ..geometry.camera import Cameras, transform_points
from .rasterize import Fragments, RasterSettings, rasterize_points


class PointRasterizer(nn.Module):
    """Rasterize a featurized point cloud seen by one camera.

    Args:
        settings: image size and rasterization options (no parameters to learn).
    """

    def __init__(self, settings: RasterSettings) -> None:
        super().__init__()
        if not isinstance(settings, RasterSettings):
            raise InputError("settings", f"expected RasterSettings, got {type(settings).__name__}")
        self.settings = settings

    def forward(self, points_world: torch.Tensor, features: torch.Tensor, cameras: Cameras,
                point_size: Optional[torch.Tensor] = None, *,
                should_stop: Optional[Callable[[], bool]] = None,
                frame: Optional[Tuple[int, int]] = None) -> Fragments:
        """Render ``features`` at ``points_world`` from the single camera in ``cameras``.

        Args:
            points_world: (N, 3) floating points in world coordinates.
            features: (N, C) float32/float64 features (gradients flow to them).
            cameras: a :class:`Cameras` batch of exactly one camera.
            point_size: optional (N,) footprint of each point in scene units (its splat
                grows with magnification, see :func:`rasterize_points`).
            should_stop: checked between chunks of points (see :func:`rasterize_points`);
                True stops with :class:`~stylize3d_core.errors.RenderInterrupted`.
            frame: (H, W) of the frame this raster stands for (None: the raster's own size). The
                intrinsics are the camera's at (H, W), scaled to the raster's size per axis, so the
                raster covers exactly the frame's extent: a (h, w) raster upsampled bilinearly
                (``align_corners=False``) lines up with the (H, W) one (split-resolution decoding).
        Returns:
            :class:`Fragments` ``image (C, H, W), weight (H, W), depth (H, W), hole (H, W)``.
        """
        if not isinstance(cameras, Cameras):
            raise InputError("cameras", f"expected Cameras, got {type(cameras).__name__}")
        if len(cameras) != 1:
            raise InputError("cameras", f"expected a batch of one camera, got {len(cameras)}")
        if not isinstance(points_world, torch.Tensor) or not points_world.is_floating_point():
            raise InputError("points_world", "expected a floating-point torch.Tensor")
        check_shape(points_world, "points_world", (None, 3))
        dtype, device = points_world.dtype, points_world.device
        world_to_cam = cameras.world_to_cam()[0].to(device=device, dtype=dtype)  # (4, 4)
        points_cam = transform_points(world_to_cam, points_world.detach())  # (N, 3)
        h, w = self.settings.height, self.settings.width
        if frame is None or tuple(frame) == (h, w):
            K = cameras.intrinsics(h, w, dtype=dtype)[0].to(device)  # (3, 3)
        else:
            fh, fw = (int(v) for v in frame)
            if fh < 1 or fw < 1:
                raise InputError("frame", f"must be a positive (height, width), got {tuple(frame)!r}")
            K = cameras.intrinsics(fh, fw, dtype=dtype)[0].clone()
            K[0] *= w / fw  # fx, cx
            K[1] *= h / fh  # fy, cy
            K = K.to(device)
        return rasterize_points(points_cam, features, K, self.settings, point_size, should_stop=should_stop)

    def extra_repr(self) -> str:
        return repr(self.settings)
