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
4. **Coverage.** How much hidden background each edge can show is measured,
   not assumed: for every foreground-edge pixel (front depth, and the farthest
   depth within 3 px behind it) the parallax ``|uv'(front) - uv'(back)|`` is
   computed for the extreme cameras of ``camera_range`` (the viewer's range)
   and of the default trajectories (``geometry/camera_range.py``); for a
   sideways move ``b`` it is ``b f |1/z_near - 1/z_far|``. The edge's hidden
   layer is that wide plus a margin, capped at ``max_band``, and absent where
   the parallax is under a pixel. The border is as wide as those cameras see
   beyond the frame (at the depths found along each side), capped at
   ``max_border``. Where the caps bind, the range is scaled down until it fits
   and the LDI reports the covered fraction (``range_scale``, ``camera_range``).
5. **Hidden layer.** Foreground pixels within their nearest edge's width of it
   that are in front of their local background (``nd`` minus its min-filter
   over that radius > ``disparity_jump``) and not clearly behind that edge get a
   second, hidden sample. Its depth and colour come from *background sources
   only*: pixels near the edge, outside the band, farther than their nearest
   foreground edge by more than the jump, and more than ``edge_exclusion_px``
   from any tear (the pixels at a tear mix foreground and background colours).
   Depth and colour (``hidden_depth="surface"``, ``inpaint_method="linear"``):
   the local linear fit of ``nd`` (affine on a plane) and of the colour at a
   source, anchored at the source's own value where the fit explains its
   neighbourhood, continued to the pixel (steps capped at one jump and at
   ``max_colour_step``, the colour gradient damped on noise-like texture): from
   the nearest source, or, where the sources on opposite sides of the pixel
   along its row or column continue to the same surface and that surface is not
   the nearest source's, the inverse-squared-distance blend of the sources on
   it (the ground behind a card that hides the ground / wall crease). Those
   pixels, and the others between the same two sources, take their colour
   where the texture's isophotes through them meet the gap's two sides (the
   sides' profiles matched for the shift an isophote makes across the gap), not
   straight along the row or column. The depth
   is then smoothed by a small normalised convolution and
   clamped to lie behind the foreground by at least ``disparity_jump``; the
   colour, background-only, never takes a foreground pixel's, so no foreground
   colour can bleed in. **Layer 0 keeps the photo's colour and depth** (the photo
   seen from its own camera stays the photo) **but on the silhouettes' background
   side** (``unmix_silhouettes``): a pixel just outside a foreground edge the
   hidden layer covers holds the anti-aliased mix of the foreground's colour and
   the background's, which, left at the background's depth, stays behind as a
   ghost outline when the foreground moves. It loses the foreground's share (its
   colour's projection on foreground minus background, the background continued
   from the sources like the hidden layer's, the foreground the pixel two steps
   across the tear), where it is such a mix; a pixel that is mostly foreground
   across a colour edge (the depth's edge inside the colour's) joins the
   foreground instead, with its colour, and the hidden layer gets the background
   behind it. Only padded boxes around clusters of
   edges are processed, and the fits are solved only at the sources some band
   pixel continues (its nearest, and its nearest along its row and column: a
   thin rim of the sources), where few, by summing their Gaussian windows
   directly rather than blurring the box. With no edge the step is skipped
   (``LDI.inpainted`` is False).
6. **Border.** The canvas is extended by ``pad`` pixels on every side (step 4).
   Colour: push-pull continuation of the photo (blur grows with the distance
   from the photo, no mirrored seams). Depth: the push-pull continuation of
   ``nd``, never closer than the replicated photo-border pixel. With
   ``border_hidden`` (default), where a foreground edge comes within ``pad`` of
   the frame, border pixels whose layer 0 continues a foreground cut by the
   frame's edge get a hidden sample: the photo's background alone continued
   the same way.

Coordinates: canvas pixel ``(i, j)`` is photo pixel ``(i - pad, j - pad)``.
"""

from __future__ import annotations

import math

from dataclasses import dataclass, field
from typing import Literal, NamedTuple, Optional, Tuple, Union

import cv2
import numpy as np

from ..checks import check_choice, check_range, check_shape
from ..depth.types import DepthMap
from ..errors import InputError
from ..geometry.camera import DEFAULT_FOV_Y_DEG, NEAR_DEPTH, check_fov
from ..geometry.camera_range import (
    CameraRange, border_overshoot, edge_parallax, range_corner_poses, trajectory_extreme_cameras,
)
from ..io.images import to_uint8
from ..threads import beside, halves
from ._fill import (
    ACROSS_REACH as _ACROSS_REACH, LinearFit, across_gap, anchored, box_clusters, continue_at, cross_median, extrapolate, local_linear_fit,
    nearest_index, push_pull, ring_min, scan_nearest, split_fit, torn_regions,
)

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
    band: Optional[float] = None
    """Width of the hidden background layer behind a foreground edge. None (default): sized,
    edge by edge, for what the cameras of ``camera_range`` (and the default trajectories)
    can uncover there: ``parallax * (1 + hidden_margin) + hidden_margin_px`` photo pixels,
    none where that parallax is under a pixel, at most ``max_band``. A number: that fixed
    fraction of the long side at every edge (at least 2 px)."""
    border: Optional[float] = None
    """Border extension on every side. None (default): as far beyond the frame as the cameras
    of ``camera_range`` (and the default trajectories) see, plus ``hidden_margin_px``, at most
    ``max_border``. A number: that fixed fraction of the long side; 0 disables it."""
    camera_range: CameraRange = field(default_factory=CameraRange)
    """The interactive camera range the hidden layer and the border are sized for (the viewer's).
    Where covering all of it would need more than ``max_band`` / ``max_border``, the LDI covers
    the largest scaled-down part (``LDI.range_scale``, ``LDI.camera_range``)."""
    cover_trajectories: bool = True
    """Also size the layer and the border for the extremes of the default trajectories."""
    max_band: float = 0.12
    """Cap of the sized hidden layer, as a fraction of the long side (~123 px at 1024)."""
    max_border: float = 0.15
    """Cap of the sized border, as a fraction of the long side (~154 px at 1024)."""
    hidden_margin: float = 0.1
    """Relative margin added to the parallax when sizing the hidden layer."""
    hidden_margin_px: float = 2.0
    """Margin in pixels added to the sized hidden layer and border."""
    edge_exclusion_px: int = 1
    """Pixels this close to a tear (either side) never give colour to the hidden layer: they
    hold anti-aliased mixtures of foreground and background (and absorb small misalignments
    of the depth edge with the colour edge)."""
    inpaint_radius: int = 3
    """Neighbourhood radius of ``cv2.inpaint``, in pixels."""
    inpaint_method: Literal["linear", "telea", "ns", "push_pull"] = "linear"
    """Colour of the hidden layer: ``"linear"``: every hidden pixel continues the local linear
    fit (colour and its gradient, over ``fit_sigma``) of its nearest background source, the
    step limited to ``max_colour_step``; ``cv2.INPAINT_TELEA`` (fast marching) or
    ``cv2.INPAINT_NS`` (Navier-Stokes) from the background sources; or ``"push_pull"``: their
    multi-scale blend alone (smooth, no streaks)."""
    hidden_depth: Literal["surface", "plane", "nearest"] = "surface"
    """Depth of the hidden layer: ``"surface"`` (default): the surface that runs on behind the
    foreground, where the background sources on opposite sides of a hidden pixel (the nearest
    along its row, left and right, or along its column, above and below) continue their local
    planes to the same disparity; those sources (and any other on that surface) are blended by
    inverse squared distance, depth and colour. A card hiding the crease where a ground meets a
    wall then has the ground behind it, continued from its sides, not the wall continued down from
    above the card. Elsewhere (no agreeing pair, or the agreeing surface is the nearest source's
    own) it is ``"plane"``. (The *nearest* of the four continued planes would not do: on estimated
    depth a receding table's plane continued from its near side comes out in front of the table,
    and a hidden layer in front of the background beside it tears from it.) ``"plane"``: the local plane of
    the nearest background source continued (a linear fit of the disparity ``1/z`` over
    ``fit_sigma``, which is affine on a plane), so a ground plane's hidden part stays on the
    ground; ``"nearest"``: the disparity of the nearest background source (flat behind every
    edge pixel)."""
    fit_sigma: float = 2.0
    """Radius (pixels) of the local linear fits of the background behind an edge."""
    border_hidden: bool = True
    """Give the border a hidden layer behind foreground that the frame's edge cuts (the
    background continued past the frame), so a camera looking past the edge sees no hole
    behind, e.g., a tower cut by the frame: rocket's holes at the dolly zoom's widened FOV
    0.202 % -> 0.070 % (+11 % points). Only as wide as the border, which is sized for the
    camera range; a smooth slanted surface reaching the frame's edge may get a needless
    hidden layer there."""
    max_colour_step: float = 0.05
    """Largest change the colour's gradient may bring, per channel (in [0, 1] colour units)."""
    unmix_silhouettes: bool = True
    """Take the foreground's share out of layer 0's background-side pixels at the tears the hidden
    layer covers (:func:`unmix_silhouette`): an anti-aliased silhouette's pixel just outside the
    foreground mixes its colour with the background's, and, left at the background's depth, that
    mix stays behind as a ghost outline when the foreground moves. False: layer 0 keeps the
    photo's colours everywhere."""
    subpixel_silhouettes: bool = True
    """Give the foreground's silhouette pixels that have the hidden layer behind them the share of the
    pixel they cover (:func:`subpixel_edges`): an anti-aliased silhouette pixel becomes a point with the
    foreground's colour, an opacity (``LDI.alpha``) and a position moved inwards by the part it does not
    cover (``LDI.offset``), shown over the hidden background by renderers that blend coverage (the plain
    renderer). Its silhouette then moves with sub-pixel accuracy instead of as whole pixels of mixed
    colour (``tests/scene/test_novel_view_analytic.py`` measures it against a ray-cast truth). False: every layer-0 point opaque at its pixel's centre."""

    def __post_init__(self) -> None:
        check_range(self.disparity_jump, "disparity_jump", 0.0, 1.0, inclusive=False)
        check_range(self.edge_min_length, "edge_min_length", 0.0, 1.0)
        check_range(self.edge_min_px, "edge_min_px", 1, 1_000_000)
        check_range(self.island_area, "island_area", 0.0, 0.1)
        check_range(self.island_min_px, "island_min_px", 0, 1_000_000)
        if self.band is not None:
            check_range(self.band, "band", 0.0, 0.5)
        if self.border is not None:
            check_range(self.border, "border", 0.0, 1.0)
        if not isinstance(self.camera_range, CameraRange):
            raise InputError("camera_range", f"expected a CameraRange, got {type(self.camera_range).__name__}")
        check_range(self.max_band, "max_band", 0.0, 0.5)
        check_range(self.max_border, "max_border", 0.0, 1.0)
        check_range(self.hidden_margin, "hidden_margin", 0.0, 10.0)
        check_range(self.hidden_margin_px, "hidden_margin_px", 0.0, 1000.0)
        check_range(self.edge_exclusion_px, "edge_exclusion_px", 0, 100)
        check_range(self.inpaint_radius, "inpaint_radius", 1, 50)
        check_choice(self.inpaint_method, "inpaint_method", ("linear", "telea", "ns", "push_pull"))
        check_choice(self.hidden_depth, "hidden_depth", ("surface", "plane", "nearest"))
        check_range(self.fit_sigma, "fit_sigma", 0.5, 50.0)
        check_range(self.max_colour_step, "max_colour_step", 0.0, 1.0)
        for name in ("unmix_silhouettes", "subpixel_silhouettes"):
            if not isinstance(getattr(self, name), bool):
                raise InputError(name, f"expected a bool, got {getattr(self, name)!r}")
        for name in ("edge_min_px", "island_min_px", "inpaint_radius", "edge_exclusion_px"):
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
        bg_edge: (Hc, Wc) bool, far side of a tear (as torn: a pixel there that joined the
            foreground, ``unmix_silhouettes``, stays marked).
        depth_scale: the factor that took the input depth to scene units.
        inpainted: False when the hidden-layer step was skipped (no depth edge).
        settings: the settings used.
        photo_size: (H, W) of the photo.
        pad: border width in pixels.
        range_scale: the fraction (in [0, 1]) of ``settings.camera_range`` the hidden
            layer and the border cover (1: all of it; less where the photo's depth
            jumps would need more than ``max_band`` / ``max_border``).
        camera_range: ``settings.camera_range.scaled(range_scale)``: the range this
            LDI shows without holes (the viewer's limits should not exceed it).
        hidden_width: widest hidden layer behind any edge, in photo pixels (0 without one).
        alpha: (Hc, Wc) float32 in (0, 1], layer 0's opacity: below 1 at the foreground's anti-aliased
            silhouette pixels (``subpixel_silhouettes``), which have the hidden layer behind them; None:
            every pixel opaque.
        offset: (Hc, Wc, 2) float32, layer 0's point positions relative to their pixel's centre, in
            pixels (x, y), at most 0.5: a silhouette pixel's point moves inwards by half of the part it
            does not cover; None: every point at its pixel's centre.
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
    range_scale: float = 1.0
    camera_range: CameraRange = field(default_factory=CameraRange)
    hidden_width: float = 0.0
    alpha: Optional[np.ndarray] = None
    offset: Optional[np.ndarray] = None

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
    def near_depth(self) -> float:
        """Depth of the photo's near surface: the 1st percentile of its layer-0 depth (scene units)."""
        return float(np.percentile(self.depth[self.photo_region], 1.0))

    @property
    def centre_depth(self) -> float:
        """Depth of the orbit centre: the median of the photo's layer-0 depth (scene units)."""
        return max(float(np.median(self.depth[self.photo_region])), self.near_depth)

    @property
    def num_points(self) -> int:
        """Number of LDI pixels: every canvas pixel of layer 0 plus layer 1."""
        return self.depth.size + int(self.hidden_mask.sum())


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
    long_side = max(h, w)
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


_DEPTH_SIGMA = 1.0
"""Smoothing (pixels) of the hidden layer's continued depth: the seams between sources only. Wider
smoothing would blur the crease of a ground meeting a wall behind a card: the hidden points near the
crease would come out between the two planes and show the rows beside theirs from a moved camera."""

_DEPTH_RIDGE = 0.25
_COLOUR_RIDGE = 0.02
"""Ridge of the local linear fits of the background's disparity and colour (relative to
``fit_sigma**2``): small, so a continued plane keeps its slope (a shrunk slope would bring a
receding floor continued from below in front of the true one)."""

_DEPTH_STEP = 1.0
"""A continued background plane changes the disparity by at most this many ``disparity_jump``
(an estimated depth's gentle slopes, continued far, would open gaps in the hidden layer)."""

_SAME_SURFACE = 0.25
"""Continued background planes within this many ``disparity_jump`` of the nearest one are taken
for the same surface (the closest source of them gives the hidden pixel its colour)."""

_JOIN = 0.1
"""With ``hidden_depth="surface"``, a source joins the surface its row's or column's agreeing pair
continues when its own plane comes within this many ``disparity_jump`` of it (the wall just above
a card where the wall runs on behind it; not where the ground has already turned away from it)."""

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
    rgb: np.ndarray, nd: np.ndarray, fg: np.ndarray, bg: np.ndarray, widths: np.ndarray, s: LDISettings
) -> Optional[Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """Hidden background behind the foreground edges, ``widths`` (H, W) pixels wide behind each.

    Returns:
        mask (H, W) bool, rgb (H, W, 3) float32 and nd (H, W) float32 of layer 1
        (valid where mask), and, with ``unmix_silhouettes``, the layer-0 pixels beside those
        edges on their background side that keep the background's depth (H, W) bool, their
        colours without the foreground's share (H, W, 3) float32 (see :func:`unmix_silhouette`),
        and the layer-0 nd (H, W) float32 of those that join the foreground instead (0
        elsewhere; layer 1 holds the background behind them); None when no band pixel was found.
    """
    h, w = nd.shape
    t = s.disparity_jump
    edges = fg & (widths > 0)
    max_width = int(math.ceil(widths.max()))
    flag = cv2.INPAINT_NS if s.inpaint_method == "ns" else cv2.INPAINT_TELEA
    ex = s.edge_exclusion_px
    exclusion = np.ones((2 * ex + 1, 2 * ex + 1), np.uint8)

    mask = np.zeros((h, w), bool)
    out_rgb = np.zeros((h, w, 3), np.float32)
    out_nd = np.zeros((h, w), np.float32)
    mask0 = np.zeros((h, w), bool)
    out_rgb0 = np.zeros((h, w, 3), np.float32)
    fore = np.zeros((h, w), np.float32)  # layer 0's new nd where a pixel joins the foreground (0 elsewhere)
    for rows, cols, members in box_clusters(edges, max_width + 2 * s.inpaint_radius + ex + 4):
        ndc = nd[rows, cols]  # (h, w)
        rgbc = rgb[rows, cols]  # (h, w, 3)
        nearest_edge = nearest_index(members)  # (h, w)
        width = widths[rows, cols][members][nearest_edge]  # (h, w) width behind the nearest edge pixel
        band_px = int(math.ceil(width.max()))
        reach = band_px + 2 * s.inpaint_radius + ex + 2  # background sources are looked for this far
        not_edge = np.where(members, 0, 255).astype(np.uint8)
        dist = cv2.distanceTransform(not_edge, cv2.DIST_L2, 5)  # (h, w) to the nearest edge pixel
        ref = ndc[members][nearest_edge]  # (h, w) nd of the nearest foreground-edge pixel
        local_min = cv2.erode(ndc, np.ones((2 * band_px + 3, 2 * band_px + 3), np.uint8))  # farthest nd nearby
        # foreground side only: a pixel clearly behind its nearest foreground edge is background,
        # unless it is the foreground of an edge of its own nearby (a middle layer: a tower's
        # base behind a pole, before the sky)
        window = np.ones((2 * band_px + 1, 2 * band_px + 1), np.uint8)
        own_fg = cv2.erode(np.where(members, ndc, np.float32(1e9)).astype(np.float32), window)  # (h, w)
        band = (dist <= width) & (width > 0) & (ndc - local_min > t) & ((ndc >= ref - t) | (own_fg <= ndc + t))
        if not band.any():
            continue
        # Anti-aliased pixels on either side of a tear mix foreground and background colours.
        mixed = cv2.dilate((fg[rows, cols] | bg[rows, cols]).astype(np.uint8), exclusion) > 0 if ex else members
        near = (dist <= reach) & ~band
        source = near & (ndc < ref - t) & ~mixed  # clearly behind the nearest foreground edge
        if not source.any():  # degenerate: nothing clearly behind; use the local background
            source = near & (ndc <= local_min + t) & ~mixed
        if not source.any():
            source = ~band & ~mixed
        if not source.any():
            source = ~band
        # every pixel takes the values of its nearest background source (no foreground can leak)
        nearest = nearest_index(source)  # (h, w)
        scan = scan_nearest(source, where=band) if s.hidden_depth == "surface" else None  # (4, N, 2)
        # layer 0's pixels just outside these edges (a 4-neighbour of one of them), on the background
        # side: their background colour is continued the same way, from the sources
        outside = (bg[rows, cols] & (dist < 1.5) & ~band) if s.unmix_silhouettes else np.zeros_like(band)
        # the fits are continued only from the sources some band pixel takes: its nearest, and in
        # "surface" mode the nearest along its row and column (a thin rim of the sources)
        used = _used_sources(nearest, source, band | outside, scan)
        srcw = source.astype(np.float32)
        lo = 0.5 * float(ndc[source].min())  # never much farther than anything seen
        want_nd, want_rgb = s.hidden_depth != "nearest", s.inpaint_method == "linear"
        nd_fit = col_fit = None
        if want_nd and want_rgb:  # one fit of the four channels (shared position moments)
            values = np.concatenate([ndc[..., None], rgbc], axis=2)
            both = local_linear_fit(values, srcw, s.fit_sigma, ridge=(_DEPTH_RIDGE,) + (_COLOUR_RIDGE,) * 3,
                                    damp=(False, True, True, True), where=used)
            both = anchored(both, values, where=used)
            nd_fit, col_fit = split_fit(both, slice(0, 1)), split_fit(both, slice(1, 4))
        elif want_nd:
            nd_fit = local_linear_fit(ndc[..., None], srcw, s.fit_sigma, ridge=_DEPTH_RIDGE, where=used)
        elif want_rgb:
            col_fit = local_linear_fit(rgbc, srcw, s.fit_sigma, ridge=_COLOUR_RIDGE, damp=True, where=used)
        if nd_fit is not None:  # continue the background's local plane (nd is affine on it)
            bg_nd = np.maximum(extrapolate(nd_fit, nearest, source, _DEPTH_STEP * s.disparity_jump, band)[..., 0], lo)
            bg_nd = np.where(source, ndc, bg_nd)
        else:
            bg_nd = ndc[source][nearest]  # (h, w)
        chosen_rgb = None
        if s.hidden_depth == "surface":
            bg_nd, chosen_rgb = _nearest_surface(nd_fit, col_fit, source, band, ndc, bg_nd, lo, s, scan, nearest, rgbc)
        # smooth the seams of that fill within band + sources (normalised convolution)
        weight = (band | source).astype(np.float32)
        blur_nd = cv2.GaussianBlur(bg_nd * weight, (0, 0), _DEPTH_SIGMA) / np.maximum(
            cv2.GaussianBlur(weight, (0, 0), _DEPTH_SIGMA), 1e-6
        )
        behind = np.minimum(blur_nd, ndc - t)  # (h, w) strictly behind the foreground
        # The hidden layer is background-only (layer 0's pixels beside the edges: below).
        todo = band
        if chosen_rgb is not None:  # chosen with the surface
            colour = np.zeros(rgbc.shape, np.float32)
            colour[band] = chosen_rgb
        elif col_fit is not None:  # the background's colour and its gradient continued
            colour = np.clip(extrapolate(col_fit, nearest, source, s.max_colour_step, todo), 0.0, 1.0)
        elif s.inpaint_method == "push_pull":  # a multi-scale blend of the background sources
            colour = push_pull(rgbc, source.astype(np.float32))
        else:
            context = np.where(source[..., None], rgbc, rgbc[source][nearest])  # background-only colours
            colour = cv2.inpaint(to_uint8(context), todo.astype(np.uint8), s.inpaint_radius, flag)
            colour = colour.astype(np.float32) / 255.0
        sub_mask = mask[rows, cols]
        sub_mask |= band
        out_rgb[rows, cols][band] = colour[band]
        out_nd[rows, cols][band] = behind[band]
        if outside.any():
            pr, pc = np.nonzero(outside)
            if col_fit is not None:
                background = np.clip(extrapolate(col_fit, nearest, source, s.max_colour_step, outside)[pr, pc], 0.0, 1.0)
            else:
                background = rgbc[source][nearest[pr, pc]]  # the nearest source's colour
            unmixed, share, fore_rgb, fore_nd = unmix_silhouette(rgbc, ndc, (pr, pc), background, t)
            # mostly foreground (the depth's edge lies inside the colour's) across a colour edge: the
            # pixel joins the foreground with its colour, and the hidden layer gets the background
            # behind it
            edge = ((fore_rgb - background) ** 2).mean(axis=1) >= _JOIN_CONTRAST ** 2
            joins = (share > _JOIN_FOREGROUND) & edge  # (N,)
            gr, gc = pr + rows.start, pc + cols.start  # in the photo
            mask0[gr[~joins], gc[~joins]] = True
            out_rgb0[gr[~joins], gc[~joins]] = unmixed[~joins]
            j = gr[joins], gc[joins]
            fore[j] = fore_nd[joins]
            mask[j] = True
            out_rgb[j] = background[joins]
            out_nd[j] = ndc[pr[joins], pc[joins]]
    if not mask.any():
        return None
    return mask, out_rgb, out_nd, mask0, out_rgb0, fore


_JOIN_FOREGROUND = 0.5
"""A background-side silhouette pixel whose foreground share (:func:`unmix_silhouette`) exceeds this
is mostly foreground (the depth's edge lies inside the colour's): it joins the foreground."""

_JOIN_CONTRAST = 0.1
"""... and only where the foreground's and the background's colours differ by at least this (RMS over
the channels): a colour edge, not texture that happens to resemble the foreground."""

_MIX_RESIDUAL = 0.25
"""A background-side silhouette pixel is taken for a mix of ``F`` and ``B`` (:func:`unmix_silhouette`)
where its colour lies within this fraction of ``|F - B|`` of the segment between them."""

_UNMIX_CONTRAST = 0.03
"""Colour contrast (per channel, RMS) below which :func:`unmix_silhouette`'s foreground share fades
out: its regulariser, so a low-contrast edge's texture is not taken for a mix."""


def unmix_silhouette(
    rgb: np.ndarray, nd: np.ndarray, pixels: Tuple[np.ndarray, np.ndarray], background: np.ndarray, jump: float
) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Take the foreground's share out of background-side silhouette pixels.

    At an anti-aliased silhouette the pixel just outside the foreground holds
    ``c = a F + (1 - a) B``: a share ``a`` of the foreground's colour ``F`` (it covers that
    much of the pixel) over the background's ``B``. Each of ``pixels`` (a background pixel
    with a nearer 4-neighbour across a tear) takes ``F`` from the foreground across the
    tear (the pixel two steps in where it is on the same surface as the one beside the
    tear, which may itself be mixed; else that one; averaged over the tears' directions)
    and ``B`` from ``background`` (estimated from background-only sources), and loses
    ``a (F - B)``, where ``a`` is its colour's projection on ``F - B``
    (``<c - B, F - B> / (|F - B|^2 + 3 * _UNMIX_CONTRAST^2)``, in [0, 1]), where it is such
    a mix (within ``_MIX_RESIDUAL |F - B|`` of the segment from ``B`` to ``F``; texture
    elsewhere). Only the part of its colour along ``F - B`` changes: what remains is the
    background's own texture.

    Args:
        rgb: (h, w, 3) float32 colours.
        nd: (h, w) float32 normalised disparity (larger is nearer).
        pixels: (rows, cols), N pixels to unmix.
        background: (N, 3) float32, their estimated background colour.
        jump: the tear threshold on ``nd``.
    Returns:
        ``(colours, share, fore, fore_nd)`` of the N pixels: (N, 3) float32 in [0, 1], their
        colours with the foreground's share taken out; (N,) float32, that share ``a`` (0 where
        the colour is no mix or no tear is found); (N, 3) float32 ``F``; (N,) float32, the ``nd``
        of the nearest neighbour across a tear (0 where none).
    """
    h, w = nd.shape
    rows, cols = (np.asarray(x, np.int64) for x in pixels)
    c = rgb[rows, cols]  # (N, 3)
    own = nd[rows, cols]  # (N,)
    fore = np.zeros(c.shape, np.float32)
    fore_nd = np.zeros(own.shape, np.float32)
    count = np.zeros(own.shape, np.float32)
    for di, dj in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        r1, c1 = rows + di, cols + dj  # the neighbour across
        inside = (r1 >= 0) & (r1 < h) & (c1 >= 0) & (c1 < w)
        r1, c1 = np.clip(r1, 0, h - 1), np.clip(c1, 0, w - 1)
        across = inside & (nd[r1, c1] - own > jump)  # (N,) a tear with a nearer pixel that way
        if not across.any():
            continue
        r2, c2 = np.clip(r1 + di, 0, h - 1), np.clip(c1 + dj, 0, w - 1)  # two steps in (the edge's, at the box's side)
        inner = np.abs(nd[r2, c2] - nd[r1, c1]) <= jump
        f = np.where(inner[:, None], rgb[r2, c2], rgb[r1, c1])  # (N, 3)
        fore[across] += f[across]
        fore_nd[across] = np.maximum(fore_nd[across], nd[r1, c1][across])
        count[across] += 1.0
    ok = count > 0  # (N,)
    fore[ok] /= count[ok, None]
    diff = fore - background  # (N, 3) F - B
    share = np.clip(((c - background) * diff).sum(-1) / ((diff * diff).sum(-1) + 3 * _UNMIX_CONTRAST ** 2), 0.0, 1.0)
    # a mix lies on the segment from B to F: far from it, the pixel is texture, not a mix
    residual = c - background - share[:, None] * diff
    mixes = (residual * residual).sum(-1) <= _MIX_RESIDUAL ** 2 * (diff * diff).sum(-1)
    share = np.where(ok & mixes, share, 0.0).astype(np.float32)  # (N,)
    out = np.clip(c - share[:, None] * diff, 0.0, 1.0).astype(np.float32)
    return out, share, fore, fore_nd


_EDGE_MIN_SHARE = 0.1
"""Least share of its pixel a silhouette point keeps (:func:`subpixel_edges`): a pixel at the
foreground's depth whose colour is almost the background's is drawn at this share."""


def subpixel_edges(
    rgb: np.ndarray, nd: np.ndarray, hidden: np.ndarray, hidden_rgb: np.ndarray, jump: float
) -> Optional[Tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The foreground's anti-aliased silhouette pixels as partly covering points.

    A pixel of layer 0 with the hidden layer behind it and a 4-neighbour behind a tear (the
    foreground's side of a silhouette, including background-side pixels that joined the
    foreground, :func:`unmix_silhouette`) holds ``c = a F + (1 - a) B + r``: a share ``a`` of
    the foreground's colour ``F`` (the pixel one step inwards, or two where that one is on the
    same surface: it may itself be mixed at a corner; averaged over the tears' directions),
    the rest the background's ``B`` (the hidden layer's colour behind it), and texture ``r``.
    ``a`` is the projection of ``c - B`` on ``F - B`` where that is a mix (within
    ``_MIX_RESIDUAL |F - B|`` of the segment) across a colour edge (``|F - B|`` >=
    ``_JOIN_CONTRAST`` RMS), at least :data:`_EDGE_MIN_SHARE`. Such a pixel's point gets the
    colour ``F + r``, the opacity ``2 a / (1 + a)`` and moves inwards (away from the tears) by
    ``s = (1 - a) / 2`` pixels: its bilinear splat then covers its own pixel by
    ``(1 - s) * 2 a / (1 + a) = a`` in the photo's view, blended over ``B``, which gives ``c``
    back up to ``(1 - a) r``, and in a moved view its silhouette lies where the covered part of
    the pixel moves, to a fraction of a pixel. A 1-pixel-wide structure (tears on opposite
    sides) keeps its pixels as they are.

    Args:
        rgb: (H, W, 3) float32 layer-0 colours.
        nd: (H, W) float32 layer-0 normalised disparity (larger is nearer).
        hidden: (H, W) bool, where the hidden layer lies.
        hidden_rgb: (H, W, 3) float32, its colours.
        jump: the tear threshold on ``nd``.
    Returns:
        None where no pixel is a partly covering silhouette pixel, else ``(colours, alpha, offset)``:
        (H, W, 3) float32 layer-0 colours, (H, W) float32 opacities in (0, 1] and (H, W, 2) float32
        offsets (x, y) of the points from their pixel centres, in pixels.
    """
    h, w = nd.shape
    rows, cols = np.nonzero(hidden)
    if rows.size == 0:
        return None
    own = nd[rows, cols]
    inward = np.zeros((rows.size, 2), np.float64)  # (N, 2) sum of the directions away from the tears (y, x)
    tears = np.zeros(rows.size, np.int64)
    for di, dj in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        r1, c1 = rows + di, cols + dj
        inside = (r1 >= 0) & (r1 < h) & (c1 >= 0) & (c1 < w)
        across = inside & (own - nd[np.clip(r1, 0, h - 1), np.clip(c1, 0, w - 1)] > jump)  # behind a tear that way
        inward[across] -= (di, dj)
        tears += across
    edge = tears > 0
    if not edge.any():
        return None
    rows, cols, own, inward = rows[edge], cols[edge], own[edge], inward[edge]
    fore = np.zeros((rows.size, 3), np.float32)
    count = np.zeros(rows.size, np.float32)
    for di, dj in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        # a step inwards: the direction opposite a tear, on the pixel's own surface
        towards = (inward[:, 0] * di + inward[:, 1] * dj) > 0
        r1, c1 = rows + di, cols + dj
        inside = (r1 >= 0) & (r1 < h) & (c1 >= 0) & (c1 < w)
        r1, c1 = np.clip(r1, 0, h - 1), np.clip(c1, 0, w - 1)
        same = towards & inside & (np.abs(nd[r1, c1] - own) <= jump)
        if not same.any():
            continue
        r2, c2 = r1 + di, c1 + dj
        inside2 = (r2 >= 0) & (r2 < h) & (c2 >= 0) & (c2 < w)
        r2, c2 = np.clip(r2, 0, h - 1), np.clip(c2, 0, w - 1)
        two = inside2 & (np.abs(nd[r2, c2] - nd[r1, c1]) <= jump)
        f = np.where(two[:, None], rgb[r2, c2], rgb[r1, c1])
        fore[same] += f[same]
        count[same] += 1.0
    ok = count > 0
    fore[ok] /= count[ok, None]
    c = rgb[rows, cols]
    back = hidden_rgb[rows, cols]
    diff = fore - back  # (N, 3) F - B
    contrast = (diff * diff).sum(-1)
    share = ((c - back) * diff).sum(-1) / np.maximum(contrast, 1e-12)
    residual = c - back - np.clip(share, 0.0, 1.0)[:, None] * diff
    mixes = (residual * residual).sum(-1) <= _MIX_RESIDUAL ** 2 * contrast
    norm = np.hypot(inward[:, 0], inward[:, 1])
    take = ok & mixes & (contrast >= 3 * _JOIN_CONTRAST ** 2) & (share < 1.0 - 1e-3) & (norm > 0)
    if not take.any():
        return None
    a = np.clip(share[take], _EDGE_MIN_SHARE, 1.0).astype(np.float32)
    r, q = rows[take], cols[take]
    colours = rgb.copy()
    colours[r, q] = np.clip(fore[take] + residual[take], 0.0, 1.0)
    alpha = np.ones((h, w), np.float32)
    alpha[r, q] = 2.0 * a / (1.0 + a)
    offset = np.zeros((h, w, 2), np.float32)
    step = (1.0 - a) / 2.0 / norm[take]  # (M,) along the unit inward direction
    offset[r, q, 0] = step * inward[take, 1]  # x
    offset[r, q, 1] = step * inward[take, 0]  # y
    return colours, alpha, offset


def _used_sources(
    nearest: np.ndarray, source: np.ndarray, band: np.ndarray, scan: Optional[np.ndarray]
) -> np.ndarray:
    """(h, w) bool: the sources a band pixel continues (its nearest; and its ``scan`` candidates,
    (4, N, 2) for the band's N pixels in raster order, where given)."""
    used = np.zeros_like(source)
    tr, tc = np.nonzero(source)
    k = nearest[band]
    used[tr[k], tc[k]] = True
    if scan is not None:
        ok = scan[..., 0] >= 0
        used[scan[..., 0][ok], scan[..., 1][ok]] = True
    return used


def _nearest_surface(
    nd_fit: LinearFit, col_fit: Optional[LinearFit], source: np.ndarray, band: np.ndarray, ndc: np.ndarray,
    fallback_nd: np.ndarray, lo: float, s: LDISettings, scan: np.ndarray, nearest: np.ndarray,
    rgbc: Optional[np.ndarray] = None,
) -> Tuple[np.ndarray, Optional[np.ndarray]]:
    """Hidden-layer disparity (h, w) and colour (N, 3) of the band's N pixels (raster order) or None.

    Every band pixel looks at the four background sources nearest along its row and column
    and continues their planes (and colour fits) to it; one that would come out in front of
    the foreground (or far beyond anything seen) is dropped. Where the two sources of a row
    or of a column agree (within ``_SAME_SURFACE`` jumps), the pixel takes the blend of the
    agreeing ones, weighted by inverse squared distance; pixels with no agreeing pair keep
    ``fallback_nd`` (and the Voronoi colour). ``scan`` is :func:`scan_nearest` of ``source`` at
    the band's pixels and ``nearest`` its :func:`nearest_index`.
    """
    br, bc = np.nonzero(band)
    cand = scan  # (4, N, 2)
    pix = (br.astype(np.float64), bc.astype(np.float64))
    limit = ndc[br, bc] - s.disparity_jump  # (N,)
    nds = np.full((4, len(br)), -np.inf)
    dist = np.abs(cand[..., 0] - br) + np.abs(cand[..., 1] - bc)  # (4, N) along the row or column

    def depth_of(k: int) -> None:  # candidate k's plane continued to its band pixels
        ok = cand[k, :, 0] >= 0
        nds[k, ok] = continue_at(nd_fit, cand[k][ok], (pix[0][ok], pix[1][ok]), _DEPTH_STEP * s.disparity_jump)[:, 0]

    halves(depth_of, 4)
    nds[(nds > limit) | (nds < lo)] = -np.inf  # in front of the foreground, or far beyond anything seen
    # A surface runs behind the foreground where the sources on opposite sides of the pixel (left
    # and right, or above and below) continue to the same disparity: the ground beside a card, on
    # its row, not the wall above it, whose plane the nearest source (just above the card) would
    # continue. Those pairs are blended by inverse squared distance (interpolated across the gap,
    # and continuous with the nearer source); a pixel with no agreeing pair keeps the nearest
    # source's plane (continued from one side alone, a surface is no more than a guess, and a
    # guess in front of the background beside it tears from it: on estimated depth the nearest
    # of the four continued planes opened holes).
    valid = np.isfinite(nds)
    finite = np.where(valid, nds, 0.0)
    agree = np.zeros((4, len(br)), bool)
    for a, b in ((0, 1), (2, 3)):
        pair = valid[a] & valid[b] & (np.abs(finite[a] - finite[b]) <= _SAME_SURFACE * s.disparity_jump)
        agree[a] |= pair
        agree[b] |= pair
    inv_d2 = 1.0 / np.maximum(dist, 1).astype(np.float64) ** 2  # (4, N)
    wts = np.where(agree, inv_d2, 0.0)
    total = wts.sum(axis=0)
    found = total > 0
    surface = (wts * finite).sum(axis=0) / np.maximum(total, 1e-300)  # (N,)
    # where that surface is the nearest source's own (a card on one wall), the nearest source's
    # continuation stays: it is the closest evidence, in any direction
    found &= np.abs(surface - fallback_nd[br, bc]) > _JOIN * s.disparity_jump
    # every source on that surface joins (the one just above a card, where the wall runs on behind it)
    on_it = valid & found[None] & (np.abs(finite - surface[None]) <= _JOIN * s.disparity_jump)
    wts = np.where(on_it | agree, inv_d2, 0.0)
    wts[:, ~found] = 0.0
    wts[:, found] /= wts[:, found].sum(axis=0)
    out = fallback_nd.copy()
    out[br[found], bc[found]] = (wts * finite).sum(axis=0)[found]
    if col_fit is None:
        return out, None
    terms = [None] * 4

    def colour_of(k: int) -> None:  # candidate k's weighted colour continued to its band pixels
        sel = wts[k] > 0
        if sel.any():
            terms[k] = (sel, wts[k, sel, None] * continue_at(col_fit, cand[k][sel], (pix[0][sel], pix[1][sel]),
                                                             s.max_colour_step))

    halves(colour_of, 4)
    rgb = np.zeros((len(br), 3))
    for term in terms:  # summed in candidate order, as one loop would
        if term is not None:
            rgb[term[0]] += term[1]
    if not found.all():  # no candidate: the Voronoi continuation
        rest = np.zeros_like(band)
        rest[br[~found], bc[~found]] = True
        fb = extrapolate(col_fit, nearest, source, s.max_colour_step, rest)
        rgb[~found] = fb[br[~found], bc[~found]]
    if rgbc is not None:
        _follow_isophotes(rgb, rgbc, source, br, bc, cand, agree, found, nearest, ndc, s.disparity_jump)
    return out, np.clip(rgb, 0.0, 1.0).astype(np.float32)


_MIX_FIT = 0.15
"""A row (column) beside the recoloured ones is taken for an anti-aliased crease where the two surfaces'
mix explains the gap's sides up to this share of their neighbours' difference (squared) ..."""
_CREASE_KINK = 0.05
"""... and where the disparity across it on the gap's sides bends by more than this many ``disparity_jump``
(a crease: the disparity is affine on each plane, so one receding plane is no crease)."""


def _follow_isophotes(
    rgb: np.ndarray, rgbc: np.ndarray, source: np.ndarray, br: np.ndarray, bc: np.ndarray, cand: np.ndarray,
    agree: np.ndarray, found: np.ndarray, nearest: np.ndarray, ndc: np.ndarray, jump: float,
) -> None:
    """Recolour, in place, the band pixels (``br``, ``bc``) that take a surface their row's or column's
    agreeing pair continues (``found``): with the colours where the texture's isophotes through them
    meet the gap's two sides (:func:`~._fill.across_gap`), not the pair's colours continued straight
    along the row or column. A pixel both pairs cover blends the two by inverse squared gap width.

    The row (column) just beside those, between the same two sides' neighbours, whose pixels continue
    a source beyond them (on the far side from the recoloured neighbour) lies on the crease between
    that source's surface and the recoloured one (a wall above a ground): its pixels are anti-aliased
    mixtures of the two.
    Where the gap's sides show such a mix (their pixel there lies between its two neighbours across
    the crease, up to ``_MIX_FIT``, and their disparity bends there, ``_CREASE_KINK``), the pixel takes the same mix of its own colour (the nearest
    source's surface continued) and of the recoloured surface's share, which follows the isophotes
    across the gap as the recoloured rows do (the sides' crease pixels less their other share,
    matched with those rows); where that share finds no match, its recoloured neighbour's colour."""
    acc = np.zeros(rgb.shape)
    total = np.zeros(len(br))
    h, w = source.shape
    edges = []
    for a, b in ((0, 1), (2, 3)):
        sel = found & agree[a] & agree[b]
        if not sel.any():
            continue
        # and every pixel between the same two sources (beside the card, nearer one of them than anything)
        key = (cand[a, :, 0].astype(np.int64) * w + cand[a, :, 1]) * (h * w) + cand[b, :, 0] * w + cand[b, :, 1]
        both = (cand[a, :, 0] >= 0) & (cand[b, :, 0] >= 0)
        sel = both & np.isin(key, key[sel])
        step = w * (h * w + 1) if a == 0 else h * w + 1  # the same sides one row (column) on
        pair = agree[a] & agree[b] & both & ~sel
        for sign in (1, -1):
            edge = pair & np.isin(key + sign * step, key[sel])
            if edge.any():
                edges.append((a, b, sign, edge, sel))
        if a == 0:  # left / right: along the rows
            col, ok = across_gap(rgbc, source, br[sel], bc[sel], cand[a, sel, 1], cand[b, sel, 1])
            gap = cand[b, sel, 1] - cand[a, sel, 1]
        else:  # above / below: the same along the columns
            col, ok = across_gap(rgbc.transpose(1, 0, 2), source.T, bc[sel], br[sel], cand[a, sel, 0], cand[b, sel, 0])
            gap = cand[b, sel, 0] - cand[a, sel, 0]
        wt = np.where(ok, 1.0 / np.maximum(gap, 1).astype(np.float64) ** 2, 0.0)
        acc[sel] += wt[:, None] * col
        total[sel] += wt
    done = total > 0
    rgb[done] = acc[done] / total[done, None]
    if not edges:
        return
    index = np.full(source.shape, -1, np.int64)
    index[br, bc] = np.arange(len(br))
    src_r, src_c = np.nonzero(source)  # ``nearest`` indexes these
    for a, b, sign, edge, sel in edges:
        # a row (column) between the same two sides next to the recoloured ones: where the surface
        # meets the nearest source's (a crease), its pixels are anti-aliased mixtures of the two;
        # the mix is measured on the gap's two sides and applied to the two colours beside the pixel
        k = np.nonzero(edge)[0]
        dr, dc = (sign, 0) if a == 0 else (0, sign)
        inner = index[br[k] + dr, bc[k] + dc]  # the recoloured neighbour
        num = np.zeros(k.size)
        den = np.zeros(k.size)
        sides = []
        # a crease: the pixel continues a source beyond it, on the far side from its recoloured neighbour
        q = nearest[br[k], bc[k]]
        usable = (inner >= 0) & (((src_r[q] - br[k]) * dr + (src_c[q] - bc[k]) * dc) < 0)
        for side in (a, b):
            sr, sc = cand[side, k, 0], cand[side, k, 1]
            ir, ic = sr + dr, sc + dc
            orow, ocol = sr - dr, sc - dc
            inside = (ir >= 0) & (ir < h) & (ic >= 0) & (ic < w) & (orow >= 0) & (orow < h) & (ocol >= 0) & (ocol < w)
            ir, ic, orow, ocol = (np.clip(ir, 0, h - 1), np.clip(ic, 0, w - 1), np.clip(orow, 0, h - 1),
                                  np.clip(ocol, 0, w - 1))
            ok = inside & source[ir, ic] & source[orow, ocol]
            v, v_in, v_out = rgbc[sr, sc], rgbc[ir, ic], rgbc[orow, ocol]
            sides.append((ok, v, v_in, v_out))
            # the disparity is affine on a plane: a crease between two shows as a kink
            ok &= np.abs(ndc[orow, ocol] - 2.0 * ndc[sr, sc] + ndc[ir, ic]) > _CREASE_KINK * jump
            num += np.where(ok, ((v - v_in) * (v_out - v_in)).sum(axis=1), 0.0)
            den += np.where(ok, ((v_out - v_in) ** 2).sum(axis=1), 0.0)
            usable &= ok
        usable &= den > 1e-6
        alpha = np.clip(num / np.maximum(den, 1e-12), 0.0, 1.0)[:, None]  # share of the other surface
        # a mixture: the sides' pixels lie between their two neighbours (texture is not)
        miss = sum(np.where(ok, ((v - v_in - alpha * (v_out - v_in)) ** 2).sum(axis=1), 0.0)
                   for ok, v, v_in, v_out in sides)
        usable &= miss <= _MIX_FIT * den
        k, alpha, inner = k[usable], alpha[usable], inner[usable]
        other = rgb[inner]
        if k.size:
            # the crease row's share of the recoloured surface, followed along its isophotes as well: the
            # sides' crease pixels less their other share, matched with the recoloured rows
            part = rgbc.copy()
            for side in (a, b):
                sr, sc = cand[side, k, 0], cand[side, k, 1]
                part[sr, sc] = (rgbc[sr, sc] - alpha * rgbc[sr - dr, sc - dc]) / np.maximum(1.0 - alpha, 0.1)
            # the recoloured rows (columns) within the profiles' reach of the crease, and the crease
            line = br if a == 0 else bc
            reach = np.zeros(max(h, w) + 1, bool)
            for at_line in np.unique(line[k]):
                reach[max(0, at_line - _ACROSS_REACH):at_line + _ACROSS_REACH + 1] = True
            pix = sel & reach[line]
            pix[k] = True
            if a == 0:
                col, ok = across_gap(part, source, br[pix], bc[pix], cand[a, pix, 1], cand[b, pix, 1])
            else:
                col, ok = across_gap(part.transpose(1, 0, 2), source.T, bc[pix], br[pix], cand[a, pix, 0],
                                     cand[b, pix, 0])
            at = np.cumsum(pix) - 1  # row of each pixel of ``pix`` in the results
            good = ok[at[k]] & (alpha[:, 0] < 0.9)
            other = np.where(good[:, None], np.clip(col[at[k]], 0.0, 1.0), other)
        rgb[k] = alpha * rgb[k] + (1.0 - alpha) * other


def _edges_near_frame(fg: np.ndarray, pad: int) -> bool:
    """Whether a foreground edge comes within ``pad`` pixels of the photo's frame (something in
    front may be cut by it; with none, e.g. a slanted plane, the border needs no hidden layer)."""
    k = min(pad, min(fg.shape) // 2)
    return bool(fg[:k].any() or fg[-k:].any() or fg[:, :k].any() or fg[:, -k:].any())


def _border(
    rgb: np.ndarray, nd: np.ndarray, fg: np.ndarray, pad: int, s: LDISettings,
) -> Tuple[np.ndarray, np.ndarray, Optional[Tuple[np.ndarray, np.ndarray, np.ndarray]]]:
    """The canvas's colour and disparity with a border of ``pad`` (:func:`_extend_border`) and the border's
    hidden samples (:func:`_border_hidden`: mask (Hc, Wc), their colours (n, 3) and depths (n,); None
    where it has none)."""
    rgb0, nd0 = _extend_border(rgb, nd, pad)
    outer = None
    if pad > 0 and s.border_hidden and _edges_near_frame(fg, pad):
        outer = _border_hidden(rgb, nd, nd0, pad, s)
    return rgb0, nd0, outer


def _border_hidden(
    rgb: np.ndarray, nd: np.ndarray, nd0: np.ndarray, pad: int, s: LDISettings,
) -> Optional[Tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Hidden background in the border, behind foreground that the frame's edge cuts: the mask (Hc, Wc) of
    the border pixels that get a hidden sample, their colours (n, 3) and depths (n,); None if none do.

    The border's layer 0 continues whatever reaches the frame's edge, a tower cut by it
    too; a camera that looks past the edge then sees the tower's continuation with
    nothing behind it. The photo's background pixels (within ``disparity_jump`` of the
    farthest ``nd`` within ``pad`` of them) are continued into the border the same way
    (push-pull); border pixels whose layer 0 is in front of that continuation by more
    than ``disparity_jump`` get it as a hidden sample.
    """
    h, w = nd.shape
    k = 2 * pad + 1
    far = cv2.erode(nd, np.ones((k, k), np.uint8), borderType=cv2.BORDER_REPLICATE)
    background = (nd - far <= s.disparity_jump).astype(np.float32)  # (H, W)
    if background.all():
        return None  # nothing in front of anything: the border's layer 0 is background already
    values = np.zeros((h + 2 * pad, w + 2 * pad, 4), np.float32)
    weight = np.zeros((h + 2 * pad, w + 2 * pad), np.float32)
    inner = (slice(pad, pad + h), slice(pad, pad + w))
    values[inner] = np.concatenate([rgb, nd[..., None]], axis=2)
    weight[inner] = background
    filled = push_pull(values, weight)  # (Hc, Wc, 4) the background continued
    outside = np.ones(nd0.shape, bool)
    outside[inner] = False
    add = outside & (nd0 - filled[..., 3] > s.disparity_jump) & (filled[..., 3] > 0)
    return add, np.clip(filled[..., :3][add], 0.0, 1.0), NEAR_DEPTH / filled[..., 3][add]


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
