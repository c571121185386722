"""Multi-view input measured on a procedural scene rendered from known poses (paper Sec. 4.4).

:func:`procedural_views` ray-casts a random textured scene (``train/procedural.py``)
from a few poses, with exact colour and depth per view, plus a held-out pose.
:func:`held_out_psnr` renders the held-out pose from the merged cloud
(:func:`~stylize3d_core.scene.multiview.merge_views`) and from each view's own
3D photo, and compares them with the true image: merging views should beat
every single view, since each view sees what the others hide.

:func:`observed_mask` marks the held-out pixels that at least one input view's
photo sees; with ``observed_only`` the PSNR is taken over those pixels. The rest
(e.g. below every input frame when the held-out camera is lowered) shows only
some view's invented border or the hole filling, a guess that merging cannot
inform: there a single view whose border happens to extrapolate more smoothly
can win by luck (seed 5: 19 % of the image, 0.4 dB of the full-image score).
"""

from __future__ import annotations

import math
from typing import Dict, List, NamedTuple, Sequence, Tuple

import numpy as np

from ..depth.types import DepthMap
from ..geometry.camera import Cameras
from ..render.plain import PlainRenderer
from ..scene.multiview import View, merge_views, pose_in_view
from ..scene.ldi import ORIGINAL
from ..scene.photo3d import Photo3D, Photo3DSettings
from ..scene.pointcloud import PointCloud
from ..train.procedural import random_scene, ray_cast
from ..train.textures import random_texture
from .metrics import psnr


class ProceduralViews(NamedTuple):
    """Views of a procedural scene and a held-out view (true image, pose)."""

    views: List[View]
    held_out_pose: np.ndarray
    held_out_rgb: np.ndarray


def look_pose(x: float, y: float = 0.0, yaw: float = 0.0) -> np.ndarray:
    """(4, 4) camera at (x, y, 0) turned by ``yaw`` radians about the y axis (positive: to the right)."""
    T = np.eye(4)
    c, s = math.cos(yaw), math.sin(yaw)
    T[:3, :3] = [[c, 0, s], [0, 1, 0], [-s, 0, c]]
    T[:3, 3] = [x, y, 0.0]
    return T


DEFAULT_POSES = (look_pose(0.0), look_pose(-0.25, 0.0, 0.08), look_pose(0.25, 0.0, -0.08))
DEFAULT_HELD_OUT = look_pose(0.15, 0.08, -0.04)


def procedural_views(seed: int = 3, size: Tuple[int, int] = (96, 128), fov_y_deg: float = 55.0,
                     poses: Sequence[np.ndarray] = DEFAULT_POSES,
                     held_out: np.ndarray = DEFAULT_HELD_OUT) -> ProceduralViews:
    """Ray-cast one random scene from ``poses`` (views with exact metric depth) and from ``held_out``."""
    rng = np.random.default_rng(seed)
    textures = [random_texture(rng, (128, 128))[1] for _ in range(6)]
    h, w = size
    scene = random_scene(rng, textures, fov_y_deg, w / h)
    views = []
    for i, pose in enumerate(poses):
        r = ray_cast(scene, Cameras.create(pose, fov_y_deg), h, w, samples=2)
        far = float(r.depth[r.hit].max()) if r.hit.any() else 1.0
        depth = np.where(r.hit, r.depth, far).astype(np.float32)
        views.append(View(r.rgb, DepthMap(depth, r.hit, "metric", f"ray cast {i}"), np.asarray(pose, np.float64),
                          fov_y_deg, f"view{i}.png"))
    truth = ray_cast(scene, Cameras.create(held_out, fov_y_deg), h, w, samples=2).rgb
    return ProceduralViews(views, np.asarray(held_out, np.float64), truth)


def _single_photos(data: ProceduralViews) -> List[Photo3D]:
    return [Photo3D.build(v.rgb, v.depth, Photo3DSettings(fov_y_deg=v.fov_y_deg)) for v in data.views]


def _held_out_camera(data: ProceduralViews, view: View, photo: Photo3D) -> Cameras:
    return Cameras.create(pose_in_view(data.held_out_pose, view, photo.ldi.depth_scale), view.fov_y_deg)


def observed_mask(data: ProceduralViews, singles: Sequence[Photo3D] = ()) -> np.ndarray:
    """(H, W) bool: held-out pixels that at least one input view's photo sees (its visible points, rasterized
    at the held-out pose, leave no hole there). Independent of the merge."""
    h, w = data.held_out_rgb.shape[:2]
    singles = list(singles) or _single_photos(data)
    seen = np.zeros((h, w), bool)
    for v, p in zip(data.views, singles):
        vis = p.points.label == ORIGINAL
        real = PointCloud(p.points.xyz[vis], p.points.rgb[vis], p.points.label[vis], p.points.image_size,
                          p.points.fov_y_deg)
        seen |= ~PlainRenderer(real).rasterize(_held_out_camera(data, v, p), h, w).hole.numpy()
    return seen


def held_out_psnr(data: ProceduralViews, centre: int = 0, *, observed_only: bool = False) -> Dict[str, float]:
    """PSNR of the held-out view rendered from the merged cloud ("merged") and from each view alone ("view i");
    over the whole image, or with ``observed_only`` over :func:`observed_mask`."""
    h, w = data.held_out_rgb.shape[:2]
    merged = merge_views(data.views, centre).photo
    singles = _single_photos(data)
    mask = observed_mask(data, singles) if observed_only else np.ones((h, w), bool)

    def score(image: np.ndarray) -> float:
        return psnr(image[mask], data.held_out_rgb[mask])

    out = {"merged": score(PlainRenderer(merged.points).render(_held_out_camera(data, data.views[centre], merged),
                                                               h, w))}
    for i, (v, single) in enumerate(zip(data.views, singles)):
        out[f"view {i}"] = score(PlainRenderer(single.points).render(_held_out_camera(data, v, single), h, w))
    return out
