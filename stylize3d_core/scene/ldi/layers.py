"""The layered depth image's data: the point labels, :class:`LDISettings` and :class:`LDI`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, Optional, Tuple

import numpy as np

from ...checks import check_choice, check_range
from ...errors import InputError
from ...geometry.camera_range import CameraRange

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
        check_choice(self.hidden_depth, "hidden_depth", ("surface", "plane", "nearest"))
        check_range(self.fit_sigma, "fit_sigma", 0.5, 50.0)
        check_range(self.max_colour_step, "max_colour_step", 0.0, 1.0)
        for name in ("unmix_silhouettes", "subpixel_silhouettes"):
            if not isinstance(getattr(self, name), bool):
                raise InputError(name, f"expected a bool, got {getattr(self, name)!r}")
        for name in ("edge_min_px", "island_min_px", "edge_exclusion_px"):
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
