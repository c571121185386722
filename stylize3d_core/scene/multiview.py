"""Several photos of one scene, with depth and camera poses, merged into one 3D photo (paper Sec. 4.4).

Each view is turned into its own layered depth image and point cloud
(:meth:`Photo3D.build`: tears, hidden layer), in that view's scene units. The
views' depths must share one unit (metric depth files, or depth in the units of
the poses): a view's points are taken back to those units (divided by its
``ldi.depth_scale``), moved into the world by its ``cam_to_world``, then into
the frame of the **centre view** and scaled by the centre view's
``depth_scale``. The result follows the conventions of a single 3D photo
(``geometry/camera.py``): the world frame is the centre view's camera and its
nearest surface is about ``NEAR_DEPTH`` away, so the encoder's NDC is the
centre view's and the model renders it with no retraining.

**Invented points** (hidden layers, borders) give way to better evidence: a
view's invented point is dropped where another view's canvas reaches it with a
shorter extrapolation (:func:`_covered_by`: its photo, i.e. a real observation,
beats any invented point; a hidden layer, next to what its view saw, beats a
border; a border pixel fewer pixels outside its photo beats one farther out),
unless it lies behind that view's surface (which may hide it). So no view's
invented background covers a surface another view saw, and outside every
photo the border of the view that extrapolated least is kept.

**Thinning** where views overlap: points are kept in priority order -- the
centre view's visible points, the other views' visible points, the hidden
layers, the centre view's border, the other views' borders -- and a point is
dropped when its cell is already taken. Cells are one centre-view pixel by one depth band
(``thin_depth`` relative), in the centre camera's (u, v, log z), so a surface
seen by several views keeps about one point per pixel of the centre view;
surfaces the centre view does not see (behind its foreground, outside its
frame) keep every view's points. Points behind the centre camera are dropped.

**Pose check** (:func:`pose_agreement`): the visible points of each other view,
projected into the centre view, must mostly land on the centre view's surface
with its colour; a pose that does not belong to its image fails that.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import List, NamedTuple, Sequence

import numpy as np

from ..depth.types import DepthMap
from ..errors import InputError
from ..geometry.camera import NEAR_DEPTH, check_fov, focal_from_fov
from .ldi import BORDER, INPAINTED, ORIGINAL
from .photo3d import Photo3D, Photo3DSettings
from .pointcloud import PointCloud

MIN_AGREEMENT = 0.75
"""Least fraction of a view's points, of those that fall inside the centre view, that must agree with it."""


@dataclass(frozen=True)
class View:
    """One input view.

    Attributes:
        rgb: (H, W, 3) float32 photo in [0, 1].
        depth: its depth, in the unit shared by every view (and the poses' translations).
        cam_to_world: (4, 4) float64 rigid pose of the view's camera.
        fov_y_deg: its vertical field of view.
        name: how errors and logs refer to it (the image file).
    """

    rgb: np.ndarray
    depth: DepthMap
    cam_to_world: np.ndarray
    fov_y_deg: float
    name: str

    def __post_init__(self) -> None:
        check_fov(self.fov_y_deg, f"{self.name}: fov_y_deg")
        T = np.asarray(self.cam_to_world, np.float64)
        if T.shape != (4, 4) or not np.isfinite(T).all():
            raise InputError(self.name, "cam_to_world must be a finite 4x4 matrix")
        R = T[:3, :3]
        if np.abs(R.T @ R - np.eye(3)).max() > 1e-4 or abs(np.linalg.det(R) - 1) > 1e-4 \
                or np.abs(T[3] - [0, 0, 0, 1]).max() > 1e-9:
            raise InputError(self.name, "cam_to_world is not a rigid transform (rotation and translation)")
        if self.depth.shape != self.rgb.shape[:2]:
            raise InputError(self.name, f"depth is {self.depth.shape} but the image is {self.rgb.shape[:2]}")


class MergedViews(NamedTuple):
    """Result of :func:`merge_views`.

    Attributes:
        photo: the merged 3D photo (the centre view's rgb, depth and LDI; the merged points).
        view_of_point: (N,) int16 view index of every merged point.
        kept: per view, how many of its points were kept.
        agreement: per view, the fraction of its points inside the centre view that agree with it (1 for the centre).
    """

    photo: Photo3D
    view_of_point: np.ndarray
    kept: List[int]
    agreement: List[float]


def _to_centre(p3d: Photo3D, view: View, centre_view: View, centre_scale: float) -> np.ndarray:
    """(N, 3) float64 points of one view's 3D photo in the centre view's scene frame."""
    metric = p3d.points.xyz.astype(np.float64) / p3d.ldi.depth_scale  # the view's camera frame, shared units
    T = np.linalg.inv(centre_view.cam_to_world) @ view.cam_to_world  # view camera -> centre camera
    return (metric @ T[:3, :3].T + T[:3, 3]) * centre_scale


def _project(xyz: np.ndarray, fov: float, size) -> np.ndarray:
    """(N, 3) pixel coordinates (u, v) and z of camera-frame points."""
    h, w = size
    f = focal_from_fov(fov, h)
    z = xyz[:, 2]
    safe = np.where(z > 1e-9, z, 1.0)
    return np.stack([xyz[:, 0] / safe * f + w / 2.0, xyz[:, 1] / safe * f + h / 2.0, z], axis=1)


def pose_agreement(xyz: np.ndarray, rgb: np.ndarray, centre: Photo3D, *, depth_tol: float = 0.05,
                   colour_tol: float = 0.12) -> float:
    """Fraction of the points ``xyz`` (centre frame, scene units) inside the centre view that land on its
    visible surface (depth within ``depth_tol``) with its colour (mean channel difference within ``colour_tol``)."""
    h, w = centre.size
    uvz = _project(xyz, centre.fov_y_deg, (h, w))
    inside = (uvz[:, 2] > 1e-6) & (uvz[:, 0] >= 0) & (uvz[:, 0] < w) & (uvz[:, 1] >= 0) & (uvz[:, 1] < h)
    if inside.sum() < 16:
        return 1.0  # nothing in common to compare
    col = uvz[inside, 0].astype(int)
    row = uvz[inside, 1].astype(int)
    z_c = centre.ldi.depth[centre.ldi.photo_region][row, col]
    rgb_c = centre.rgb[row, col]
    z = uvz[inside, 2]
    unoccluded = z <= z_c * (1 + depth_tol)  # a point behind the centre's surface may be hidden there
    same = (np.abs(z - z_c) <= depth_tol * z_c) & (np.abs(rgb[inside] - rgb_c).mean(axis=1) <= colour_tol)
    return float(same[unoccluded].sum() / max(1, int(unoccluded.sum())))


def _reach(u: np.ndarray, v: np.ndarray, size) -> np.ndarray:
    """(N,) how far (photo pixels) canvas positions ``(u, v)`` lie outside the photo: 0 inside, the distance
    to the photo's rectangle in its border (how far its colour and depth were extrapolated)."""
    h, w = size
    dx = np.maximum(0.0, np.maximum(-u, u - w))
    dy = np.maximum(0.0, np.maximum(-v, v - h))
    return np.hypot(dx, dy)


def _own_reach(p3d: Photo3D, label: int) -> np.ndarray:
    """(N,) extrapolation distance of the points of ``p3d`` with ``label`` (see :func:`_reach`); the hidden
    layer is invented next to what the view saw: :data:`HIDDEN_REACH`."""
    sel = p3d.points.label == label
    if label == INPAINTED:
        return np.full(int(sel.sum()), HIDDEN_REACH)
    uvz = _project(p3d.points.xyz[sel].astype(np.float64), p3d.fov_y_deg, p3d.size)
    return _reach(uvz[:, 0], uvz[:, 1], p3d.size)


HIDDEN_REACH = 0.5
"""Extrapolation distance given to hidden-layer points: more than a view's real surface (0), less than
any border pixel (>= 0.5 photo pixels outside the frame)."""


def _covered_by(xyz: np.ndarray, reach: np.ndarray, p3d: Photo3D, view: View, centre_view: View,
                centre_scale: float, depth_tol: float = 0.05) -> np.ndarray:
    """(N,) bool: invented points ``xyz`` (centre frame, scene units; extrapolated ``reach`` pixels) that
    ``view`` has better evidence for: they land on its canvas where its layer-0 surface is extrapolated less
    (its photo: real, seen) and lie in front of that surface or on it (``depth_tol``), i.e. the view would
    have shown them had they been there."""
    T = np.linalg.inv(view.cam_to_world) @ centre_view.cam_to_world  # centre camera -> view camera
    local = ((xyz / centre_scale) @ T[:3, :3].T + T[:3, 3]) * p3d.ldi.depth_scale  # the view's scene frame
    h, w = p3d.size
    pad = p3d.ldi.pad
    uvz = _project(local, view.fov_y_deg, (h, w))
    u, v = uvz[:, 0] + pad, uvz[:, 1] + pad  # canvas pixels
    hc, wc = p3d.ldi.canvas_size
    inside = (uvz[:, 2] > 1e-6) & (u >= 0) & (u < wc) & (v >= 0) & (v < hc)
    out = np.zeros(len(xyz), bool)
    col, row = u[inside].astype(int), v[inside].astype(int)
    surface = p3d.ldi.depth[row, col]
    better = _reach(col - pad + 0.5, row - pad + 0.5, (h, w)) < reach[inside]
    out[inside] = better & (uvz[inside, 2] <= surface * (1 + depth_tol))
    return out


def pose_in_view(cam_to_world: np.ndarray, view: View, depth_scale: float) -> np.ndarray:
    """(4, 4) the world pose ``cam_to_world`` in a view's scene frame (its camera, scaled by ``depth_scale``)."""
    T = np.linalg.inv(view.cam_to_world) @ np.asarray(cam_to_world, np.float64)
    T[:3, 3] *= depth_scale
    return T


def merge_views(views: Sequence[View], centre: int = 0, settings: Photo3DSettings = Photo3DSettings(), *,
                thin_depth: float = 0.03, check_poses: bool = True) -> MergedViews:
    """Merge ``views`` into one 3D photo in the frame of ``views[centre]`` (see the module docstring)."""
    if len(views) == 0:
        raise InputError("views", "no views given")
    if not 0 <= centre < len(views):
        raise InputError("centre", f"must index the {len(views)} views, got {centre}")
    t0 = time.perf_counter()
    photos = [Photo3D.build(v.rgb, v.depth, Photo3DSettings(fov_y_deg=v.fov_y_deg, ldi=settings.ldi)) for v in views]
    c = photos[centre]
    scale = c.ldi.depth_scale
    xyz = [_to_centre(p, v, views[centre], scale) for p, v in zip(photos, views)]
    agreement = []
    for i, (p, pts) in enumerate(zip(photos, xyz)):
        if i == centre:
            agreement.append(1.0)
            continue
        vis = p.points.label == ORIGINAL
        a = pose_agreement(pts[vis], p.points.rgb[vis], c)
        agreement.append(a)
        if check_poses and a < MIN_AGREEMENT:
            raise InputError(views[i].name, f"its pose does not match the images: only {a:.0%} of its points that "
                                            f"the centre view {views[centre].name} also sees agree with it "
                                            f"(at least {MIN_AGREEMENT:.0%} expected)")
    # Priority groups: (view, label) in keeping order.
    order = [(centre, ORIGINAL)] + [(i, ORIGINAL) for i in range(len(views)) if i != centre]
    order += [(centre, INPAINTED)] + [(i, INPAINTED) for i in range(len(views)) if i != centre] + [(centre, BORDER)]
    order += [(i, BORDER) for i in range(len(views)) if i != centre]
    taken: set = set()
    keep_xyz, keep_rgb, keep_label, keep_view = [], [], [], []
    kept = [0] * len(views)
    log_step = math.log1p(thin_depth)
    for i, label in order:
        sel = photos[i].points.label == label
        pts = xyz[i][sel]
        ahead = pts[:, 2] > 0.05 * NEAR_DEPTH
        pts = pts[ahead]
        rgb = photos[i].points.rgb[sel][ahead]
        if len(pts) == 0:
            continue
        if label != ORIGINAL:  # invented surface (hidden layer, border): dropped where another view has better evidence
            reach = _own_reach(photos[i], label)[ahead]
            for j, (pj, vj) in enumerate(zip(photos, views)):
                if j != i and len(pts):
                    keep = ~_covered_by(pts, reach, pj, vj, views[centre], scale)
                    pts, rgb, reach = pts[keep], rgb[keep], reach[keep]
            if len(pts) == 0:
                continue
        uvz = _project(pts, c.fov_y_deg, c.size)
        cells = np.stack([np.floor(uvz[:, 0]), np.floor(uvz[:, 1]), np.floor(np.log(uvz[:, 2]) / log_step)], 1)
        cells = cells.astype(np.int64)
        keys = (cells[:, 0] * 1_000_003 + cells[:, 1]) * 1_000_033 + cells[:, 2]
        if (i, label) == order[0]:
            new = np.ones(len(pts), bool)  # the centre view's visible surface is kept whole
        else:
            new = np.fromiter((k not in taken for k in keys.tolist()), bool, len(keys))
            _, first = np.unique(keys, return_index=True)  # and one point per new cell from this group
            once = np.zeros(len(pts), bool)
            once[first] = True
            new &= once
        taken.update(keys[new].tolist())
        keep_xyz.append(pts[new])
        keep_rgb.append(rgb[new])
        keep_label.append(np.full(int(new.sum()), label, np.uint8))
        keep_view.append(np.full(int(new.sum()), i, np.int16))
        kept[i] += int(new.sum())
    points = PointCloud(np.concatenate(keep_xyz).astype(np.float32), np.concatenate(keep_rgb).astype(np.float32),
                        np.concatenate(keep_label), c.size, c.fov_y_deg)
    timings = dict(c.timings)
    timings["merge"] = time.perf_counter() - t0
    merged = Photo3D(c.rgb, c.depth, c.ldi, points, c.fov_y_deg, timings)
    return MergedViews(merged, np.concatenate(keep_view), kept, agreement)
