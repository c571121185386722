""":func:`build_ldi`: a photo and its depth -> the layered depth image (see the package docstring)."""

from __future__ import annotations

import math
from typing import NamedTuple, Tuple, Union

import cv2
import numpy as np

from ...checks import check_shape
from ...depth.types import DepthMap
from ...errors import InputError
from ...geometry.camera import DEFAULT_FOV_Y_DEG, NEAR_DEPTH, check_fov
from ...geometry.camera_range import border_overshoot, edge_parallax, range_corner_poses, trajectory_extreme_cameras
from ...threads import beside
from .._fill import cross_median
from .border import _border
from .hidden import _hidden_layer
from .layers import _RGB_TOLERANCE, BORDER, LDI, MIN_PHOTO_SIDE, ORIGINAL, LDISettings
from .silhouettes import subpixel_edges
from .tear import _tear


def build_ldi(
    rgb: np.ndarray, depth: Union[np.ndarray, DepthMap], settings: LDISettings = LDISettings(),
    fov_y_deg: float = DEFAULT_FOV_Y_DEG,
) -> LDI:
    """Build the layered depth image of a photo (see the module docstring).

    Args:
        rgb: (H, W, 3) float in [0, 1], or uint8 (divided by 255).
        depth: (H, W) depth, finite and > 0 (any scale), or a :class:`DepthMap`.
        settings: see :class:`LDISettings`.
        fov_y_deg: vertical field of view of the photo in degrees (the parallax a camera
            move causes, hence the sized hidden layer and border, depend on it).
    Returns:
        The :class:`LDI`. The inputs are not modified.
    Raises:
        InputError: on a shape mismatch, a non-finite or non-positive depth, colours
            outside [0, 1], or a photo smaller than :data:`MIN_PHOTO_SIDE`.
    """
    if not isinstance(settings, LDISettings):
        raise InputError("settings", f"expected LDISettings, got {type(settings).__name__}")
    fov = check_fov(fov_y_deg, "fov_y_deg")
    image = _check_rgb(rgb)
    z = _check_depth(depth, image.shape[:2])
    h, w = z.shape
    q1 = float(np.percentile(z, 1.0))
    depth_scale = NEAR_DEPTH / q1
    nd = (q1 / z).astype(np.float32)  # (H, W) = NEAR_DEPTH / (depth_scale * z)
    if settings.median_filter:
        nd = cross_median(nd)
    nd, fg, bg = _tear(nd, settings)
    cover = _coverage(nd, fg, settings, fov)
    pad = cover.pad
    # the border (its push-pull fills) and the hidden layer behind the photo's edges do not depend on each
    # other: the border is built beside the hidden layer (OpenCV and numpy free the GIL on whole images)
    border = beside(_border, image, nd, fg, pad, settings)
    hidden = _hidden_layer(image, nd, fg, bg, cover.widths, settings) if cover.widths.any() else None
    rgb0, nd0, outer = border.result()
    hc, wc = h + 2 * pad, w + 2 * pad
    inner = (slice(pad, pad + h), slice(pad, pad + w))
    label = np.full((hc, wc), BORDER, np.uint8)
    label[inner] = ORIGINAL
    hidden_mask = np.zeros((hc, wc), bool)
    hidden_rgb = np.zeros((hc, wc, 3), np.float32)
    hidden_depth = np.zeros((hc, wc), np.float32)
    if hidden is not None:
        mask1, rgb1, nd1, mask0, unmixed, fore = hidden
        rgb0[inner][mask0] = unmixed[mask0]  # the background-side silhouette pixels, foreground share out
        joins = fore > 0
        nd0[inner][joins] = fore[joins]  # ... or joined to the foreground
        hidden_mask[inner] = mask1
        hidden_rgb[inner][mask1] = rgb1[mask1]
        hidden_depth[inner][mask1] = NEAR_DEPTH / nd1[mask1]
    if outer is not None:  # the border's hidden samples: outside the photo, where the layer above put none
        add, add_rgb, add_depth = outer
        hidden_mask |= add
        hidden_rgb[add] = add_rgb
        hidden_depth[add] = add_depth
    fg_c = np.zeros((hc, wc), bool)
    bg_c = np.zeros((hc, wc), bool)
    fg_c[inner], bg_c[inner] = fg, bg
    alpha = offset = None
    if hidden is not None and settings.subpixel_silhouettes:
        edge = subpixel_edges(rgb0[inner], nd0[inner], hidden_mask[inner], hidden_rgb[inner], settings.disparity_jump)
        if edge is not None:
            colours, share, shift = edge
            alpha = np.ones((hc, wc), np.float32)
            offset = np.zeros((hc, wc, 2), np.float32)
            rgb0[inner] = colours
            alpha[inner] = share
            offset[inner] = shift
    return LDI(
        rgb=rgb0,
        depth=(NEAR_DEPTH / nd0).astype(np.float32),
        label=label,
        hidden_mask=hidden_mask,
        hidden_rgb=hidden_rgb,
        hidden_depth=hidden_depth,
        fg_edge=fg_c,
        bg_edge=bg_c,
        depth_scale=depth_scale,
        inpainted=bool(hidden_mask.any()),
        settings=settings,
        photo_size=(h, w),
        pad=pad,
        range_scale=cover.scale,
        camera_range=settings.camera_range.scaled(cover.scale),
        hidden_width=float(cover.widths.max()) if cover.widths.size else 0.0,
        alpha=alpha,
        offset=offset,
    )


class _Coverage(NamedTuple):
    """What the hidden layer and the border must cover (see :func:`_coverage`)."""

    widths: np.ndarray  # (H, W) float32 hidden-layer width behind each foreground-edge pixel, 0 elsewhere
    pad: int  # border width in pixels
    scale: float  # fraction of the camera range covered

_SEARCH_EDGES = 1500
"""The range scale is searched on at most this many foreground-edge pixels (evenly picked)."""


def _coverage(nd: np.ndarray, fg: np.ndarray, s: LDISettings, fov: float) -> _Coverage:
    """Hidden-layer width per foreground-edge pixel, border width and the covered range scale.

    Parallax of every edge (front: its own depth; back: the farthest depth within
    3 px) and the border overshoot are measured for the corners of the camera
    range and the trajectories' extremes (:mod:`~stylize3d_core.geometry.camera_range`).
    The range is scaled down (bisection) until both fit their caps.
    """
    h, w = nd.shape
    long_side = max(h, w)
    z = NEAR_DEPTH / nd  # (H, W) scene units
    near = float(np.percentile(z, 1.0))
    centre = max(float(np.median(z)), near)
    band_cap = float(max(2, round(s.band * long_side))) if s.band is not None else s.max_band * long_side
    border_cap = s.border * long_side if s.border is not None else s.max_border * long_side
    if s.cover_trajectories:
        traj_poses, traj_fovs = trajectory_extreme_cameras(fov)
    else:
        traj_poses, traj_fovs = np.zeros((0, 4, 4)), np.zeros(0)

    rows, cols = np.nonzero(fg)
    uv = np.stack([cols + 0.5, rows + 0.5], axis=1).astype(np.float64)  # (E, 2)
    z_front = z[rows, cols].astype(np.float64)
    z_back = (NEAR_DEPTH / np.maximum(cv2.erode(nd, np.ones((7, 7), np.uint8)), 1e-6))[rows, cols].astype(np.float64)
    sides = tuple(np.array([v.min(), v.max()], np.float64) for v in (z[0], z[-1], z[:, 0], z[:, -1]))
    pick = np.linspace(0, len(uv) - 1, min(len(uv), _SEARCH_EDGES)).astype(int) if len(uv) else np.zeros(0, int)

    def viewer(scale: float, idx: np.ndarray) -> Tuple[np.ndarray, float]:
        poses = range_corner_poses(s.camera_range.scaled(scale), centre, near)
        fovs = np.full(len(poses), fov)
        par = edge_parallax(uv[idx], z_front[idx], z_back[idx], poses, fovs, (h, w), fov)
        return par, border_overshoot(sides, poses, fovs, (h, w), fov)

    def excess(scale: float) -> float:
        """Largest ratio of what the range scaled by ``scale`` needs to its cap (<= 1: fits)."""
        par, over = viewer(scale, pick)
        need = float((par * (1.0 + s.hidden_margin) + s.hidden_margin_px).max()) if par.size else 0.0
        return max(need / band_cap, (over + s.hidden_margin_px) / max(border_cap, 1e-9))

    # Parallax and overshoot grow about linearly with the range's scale: start from the
    # linear estimate, then shrink until it fits.
    scale, ratio = 1.0, excess(1.0)
    for _ in range(12):
        if ratio <= 1.0:
            break
        scale *= 0.97 / ratio if ratio < 4.0 else 0.25
        ratio = excess(scale)
    else:
        scale = 0.0
    par, over = viewer(scale, np.arange(len(uv)))
    traj_par = edge_parallax(uv, z_front, z_back, traj_poses, traj_fovs, (h, w), fov)
    traj_over = border_overshoot(sides, traj_poses, traj_fovs, (h, w), fov)
    need = np.maximum(par, traj_par)  # (E,) photo pixels of background a camera can uncover
    if s.band is not None:
        width = np.full(len(uv), band_cap)
    else:
        width = np.minimum(band_cap, need * (1.0 + s.hidden_margin) + s.hidden_margin_px)
        width[need < 1.0] = 0.0  # the jump uncovers less than a pixel: no hidden layer there
    widths = np.zeros((h, w), np.float32)
    widths[rows, cols] = width
    if s.border is not None:
        pad = int(round(border_cap))
    else:
        pad = min(int(round(border_cap)), int(math.ceil(max(over, traj_over) + s.hidden_margin_px)))
    return _Coverage(widths, pad, float(scale))


def _check_rgb(rgb: np.ndarray) -> np.ndarray:
    """(H, W, 3) float32 copy in [0, 1] of a float or uint8 colour image."""
    a = np.asarray(rgb)
    check_shape(a, "rgb", (None, None, 3))
    if a.dtype == np.uint8:
        return a.astype(np.float32) / 255.0
    if not np.issubdtype(a.dtype, np.floating):
        raise InputError("rgb", f"expected float in [0, 1] or uint8, got dtype {a.dtype}")
    if not np.isfinite(a).all():
        raise InputError("rgb", "contains NaN or infinite values")
    lo, hi = float(a.min()), float(a.max())
    if lo < -_RGB_TOLERANCE or hi > 1.0 + _RGB_TOLERANCE:
        raise InputError("rgb", f"float colours must lie in [0, 1], got [{lo:.4g}, {hi:.4g}]")
    return np.clip(a, 0.0, 1.0).astype(np.float32)


def _check_depth(depth: Union[np.ndarray, DepthMap], size: Tuple[int, int]) -> np.ndarray:
    """(H, W) float32 depth, finite and > 0, of the photo's size."""
    source = "depth"
    if isinstance(depth, DepthMap):
        source, depth = depth.source, depth.depth
    z = np.asarray(depth)
    check_shape(z, source, (None, None))
    if tuple(z.shape) != tuple(size):
        raise InputError(source, f"depth size {tuple(z.shape)} does not match the photo's {tuple(size)}")
    if min(size) < MIN_PHOTO_SIDE:
        raise InputError("rgb", f"photo must be at least {MIN_PHOTO_SIDE} x {MIN_PHOTO_SIDE} px, got {size}")
    if not (np.issubdtype(z.dtype, np.floating) or np.issubdtype(z.dtype, np.integer)):
        raise InputError(source, f"expected a numeric depth, got dtype {z.dtype}")
    z = z.astype(np.float32)
    if not np.isfinite(z).all():
        raise InputError(source, "depth contains NaN or infinite values (or exceeds float32)")
    if not (z > 0).all():
        raise InputError(source, "depth must be > 0 everywhere")
    return z
