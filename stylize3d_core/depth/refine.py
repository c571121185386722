"""Align depth edges with image edges; usable on the output of any depth source.

Depth from a file, a network or stereo often has soft or misplaced edges; the
layered depth image tears the surface at depth edges, so a depth edge that does
not sit on the photo's colour edge shows as a halo. Like 3DPhoto (Shih et al.
2020) we sharpen depth with a **bilateral median filter**: every pixel takes the
weighted median of the disparities around it, each neighbour weighted by its
distance and its colour similarity in the photo. A median never averages across
an edge (it picks one side), so a soft edge becomes a step, and the colour
weights move the step onto the photo's edge. A joint bilateral filter and a
guided filter (``cv2.ximgproc``) are offered as faster, smoothing alternatives.

All filters work on disparity (1 / depth), where edges and noise are more
uniform than in depth.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal, Optional

import cv2
import numpy as np

from ..checks import check_choice, check_range, check_shape
from ..errors import InputError
from ._util import check_rgb
from .fill import fill_nearest
from .types import DepthMap

RefineMethod = Literal["bilateral_median", "joint_bilateral", "guided"]
REFINE_METHODS = ("bilateral_median", "joint_bilateral", "guided")


@dataclass(frozen=True)
class RefineSettings:
    """How depth edges are aligned with the photo's edges."""

    method: RefineMethod = "bilateral_median"
    """"bilateral_median" (3DPhoto; sharpens), "joint_bilateral" or "guided" (smooth)."""
    radius: int = 3
    """Window radius in pixels (the window is (2 radius + 1)^2)."""
    sigma_color: float = 0.1
    """Colour scale of the weights (photo values in [0, 1]); for "guided" its square is the eps."""
    sigma_space: Optional[float] = None
    """Spatial scale of the weights in pixels; None = radius (a flat window: the whole same-coloured
    part of the window decides, which moves misplaced edges farthest; unused by "guided")."""
    iterations: int = 1
    """How many times the filter is applied."""

    def __post_init__(self) -> None:
        check_choice(self.method, "refine method", REFINE_METHODS)
        check_range(self.radius, "refine radius", 1, 64)
        if int(self.radius) != self.radius:
            raise InputError("refine radius", f"must be an integer, got {self.radius!r}")
        check_range(self.sigma_color, "refine sigma_color", 0.0, 10.0, inclusive=False)
        if self.sigma_space is not None:
            check_range(self.sigma_space, "refine sigma_space", 0.0, 1e3, inclusive=False)
        check_range(self.iterations, "refine iterations", 1, 20)


def bilateral_median(
    values: np.ndarray,
    guide: np.ndarray,
    radius: int,
    sigma_color: float,
    sigma_space: float,
    weights: Optional[np.ndarray] = None,
    *,
    chunk_rows: int = 64,
) -> np.ndarray:
    """Joint bilateral weighted median.

    Args:
        values: (H, W) float values to filter (e.g. disparity).
        guide: (H, W, C) float guide image (the photo in [0, 1]).
        radius: window radius; the window is clipped at the image border
            (border pixels repeat the edge).
        sigma_color: colour scale: weight ``exp(-|g_p - g_q|^2 / (2 sigma_color^2))``.
        sigma_space: spatial scale: weight ``exp(-|p - q|^2 / (2 sigma_space^2))``.
        weights: optional (H, W) per-pixel confidence in [0, 1] multiplied into
            every neighbour's weight (0 = invalid pixel, never chosen unless its
            whole window is invalid).
        chunk_rows: rows processed at once (bounds memory to about
            ``4 * (2r+1)^2 * chunk_rows * W`` floats).
    Returns:
        (H, W) float32: at each pixel the smallest window value whose cumulative
        weight (values sorted ascending) reaches half the window's total weight.
    """
    h, w = values.shape
    r = int(radius)
    vals = np.pad(values.astype(np.float32), r, mode="edge")  # (H+2r, W+2r)
    gd = np.pad(guide.astype(np.float32), ((r, r), (r, r), (0, 0)), mode="edge")
    conf = None if weights is None else np.pad(weights.astype(np.float32), r, mode="edge")
    offsets = [(dy, dx) for dy in range(-r, r + 1) for dx in range(-r, r + 1)]
    spatial = np.array([np.exp(-(dy * dy + dx * dx) / (2.0 * sigma_space**2)) for dy, dx in offsets], np.float32)
    inv_c = -0.5 / sigma_color**2
    out = np.empty((h, w), np.float32)
    for r0 in range(0, h, chunk_rows):
        r1 = min(h, r0 + chunk_rows)
        centre = gd[r0 + r : r1 + r, r : r + w]  # (n, W, C)
        stack_v = np.empty((r1 - r0, w, len(offsets)), np.float32)  # (n, W, K)
        stack_w = np.empty_like(stack_v)
        for k, (dy, dx) in enumerate(offsets):
            ys = slice(r0 + r + dy, r1 + r + dy)
            xs = slice(r + dx, r + dx + w)
            diff = gd[ys, xs] - centre
            wk = spatial[k] * np.exp(inv_c * np.einsum("ijc,ijc->ij", diff, diff))
            if conf is not None:
                wk = wk * conf[ys, xs]
            stack_v[..., k] = vals[ys, xs]
            stack_w[..., k] = wk
        # Ties may come out in any order: the value picked is the same.
        order = np.argsort(stack_v, axis=-1)
        sorted_v = np.take_along_axis(stack_v, order, axis=-1)
        cum = np.cumsum(np.take_along_axis(stack_w, order, axis=-1), axis=-1)  # (n, W, K)
        # All-zero weights (a window of invalid pixels): plain median instead.
        uniform = cum[..., -1] <= 0
        if uniform.any():
            cum[uniform] = np.arange(1, len(offsets) + 1, dtype=np.float32)
        pick = np.argmax(cum >= 0.5 * cum[..., -1:], axis=-1)  # (n, W)
        out[r0:r1] = np.take_along_axis(sorted_v, pick[..., None], axis=-1)[..., 0]
    return out


def refine_disparity(
    disparity: np.ndarray, rgb: np.ndarray, settings: RefineSettings, valid: Optional[np.ndarray] = None
) -> np.ndarray:
    """Filter a disparity map (H, W) guided by the photo ``rgb`` (H, W, 3); returns (H, W) float32.

    ``valid`` (H, W) bool marks trustworthy pixels: the bilateral median never
    picks an invalid value where valid ones are in reach; the smoothing filters
    see invalid pixels filled from their nearest valid neighbour.
    """
    s = settings
    guide = check_rgb(rgb)
    check_shape(disparity, "disparity", guide.shape[:2])
    d = disparity.astype(np.float32)
    if valid is not None and valid.any() and not valid.all():
        d = fill_nearest(d, valid)
    sigma_space = s.sigma_space if s.sigma_space is not None else float(s.radius)
    for _ in range(s.iterations):
        if s.method == "bilateral_median":
            conf = None if valid is None or not valid.any() else valid.astype(np.float32)
            d = bilateral_median(d, guide, s.radius, s.sigma_color, sigma_space, conf)
        elif s.method == "joint_bilateral":
            d = cv2.ximgproc.jointBilateralFilter(guide, d, 2 * s.radius + 1, s.sigma_color, sigma_space)
        else:  # "guided" (check_choice in RefineSettings rules out anything else)
            d = cv2.ximgproc.guidedFilter(guide, d, s.radius, s.sigma_color**2)
    return d.astype(np.float32)


def refine_depth(depth: DepthMap, rgb: np.ndarray, settings: RefineSettings = RefineSettings()) -> DepthMap:
    """Align the edges of ``depth`` with those of the photo ``rgb`` (H, W, 3).

    Works in disparity and maps back; the result stays finite and positive and
    keeps ``valid``, ``kind`` and the depth range of the input (values are
    clipped to the input's min/max, so refinement never invents a new near or
    far plane). ``source`` gets a " + <method>" suffix.
    """
    if depth.shape != rgb.shape[:2]:
        raise InputError("depth", f"depth {depth.shape} and photo {rgb.shape[:2]} must have the same size")
    lo, hi = float(depth.depth.min()), float(depth.depth.max())
    disp = 1.0 / depth.depth.astype(np.float64)
    d = refine_disparity(disp.astype(np.float32), rgb, settings, depth.valid)
    d = np.clip(np.nan_to_num(d, nan=1.0 / hi, posinf=1.0 / lo, neginf=1.0 / hi), 1.0 / hi, 1.0 / lo)
    out = np.clip(1.0 / d.astype(np.float64), lo, hi).astype(np.float32)
    return replace(depth, depth=out, source=f"{depth.source} + {settings.method}")
