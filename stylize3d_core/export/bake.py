"""Bake the colours of rendered views onto the points of a 3D photo.

The stylized model has no per-point colour: its U-Net decodes rasterized
features into images. To export a stylized point cloud (PLY for Blender and
MeshLab, a Gaussian splat file) each point takes the colour of the rendered
views at its projection, from the first view in which it is visible
(:func:`stylize3d_core.render.reproject.sample_view`: inside the image, in front
of the camera and on the view's front surface). The first view is the photo's
own camera, so what the photo shows gets the colours of the photo's view;
points it hides (the hidden layer behind foreground edges) get theirs from the
side views of :func:`bake_cameras`, and points that no view sees take the
colour of the nearest point that was seen.
"""

from __future__ import annotations

from typing import Callable, NamedTuple, Tuple

import numpy as np
import torch

from ..checks import check_range
from ..errors import InputError
from ..geometry.camera import Cameras
from ..points.neighbours import knn
from ..render.rasterize import RasterSettings
from ..render.rasterizer import PointRasterizer
from ..render.reproject import sample_view

RenderFn = Callable[[Cameras, int, int], np.ndarray]
"""``render(camera, H, W) -> (H, W, 3)`` float32 in [0, 1] (``Stylized3DPhoto.render``, ``PlainRenderer.render``)."""


class BakedColours(NamedTuple):
    """Result of :func:`bake_colours`.

    Attributes:
        rgb: (N, 3) float32 colours in [0, 1].
        seen: (N,) bool, True where a view saw the point (the others copy their nearest seen point).
        view: (N,) int16 index of the view each point's colour came from (-1: copied).
    """

    rgb: np.ndarray
    seen: np.ndarray
    view: np.ndarray


def bake_cameras(fov_y_deg: float, n_side: int = 6, radius: float = 0.04) -> Cameras:
    """The photo's camera followed by ``n_side`` cameras on a circle of ``radius`` (scene units) around it,
    all looking along +z: side views see behind the foreground edges."""
    check_range(radius, "radius", 0.0, 1.0)
    if int(n_side) != n_side or n_side < 0:
        raise InputError("n_side", f"must be an integer >= 0, got {n_side!r}")
    poses = np.tile(np.eye(4), (int(n_side) + 1, 1, 1))
    angles = 2 * np.pi * np.arange(n_side) / max(1, n_side)
    poses[1:, 0, 3] = radius * np.cos(angles)
    poses[1:, 1, 3] = radius * np.sin(angles)
    return Cameras.create(poses, fov_y_deg)


def bake_colours(xyz: np.ndarray, render: RenderFn, cameras: Cameras, size: Tuple[int, int], *,
                 depth_tolerance: float = 0.02) -> BakedColours:
    """Colour every point ``xyz`` (N, 3) with the views ``render`` draws from ``cameras`` at ``size`` (H, W)
    (see the module docstring)."""
    if not isinstance(xyz, np.ndarray) or xyz.ndim != 2 or xyz.shape[1] != 3 or len(xyz) == 0:
        raise InputError("xyz", f"expected a non-empty (N, 3) array, got {getattr(xyz, 'shape', None)}")
    if not isinstance(cameras, Cameras) or len(cameras) == 0:
        raise InputError("cameras", "expected at least one camera")
    h, w = (int(v) for v in size)
    points = torch.from_numpy(np.ascontiguousarray(xyz, dtype=np.float32))
    n = points.shape[0]
    rgb = torch.zeros(n, 3)
    view = torch.full((n,), -1, dtype=torch.int16)
    rasterizer = PointRasterizer(RasterSettings(height=h, width=w, depth_tolerance=depth_tolerance))
    ones = torch.ones(n, 1)
    with torch.inference_mode():
        for i in range(len(cameras)):
            cam = cameras[i]
            image = render(cam, h, w)
            if image.shape != (h, w, 3) or not np.isfinite(image).all():
                raise InputError("render", f"view {i} is not a finite ({h}, {w}, 3) image")
            zbuffer = rasterizer(points, ones, cam).depth  # (H, W), +inf at holes
            samples = sample_view(points, torch.from_numpy(np.ascontiguousarray(image)).permute(2, 0, 1),
                                  zbuffer, cam, depth_tolerance)
            new = samples.visible & (view < 0)
            rgb[new] = samples.colour[new]
            view[new] = i
    seen = view >= 0
    if not bool(seen.any()):
        raise InputError("cameras", "no view sees any point; bake from cameras that look at the scene")
    if not bool(seen.all()):
        nearest = knn(points[seen], points[~seen], 1).idx[:, 0]  # (M,)
        rgb[~seen] = rgb[seen][nearest]
    return BakedColours(rgb.clamp_(0.0, 1.0).numpy(), seen.numpy(), view.numpy())
