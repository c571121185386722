"""Procedural geometry for training: random depth maps, and textured scenes ray-cast analytically.

Conventions are those of :mod:`stylize3d_core.geometry.camera` (+z forward, x
right, y down, pixel centres at +0.5, ``cam_to_world``, FOV vertical). The world
frame is the source camera's frame.

**Random depth maps** (:func:`random_depth`) give a photo a plausible but random
geometry for the LDI: a slanted background plane, often a ground plane below a
horizon, and a few nearer objects with sharp outlines (ellipses, rotated
rectangles, polygons, or segments of the photo itself found by graph-based
segmentation, so some outlines follow the photo's edges). They are built in
*disparity* (1 / depth), where a plane is an affine function of the pixel
coordinates, and composited nearest-wins, so the LDI tears and inpaints at the
objects' outlines.

**Scenes** (:class:`Scene`) are textured rectangles ("quads"): a back wall, a
ground plane, cards and boxes (six quads each). :func:`ray_cast` intersects
the camera rays with every quad (vectorised numpy over the rays; a quad in
front of the camera is only tested against the rays inside its projected
bounding box), keeps the nearest hit and samples that quad's texture
bilinearly (mirrored repeat).
Colours average ``samples x samples`` rays per pixel (anti-aliasing); depth and
hit points are those of the pixel-centre ray. :func:`visible_from` tells which
world points a camera sees, so a true novel view can be split into what the
source view saw and what it did not.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List, NamedTuple, Optional, Sequence, Tuple

import cv2
import numpy as np

from ..checks import check_range, check_shape
from ..errors import InputError
from ..geometry.camera import Cameras
from ..io.images import to_uint8

# ----------------------------------------------------------------------------- depth maps


def _shape_mask(rng: np.random.Generator, h: int, w: int, segments: Optional[np.ndarray]) -> np.ndarray:
    """A random (h, w) bool object outline: ellipse, rotated rectangle, polygon or photo segment."""
    mask = np.zeros((h, w), np.uint8)
    kind = int(rng.integers(0, 4 if segments is not None else 3))
    cx, cy = rng.uniform(0.1, 0.9) * w, rng.uniform(0.15, 1.0) * h
    r = rng.uniform(0.08, 0.35) * min(h, w)
    if kind == 0:
        axes = (max(2, int(r)), max(2, int(r * rng.uniform(0.4, 1.6))))
        cv2.ellipse(mask, (int(cx), int(cy)), axes, rng.uniform(0, 180), 0, 360, 1, -1)
    elif kind == 1:
        box = cv2.boxPoints(((cx, cy), (2 * r, 2 * r * rng.uniform(0.3, 1.5)), rng.uniform(-30, 30)))
        cv2.fillPoly(mask, [np.round(box).astype(np.int32)], 1)
    elif kind == 2:
        n = int(rng.integers(3, 9))
        ang = np.sort(rng.uniform(0, 2 * math.pi, n))
        rad = r * rng.uniform(0.5, 1.2, n)
        pts = np.stack([cx + rad * np.cos(ang), cy + rad * np.sin(ang)], axis=1)
        cv2.fillPoly(mask, [np.round(pts).astype(np.int32)], 1)
    else:
        areas = np.bincount(segments.ravel())
        ok = np.nonzero((areas > 0.01 * h * w) & (areas < 0.35 * h * w))[0]
        if ok.size == 0:
            return _shape_mask(rng, h, w, None)
        mask = (segments == ok[int(rng.integers(0, ok.size))]).astype(np.uint8)
        mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, np.ones((5, 5), np.uint8))
    return mask.astype(bool)


def random_depth(rng: np.random.Generator, size: Tuple[int, int], photo: Optional[np.ndarray] = None) -> np.ndarray:
    """A random depth map (see the module docstring).

    Args:
        rng: random generator (the result is a function of its state).
        size: (H, W).
        photo: optional (H, W, 3) float image in [0, 1]; some objects are its segments.
    Returns:
        (H, W) float32 depth, finite, in [1, 12] (relative units).
    """
    h, w = int(size[0]), int(size[1])
    if h < 4 or w < 4:
        raise InputError("size", f"must be at least 4 x 4, got {(h, w)}")
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    xn, yn = (x + 0.5) / w * 2 - 1, (y + 0.5) / h * 2 - 1  # (H, W) in [-1, 1]
    base = rng.uniform(0.12, 0.4)
    nd = base + rng.uniform(-0.06, 0.06) * xn + rng.uniform(-0.06, 0.06) * yn  # slanted background
    if rng.random() < 0.65:  # ground plane below a horizon: disparity linear in the row
        horizon = rng.uniform(-0.5, 0.4)
        bottom = rng.uniform(0.55, 1.0)
        ground = base + (bottom - base) * (yn - horizon) / (1.0 - horizon)
        nd = np.maximum(nd, ground)
    segments = None
    if photo is not None:
        check_shape(photo, "photo", (h, w, 3))
        seg = cv2.ximgproc.segmentation.createGraphSegmentation(sigma=0.8, k=300, min_size=max(20, h * w // 400))
        segments = seg.processImage(to_uint8(photo))
    n_objects = int(rng.choice([0, 1, 1, 2, 2, 3, 4]))
    for _ in range(n_objects):
        mask = _shape_mask(rng, h, w, segments)
        if not mask.any():
            continue
        under = float(nd[mask].max())
        level = min(1.0, under + rng.uniform(0.08, 0.5))
        obj = level + rng.uniform(-0.05, 0.05) * xn + rng.uniform(-0.05, 0.05) * yn
        if rng.random() < 0.5:  # rounded, not flat: a bulge over the mask's distance transform
            dist = cv2.distanceTransform(mask.astype(np.uint8), cv2.DIST_L2, 3)
            obj = obj + rng.uniform(0.0, 0.1) * np.sqrt(dist / max(float(dist.max()), 1.0))
        nd = np.where(mask, np.maximum(nd, obj), nd)
    if rng.random() < 0.5:  # gentle relief
        nd = nd * (1.0 + 0.03 * (_smooth_noise(rng, h, w) - 0.5))
    return (1.0 / np.clip(nd, 1.0 / 12.0, 1.0)).astype(np.float32)


def _smooth_noise(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    grid = rng.random((6, 6)).astype(np.float32)
    return cv2.resize(grid, (w, h), interpolation=cv2.INTER_CUBIC)


# ----------------------------------------------------------------------------- scenes


@dataclass(frozen=True)
class Scene:
    """Textured rectangles ("quads") in world coordinates (Q quads, T textures).

    A quad is ``centre + s1 * e1 + s2 * e2`` for ``|s1| <= half[:, 0]``,
    ``|s2| <= half[:, 1]``; its colour at ``(s1, s2)`` is its texture at pixel
    ``(s1 / texel + offset[0], s2 / texel + offset[1])`` (x, y; mirrored repeat).

    Attributes:
        centre: (Q, 3) float64.
        e1: (Q, 3) float64 unit vectors.
        e2: (Q, 3) float64 unit vectors orthogonal to ``e1``.
        half: (Q, 2) float64 half extents, > 0.
        texel: (Q,) float64 world size of one texture pixel, > 0.
        offset: (Q, 2) float64 texture offset in pixels.
        texture_id: (Q,) int64 index into ``textures``.
        textures: T images (h, w, 3) float32 in [0, 1].
    """

    centre: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    half: np.ndarray
    texel: np.ndarray
    offset: np.ndarray
    texture_id: np.ndarray
    textures: Tuple[np.ndarray, ...]

    def __post_init__(self) -> None:
        q = self.centre.shape[0] if self.centre.ndim == 2 else -1
        check_shape(self.centre, "centre", (None, 3))
        for name, shape in (("e1", (q, 3)), ("e2", (q, 3)), ("half", (q, 2)), ("texel", (q,)), ("offset", (q, 2)),
                            ("texture_id", (q,))):
            check_shape(getattr(self, name), name, shape)
        if q == 0:
            raise InputError("scene", "needs at least one quad")
        if not (np.all(self.half > 0) and np.all(self.texel > 0)):
            raise InputError("scene", "half extents and texel sizes must be > 0")
        if np.abs((self.e1 * self.e2).sum(1)).max() > 1e-6:
            raise InputError("scene", "e1 and e2 must be orthogonal")
        if self.texture_id.min() < 0 or self.texture_id.max() >= len(self.textures):
            raise InputError("texture_id", f"must index the {len(self.textures)} textures")
        for t in self.textures:
            check_shape(t, "texture", (None, None, 3))

    @property
    def normal(self) -> np.ndarray:
        """(Q, 3) unit normals ``e1 x e2``."""
        return np.cross(self.e1, self.e2)

    def scaled(self, s: float) -> "Scene":
        """The scene scaled by ``s`` about the world origin (textures scale with it)."""
        check_range(s, "scale", 0.0, math.inf, inclusive=False)
        return Scene(self.centre * s, self.e1, self.e2, self.half * s, self.texel * s, self.offset,
                     self.texture_id, self.textures)


def _rotation(yaw: float, pitch: float, roll: float) -> np.ndarray:
    """(3, 3) rotation: roll about z, then pitch about x, then yaw about y (radians)."""
    cy, sy = math.cos(yaw), math.sin(yaw)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cr, sr = math.cos(roll), math.sin(roll)
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rx = np.array([[1, 0, 0], [0, cp, -sp], [0, sp, cp]])
    rz = np.array([[cr, -sr, 0], [sr, cr, 0], [0, 0, 1]])
    return ry @ rx @ rz


class _QuadList:
    """Accumulates quads for :class:`Scene`."""

    def __init__(self) -> None:
        self.rows: List[tuple] = []

    def add(self, centre, e1, e2, half, texel, offset, texture_id) -> None:
        self.rows.append((np.asarray(centre, float), np.asarray(e1, float), np.asarray(e2, float),
                          np.asarray(half, float), float(texel), np.asarray(offset, float), int(texture_id)))

    def build(self, textures: Sequence[np.ndarray]) -> Scene:
        cols = list(zip(*self.rows))
        return Scene(np.stack(cols[0]), np.stack(cols[1]), np.stack(cols[2]), np.stack(cols[3]),
                     np.array(cols[4]), np.stack(cols[5]), np.array(cols[6], np.int64), tuple(textures))


def random_scene(rng: np.random.Generator, textures: Sequence[np.ndarray], fov_y_deg: float, aspect: float) -> Scene:
    """A random scene in front of the source camera (identity pose).

    A textured back wall (sometimes turned), often a ground plane, 1-4 cards
    (sometimes standing on the ground) and 0-2 boxes, all inside the view.

    Args:
        rng: random generator.
        textures: the texture pool (each (h, w, 3) in [0, 1]); quads pick from it.
        fov_y_deg: the source camera's vertical FOV; aspect: its W / H.
    """
    if len(textures) == 0:
        raise InputError("textures", "needs at least one texture")
    tan_y = math.tan(math.radians(fov_y_deg) / 2.0)
    tan_x = tan_y * aspect
    quads = _QuadList()

    def pick() -> Tuple[int, float]:
        i = int(rng.integers(0, len(textures)))
        return i, float(max(textures[i].shape[:2]))

    def offset(i: int) -> np.ndarray:
        return rng.uniform(0, 1, 2) * np.array(textures[i].shape[1::-1], float)

    z_wall = rng.uniform(1.0, 2.5)
    rot = _rotation(rng.uniform(-0.4, 0.4) if rng.random() < 0.5 else 0.0, 0.0, 0.0)
    i, n = pick()
    texel = 2.0 * z_wall * tan_x / n * rng.uniform(0.7, 1.3)  # one texture spans about the visible wall
    centred = np.array(textures[i].shape[1::-1], float) * rng.uniform(0.4, 0.6, 2)  # its mirror seams off-centre
    quads.add((0.0, 0.0, z_wall), rot[:, 0], rot[:, 1], (50.0, 50.0), texel, centred, i)
    ground = None
    if rng.random() < 0.75:
        ground = rng.uniform(0.12, 0.3)  # camera height above the ground (+y is down)
        i, n = pick()
        quads.add((0.0, ground, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0), (50.0, 50.0),
                  rng.uniform(0.3, 1.0) / n, offset(i), i)
    z_max = min(0.95, 0.8 * z_wall)
    for _ in range(int(rng.integers(1, 5))):  # cards
        z = rng.uniform(0.33, z_max)
        h1, h2 = rng.uniform(0.1, 0.45, 2) * z * tan_y
        centre = np.array([rng.uniform(-0.8, 0.8) * z * tan_x, rng.uniform(-0.8, 0.8) * z * tan_y, z])
        standing = ground is not None and rng.random() < 0.5
        rot = _rotation(rng.uniform(-0.6, 0.6), 0.0 if standing else rng.uniform(-0.35, 0.35),
                        0.0 if standing else rng.uniform(-0.25, 0.25))
        if standing:
            centre[1] = ground - h2
        i, n = pick()
        quads.add(centre, rot[:, 0], rot[:, 1], (h1, h2), 2.0 * max(h1, h2) / n * rng.uniform(0.5, 1.5), offset(i), i)
    for _ in range(int(rng.choice([0, 0, 1, 2]))):  # boxes
        z = rng.uniform(0.4, z_max)
        hx, hy, hz = rng.uniform(0.06, 0.3, 3) * z * tan_y
        centre = np.array([rng.uniform(-0.7, 0.7) * z * tan_x, rng.uniform(-0.6, 0.6) * z * tan_y, z + hz])
        if ground is not None:
            centre[1] = ground - hy
        rot = _rotation(rng.uniform(-0.8, 0.8), 0.0, 0.0)
        i, n = pick()
        texel = 2.0 * max(hx, hy, hz) / n * rng.uniform(0.5, 1.5)
        ax = [rot[:, 0], rot[:, 1], rot[:, 2]]
        hs = [hx, hy, hz]
        for a in range(3):  # two faces perpendicular to each box axis
            b, c = [k for k in range(3) if k != a]
            for sign in (-1.0, 1.0):
                quads.add(centre + sign * hs[a] * ax[a], ax[b], ax[c], (hs[b], hs[c]), texel, offset(i), i)
    return quads.build(textures)


# ----------------------------------------------------------------------------- ray casting


class RayHits(NamedTuple):
    """Nearest hits of R rays."""

    t: np.ndarray  # (R,) ray parameter of the hit = camera-frame depth (inf where none)
    quad: np.ndarray  # (R,) int64 quad index (-1 where none)
    s: np.ndarray  # (R, 2) quad-local coordinates of the hit (0 where none)


def intersect(scene: Scene, cam_to_world: np.ndarray, dirs_cam: np.ndarray) -> RayHits:
    """Nearest quad hit of camera rays (two-sided quads, t > 1e-9).

    Args:
        scene: the quads.
        cam_to_world: (4, 4) pose of the camera the rays start from.
        dirs_cam: (R, 3) camera-frame directions with z = 1, so the ray
            parameter ``t`` of a hit is its camera-frame depth.

    A quad whose corners are all in front of the camera is only tested against
    the rays inside the bounding box of its projected corners; one wholly behind
    the camera is skipped; others (the huge wall and ground) are tested against
    every ray.
    """
    rot, origin = cam_to_world[:3, :3], cam_to_world[:3, 3]
    dirs = dirs_cam @ rot.T  # (R, 3) world directions
    n = scene.normal  # (Q, 3)
    oc = origin[None, :] - scene.centre  # (Q, 3)
    num = -(oc * n).sum(1)  # (Q,)
    o1, o2 = (oc * scene.e1).sum(1), (oc * scene.e2).sum(1)  # (Q,)
    signs = np.array([[-1, -1], [-1, 1], [1, -1], [1, 1]], float)  # (4, 2)
    corners = (scene.centre[:, None] + (signs[None, :, :1] * scene.half[:, None, :1]) * scene.e1[:, None]
               + (signs[None, :, 1:] * scene.half[:, None, 1:]) * scene.e2[:, None])  # (Q, 4, 3)
    corners_cam = (corners - origin) @ rot  # (Q, 4, 3)
    R = dirs.shape[0]
    best_t = np.full(R, np.inf)
    best_q = np.full(R, -1, np.int64)
    best_s = np.zeros((R, 2))
    every = np.arange(R)
    for q in range(n.shape[0]):
        cz = corners_cam[q, :, 2]
        if (cz <= 1e-9).all():
            continue  # wholly behind the camera
        if (cz > 1e-9).all():
            px, py = corners_cam[q, :, 0] / cz, corners_cam[q, :, 1] / cz
            sel = np.nonzero((dirs_cam[:, 0] >= px.min() - 1e-9) & (dirs_cam[:, 0] <= px.max() + 1e-9)
                             & (dirs_cam[:, 1] >= py.min() - 1e-9) & (dirs_cam[:, 1] <= py.max() + 1e-9))[0]
        else:
            sel = every
        if sel.size == 0:
            continue
        d = dirs[sel]  # (r, 3)
        dn = d @ n[q]  # (r,)
        safe = np.abs(dn) > 1e-12
        t = num[q] / np.where(safe, dn, 1.0)
        s1 = t * (d @ scene.e1[q]) + o1[q]
        s2 = t * (d @ scene.e2[q]) + o2[q]
        ok = safe & (t > 1e-9) & (t < best_t[sel]) & (np.abs(s1) <= scene.half[q, 0]) & (np.abs(s2) <= scene.half[q, 1])
        idx = sel[ok]
        best_t[idx] = t[ok]
        best_q[idx] = q
        best_s[idx, 0], best_s[idx, 1] = s1[ok], s2[ok]
    return RayHits(best_t, best_q, best_s)


def _mirror(i: np.ndarray, n: int) -> np.ndarray:
    m = np.mod(i, 2 * n)
    return np.where(m >= n, 2 * n - 1 - m, m)


def shade(scene: Scene, hits: RayHits) -> np.ndarray:
    """Texture colour (R, 3) float32 of every hit (0 where a ray hit nothing)."""
    out = np.zeros((hits.t.shape[0], 3), np.float32)
    for q in np.unique(hits.quad[hits.quad >= 0]):
        rows = np.nonzero(hits.quad == q)[0]
        tex = scene.textures[int(scene.texture_id[q])]
        th, tw = tex.shape[:2]
        px = hits.s[rows, 0] / scene.texel[q] + scene.offset[q, 0] - 0.5  # texel-centre coordinates
        py = hits.s[rows, 1] / scene.texel[q] + scene.offset[q, 1] - 0.5
        x0, y0 = np.floor(px), np.floor(py)
        fx, fy = (px - x0)[:, None], (py - y0)[:, None]
        x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
        xa, xb, ya, yb = _mirror(x0, tw), _mirror(x0 + 1, tw), _mirror(y0, th), _mirror(y0 + 1, th)
        out[rows] = ((1 - fy) * ((1 - fx) * tex[ya, xa] + fx * tex[ya, xb])
                     + fy * ((1 - fx) * tex[yb, xa] + fx * tex[yb, xb]))
    return out


class RayCastResult(NamedTuple):
    """What one camera sees of a :class:`Scene` (H, W image)."""

    rgb: np.ndarray  # (H, W, 3) float32 in [0, 1], anti-aliased
    depth: np.ndarray  # (H, W) float32 camera-frame z of the pixel-centre hit (inf where none)
    hit: np.ndarray  # (H, W) bool, the pixel-centre ray hit something
    points: np.ndarray  # (H, W, 3) float64 world position of the pixel-centre hit (0 where none)


def _camera(camera: Cameras) -> Tuple[np.ndarray, float]:
    if not isinstance(camera, Cameras) or len(camera) != 1:
        raise InputError("camera", "expected a Cameras batch of exactly one camera")
    return camera.cam_to_world[0].double().numpy(), float(camera.fov_y_deg[0])


def _rays(fov: float, h: int, w: int, uv: np.ndarray) -> np.ndarray:
    """Camera-frame directions (R, 3) with z = 1 through pixel coordinates uv (R, 2)."""
    f = 0.5 * h / math.tan(math.radians(fov) / 2.0)
    return np.stack([(uv[:, 0] - w / 2.0) / f, (uv[:, 1] - h / 2.0) / f, np.ones(len(uv))], axis=1)


def ray_cast(scene: Scene, camera: Cameras, height: int, width: int, samples: int = 3) -> RayCastResult:
    """Render ``scene`` seen by one camera (see the module docstring).

    Args:
        scene: the quads and textures.
        camera: a batch of one camera.
        height, width: image size (H, W).
        samples: anti-aliasing rays per pixel along each axis (``samples ** 2`` per pixel), 1..8.
    """
    if not (isinstance(samples, int) and 1 <= samples <= 8):
        raise InputError("samples", f"must be an integer in [1, 8], got {samples!r}")
    if not (isinstance(height, int) and isinstance(width, int) and height >= 1 and width >= 1):
        raise InputError("image size", f"must be positive integers, got {(height, width)!r}")
    c2w, fov = _camera(camera)
    origin = c2w[:3, 3]
    jj, ii = np.meshgrid(np.arange(width, dtype=float), np.arange(height, dtype=float))
    centre_uv = np.stack([jj.ravel() + 0.5, ii.ravel() + 0.5], axis=1)  # (HW, 2)
    centre_dirs = _rays(fov, height, width, centre_uv)  # (HW, 3) camera frame
    centre_hits = intersect(scene, c2w, centre_dirs)
    rgb = np.zeros((height * width, 3), np.float64)
    offsets = (np.arange(samples) + 0.5) / samples - 0.5
    for dy in offsets:
        for dx in offsets:
            if samples % 2 == 1 and dx == 0 and dy == 0:
                hits = centre_hits
            else:
                hits = intersect(scene, c2w, _rays(fov, height, width, centre_uv + np.array([dx, dy])))
            rgb += shade(scene, hits)
    rgb /= samples**2
    hit = np.isfinite(centre_hits.t)
    points = np.where(hit[:, None], origin + centre_hits.t[:, None] * (centre_dirs @ c2w[:3, :3].T), 0.0)
    return RayCastResult(
        np.clip(rgb, 0.0, 1.0).astype(np.float32).reshape(height, width, 3),
        np.where(hit, centre_hits.t, np.inf).astype(np.float32).reshape(height, width),
        hit.reshape(height, width),
        points.reshape(height, width, 3),
    )


def visible_from(scene: Scene, points: np.ndarray, camera: Cameras, height: int, width: int) -> np.ndarray:
    """Which world points (M, 3) one camera sees inside its (H, W) image, unoccluded: (M,) bool."""
    check_shape(points, "points", (None, 3))
    c2w, fov = _camera(camera)
    w2c = np.linalg.inv(c2w)
    p_cam = points @ w2c[:3, :3].T + w2c[:3, 3]  # (M, 3)
    z = p_cam[:, 2]
    f = 0.5 * height / math.tan(math.radians(fov) / 2.0)
    z_safe = np.where(z > 1e-9, z, 1.0)
    u = f * p_cam[:, 0] / z_safe + width / 2.0
    v = f * p_cam[:, 1] / z_safe + height / 2.0
    inside = (z > 1e-9) & (u >= 0) & (u < width) & (v >= 0) & (v < height)
    out = np.zeros(points.shape[0], bool)
    idx = np.nonzero(inside)[0]
    if idx.size:
        t = intersect(scene, c2w, p_cam[idx] / z_safe[idx, None]).t  # rays with camera z = 1
        out[idx] = t >= z[idx] * (1.0 - 1e-6) - 1e-9
    return out
