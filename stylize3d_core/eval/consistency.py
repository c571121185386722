"""Multi-view consistency of rendered frames (paper Sec. 4.2).

Two frames of the same 3D photo are consistent when a surface point has the
same colour in both. We measure it by **warping** view ``i`` into view ``j``
through the point cloud and comparing with view ``j`` over the pixels both
views see (co-visible pixels):

1. **Geometry of a view** (:func:`view_geometry`): the points are rasterized at
   the view's camera with their camera-space depth as the one feature. This
   gives, per pixel, the z-buffer (front-most depth), the depth of the front
   surface (the weighted mean depth of the front points the rasterizer keeps)
   and the holes (no point). The frames themselves were rendered from the same
   point cloud (ours and the 2D baseline's alike), so this is their geometry.
2. **Warp** (:func:`warp_view`): every non-hole pixel centre of view ``j`` is
   back-projected at its front-surface depth, moved into camera ``i`` and
   projected. It is *co-visible* when it lands inside view ``i``, in front of
   that camera, on a non-hole pixel, and not behind view ``i``'s front surface
   (``z_i <= zbuffer_i * (1 + depth_tolerance)``, the rasterizer's test). View
   ``i`` is sampled there bilinearly (pixel centres at +0.5), and the pixel counts
   only where all four pixels the sample reads show that same surface (their
   z-buffers within the depth band of the point): beside a depth edge a bilinear
   sample mixes the two surfaces' colours, which no frame of a consistent 3D photo
   shows for that point, so counting it would measure the resampling rather than
   the frames. Such pixels lie within a pixel of an occlusion edge; they are most
   of the pixels a disocclusion reveals between adjacent frames (a strip a few
   pixels wide beside the silhouette), where they would make the error of even the
   plain, unstyled 3D photo look larger than elsewhere. ``one_surface=False`` gives the
   single-pixel test.
3. **RMSE** over the co-visible pixels and the three channels, colours in [0, 1].
4. **Masked feature distance** (:func:`masked_feature_distance`), an LPIPS-like
   perceptual distance without learned weights: EfficientNet-Lite0 features of
   both images (stages 1..3 by default, strides 4, 8, 16), each feature vector
   unit-normalised over its channels, the squared difference summed over
   channels, averaged over the co-visible mask area-resized to the stage, and
   the stages averaged. It lies in [0, 4]; 0 for identical images. Outside the
   mask the warped image is replaced by view ``j``, so pixels that are not
   co-visible contribute no difference of their own.

Why back-projecting pixels rather than splatting sampled point colours: a
pixel-wise warp weighs every pixel once, whatever the point density, and it
resamples only once, so a camera warped into itself gives exactly the same
image (RMSE 0); splatting colours sampled from view ``i`` would blur them twice
and report an error for perfectly consistent frames.

Pairs: :func:`short_range_pairs` ``(t, t + 1)`` (adjacent frames) and
:func:`long_range_pairs` ``(t, t + gap)`` with ``gap = 7`` by default. The
paper's protocol uses adjacent views for short range and views farther apart
for long range; 7 frames is our choice (a convention of video / novel-view
stylization evaluations; on the default 90-frame circle trajectory it is about
a sixth of a loop). A pair ``(i, j)`` warps ``i`` into ``j`` (one direction).

Conventions (axes, pixel centres, ``cam_to_world``) are those of
:mod:`stylize3d_core.geometry.camera`.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Dict, List, NamedTuple, Optional, Sequence, Tuple, Union

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from ..checks import check_range, check_shape
from ..errors import InputError
from ..geometry.camera import Cameras, pixel_centres, project, transform_points, unproject
from ..models.efficientnet_lite import EfficientNetLiteFeatures
from ..render.rasterize import RasterSettings
from ..render.rasterizer import PointRasterizer

Image = Union[np.ndarray, torch.Tensor]

DEFAULT_LONG_GAP = 7
"""Frames between the two views of a long-range pair (see the module docstring)."""


@dataclass(frozen=True)
class ConsistencySettings:
    """Options of :func:`consistency_metrics`.

    Attributes:
        depth_tolerance: relative depth band of the visibility test and of the
            rasterizer's front surface. Default 0.02, the rasterizer's default
            (2 % of the depth: far more than the depth step between neighbouring
            points of a surface, far less than the gap at an occlusion edge). In [0, 1].
        feature_stages: EfficientNet-Lite0 stages of the feature distance. Default
            (1, 2, 3): strides 4, 8, 16 (VGG relu2_1..relu4_1 in role); stage 0 is
            mostly colour, which the RMSE already measures.
    """

    depth_tolerance: float = 0.02
    feature_stages: Tuple[int, ...] = (1, 2, 3)

    def __post_init__(self) -> None:
        check_range(self.depth_tolerance, "depth_tolerance", 0.0, 1.0)
        stages = tuple(self.feature_stages)
        if not stages or list(stages) != sorted(set(stages)) or stages[0] < 0 or stages[-1] > 4:
            raise InputError("feature_stages", f"must be ascending distinct indices in 0..4, got {stages!r}")


class ViewGeometry(NamedTuple):
    """What the point cloud looks like from one camera (all (H, W), float32 except ``hole``).

    Attributes:
        depth: front-surface depth (weighted mean of the kept front points); 0 at holes.
        zbuffer: front-most depth; +inf at holes.
        hole: bool, True where no point lands.
    """

    depth: torch.Tensor
    zbuffer: torch.Tensor
    hole: torch.Tensor


class Warp(NamedTuple):
    """A view warped into another camera.

    Attributes:
        image: (C, H, W) the source view sampled at each target pixel's surface point; 0 where not ``mask``.
        mask: (H, W) bool, co-visible pixels of the target view.
    """

    image: torch.Tensor
    mask: torch.Tensor


class ConsistencyResult(NamedTuple):
    """Consistency of frames over pairs of views (see the module docstring).

    Attributes:
        rmse: mean over the pairs that share co-visible pixels of the per-pair RMSE.
        per_pair_rmse: RMSE of every pair (nan where ``n_covisible`` is 0).
        feature_distance: mean over those pairs of the masked feature distance.
        per_pair_feature_distance: per pair (nan where ``n_covisible`` is 0).
        n_covisible: co-visible pixels of every pair.
        pairs: the ``(i, j)`` pairs (view ``i`` warped into view ``j``).
    """

    rmse: float
    per_pair_rmse: Tuple[float, ...]
    feature_distance: float
    per_pair_feature_distance: Tuple[float, ...]
    n_covisible: Tuple[int, ...]
    pairs: Tuple[Tuple[int, int], ...]


def short_range_pairs(n_frames: int) -> List[Tuple[int, int]]:
    """Adjacent frames ``(t, t + 1)`` for ``t`` in ``0 .. n_frames - 2``."""
    return long_range_pairs(n_frames, gap=1)


def long_range_pairs(n_frames: int, gap: int = DEFAULT_LONG_GAP) -> List[Tuple[int, int]]:
    """Frames ``gap`` apart, ``(t, t + gap)`` for ``t`` in ``0 .. n_frames - gap - 1`` (empty if too few)."""
    for name, value, low in (("n_frames", n_frames, 0), ("gap", gap, 1)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
            raise InputError(name, f"must be an integer >= {low}, got {value!r}")
    return [(t, t + int(gap)) for t in range(int(n_frames) - int(gap))]


# ----------------------------------------------------------------------------- geometry and warp


def view_geometry(
    points_world: torch.Tensor, camera: Cameras, height: int, width: int, depth_tolerance: float = 0.02
) -> ViewGeometry:
    """Rasterize ``points_world`` (N, 3) at the single ``camera``: front depth, z-buffer and holes (H, W)."""
    if not isinstance(points_world, torch.Tensor) or not points_world.is_floating_point():
        raise InputError("points_world", "expected a floating-point torch.Tensor")
    check_shape(points_world, "points_world", (None, 3))
    if not isinstance(camera, Cameras) or len(camera) != 1:
        raise InputError("camera", "expected Cameras holding exactly one camera")
    pts = points_world.detach().float()
    w2c = camera.world_to_cam()[0].float()  # (4, 4)
    z = transform_points(w2c, pts)[:, 2:3].contiguous()  # (N, 1) camera-space depth
    raster = PointRasterizer(RasterSettings(height=int(height), width=int(width), depth_tolerance=depth_tolerance))
    with torch.no_grad():
        frags = raster(pts, torch.nan_to_num(z, nan=0.0, posinf=0.0, neginf=0.0), camera)
    return ViewGeometry(frags.image[0].contiguous(), frags.depth, frags.hole)


def warp_view(
    source: torch.Tensor, source_geometry: ViewGeometry, source_camera: Cameras,
    target_geometry: ViewGeometry, target_camera: Cameras, depth_tolerance: float = 0.02,
    one_surface: bool = True,
) -> Warp:
    """Warp ``source`` (C, H, W) into the target camera through the target's front surface.

    Both views have the same size (H, W); the geometries come from :func:`view_geometry`.
    ``one_surface`` True (default): a pixel is co-visible only where every source pixel its bilinear
    sample reads (weight > 0) shows the same surface (its z-buffer within the depth band of the point,
    on both sides). False: only the pixel the sample lands in is tested (not behind its front), so a
    sample beside a depth edge mixes in the other surface's colour (module docstring).
    """
    check_shape(source, "source", (None, None, None))
    C, H, W = source.shape
    for name, g in (("source_geometry", source_geometry), ("target_geometry", target_geometry)):
        if not isinstance(g, ViewGeometry):
            raise InputError(name, f"expected a ViewGeometry, got {type(g).__name__}")
        check_shape(g.depth, f"{name}.depth", (H, W))
    for name, cam in (("source_camera", source_camera), ("target_camera", target_camera)):
        if not isinstance(cam, Cameras) or len(cam) != 1:
            raise InputError(name, "expected Cameras holding exactly one camera")
    dtype = torch.float32
    K = target_camera.intrinsics(H, W, dtype=dtype)[0]  # (3, 3), same FOV convention for both
    Ks = source_camera.intrinsics(H, W, dtype=dtype)[0]
    valid = ~target_geometry.hole  # (H, W)
    uv = pixel_centres(H, W, dtype=dtype)  # (H, W, 2)
    cam_t = unproject(uv, target_geometry.depth.to(dtype), K).reshape(-1, 3)  # (HW, 3)
    t_to_s = source_camera.world_to_cam()[0] @ target_camera.cam_to_world[0]  # (4, 4) float64
    cam_s = transform_points(t_to_s.to(dtype), cam_t)  # (HW, 3)
    uv_s, z_s = project(cam_s, Ks)  # (HW, 2), (HW,)
    inside = (z_s > 1e-6) & (uv_s[:, 0] >= 0) & (uv_s[:, 0] < W) & (uv_s[:, 1] >= 0) & (uv_s[:, 1] < H)
    inside &= valid.reshape(-1) & torch.isfinite(uv_s).all(dim=1)
    uv_safe = torch.where(inside[:, None], uv_s, torch.zeros_like(uv_s))
    col = uv_safe[:, 0].long().clamp(0, W - 1)
    row = uv_safe[:, 1].long().clamp(0, H - 1)
    front = source_geometry.zbuffer[row, col].to(dtype)  # (HW,), +inf at source holes
    mask = inside & torch.isfinite(front) & (z_s <= front * (1.0 + depth_tolerance))  # (HW,)
    if one_surface:
        mask &= _taps_on_one_surface(source_geometry.zbuffer, uv_safe, z_s, depth_tolerance)
    grid = torch.stack([uv_safe[:, 0] / W * 2 - 1, uv_safe[:, 1] / H * 2 - 1], dim=-1)  # (HW, 2)
    sampled = F.grid_sample(source[None].to(dtype), grid.view(1, H, W, 2), mode="bilinear",
                            padding_mode="border", align_corners=False)[0]  # (C, H, W)
    mask = mask.view(H, W)
    return Warp(torch.where(mask, sampled, torch.zeros_like(sampled)), mask)


def _taps_on_one_surface(zbuffer: torch.Tensor, uv: torch.Tensor, z: torch.Tensor, tol: float) -> torch.Tensor:
    """(HW,) bool: every pixel that bilinear sampling at ``uv`` (HW, 2) reads with a weight > 0 has its
    front depth within the band ``[z / (1 + tol), z * (1 + tol)]`` of the sampled point's depth ``z``
    (grid_sample's conventions: pixel centres at +0.5, border padding, i.e. indices clamped)."""
    H, W = zbuffer.shape
    a = uv - 0.5  # (HW, 2) in pixel-index units
    base = torch.floor(a)
    frac = a - base
    ok = torch.ones(a.shape[0], dtype=torch.bool, device=a.device)
    for dx in (0, 1):
        for dy in (0, 1):
            wx = frac[:, 0] if dx else 1.0 - frac[:, 0]
            wy = frac[:, 1] if dy else 1.0 - frac[:, 1]
            col = (base[:, 0] + dx).long().clamp(0, W - 1)
            row = (base[:, 1] + dy).long().clamp(0, H - 1)
            front = zbuffer[row, col].to(z.dtype)  # +inf at holes
            same = torch.isfinite(front) & (z <= front * (1.0 + tol)) & (z * (1.0 + tol) >= front)
            ok &= same | (wx * wy <= 0.0)
    return ok


# ----------------------------------------------------------------------------- distances


def masked_rmse(a: torch.Tensor, b: torch.Tensor, mask: torch.Tensor) -> float:
    """RMSE of (C, H, W) images over the pixels of ``mask`` (H, W) and all channels; nan if the mask is empty."""
    n = int(mask.sum())
    if n == 0:
        return math.nan
    d = (a - b)[:, mask]  # (C, n)
    return float(torch.sqrt((d.double() ** 2).mean()))


@functools.lru_cache(maxsize=1)
def _shared_extractor(deepest: int) -> EfficientNetLiteFeatures:
    return EfficientNetLiteFeatures(stages=tuple(range(deepest + 1)))


def feature_extractor(stages: Sequence[int] = (1, 2, 3)) -> nn.Module:
    """The frozen EfficientNet-Lite0 extractor (stages ``0 .. max(stages)``), shared within the process."""
    return _shared_extractor(int(max(stages)))


def _unit(f: torch.Tensor, eps: float = 1e-10) -> torch.Tensor:
    """Normalise (B, C, h, w) features to unit length over the channels (LPIPS's normalisation)."""
    return f / torch.sqrt((f * f).sum(dim=1, keepdim=True) + eps)


def masked_feature_distance(
    a_feats: Sequence[torch.Tensor], b_feats: Sequence[torch.Tensor], mask: torch.Tensor, stages: Sequence[int]
) -> float:
    """LPIPS-like distance of two images' feature maps, averaged over ``mask`` (H, W) per stage.

    ``a_feats[s]`` and ``b_feats[s]`` are (1, C_s, h_s, w_s) maps of the extractor's stage ``s``.
    Returns the mean over ``stages`` of the mask-weighted mean of
    ``sum_c (unit(a) - unit(b))**2``; nan if the mask is empty.
    """
    if not bool(mask.any()):
        return math.nan
    m = mask[None, None].float()  # (1, 1, H, W)
    per_stage = []
    for s in stages:
        fa, fb = _unit(a_feats[s].float()), _unit(b_feats[s].float())
        d = ((fa - fb) ** 2).sum(dim=1, keepdim=True)  # (1, 1, h, w)
        w = F.adaptive_avg_pool2d(m, d.shape[-2:])  # (1, 1, h, w) fraction of each cell that is co-visible
        per_stage.append(float((d * w).sum() / w.sum().clamp_min(1e-12)))
    return float(np.mean(per_stage))


# ----------------------------------------------------------------------------- the metric


def _frame_tensor(frame: Image, index: int, size: Optional[Tuple[int, int]]) -> torch.Tensor:
    name = f"frames[{index}]"
    t = frame if isinstance(frame, torch.Tensor) else torch.from_numpy(np.asarray(frame))
    check_shape(t, name, (None, None, 3) if size is None else (size[0], size[1], 3))
    if not t.is_floating_point():
        raise InputError(name, f"expected a float image in [0, 1], got {t.dtype}")
    t = t.detach().to(torch.float32)
    if not torch.isfinite(t).all():
        raise InputError(name, "contains NaN or infinite values")
    return t.permute(2, 0, 1).contiguous()  # (3, H, W)


def _check_pairs(pairs: Sequence[Tuple[int, int]], n: int) -> Tuple[Tuple[int, int], ...]:
    out = []
    for p in pairs:
        if len(p) != 2 or not all(isinstance(k, (int, np.integer)) and not isinstance(k, bool) for k in p):
            raise InputError("pairs", f"expected (i, j) integer pairs, got {p!r}")
        i, j = int(p[0]), int(p[1])
        if not (0 <= i < n and 0 <= j < n):
            raise InputError("pairs", f"pair {(i, j)} is out of range for {n} frames")
        out.append((i, j))
    if not out:
        raise InputError("pairs", "no pairs of views to compare (too few frames for this gap?)")
    return tuple(out)


def consistency_metrics(
    points_world: Union[torch.Tensor, np.ndarray],
    frames: Sequence[Image],
    cameras: Cameras,
    pairs: Sequence[Tuple[int, int]],
    settings: ConsistencySettings = ConsistencySettings(),
    extractor: Optional[nn.Module] = None,
) -> ConsistencyResult:
    """RMSE and masked feature distance between warped views (see the module docstring).

    Args:
        points_world: (N, 3) the point cloud the frames were rendered from.
        frames: B images (H, W, 3) float in [0, 1], numpy or torch, all the same size.
        cameras: the B cameras of the frames.
        pairs: ``(i, j)`` frame indices; view ``i`` is warped into view ``j``.
        settings: visibility tolerance and feature stages.
        extractor: a module mapping (1, 3, H, W) images in [0, 1] to a tuple of
            feature maps indexed by stage; default the shared EfficientNet-Lite0.
    Raises:
        InputError: on bad shapes, non-finite frames, a camera count that does
            not match, pairs out of range, or no pair with a co-visible pixel.
    """
    pts = points_world if isinstance(points_world, torch.Tensor) else torch.from_numpy(np.asarray(points_world))
    check_shape(pts, "points_world", (None, 3))
    if not pts.is_floating_point():
        raise InputError("points_world", f"expected floating-point coordinates, got {pts.dtype}")
    if not isinstance(cameras, Cameras):
        raise InputError("cameras", f"expected Cameras, got {type(cameras).__name__}")
    frames = list(frames)
    if len(frames) != len(cameras):
        raise InputError("frames", f"{len(frames)} frames for {len(cameras)} cameras")
    pairs = _check_pairs(pairs, len(frames))
    if extractor is None:
        extractor = feature_extractor(settings.feature_stages)
    tol = settings.depth_tolerance
    images: Dict[int, torch.Tensor] = {}
    geometry: Dict[int, ViewGeometry] = {}
    target_feats: Dict[int, Tuple[torch.Tensor, ...]] = {}
    size: Optional[Tuple[int, int]] = None

    def image(k: int) -> torch.Tensor:
        nonlocal size
        if k not in images:
            images[k] = _frame_tensor(frames[k], k, size)  # (3, H, W)
            size = tuple(images[k].shape[1:])
        return images[k]

    for k in sorted({k for p in pairs for k in p}):  # validate every frame used before any work
        image(k)
    H, W = size
    rmse, feat, counts = [], [], []
    with torch.no_grad():
        for i, j in pairs:
            for k in (i, j):
                if k not in geometry:
                    geometry[k] = view_geometry(pts, cameras[k], H, W, tol)
            warp = warp_view(image(i), geometry[i], cameras[i], geometry[j], cameras[j], tol)
            n = int(warp.mask.sum())
            counts.append(n)
            if n == 0:
                rmse.append(math.nan)
                feat.append(math.nan)
                continue
            rmse.append(masked_rmse(warp.image, image(j), warp.mask))
            composite = torch.where(warp.mask, warp.image, image(j))  # (3, H, W)
            if j not in target_feats:
                target_feats[j] = extractor(image(j)[None])
            feat.append(masked_feature_distance(extractor(composite[None]), target_feats[j], warp.mask,
                                                settings.feature_stages))
    used = [k for k, n in enumerate(counts) if n > 0]
    if not used:
        raise InputError("pairs", "no pair of views shares a co-visible pixel")
    return ConsistencyResult(
        rmse=float(np.mean([rmse[k] for k in used])), per_pair_rmse=tuple(rmse),
        feature_distance=float(np.mean([feat[k] for k in used])), per_pair_feature_distance=tuple(feat),
        n_covisible=tuple(counts), pairs=pairs,
    )
