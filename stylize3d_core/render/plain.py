"""Render a plain (unstylized) 3D photo: rasterize point colours, fill pinholes.

The stylized path decodes rasterized features with the model's U-Net instead;
this path shows the photo's own colours and is the baseline the stylization is
compared with. Splats grow with the magnification at each point and, on full
frames of an LDI's cloud, stretch to the next point of the same surface in the
view (``PlainRenderSettings.stretch_splats``), so neither a dolly in nor a
slanted surface shows a grid of gaps.

Previews (both paths) rasterize a *prefix* of the points held in a fixed
:class:`StratifiedOrder`, i.e. a uniform random subset of (up to 1/8 more
than) :func:`preview_point_count` points, with no copy; the hole filling
(plain) or the decoder (stylized) closes the gaps.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from typing import Callable, Iterator, List, Optional, Tuple, Union

import numpy as np
import torch

from ..checks import check_range
from ..errors import InputError, RenderInterrupted
from ..geometry.camera import NEAR_DEPTH, Cameras, focal_from_fov
from ..scene.ldi import INPAINTED, ORIGINAL
from ..scene.pointcloud import PointCloud, PointTensors
from .holes import fill_holes
from .rasterize import Fragments, RasterSettings
from .rasterizer import PointRasterizer, columns


@dataclass(frozen=True)
class PlainRenderSettings:
    """Options of :class:`PlainRenderer`.

    Attributes:
        supersample: 1 (default) or 2. 2 rasterizes at twice the size and
            averages down: smoother when the camera moves away (minification),
            but magnified surfaces leave pinholes that the hole filling blurs, so
            1 is the better default for the short camera moves of a 3D photo.
        depth_tolerance: relative depth band of the front surface (see RasterSettings).
        preview_points_per_pixel: points a preview rasterizes per output pixel. Default 2.
        seed: seed of the random point order that previews take a prefix of.
        grow_splats: True (default): each point's splat covers its photo pixel's footprint
            in the view (``point_size = z / f_photo``, see ``render/rasterize.py``), so
            moving in shows surfaces rather than a grid of points; a preview's subset grows
            them by ``sqrt(N / kept)``. Needs a :class:`PointCloud` (photo size and FOV);
            False: bilinear splats.
        soft_edges: True (default): silhouettes keep their size however large the splats
            grow (``RasterSettings.soft_edges``); False: every splat tap can occlude, and a
            grown splat's faint fringe can hide the surface behind it.
        stretch_splats: True (default): with ``grow_splats``, on full frames of an LDI's
            cloud (:func:`canvas_grid_shape`), a layer-0 point's splat also spans the gap
            to its farthest 4-neighbour in the view where no tear lies between them
            (their disparities differ by at most :data:`STRETCH_JUMP`): a surface seen at
            a slant or magnified unevenly (a forward dolly over rough depth) shows no
            gaps. False: the splat grows with the magnification at the point only.
        blend_coverage: True (default): a pixel a nearer surface covers only partly (a
            silhouette) shows it over the surface behind, by the share it covers
            (``RasterSettings.blend_coverage``), so silhouettes are anti-aliased rather than
            grown by up to a pixel (at ``supersample`` 1 with ``grow_splats`` and a
            :class:`PointCloud`; 2 anti-aliases by its sub-pixels instead); False: the front
            surface alone.
    """

    supersample: int = 1
    depth_tolerance: float = 0.02
    preview_points_per_pixel: float = 2.0
    seed: int = 0
    grow_splats: bool = True
    soft_edges: bool = True
    stretch_splats: bool = True
    blend_coverage: bool = True

    def __post_init__(self) -> None:
        if self.supersample not in (1, 2):
            raise InputError("supersample", f"must be 1 or 2, got {self.supersample!r}")
        check_range(self.depth_tolerance, "depth_tolerance", 0.0, 1.0)
        check_range(self.preview_points_per_pixel, "preview_points_per_pixel", 0.5, 100.0)


STRETCH_JUMP = 0.04
"""Neighbours whose normalised disparity (``NEAR_DEPTH / z`` in scene units) differs by at
most this lie on one surface for :attr:`PlainRenderSettings.stretch_splats`: the LDI's
default tear threshold (``LDISettings.disparity_jump``), so torn neighbours never stretch."""


STRETCH_MIN = 1.2
"""A splat stretches to its neighbours only where they lie more than this many of its
half-widths away in the view."""


def canvas_grid_shape(points: PointCloud) -> Optional[Tuple[int, int]]:
    """(Hc, Wc) when ``points`` starts with an LDI canvas in raster order, as
    :func:`~stylize3d_core.scene.pointcloud.ldi_to_points` lays it out (layer 0: every
    canvas pixel, labels ORIGINAL inside the photo and BORDER outside, then only hidden
    points), else None."""
    h, w = points.image_size
    label = points.label
    n0 = int(np.count_nonzero(label != INPAINTED))
    if n0 < h * w or (label[n0:] != INPAINTED).any() or (label[:n0] == INPAINTED).any():
        return None
    # (h + 2 p)(w + 2 p) = n0
    pad = (-(h + w) + math.sqrt((h + w) ** 2 - 4 * (h * w - n0))) / 4.0
    p = int(round(pad))
    if (h + 2 * p) * (w + 2 * p) != n0:
        return None
    hc, wc = h + 2 * p, w + 2 * p
    grid = label[:n0].reshape(hc, wc)
    if (grid[p:p + h, p:p + w] != ORIGINAL).any() or (grid == ORIGINAL).sum() != h * w:
        return None
    f = focal_from_fov(points.fov_y_deg, h)
    xyz = points.xyz[:n0].reshape(hc, wc, 3)
    rays = xyz[..., 0] / xyz[..., 2], xyz[..., 1] / xyz[..., 2]  # x / z, y / z
    want_x = (np.arange(wc) - p + 0.5 - w / 2.0) / f
    want_y = (np.arange(hc) - p + 0.5 - h / 2.0) / f
    tol = 0.5 / f + 1e-4  # silhouette points may sit up to half a pixel from their pixel's centre (LDI.offset)
    if (np.abs(rays[0] - want_x[None]).max() > tol) or (np.abs(rays[1] - want_y[:, None]).max() > tol):
        return None
    return hc, wc


PREVIEW_MIN_POINTS = 1024
"""A preview never rasterizes fewer points than this (or all of them, if fewer)."""


def preview_point_count(n_points: int, height: int, width: int, per_pixel: float) -> int:
    """Points a preview of (H, W) rasterizes: ``ceil(per_pixel * H * W)``, at least
    :data:`PREVIEW_MIN_POINTS`, at most ``n_points``."""
    return int(min(n_points, max(PREVIEW_MIN_POINTS, math.ceil(per_pixel * height * width))))


def random_order(n_points: int, seed: int) -> torch.Tensor:
    """A fixed random permutation (N,) of the points: any prefix of it is a uniform random subset."""
    return torch.randperm(int(n_points), generator=torch.Generator().manual_seed(int(seed)))


PREVIEW_LEVEL_GROWTH = 1.125
"""Each level of a :class:`StratifiedOrder` holds 1/8 as many points as all the levels before it."""


class StratifiedOrder:
    """A point order whose level prefixes are uniform random subsets and whose levels are in memory order.

    A random permutation cut into levels at ``bounds`` (0, 1024, 1152, 1296, ...:
    each level 1/8 of the points before it, the last ending at N); inside each
    level the points keep their original order (the LDI's raster order), so a
    rasterizer reading their features pixel by pixel touches nearby memory
    (about 1.7x faster than a fully random order for a 1 MP photo at 512 px).
    A prefix that ends at a level boundary is a uniform random subset:
    previews take :meth:`prefix` points, the smallest boundary at or above the
    count they ask for (at most 1/8 more).

    Attributes:
        order: (N,) int64 permutation (new position -> original index).
        bounds: the level boundaries, ascending, from 0 to N.
    """

    def __init__(self, n_points: int, seed: int, first: int = PREVIEW_MIN_POINTS,
                 growth: float = PREVIEW_LEVEL_GROWTH) -> None:
        n = int(n_points)
        perm = random_order(n, seed)
        bounds, b = [0], min(n, int(first))
        while True:
            bounds.append(b)
            if b >= n:
                break
            b = min(n, max(b + 1, math.ceil(b * growth)))
        if n == 0:
            bounds = [0]
        self.bounds: List[int] = bounds
        # each point's level (by its position in perm), then one stable sort by level: inside a level the
        # original indices stay ascending (the same order as sorting each level's slice of perm, in one pass)
        sizes = torch.tensor([hi - lo for lo, hi in zip(bounds[:-1], bounds[1:])], dtype=torch.int64)
        key = torch.empty(n, dtype=torch.int32)
        key[perm] = torch.repeat_interleave(torch.arange(len(sizes), dtype=torch.int32), sizes)
        self.order = torch.sort(key, stable=True).indices if n else perm

    def prefix(self, count: int) -> int:
        """The smallest level boundary >= ``count`` (N if count > N)."""
        i = bisect.bisect_left(self.bounds, int(count))
        return self.bounds[min(i, len(self.bounds) - 1)]


def frame_size(photo_size: Tuple[int, int], long_side: int, *, even: bool = True) -> Tuple[int, int]:
    """(H, W) of output frames whose long side is ``long_side`` and aspect is the photo's.

    With ``even`` (default) both sides are rounded to even numbers, as H.264 in
    yuv420p needs.
    """
    if int(long_side) != long_side or not 16 <= long_side <= 8192:
        raise InputError("size", f"must be an integer from 16 to 8192, got {long_side!r}")
    h, w = photo_size
    if h < 1 or w < 1:
        raise InputError("photo size", f"must be positive, got {tuple(photo_size)!r}")
    scale = long_side / max(h, w)
    step = 2 if even else 1
    H = max(step, int(round(h * scale / step)) * step)
    W = max(step, int(round(w * scale / step)) * step)
    return H, W


class PlainRenderer:
    """Renders a point cloud's colours from any camera. Holds the points as tensors,
    in a fixed :class:`StratifiedOrder` (see the module docstring on previews).

    Runs on whatever thread calls it (torch releases the GIL in its kernels).
    """

    def __init__(self, points: Union[PointCloud, PointTensors],
                 settings: PlainRenderSettings = PlainRenderSettings()) -> None:
        t = points if isinstance(points, PointTensors) else points.to_tensors()
        self._strata = StratifiedOrder(t.xyz.shape[0], settings.seed)
        order = self._strata.order
        self._xyz = columns(t.xyz.index_select(0, order))  # (N, 3), stored as (3, N) (the fast layout)
        self._rgb = t.rgb.index_select(0, order)  # (N, 3)
        # (N,) opacities (silhouette points that cover part of their pixel), for blend_coverage
        self._alpha = None if t.alpha is None else t.alpha.index_select(0, order)
        self._size: Optional[torch.Tensor] = None  # (N,) footprint of each point, scene units
        self._grid: Optional[Tuple[torch.Tensor, torch.Tensor, torch.Tensor]] = None
        if settings.grow_splats and isinstance(points, PointCloud):
            f = focal_from_fov(points.fov_y_deg, points.image_size[0])
            self._size = self._xyz[:, 2].abs() / f
            shape = canvas_grid_shape(points)
            if shape is not None and settings.stretch_splats:
                hc, wc = shape
                xyz0 = t.xyz[: hc * wc].reshape(hc, wc, 3)
                nd = NEAR_DEPTH / xyz0[..., 2]  # (Hc, Wc) normalised disparity (scene units)
                # right and down neighbours on one surface (no tear between them)
                self._grid = (xyz0, (nd[:, 1:] - nd[:, :-1]).abs() <= STRETCH_JUMP,
                              (nd[1:] - nd[:-1]).abs() <= STRETCH_JUMP)
                self._inverse = torch.empty_like(order)
                self._inverse[order] = torch.arange(order.numel())  # original index -> position
        self.settings = settings

    @property
    def num_points(self) -> int:
        return int(self._xyz.shape[0])

    def rasterize(self, camera: Cameras, height: int, width: int, *, preview: bool = False,
                  should_stop: Optional[Callable[[], bool]] = None) -> Fragments:
        """The point colours rasterized by the single camera ``camera`` before hole filling
        (``Fragments.hole`` marks the pixels no point covered); ``preview`` rasterizes only
        a :meth:`StratifiedOrder.prefix` of :func:`preview_point_count` of the points.

        ``should_stop`` is checked between chunks of points; True stops with
        :class:`~stylize3d_core.errors.RenderInterrupted`."""
        keep = self.num_points
        if preview:
            keep = self._strata.prefix(preview_point_count(keep, height, width,
                                                           self.settings.preview_points_per_pixel))
        raster = RasterSettings(
            height=int(height), width=int(width),
            depth_tolerance=self.settings.depth_tolerance, supersample=self.settings.supersample,
            soft_edges=self.settings.soft_edges, blend_coverage=self.settings.blend_coverage,
        )
        size = self._size
        if size is not None and keep < self.num_points:  # a full frame uses the cached sizes as they are
            size = size[:keep] * math.sqrt(self.num_points / max(keep, 1))
        elif size is not None and self._grid is not None:
            size = self._stretched_sizes(camera, height)
        alpha = self._alpha[:keep] if self._alpha is not None and size is not None else None
        with torch.inference_mode():
            return PointRasterizer(raster)(self._xyz[:keep], self._rgb[:keep], camera, size,
                                           should_stop=should_stop, point_alpha=alpha)

    def _stretched_sizes(self, camera: Cameras, height: int) -> torch.Tensor:
        """(N,) footprints (renderer order) that also span the gap to each neighbour in this view.

        A surface seen at a slant from the new camera spreads its photo pixels apart by
        more than the magnification at the points: each layer-0 point's splat half-width
        (in view pixels) becomes at least the distance to its farthest untorn 4-neighbour
        there (where that exceeds :data:`STRETCH_MIN` times its own), as a bilinear splat's
        half-width is the spacing of its points."""
        xyz0, link_h, link_v = self._grid
        hc, wc = xyz0.shape[:2]
        with torch.inference_mode():
            w2c = camera.world_to_cam()[0].to(xyz0.dtype)  # (4, 4)
            pc = xyz0 @ w2c[:3, :3].T + w2c[:3, 3]  # (Hc, Wc, 3) camera coordinates
            z = pc[..., 2].clamp_min(1e-6)
            f = focal_from_fov(float(camera.fov_y_deg[0]), int(height))
            uv = pc[..., :2] / z[..., None] * f  # (Hc, Wc, 2) view pixels (up to the principal point)
            dh = torch.where(link_h, (uv[:, 1:] - uv[:, :-1]).norm(dim=-1), 0.0)  # (Hc, Wc - 1)
            dv = torch.where(link_v, (uv[1:] - uv[:-1]).norm(dim=-1), 0.0)  # (Hc - 1, Wc)
            gap = torch.zeros(hc, wc, dtype=xyz0.dtype)
            gap[:, :-1] = dh
            gap[:, 1:] = torch.maximum(gap[:, 1:], dh)
            gap[:-1] = torch.maximum(gap[:-1], dv)
            gap[1:] = torch.maximum(gap[1:], dv)
            size = self._size.clone()
            pos = self._inverse[: hc * wc]
            base = size[pos]  # (Hc Wc,) footprint from the magnification, scene units
            gap, z = gap.reshape(-1), z.reshape(-1)
            # a tent overlaps its neighbours' up to a spacing of twice its half-width: stretch only
            # where the spacing exceeds STRETCH_MIN times it (a nearly unstretched splat keeps its
            # 2 x 2 bilinear taps, so rasterization costs the same there)
            wide = gap > STRETCH_MIN * torch.clamp_min(base * f / z, 1.0)
            size[pos] = torch.where(wide, torch.maximum(base, gap * z / f), base)
        return size

    def render(self, camera: Cameras, height: int, width: int, *, preview: bool = False,
               should_stop: Optional[Callable[[], bool]] = None) -> np.ndarray:
        """One frame (H, W, 3) float32 in [0, 1] seen by the single camera ``camera``: the
        :meth:`rasterize` result with its holes filled.

        ``should_stop`` is checked between chunks of points while rasterizing and
        before the hole filling; True stops with
        :class:`~stylize3d_core.errors.RenderInterrupted`."""
        frags = self.rasterize(camera, height, width, preview=preview, should_stop=should_stop)
        if should_stop is not None and should_stop():
            raise RenderInterrupted("render stopped before filling holes")
        with torch.inference_mode():
            image = fill_holes(frags.image, frags.hole).clamp_(0.0, 1.0)  # (3, H, W), never NaN
        return image.permute(1, 2, 0).contiguous().numpy()

    def frames(self, cameras: Cameras, height: int, width: int) -> Iterator[np.ndarray]:
        """Lazily render one frame per camera (for streaming into a video writer)."""
        for i in range(len(cameras)):
            yield self.render(cameras[i], height, width)
