"""Stereo renders for VR headsets and 3D viewing: two eyes per camera.

Each camera of a path becomes two: the left eye moved by ``-eye_distance / 2``
along the camera's own x axis (right in the image, geometry/camera.py), the right
eye by ``+eye_distance / 2``; both keep the camera's orientation and FOV
(parallel eyes, as VR players expect). ``eye_distance`` is in scene units,
where the nearest surface of the photo is about ``NEAR_DEPTH`` = 1/3 away; the
default 0.01 (1/33 of that: the stereographers' 1/30 rule) gives a comfortable
depth.

Layouts of one stereo frame, from the left view L and right view R, each (H, W):

* ``sbs``, full width: ``[L | R]``, (H, 2W): for VR players and 3D TVs in "full SBS";
* ``sbs``, half width: L and R each squeezed to (H, W/2), side by side, (H, W):
  "half SBS", the frame size of the mono video;
* ``anaglyph``: red-cyan colour anaglyph, (H, W): red from L, green and blue from R,
  for red (left) / cyan (right) glasses.

An eye distance so large that an eye would pass beside or into the nearest
surface is refused (:func:`check_eye_distance`).
"""

from __future__ import annotations

from typing import Iterator, Literal, Tuple

import cv2
import numpy as np
import torch

from ..errors import InputError
from ..geometry.camera import Cameras, project, transform_points
from .bake import RenderFn

StereoLayout = Literal["full", "half"]
MAX_EYE_RATIO = 0.5
"""The eyes may be at most this fraction of the nearest surface's depth apart (in every frame)."""


def _check_eye_distance_value(eye_distance: float) -> float:
    e = float(eye_distance)
    if not np.isfinite(e) or e <= 0:
        raise InputError("eye_distance", f"must be a finite number > 0, got {eye_distance!r}")
    return e


def _check_views(left: np.ndarray, right: np.ndarray) -> None:
    if left.shape != right.shape or left.ndim != 3 or left.shape[2] != 3:
        raise InputError("stereo views", f"the two views differ or are not (H, W, 3): {left.shape}, {right.shape}")


def eye_cameras(cameras: Cameras, eye_distance: float) -> Tuple[Cameras, Cameras]:
    """(left eyes, right eyes) of ``cameras``: each moved by -/+ ``eye_distance / 2`` along its own x axis."""
    if not isinstance(cameras, Cameras) or len(cameras) == 0:
        raise InputError("cameras", "expected at least one camera")
    e = _check_eye_distance_value(eye_distance)
    c2w = cameras.cam_to_world.to(torch.float64)
    shift = c2w[:, :3, 0] * (e / 2.0)  # (B, 3): the camera's x axis in the world
    left, right = c2w.clone(), c2w.clone()
    left[:, :3, 3] -= shift
    right[:, :3, 3] += shift
    return Cameras(left, cameras.fov_y_deg.clone()), Cameras(right, cameras.fov_y_deg.clone())


def nearest_depths(points: np.ndarray, cameras: Cameras, size: Tuple[int, int]) -> np.ndarray:
    """(B,) depth of the nearest point (the 0.1th percentile, robust to strays) each camera sees at ``size``."""
    pts = torch.from_numpy(np.ascontiguousarray(points, dtype=np.float64))
    h, w = size
    out = np.empty(len(cameras))
    K = cameras.intrinsics(h, w, dtype=torch.float64)
    w2c = cameras.world_to_cam()
    for i in range(len(cameras)):
        pc = transform_points(w2c[i], pts)
        uv, z = project(pc, K[i])
        inside = (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
        zs = z[inside].numpy()
        out[i] = np.percentile(zs, 0.1) if zs.size else np.inf
    return out


def check_eye_distance(eye_distance: float, points: np.ndarray, cameras: Cameras, size: Tuple[int, int]) -> float:
    """``eye_distance`` if every frame's nearest visible surface is at least ``eye_distance / MAX_EYE_RATIO``
    away, else an :class:`InputError` naming ``eye_distance`` with the largest distance that fits."""
    e = _check_eye_distance_value(eye_distance)
    near = nearest_depths(points, cameras, size)
    if not np.isfinite(near).any():
        raise InputError("cameras", "no camera of the path sees the scene")
    i = int(np.argmin(near))
    if near[i] <= 0 or e > MAX_EYE_RATIO * near[i]:
        raise InputError(
            "eye_distance",
            f"{e:g} would put an eye beside or inside the scene: the nearest surface is {near[i]:.3g} scene "
            f"units from camera {i}; use at most {MAX_EYE_RATIO * max(near[i], 0):.3g}")
    return e


def side_by_side(left: np.ndarray, right: np.ndarray, layout: StereoLayout = "full") -> np.ndarray:
    """One side-by-side frame of two (H, W, 3) views: (H, 2W, 3) full width, or (H, W, 3) half width
    (each view squeezed to W // 2 and W - W // 2 columns)."""
    _check_views(left, right)
    if layout == "full":
        return np.concatenate([left, right], axis=1)
    if layout != "half":
        raise InputError("stereo_layout", f"must be 'full' or 'half', got {layout!r}")
    h, w = left.shape[:2]
    if w < 2:
        raise InputError("stereo views", "half-width side by side needs views at least 2 pixels wide")
    wl, wr = w // 2, w - w // 2
    squeeze = [cv2.resize(np.ascontiguousarray(v, dtype=np.float32), (ww, h), interpolation=cv2.INTER_AREA)
               for v, ww in ((left, wl), (right, wr))]
    return np.concatenate(squeeze, axis=1)


def anaglyph(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """Red-cyan colour anaglyph (H, W, 3) of two (H, W, 3) views: red from ``left``, green and blue from ``right``."""
    _check_views(left, right)
    out = np.array(right, dtype=np.float32, copy=True)
    out[..., 0] = left[..., 0]
    return out


def stereo_frames(render: RenderFn, cameras: Cameras, height: int, width: int, eye_distance: float,
                  kind: Literal["sbs", "anaglyph"], layout: StereoLayout = "full") -> Iterator[np.ndarray]:
    """Lazily render one stereo frame per camera (``kind`` "sbs" in ``layout``, or "anaglyph")."""
    if kind not in ("sbs", "anaglyph"):
        raise InputError("export", f"stereo frames are 'sbs' or 'anaglyph', got {kind!r}")
    lefts, rights = eye_cameras(cameras, eye_distance)
    for i in range(len(cameras)):
        lv, rv = render(lefts[i], height, width), render(rights[i], height, width)
        yield side_by_side(lv, rv, layout) if kind == "sbs" else anaglyph(lv, rv)
