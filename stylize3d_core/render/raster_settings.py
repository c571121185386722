"""What :func:`~stylize3d_core.render.rasterize.rasterize_points` is asked to do (:class:`RasterSettings`) and what
it returns besides the image (:class:`Fragments`)."""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import NamedTuple

import torch

from ..checks import check_range
from ..errors import InputError

MAX_IMAGE_SIDE = 16384
"""Largest image height or width accepted (before supersampling)."""


RASTER_BACKENDS = ("auto", "tensor")
"""The values of :attr:`RasterSettings.backend`."""


@dataclass(frozen=True)
class RasterSettings:
    """How to rasterize a point cloud.

    Attributes:
        height: output image height H in pixels, 1..16384.
        width: output image width W in pixels, 1..16384.
        depth_tolerance: relative depth band of the front surface; a contribution
            is kept when ``zmin / (1 + depth_tolerance) <= z <= zmin * (1 + depth_tolerance)``
            (``zmin``: the front, see the module docstring). Default 0.02: 2 % of
            the depth, i.e. ~0.007 scene units at the normalised near depth 1/3, far
            more than the depth step between neighbouring points of one surface and
            far less than the gap at an occlusion edge. In [0, 1].
        supersample: 1 (default) or 2; 2 z-buffers at (2H, 2W) and pools back,
            which anti-aliases occlusion edges; it costs little more, as only the
            depth buffer is 4x larger (features are accumulated at (H, W)).
        hole_weight_threshold: a pixel whose kept weight sum is below this is a
            hole. Default 1e-3: any pixel touched by a point with a weight of at
            least a thousandth is shown. Finite and > 0.
        near_clip: points with ``z <= near_clip`` (scene units) are culled.
            Default 1e-3, 1/333 of the normalised near depth 1/3. Finite and > 0.
        soft_edges: False (default): a (sub-)pixel's front depth is the least depth of
            the contributions of weight >= ``hole_weight_threshold`` it receives (of all,
            where it has none), and contributions nearer than the front band are dropped.
            True: of those, only *core* contributions (every
            bilinear one, and a grown splat's taps of weight >= :data:`~stylize3d_core.render.splat.CORE_WEIGHT` /
            half-width^2, which it gives to at least the pixel nearest it) set the
            front, where there is one: the thin fringe of a
            nearer surface's splats gives way to the surface behind instead of hiding it
            (or, below the hole threshold, leaving a hole), so silhouettes keep their
            size however large the splats grow.
        blend_coverage: False (default): a pixel shows its front surface alone (normalised by
            its weight). True: a pixel the front covers only partly (its *coverage*, the sum of the
            front's kept taps' tent values (before the splat's normalisation; times the point's
            opacity, ``point_alpha``), below 1, as at a silhouette, where the tent of the last point
            is the share of the pixel its footprint covers; tents of half-width h spaced h apart sum
            to exactly 1, so a magnified surface covers its pixels at any phase)
            shows the front over the next surface behind it (the nearest depth of the
            front-setting contributions behind the front band, and its own band):
            ``coverage * front + (1 - coverage) * behind``. Silhouettes are anti-aliased instead
            of grown by up to a pixel; a pixel with nothing behind shows its front alone.
            Needs ``point_size`` (grown splats tile the view, so their weight measures the
            coverage; bilinear splats of a magnified surface do not, and the surface behind would
            show through it); supersampling (2) ignores it: its sub-pixel z-buffer anti-aliases
            silhouettes, and the sub-pixel splats of grown points do not tile the sub-pixels.
        backend: "auto" (default): the compiled inference path (:mod:`.rasterize_fast`) where it applies
            and Numba imports, the tensor path otherwise; "tensor": always the tensor path (the reference,
            and what ``bench speed`` compares the compiled path with). Both give the same fragments up to
            float rounding.
    """

    height: int
    width: int
    depth_tolerance: float = 0.02
    supersample: int = 1
    hole_weight_threshold: float = 1e-3
    near_clip: float = 1e-3
    soft_edges: bool = False
    blend_coverage: bool = False
    backend: str = "auto"

    def __post_init__(self) -> None:
        for name in ("height", "width", "supersample"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, numbers.Integral):
                raise InputError(name, f"must be an integer, got {value!r}")
            object.__setattr__(self, name, int(value))  # numpy integers become ints
            check_range(value, name, 1, MAX_IMAGE_SIDE)
        if self.supersample not in (1, 2):
            raise InputError("supersample", f"must be 1 or 2, got {self.supersample!r}")
        check_range(self.depth_tolerance, "depth_tolerance", 0.0, 1.0)
        check_range(self.hole_weight_threshold, "hole_weight_threshold", 0.0, math.inf, inclusive=False)
        check_range(self.near_clip, "near_clip", 0.0, math.inf, inclusive=False)
        if self.backend not in RASTER_BACKENDS:
            raise InputError("backend", f"must be one of {', '.join(RASTER_BACKENDS)}, got {self.backend!r}")


class Fragments(NamedTuple):
    """Result of :func:`rasterize_points`.

    Attributes:
        image: (C, H, W) weighted mean of the kept features, 0 at holes, in the
            features' dtype. Its memory is channels-last: it is a permuted view of
            a contiguous (H, W, C) tensor, so ``image.unsqueeze(0)`` is a
            ``torch.channels_last`` batch (call ``.contiguous()`` for NCHW memory).
        weight: (H, W) kept weight sum, in the features' dtype (it can be > 0,
            though below the threshold, at holes).
        depth: (H, W) front depth (the least over its sub-pixels with supersampling), in the
            features' dtype: the least depth of the front-setting contributions (see the
            module docstring), or of all where there are none; ``+inf`` at holes
            (a z-buffer value, not an image: mask it with ``hole`` before use).
        hole: (H, W) bool, True where the kept weight sum is below the threshold.
    """

    image: torch.Tensor
    weight: torch.Tensor
    depth: torch.Tensor
    hole: torch.Tensor
