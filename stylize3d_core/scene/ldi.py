"""Layered depth image (LDI): the photo's surface torn at depth edges, plus hidden background.

Stage 3 of the pipeline (docs/architecture.md, "Pipeline stages"), after 3DPhoto (Shih et al. 2020):

1. **Scene units.** The depth is multiplied by ``depth_scale`` so that its 1st
   percentile equals :data:`~stylize3d_core.geometry.camera.NEAR_DEPTH` (1/3).
   Edges are then found on the *normalised disparity* ``nd = NEAR_DEPTH / depth``,
   i.e. the disparity divided by its robust maximum (its 99th percentile): the
   near surface has ``nd`` = 1, as 3DPhoto's disparity normalised by its maximum.
2. **Pre-filter.** A 5-point ("+"-shaped) median on ``nd`` removes single-pixel
   speckle but keeps corners and 2-pixel-wide structures (a 3x3 median would
   round off every corner).
3. **Discontinuities.** Two 4-neighbours whose ``nd`` differs by more than
   ``disparity_jump`` are torn apart: the nearer one is a *foreground-edge*
   pixel, the farther one a *background-edge* pixel. Tiny regions enclosed by
   tears (fewer pixels than the island threshold) are flattened: their depth
   becomes the farthest depth found just outside them, so nothing floats. Edge
   components with fewer foreground-edge pixels than the minimum length are
   then ignored (no tear, no hidden layer).
4. **Hidden layer.** Foreground pixels within ``band`` of a foreground edge that
   are in front of their local background (``nd`` minus its min-filter over the
   band radius > ``disparity_jump``) get a second, hidden sample. Its depth comes
   from *background sources only*: pixels near the edge, outside the band and
   farther than their nearest foreground edge by more than the jump. Every band
   pixel takes the ``nd`` of its nearest source (distance transform), smoothed
   by a small normalised convolution over band and sources, then clamped to lie
   behind the foreground by at least ``disparity_jump``. Its colour comes from
   ``cv2.inpaint`` of the band, after every pixel that is not a source has been
   given its nearest source's colour, so no foreground colour can bleed in.
   Only padded boxes around clusters of edges are processed. With no edge the
   step is skipped (``LDI.inpainted`` is False).
5. **Border.** The canvas is extended by ``pad = round(border * long side)`` on every
   side. Colour: push-pull continuation of the photo (blur grows with the
   distance from the photo, no mirrored seams). Depth: the push-pull continuation
   of ``nd``, never closer than the replicated photo-border pixel.

Coordinates: canvas pixel ``(i, j)`` is photo pixel ``(i - pad, j - pad)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, Optional, Tuple, Union

import cv2
import numpy as np

from ..checks import check_choice, check_range, check_shape
from ..depth.types import DepthMap
from ..errors import InputError
from ..geometry.camera import NEAR_DEPTH
from ..io.images import to_uint8
from ._fill import box_clusters, cross_median, nearest_index, push_pull, ring_min, torn_regions

ORIGINAL = 0
"""Label of a point seen in the photo (layer 0 inside the photo)."""
INPAINTED = 1
"""Label of a hidden-layer point (layer 1: background behind a foreground edge)."""
BORDER = 2
"""Label of a point in the border extension around the photo (layer 0 outside the photo)."""

MIN_PHOTO_SIDE = 16
"""Smallest photo height or width accepted by :func:`build_ldi`, in pixels."""

_RGB_TOLERANCE = 1e-3
"""Float colours may exceed [0, 1] by this much (rounding); they are clipped."""


@dataclass(frozen=True)
class LDISettings:
    """How :func:`build_ldi` tears, fills and extends a photo.

    Lengths given as fractions are fractions of the photo's long side, so the
    result does not depend on the resolution.
    """

    disparity_jump: float = 0.04
    """Tear threshold on the normalised disparity ``nd`` (near surface = 1), as in
    3DPhoto (0.04). Also the least gap between the hidden layer and the foreground."""
    median_filter: bool = True
    """Apply the 5-point median to ``nd`` before looking for edges (speckle removal)."""
    edge_min_length: float = 0.01
    """Edge components shorter than this (in foreground-edge pixels, ~10 px at 1024) are ignored."""
    edge_min_px: int = 4
    """Lower bound of the minimum edge length, in pixels, for small photos."""
    island_area: float = 1e-4
    """Regions enclosed by tears smaller than this fraction of the photo's area
    (~100 px = 10 x 10 at 1 MP) are flattened into their surroundings."""
    island_min_px: int = 9
    """Lower bound of the island threshold in pixels: anything smaller than 3 x 3 is flattened."""
    band: float = 0.04
    """Width of the hidden background layer behind a foreground edge (~41 px at 1024); at least 2 px."""
    border: float = 0.08
    """Border extension on every side (~82 px at 1024); 0 disables it."""
    inpaint_radius: int = 3
    """Neighbourhood radius of ``cv2.inpaint``, in pixels."""
    inpaint_method: Literal["telea", "ns"] = "telea"
    """``cv2.INPAINT_TELEA`` (fast marching) or ``cv2.INPAINT_NS`` (Navier-Stokes)."""

    def __post_init__(self) -> None:
        check_range(self.disparity_jump, "disparity_jump", 0.0, 1.0, inclusive=False)
        check_range(self.edge_min_length, "edge_min_length", 0.0, 1.0)
        check_range(self.edge_min_px, "edge_min_px", 1, 1_000_000)
        check_range(self.island_area, "island_area", 0.0, 0.1)
        check_range(self.island_min_px, "island_min_px", 0, 1_000_000)
        check_range(self.band, "band", 0.0, 0.5)
        check_range(self.border, "border", 0.0, 1.0)
        check_range(self.inpaint_radius, "inpaint_radius", 1, 50)
        check_choice(self.inpaint_method, "inpaint_method", ("telea", "ns"))
        for name in ("edge_min_px", "island_min_px", "inpaint_radius"):
            if int(getattr(self, name)) != getattr(self, name):
                raise InputError(name, f"must be an integer, got {getattr(self, name)!r}")


@dataclass(frozen=True)
class LDI:
    """A two-layer depth image on a canvas of ``(Hc, Wc) = (H + 2 pad, W + 2 pad)``.

    Depths are z in scene units (see ``geometry/camera.py``); canvas pixel
    ``(i, j)`` is photo pixel ``(i - pad, j - pad)``.

    Attributes:
        rgb: (Hc, Wc, 3) float32 in [0, 1], layer 0 (visible surface + border).
        depth: (Hc, Wc) float32 > 0, layer 0.
        label: (Hc, Wc) uint8, :data:`ORIGINAL` inside the photo, :data:`BORDER` outside.
        hidden_mask: (Hc, Wc) bool, True where layer 1 (label :data:`INPAINTED`) exists.
        hidden_rgb: (Hc, Wc, 3) float32 in [0, 1], layer 1 colour (0 where no layer 1).
        hidden_depth: (Hc, Wc) float32, layer 1 depth, > the layer-0 depth where
            ``hidden_mask`` (0 elsewhere).
        fg_edge: (Hc, Wc) bool, near side of a tear.
        bg_edge: (Hc, Wc) bool, far side of a tear.
        depth_scale: the factor that took the input depth to scene units.
        inpainted: False when the hidden-layer step was skipped (no depth edge).
        settings: the settings used.
        photo_size: (H, W) of the photo.
        pad: border width in pixels.
    """

    rgb: np.ndarray
    depth: np.ndarray
    label: np.ndarray
    hidden_mask: np.ndarray
    hidden_rgb: np.ndarray
    hidden_depth: np.ndarray
    fg_edge: np.ndarray
    bg_edge: np.ndarray
    depth_scale: float
    inpainted: bool
    settings: LDISettings
    photo_size: Tuple[int, int]
    pad: int

    @property
    def canvas_size(self) -> Tuple[int, int]:
        """(Hc, Wc) of every canvas map."""
        return (self.photo_size[0] + 2 * self.pad, self.photo_size[1] + 2 * self.pad)

    @property
    def photo_region(self) -> Tuple[slice, slice]:
        """Index ``canvas_map[ldi.photo_region]`` to get the (H, W, ...) photo part."""
        h, w = self.photo_size
        return slice(self.pad, self.pad + h), slice(self.pad, self.pad + w)

    @property
    def num_points(self) -> int:
        """Number of LDI pixels: every canvas pixel of layer 0 plus layer 1."""
        return self.depth.size + int(self.hidden_mask.sum())


def build_ldi(
    rgb: np.ndarray, depth: Union[np.ndarray, DepthMap], settings: LDISettings = LDISettings()
) -> LDI:
    """Build the layered depth image of a photo (see the module docstring).

    Args:
        rgb: (H, W, 3) float in [0, 1], or uint8 (divided by 255).
        depth: (H, W) depth, finite and > 0 (any scale), or a :class:`DepthMap`.
        settings: see :class:`LDISettings`.
    Returns:
        The :class:`LDI`. The inputs are not modified.
    Raises:
        InputError: on a shape mismatch, a non-finite or non-positive depth, colours
            outside [0, 1], or a photo smaller than :data:`MIN_PHOTO_SIDE`.
    """
    if not isinstance(settings, LDISettings):
        raise InputError("settings", f"expected LDISettings, got {type(settings).__name__}")
    image = _check_rgb(rgb)
    z = _check_depth(depth, image.shape[:2])
    h, w = z.shape
    long_side = max(h, w)
    q1 = float(np.percentile(z, 1.0))
    depth_scale = NEAR_DEPTH / q1
    nd = (q1 / z).astype(np.float32)  # (H, W) = NEAR_DEPTH / (depth_scale * z)
    if settings.median_filter:
        nd = cross_median(nd)
    nd, fg, bg = _tear(nd, settings)
    hidden = _hidden_layer(image, nd, fg, settings) if fg.any() else None

    pad = int(round(settings.border * long_side))
    rgb0, nd0 = _extend_border(image, nd, pad)
    hc, wc = h + 2 * pad, w + 2 * pad
    inner = (slice(pad, pad + h), slice(pad, pad + w))
    label = np.full((hc, wc), BORDER, np.uint8)
    label[inner] = ORIGINAL
    hidden_mask = np.zeros((hc, wc), bool)
    hidden_rgb = np.zeros((hc, wc, 3), np.float32)
    hidden_depth = np.zeros((hc, wc), np.float32)
    if hidden is not None:
        mask1, rgb1, nd1 = hidden
        hidden_mask[inner] = mask1
        hidden_rgb[inner][mask1] = rgb1[mask1]
        hidden_depth[inner][mask1] = NEAR_DEPTH / nd1[mask1]
    fg_c = np.zeros((hc, wc), bool)
    bg_c = np.zeros((hc, wc), bool)
    fg_c[inner], bg_c[inner] = fg, bg
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
    )


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


def _edges(nd: np.ndarray, jump: float) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Signed neighbour differences and cut maps: dx (H, W-1), dy (H-1, W), cut_h, cut_v."""
    dx = nd[:, 1:] - nd[:, :-1]
    dy = nd[1:, :] - nd[:-1, :]
    return dx, dy, np.abs(dx) > jump, np.abs(dy) > jump


def _tear(nd: np.ndarray, s: LDISettings) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flatten tiny islands, then find the foreground / background edge maps (H, W)."""
    h, w = nd.shape
    dx, dy, cut_h, cut_v = _edges(nd, s.disparity_jump)
    min_area = max(s.island_min_px, s.island_area * h * w)
    for _ in range(2):  # a second pass catches islands left behind by the first
        if not (cut_h.any() or cut_v.any()):
            break
        graph = torn_regions(cut_h, cut_v)
        small = graph.areas < min_area  # (R,)
        small[0] = False  # label 0 is unused
        if not small.any():
            break
        fill = ring_min(nd, graph.labels, small)  # (R,)
        small &= np.isfinite(fill)
        if not small.any():
            break
        flat = small[graph.labels]  # (H, W)
        nd = nd.copy()
        nd[flat] = fill[graph.labels[flat]]
        dx, dy, cut_h, cut_v = _edges(nd, s.disparity_jump)

    fg = np.zeros((h, w), bool)
    bg = np.zeros((h, w), bool)
    if not (cut_h.any() or cut_v.any()):
        return nd, fg, bg
    t = s.disparity_jump
    fg[:, 1:] |= dx > t
    bg[:, :-1] |= dx > t
    fg[:, :-1] |= dx < -t
    bg[:, 1:] |= dx < -t
    fg[1:, :] |= dy > t
    bg[:-1, :] |= dy > t
    fg[:-1, :] |= dy < -t
    bg[1:, :] |= dy < -t

    min_len = max(s.edge_min_px, s.edge_min_length * max(h, w))
    n, lab = cv2.connectedComponents((fg | bg).astype(np.uint8), connectivity=8, ltype=cv2.CV_32S)
    length = np.bincount(lab[fg], minlength=n)  # (n,) foreground-edge pixels per component
    keep = length >= min_len
    keep[0] = False
    kept = keep[lab]  # (H, W)
    return nd, fg & kept, bg & kept


def _hidden_layer(
    rgb: np.ndarray, nd: np.ndarray, fg: np.ndarray, s: LDISettings
) -> Optional[Tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Hidden background behind the foreground edges.

    Returns:
        mask (H, W) bool, rgb (H, W, 3) float32 and nd (H, W) float32 of layer 1
        (valid where mask), or None when no band pixel was found.
    """
    h, w = nd.shape
    t = s.disparity_jump
    band_px = max(2, int(round(s.band * max(h, w))))
    reach = band_px + 2 * s.inpaint_radius + 2  # background sources are looked for this far
    window = np.ones((2 * band_px + 3, 2 * band_px + 3), np.uint8)
    sigma = max(1.0, band_px / 8.0)  # smoothing of the hidden depth, in pixels
    flag = cv2.INPAINT_TELEA if s.inpaint_method == "telea" else cv2.INPAINT_NS

    mask = np.zeros((h, w), bool)
    out_rgb = np.zeros((h, w, 3), np.float32)
    out_nd = np.zeros((h, w), np.float32)
    for rows, cols, members in box_clusters(fg, reach + 2):
        ndc = nd[rows, cols]  # (h, w)
        rgbc = rgb[rows, cols]  # (h, w, 3)
        not_edge = np.where(members, 0, 255).astype(np.uint8)
        dist = cv2.distanceTransform(not_edge, cv2.DIST_L2, 5)  # (h, w) to the nearest edge pixel
        ref = ndc[members][nearest_index(members)]  # (h, w) nd of the nearest foreground-edge pixel
        local_min = cv2.erode(ndc, window)  # (h, w) farthest nd within the band radius
        band = (dist <= band_px) & (ndc - local_min > t)
        if not band.any():
            continue
        near = (dist <= reach) & ~band
        source = near & (ndc < ref - t)  # clearly behind the nearest foreground edge
        if not source.any():  # degenerate: nothing clearly behind; use the local background
            source = near & (ndc <= local_min + t)
        if not source.any():
            source = ~band
        # every pixel takes the values of its nearest background source (no foreground can leak)
        nearest = nearest_index(source)  # (h, w)
        bg_nd = ndc[source][nearest]  # (h, w)
        bg_rgb = rgbc[source][nearest]  # (h, w, 3)
        # smooth the Voronoi seams of that fill within band + sources (normalised convolution)
        weight = (band | source).astype(np.float32)
        blur_nd = cv2.GaussianBlur(bg_nd * weight, (0, 0), sigma) / np.maximum(
            cv2.GaussianBlur(weight, (0, 0), sigma), 1e-6
        )
        behind = np.minimum(blur_nd, ndc - t)  # (h, w) strictly behind the foreground
        context = np.where(source[..., None], rgbc, bg_rgb)  # background-only colours
        context8 = to_uint8(context)
        colour = cv2.inpaint(context8, band.astype(np.uint8), s.inpaint_radius, flag)
        sub_mask = mask[rows, cols]
        sub_mask |= band
        out_rgb[rows, cols][band] = colour[band].astype(np.float32) / 255.0
        out_nd[rows, cols][band] = behind[band]
    if not mask.any():
        return None
    return mask, out_rgb, out_nd


def _extend_border(rgb: np.ndarray, nd: np.ndarray, pad: int) -> Tuple[np.ndarray, np.ndarray]:
    """Canvas colour (Hc, Wc, 3) and normalised disparity (Hc, Wc) with a border of ``pad``."""
    if pad == 0:
        return rgb.copy(), nd.copy()
    h, w = nd.shape
    values = np.zeros((h + 2 * pad, w + 2 * pad, 4), np.float32)
    weight = np.zeros((h + 2 * pad, w + 2 * pad), np.float32)
    inner = (slice(pad, pad + h), slice(pad, pad + w))
    values[inner] = np.concatenate([rgb, nd[..., None]], axis=2)
    weight[inner] = 1.0
    filled = push_pull(values, weight)  # (Hc, Wc, 4)
    replicated = cv2.copyMakeBorder(nd, pad, pad, pad, pad, cv2.BORDER_REPLICATE)
    nd_c = np.minimum(filled[..., 3], replicated)  # never nearer than the photo's border pixel
    rgb_c = np.clip(filled[..., :3], 0.0, 1.0)
    rgb_c[inner] = rgb
    nd_c[inner] = nd
    return np.ascontiguousarray(rgb_c), np.ascontiguousarray(nd_c)
