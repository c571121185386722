"""Differentiable z-buffered point rasterizer: bilinear splats of C-channel features.

Conventions are those of :mod:`stylize3d_core.geometry.camera` (+z forward,
pixel centres at +0.5, ``u = fx * x / z + cx``).

What one point does (the *splat*): a point projecting to ``(u, v)`` touches the
2 x 2 pixels around it. With ``a = u - 0.5``, ``b = v - 0.5`` (so that integer
``a, b`` are pixel centres), ``x0 = floor(a)``, ``y0 = floor(b)``,
``fx = a - x0``, ``fy = b - y0``, it touches columns ``x0, x0 + 1`` with weights
``1 - fx, fx`` and rows ``y0, y0 + 1`` with weights ``1 - fy, fy``; each of the
four pixels gets the product. A point exactly at a pixel centre lands on that
pixel alone (weight 1); a point at a pixel corner gives 0.25 to each of four.
Contributions with zero weight, or outside the image, are dropped.

Grown splats (``point_size`` given): a point that stands for a patch of side
``size`` (scene units, at its depth; ``z / f_photo`` for one point per photo
pixel) covers ``k = f * size / z`` output pixels of this view. Where the view magnifies
(``k > 1``: moving in, zooming in, a finer image than the photo) the splat is a
separable tent of half-width ``k`` raster (sub-)pixels (capped at
:data:`MAX_SPLAT_SCALE`) instead of ``1``, over the ``2 ceil(k)`` columns and rows nearest the point, with weights
``max(0, 1 - |d| / k)`` normalised to sum to 1 per axis; so neighbouring points
still overlap and a magnified surface shows no gaps. With ``k <= 1`` (and
without sizes) the splat is the bilinear one above, which is the tent with ``k = 1``.

Z-buffer ("bilinear splat among the front-most surface"): per pixel, ``zmin`` is
the smallest depth among the *front-setting* contributions it receives: those
whose weight is at least ``hole_weight_threshold`` (a tap too faint to show its
point on its own, such as the ~1e-7 tap a point almost on a pixel centre gives
its neighbours, must not hide the surface behind it either); a pixel with none
takes the smallest depth of all it receives. Only contributions with
``zmin / (1 + depth_tolerance) <= z <= zmin * (1 + depth_tolerance)`` are kept, so
the points of one surface blend while a surface behind it is hidden (and the
faint taps of a nearer one are dropped). The pixel's feature is the weighted
mean of its kept contributions, ``sum(w * f) / sum(w)``. A pixel whose kept
weight sum is below ``hole_weight_threshold`` is a *hole*: its feature is 0
(the caller fills holes, e.g. :func:`stylize3d_core.render.holes.fill_holes`).

Culling comes first, before any per-contribution work: points with a NaN or
infinite coordinate, with ``z <= near_clip`` (behind or at the camera), or
whose 2 x 2 footprint misses the image are dropped. Gradients flow to the
features only (point positions are treated as constants).

Supersampling (``supersample=2``) rasterizes at ``(2H, 2W)`` with ``K`` scaled
by 2 (z-buffer per sub-pixel) and pools back: a pixel's feature is the weighted
mean of the kept contributions of its 2 x 2 sub-pixels (the average pool of
``w * f`` over the average pool of ``w``), its weight the *sum* of theirs (so
every point deposits a total weight of 1 at either setting and the hole
threshold means the same) and its depth the front-most of theirs. The
splats of neighbouring points lie 2 sub-pixels apart at (2H, 2W), so the
z-buffer test also uses the nearest front-setting depth in each sub-pixel's 3 x 3
neighbourhood ("visibility splatting"): a farther surface cannot show through the gaps of a
nearer one, even when the camera magnifies it up to 2x.

Implementation: the z-buffer is a ``scatter_reduce_("amin")`` over the corners
of the points that survive culling; the feature accumulation is a sparse (H*W, N) matrix with
pre-normalised weights times the features, computed by ``embedding_bag`` (one
bag of point indices per pixel), which never materialises a (4N, C) tensor. Its
gradient is the transposed matrix, again an ``embedding_bag`` (one bag of pixel
indices per point). Cost is linear in N and H*W.

Compiled path: inference with bilinear splats at supersample 1 (no point sizes, soft edges or
coverage blending), float32 on the CPU, runs in :mod:`~stylize3d_core.render.rasterize_fast`
(Numba kernels, the same taps and tests, sums up to float rounding; several times faster:
``bench speed`` compares the two through ``RasterSettings.backend``);
everything else, and every call where Numba is missing, takes the tensor path below.

Interruptible rasterization (``should_stop=``, e.g. the viewer's full frames):
the work runs in steps of about ``chunk_points`` points (default
:data:`CHUNK_POINTS`), with the check before each: culling, splatting and the
z-buffer (and, with ``soft_edges``, the core z-buffer) per chunk of points,
then the kept test per chunk, the weight sums in order, and the feature
accumulation in bands of consecutive pixels (each bag keeps its entries and
their order). A point's taps and weights come from its own position and
footprint alone, and the entries are laid out in the same order at any chunk
size (by tap count, then tap, then point), so the result is identical, to the
bit, to the one-shot rasterization, grown splats included.
"""

from __future__ import annotations

import math
import numbers
import threading
from dataclasses import dataclass
from typing import Callable, Dict, List, NamedTuple, Optional

import torch
import torch.nn.functional as F

from ..checks import check_range, check_shape
from ..errors import InputError, RenderInterrupted
from ..geometry.camera import project
from . import rasterize_fast


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
            bilinear one, and a grown splat's taps of weight >= :data:`CORE_WEIGHT` /
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


CORE_WEIGHT = 0.24
"""With ``soft_edges``, a tap whose weight is at least this (divided by the splat's
squared half-width) sets its pixel's front depth: the tap nearest a point weighs >= 1/4."""

_GROWN = 1.0 + 1e-3
"""A footprint below this many pixels is splatted bilinearly (rounding must not add taps)."""

MAX_SPLAT_SCALE = 4.0
"""Largest splat half-width, in (sub-)pixels: a point magnified more covers at most 8 x 8 pixels."""


class _Splats(NamedTuple):
    """The tap contributions of the M points that survive culling, as flat (E,) entries.

    Entries are grouped by tap count (ascending), and within a group tap-major:
    with one tap count for every point (``taps`` > 0, always so without point
    sizes), entry ``t * M + m`` is tap ``t`` of surviving point ``m``. The layout
    does not depend on the chunking of the points.
    """

    point: torch.Tensor  # (M,) int64 index of each surviving point into the features, ascending
    entry_point: torch.Tensor  # (E,) int64 feature row of each entry
    pixel: torch.Tensor  # (E,) int64 output pixel i * W + j of each entry, 0 where not kept
    weight: torch.Tensor  # (E,) splat weight of each entry, 0 where not kept
    kept: torch.Tensor  # (E,) bool, the entry survived the z-buffer test
    depth: torch.Tensor  # (H, W) front-most depth, +inf where nothing landed
    taps: int  # taps per point when uniform, else 0
    corner00: Optional[torch.Tensor] = None  # (M,) int64 output pixel of corner 00 (unmasked), bilinear 4-tap
    # splats at supersample 1 only
    back_weight: Optional[torch.Tensor] = None  # (E,) blend_coverage: splat weight of the entries kept
    # on the surface behind the front, 0 elsewhere
    cover: Optional[torch.Tensor] = None  # (E,) blend_coverage: front entries' tent value (times the opacity), 0 elsewhere


def _check_inputs(points_cam: torch.Tensor, features: torch.Tensor, K: torch.Tensor, settings,
                  point_size=None, features_finite: bool = False) -> None:
    if not isinstance(settings, RasterSettings):
        raise InputError("settings", f"expected RasterSettings, got {type(settings).__name__}")
    for name, t in (("points_cam", points_cam), ("features", features), ("K", K)):
        if not isinstance(t, torch.Tensor):
            raise InputError(name, f"expected a torch.Tensor, got {type(t).__name__}")
        if not t.is_floating_point():
            raise InputError(name, f"expected a floating-point tensor, got {t.dtype}")
    check_shape(points_cam, "points_cam", (None, 3))
    check_shape(features, "features", (points_cam.shape[0], None))
    check_shape(K, "K", (3, 3))
    if points_cam.shape[0] >= 2**31:
        raise InputError("points_cam", f"at most 2**31 - 1 points, got {points_cam.shape[0]}")
    if features.shape[1] < 1:
        raise InputError("features", "must have at least one channel")
    if features.dtype not in (torch.float32, torch.float64):
        raise InputError("features", f"expected float32 or float64, got {features.dtype}")
    if features.device != points_cam.device:
        raise InputError("features", f"on {features.device}, points_cam on {points_cam.device}")
    if not torch.isfinite(K).all():
        raise InputError("K", "contains NaN or infinite values")
    if point_size is not None:
        if not isinstance(point_size, torch.Tensor) or not point_size.is_floating_point():
            raise InputError("point_size", "expected a floating-point torch.Tensor")
        check_shape(point_size, "point_size", (points_cam.shape[0],))
        if point_size.device != points_cam.device:
            raise InputError("point_size", f"on {point_size.device}, points_cam on {points_cam.device}")
    if features_finite:  # the caller checked them (a full frame's 1.7M x 35 sum: ~8 ms of each frame)
        return
    # One reduction is far cheaper than an element-wise test; a non-finite sum is
    # only a hint (it can also overflow), confirmed by the exact test.
    with torch.no_grad():
        if not torch.isfinite(features.sum()) and not torch.isfinite(features).all():
            raise InputError("features", "contains NaN or infinite values")


def _check_alpha(point_alpha, points_cam: torch.Tensor) -> None:
    if not isinstance(point_alpha, torch.Tensor) or not point_alpha.is_floating_point():
        raise InputError("point_alpha", "expected a floating-point torch.Tensor")
    check_shape(point_alpha, "point_alpha", (points_cam.shape[0],))
    if point_alpha.device != points_cam.device:
        raise InputError("point_alpha", f"on {point_alpha.device}, points_cam on {points_cam.device}")
    if point_alpha.numel() and not bool(((point_alpha >= 0.0) & (point_alpha <= 1.0)).all()):
        raise InputError("point_alpha", "opacities must lie in [0, 1] (no NaN)")


def _check_stop(should_stop: Optional[Callable[[], bool]]) -> None:
    if should_stop is not None and should_stop():
        raise RenderInterrupted("render stopped while rasterizing")


def _pieces(n: int, step: Optional[int]) -> List[slice]:
    """Consecutive slices covering range(n), ``step`` long (one slice if None); one empty slice if n == 0."""
    if step is None or n <= step:
        return [slice(0, n)]
    return [slice(i, min(i + step, n)) for i in range(0, n, step)]


def _row_sum(t: torch.Tensor) -> torch.Tensor:
    """(1, m): the sum of the rows of (k, m) ``t``, added in row order, column by column."""
    total = t[0].clone()
    for k in range(1, t.shape[0]):
        total += t[k]
    return total[None]


@torch.no_grad()
def _splat(points_cam: torch.Tensor, K: torch.Tensor, settings: RasterSettings, point_size=None,
           should_stop: Optional[Callable[[], bool]] = None, chunk: Optional[int] = None,
           point_alpha: Optional[torch.Tensor] = None) -> _Splats:
    """Cull, splat and z-buffer: everything but the feature accumulation.

    Per-tap arrays are (T, m) per group of points with the same tap count
    (rows are taps): element-wise work on contiguous rows is several times
    faster than on (m, T).

    With ``chunk``, the points are processed ``chunk`` at a time (``should_stop``
    checked before each): a point's taps depend on that point alone and the
    z-buffers are a min, so the result is the same; the chunks' groups are
    joined in point order, which gives the one-shot layout.
    """
    s = settings.supersample
    H, W = settings.height, settings.width
    Hs, Ws = H * s, W * s  # raster (sub-pixel) size
    dtype = points_cam.dtype if points_cam.dtype == torch.float64 else torch.float32
    dev = points_cam.device
    Ks = K.detach().to(device=dev, dtype=dtype).clone()
    Ks[:2] *= s  # (3, 3) intrinsics of the sub-pixel raster
    soft = settings.soft_edges
    # at 2x the sub-pixel z-buffer anti-aliases silhouettes; without point sizes a magnified surface's
    # bilinear splats do not tile the view, so their weight does not measure the coverage
    blend = settings.blend_coverage and s == 1 and point_size is not None
    zbuf = torch.full((Hs * Ws,), math.inf, dtype=dtype, device=dev)  # least depth of every tap
    zfront = torch.full((Hs * Ws,), math.inf, dtype=dtype, device=dev)  # least depth of the front-setting taps
    strong_weight = settings.hole_weight_threshold

    chunks: List[Dict[int, tuple]] = []  # per chunk: reach -> (rows, w, ok, q, o, zg, c00)
    survivors = []
    for piece in _pieces(points_cam.shape[0], chunk):
        _check_stop(should_stop)
        pts = points_cam[piece].detach().to(dtype)
        uv, z = project(pts, Ks)  # (n, 2), (n,)
        a, b = uv[:, 0] - 0.5, uv[:, 1] - 0.5  # (n,) integers at pixel centres
        if point_size is None:
            half = torch.ones_like(z)  # (n,) splat half-width in raster pixels: bilinear
        else:
            size = point_size[piece].detach().to(device=dev, dtype=dtype)
            # the footprint in *output* pixels: with supersampling, the bilinear sub-pixel splats
            # already cover a point spacing of s sub-pixels (pooling and visibility splatting)
            half = (K[0, 0].detach().abs().to(dtype) * size / z.abs().clamp_min(1e-12)).nan_to_num(1.0)
            half = torch.where(half < _GROWN, 1.0, half.clamp(max=MAX_SPLAT_SCALE))  # ~1 stays bilinear
        # NaN fails every comparison; an infinite x or y gives an infinite a or b.
        inside = (z > settings.near_clip) & (z < math.inf) & (a > -half) & (a < Ws - 1 + half)
        inside &= (b > -half) & (b < Hs - 1 + half)
        idx = inside.nonzero().squeeze(1)  # (m,) surviving points of the chunk, ascending
        a, b, z, half = (t.index_select(0, idx) for t in (a, b, z, half))  # (m,)
        idx = idx + piece.start  # (m,) into the features
        survivors.append(idx)
        reach = half.ceil().long()  # (m,) taps per side of the point, per axis
        groups = [None] if point_size is None else [int(r) for r in torch.unique(reach).tolist()]

        # Per group: taps, weights and raster indices (flat, unpadded; outside taps have weight 0).
        parts = {}
        for r in groups:
            sel = None if r is None else (reach == r).nonzero().squeeze(1)  # (mg,) into the survivors
            r = 1 if r is None else r
            ag, bg_, zg, hg = (t if sel is None else t.index_select(0, sel) for t in (a, b, z, half))
            x0f, y0f = ag.floor(), bg_.floor()
            offs = torch.arange(1 - r, r + 1, device=dev, dtype=dtype)  # (2r,) tap offsets per axis
            xs, ys = x0f + offs[:, None], y0f + offs[:, None]  # (2r, mg)
            if point_size is None:  # half-width 1: the division is exact, skip it
                wx = (1.0 - (xs - ag).abs()).clamp_min_(0.0)  # (2r, mg) tent of half-width 1
                wy = (1.0 - (ys - bg_).abs()).clamp_min_(0.0)
            else:
                wx = (1.0 - (xs - ag).abs() / hg).clamp_min(0.0)  # (2r, mg) tent of half-width hg
                wy = (1.0 - (ys - bg_).abs() / hg).clamp_min(0.0)
            T, mg = 4 * r * r, ag.shape[0]
            # blend_coverage: a tap's share of its pixel is the tent's own value there: tents of half-width
            # h spaced h apart sum to exactly 1 (a partition of unity), so a magnified surface covers its
            # pixels wholly at any phase of its points against the pixel grid (the normalised weights times
            # h^2 summed to 0.8-1.1 with the phase, and the surface behind showed through as a grid)
            tent = (wy[:, None] * wx[None]).reshape(T, mg) if blend else None
            if r > 1:  # every point deposits a total weight of 1 (the bilinear weights already do)
                # summed row by row (element-wise, in a fixed order): a reduction kernel's order can
                # depend on the number of points, and the result must not depend on the chunking
                wx = wx / _row_sum(wx)
                wy = wy / _row_sum(wy)
            w = (wy[:, None] * wx[None]).reshape(T, mg)  # (T, mg), row = dy * 2r + dx
            # per axis (2r, mg), then combined: the same as testing the (T, mg) taps
            xl, yl = xs.long(), ys.long()
            ok = ((yl >= 0) & (yl < Hs))[:, None] & ((xl >= 0) & (xl < Ws))[None]  # (2r, 2r, mg)
            ok = ok.reshape(T, mg) & (w > 0)
            raster = (yl * Ws)[:, None] + xl[None]  # (2r, 2r, mg): yi * Ws + xi
            raster = raster.reshape(T, mg)
            q = torch.where(ok, raster, 0)  # (T, mg) raster index
            if s == 1:
                o = raster  # (T, mg) output pixel of each tap
            else:
                o = ((yl >> 1) * W)[:, None] + (xl >> 1)[None]
                o = o.reshape(T, mg)
            zbuf.scatter_reduce_(0, q.reshape(-1), torch.where(ok, zg, math.inf).reshape(-1), reduce="amin")
            # Front-setting taps: a tap too faint to show its point on its own (weight below the
            # hole threshold) must not hide the surface behind it either.
            sets = ok & (w >= strong_weight)  # (T, mg)
            if soft:  # and only core taps (bilinear taps all are)
                sets &= (w >= CORE_WEIGHT / (hg * hg)) | (hg == 1.0)
            zfront.scatter_reduce_(0, q.reshape(-1), torch.where(sets, zg, math.inf).reshape(-1), reduce="amin")
            rows = idx if sel is None else idx.index_select(0, sel)
            c00 = o[0] if (r == 1 and s == 1) else None  # (mg,) corner 00 = y0 * W + x0, unmasked
            parts[r] = (rows, w, ok, q, o, zg, c00, sets, tent)
        chunks.append(parts)

    # A (sub-)pixel's own front: its front-setting taps' least depth, where it has one, else its
    # least depth of all (a pixel reached by faint taps alone; it is a hole unless they add up).
    own = torch.where(zfront < math.inf, zfront, zbuf)  # (Hs * Ws,)
    if s == 2:
        _check_stop(should_stop)
        # Visibility splatting: a sub-pixel's front is also the nearest front-setting depth in its
        # 3 x 3 neighbourhood, so a surface behind cannot show through the gaps between
        # the 2 x 2 splats of a front surface (they are 2 sub-pixels apart).
        near = -F.max_pool2d(-zfront.view(1, 1, Hs, Ws), 3, stride=1, padding=1).view(-1)  # (Hs * Ws,)
        near = torch.minimum(near, own)
    else:
        near = own

    tol = 1.0 + settings.depth_tolerance
    zback = torch.full((Hs * Ws,), math.inf, dtype=dtype, device=dev) if blend else None  # next surface's front
    tested: Dict[int, list] = {}  # reach -> per chunk (rows, pixel, weight, kept, c00, back, cover), in point order
    for parts in chunks:
        if len(chunks) > 1:
            _check_stop(should_stop)
        for r, (rows, w, ok, q, o, zg, c00, sets, _) in parts.items():
            front = near.index_select(0, q.reshape(-1)).view_as(q)  # (T, mg)
            keep = (zg <= front * tol) & ok  # (T, mg)
            # a nearer surface's faint taps (or, with soft edges, its fringe) give way to the front
            keep &= zg * tol >= front
            if blend:  # the front-setting taps behind the front band set the next surface's front
                behind = sets & (zg > front * tol)
                zback.scatter_reduce_(0, q.reshape(-1), torch.where(behind, zg, math.inf).reshape(-1), reduce="amin")
            tested.setdefault(r, []).append([rows, torch.where(keep, o, 0), torch.where(keep, w, 0.0), keep, c00,
                                             None, None])
    if blend:
        for k, parts in enumerate(chunks):
            if len(chunks) > 1:
                _check_stop(should_stop)
            for r, (rows, w, ok, q, o, zg, c00, sets, tent) in parts.items():
                entry = tested[r][sum(1 for c in chunks[:k] if r in c)]
                front = near.index_select(0, q.reshape(-1)).view_as(q)
                z2 = zback.index_select(0, q.reshape(-1)).view_as(q)
                back = ok & (zg > front * tol) & (zg <= z2 * tol) & (zg * tol >= z2)  # (T, mg)
                entry[1] = torch.where(back, o, entry[1])
                entry[3] = entry[3] | back
                entry[5] = torch.where(back, w, 0.0)
                cover = tent  # a tap's share of its pixel (the splats of one surface tile the view)
                if point_alpha is not None:  # ... times its point's opacity
                    cover = cover * point_alpha.index_select(0, rows).to(device=dev, dtype=dtype)
                entry[6] = torch.where(entry[3] & ~back, cover, 0.0)  # coverage of the kept front taps

    # Join the chunks per group (along the points, which keeps them ascending), groups by tap count:
    # the same layout as one chunk.
    cat1 = (lambda xs, dim=0: xs[0] if len(xs) == 1 else torch.cat(xs, dim))
    entry_point, pixel, weight, kept, back_w, cover = [], [], [], [], [], []
    for r in sorted(tested):
        pieces = tested[r]
        rows = cat1([p[0] for p in pieces])  # (Mg,)
        T = pieces[0][1].shape[0]
        pixel.append(cat1([p[1] for p in pieces], 1).reshape(-1))
        weight.append(cat1([p[2] for p in pieces], 1).reshape(-1))
        kept.append(cat1([p[3] for p in pieces], 1).reshape(-1))
        if blend:
            back_w.append(cat1([p[5] for p in pieces], 1).reshape(-1))
            cover.append(cat1([p[6] for p in pieces], 1).reshape(-1))
        entry_point.append(rows.repeat(T))  # tap-major, as the (T, Mg) rows
    depth = own.view(Hs, Ws)
    if s == 2:
        depth = depth.reshape(H, 2, W, 2).amin(dim=(1, 3))
    taps = tested[next(iter(tested))][0][1].shape[0] if len(tested) == 1 else 0
    if len(tested) == 0:
        taps = 4
    c00 = None
    if s == 1 and list(tested) == [1]:
        c00 = cat1([p[4] for p in tested[1]])
    elif s == 1 and len(tested) == 0:
        c00 = torch.zeros(0, dtype=torch.long, device=dev)
    cat = (lambda xs, like: (xs[0] if len(xs) == 1 else torch.cat(xs)) if xs else
           torch.zeros(0, dtype=like, device=dev))
    return _Splats(cat1(survivors), cat(entry_point, torch.long), cat(pixel, torch.long), cat(weight, dtype),
                   cat(kept, torch.bool), depth.clone(), taps, c00,
                   cat(back_w, dtype) if blend else None, cat(cover, dtype) if blend else None)


def _bag_sum(index: torch.Tensor, table: torch.Tensor, offsets: torch.Tensor, weights: torch.Tensor):
    """(B, C): bag b is ``sum_k weights[k] * table[index[k]]`` over ``offsets[b] <= k < offsets[b + 1]``."""
    return F.embedding_bag(index, table, offsets, mode="sum", per_sample_weights=weights, include_last_offset=True)


class _SparseSplat(torch.autograd.Function):
    """``out = S @ features`` for a sparse S given in both row- and column-major bags."""

    @staticmethod
    def forward(ctx, features, pix_index, pix_offsets, pix_weights, pt_index, pt_offsets, pt_weights):
        ctx.save_for_backward(pt_index, pt_offsets, pt_weights)
        # Detached, embedding_bag skips the bookkeeping for its own backward.
        return _bag_sum(pix_index, features.detach(), pix_offsets, pix_weights)  # (HW, C)

    @staticmethod
    def backward(ctx, grad):
        pt_index, pt_offsets, pt_weights = ctx.saved_tensors
        grad_features = _bag_sum(pt_index, grad.contiguous(), pt_offsets, pt_weights)  # (N, C)
        return grad_features, None, None, None, None, None, None


def _offsets(counts: torch.Tensor, dtype: torch.dtype = torch.long) -> torch.Tensor:
    """(B + 1,) exclusive prefix sum of (B,) counts."""
    out = torch.zeros(counts.numel() + 1, dtype=dtype, device=counts.device)
    torch.cumsum(counts, dim=0, out=out[1:])
    return out


CORNER_PATH_MAX_CHANNELS = 16
"""At supersample 1, inference with at most this many channels (the plain renderer's colours) accumulates
per corner after one sort of the points (:func:`_accumulate_by_corner`); wider features (the model's) are
faster with one sort of all the kept corners, which reads each feature row once per pixel."""

CHUNK_POINTS = 1 << 18
"""Points per step of an interruptible rasterization (``should_stop`` given): ~30-40 ms each on one CPU core."""


def rasterize_points(
    points_cam: torch.Tensor, features: torch.Tensor, K: torch.Tensor, settings: RasterSettings,
    point_size: Optional[torch.Tensor] = None, *,
    should_stop: Optional[Callable[[], bool]] = None, chunk_points: Optional[int] = None,
    features_finite: bool = False, point_alpha: Optional[torch.Tensor] = None,
) -> Fragments:
    """Rasterize points with features into an image (see the module docstring).

    Args:
        points_cam: (N, 3) floating points in the camera frame; non-finite
            points are culled. Computation is float32 unless these are float64.
        features: (N, C) float32 or float64 finite features; gradients flow to them.
        K: (3, 3) finite intrinsics at the output size (H, W) (skew is ignored,
            as in :func:`stylize3d_core.geometry.camera.project`).
        settings: image size, depth tolerance, supersampling, hole threshold, near clip.
        point_size: optional (N,) footprint of each point, in scene units at its depth
            (e.g. ``z / f`` for a point per photo pixel): its splat grows with the
            magnification (see the module docstring). None: bilinear splats.
        should_stop: checked between steps of about ``chunk_points`` points (or
            entries); once it returns True the call raises
            :class:`~stylize3d_core.errors.RenderInterrupted`.
        chunk_points: points per step (default :data:`CHUNK_POINTS` with
            ``should_stop``, else all at once). The result is the same, to the
            bit, at any chunk size: a point's splat depends on that point alone,
            the z-buffers are a min, the weight sums are added in the same order,
            and the feature accumulation runs in bands of pixels whose bags hold
            the same entries in the same order.
        features_finite: True where the caller has checked that every feature is finite (a
            renderer drawing the same features frame after frame checks them once); False
            (default) checks them here.
        point_alpha: optional (N,) opacity of each point in [0, 1], used by ``blend_coverage``
            only: a front tap's coverage is scaled by its point's opacity, so a point that covers
            part of its photo pixel (an anti-aliased silhouette, see
            :attr:`~stylize3d_core.scene.ldi.LDI.alpha`) shows the surface behind it through the rest.
            None: every point opaque. Without ``blend_coverage`` (and on the compiled path, which never
            blends) it is not used.
    Returns:
        :class:`Fragments` ``image (C, H, W), weight (H, W), depth (H, W), hole (H, W)``.
    Raises:
        InputError: on a wrong shape or dtype, a non-finite K or features, a chunk_points < 1.
        RenderInterrupted: ``should_stop()`` returned True.
    """
    _check_inputs(points_cam, features, K, settings, point_size, features_finite)
    if point_alpha is not None:
        _check_alpha(point_alpha, points_cam)
    if chunk_points is None and should_stop is not None:
        chunk_points = CHUNK_POINTS
    if chunk_points is not None:
        if isinstance(chunk_points, bool) or not isinstance(chunk_points, numbers.Integral) or chunk_points < 1:
            raise InputError("chunk_points", f"must be a positive integer, got {chunk_points!r}")
        chunk_points = int(chunk_points)
    H, W = settings.height, settings.width
    C = features.shape[1]
    N = points_cam.shape[0]
    if rasterize_fast.applies(points_cam, features, settings, point_size):  # the compiled inference path
        try:
            out, wsum, depth, hole = rasterize_fast.rasterize_fast(points_cam, features, K, settings,
                                                                   should_stop, chunk_points)
        except RenderInterrupted:
            raise
        except Exception as exc:  # noqa: BLE001 (kernels that fail to compile or run here: the tensor path)
            rasterize_fast.disable(exc)
        else:
            return Fragments(out.view(H, W, C).permute(2, 0, 1), wsum.view(H, W), depth.view(H, W),
                             hole.view(H, W))
    sp = _splat(points_cam, K, settings, point_size, should_stop, chunk_points, point_alpha)
    M = sp.point.shape[0]
    E = sp.pixel.shape[0]
    step = None if chunk_points is None else 4 * chunk_points  # entries per step
    with torch.no_grad():
        w_all = sp.weight.to(features.dtype)  # (E,)
        pix = sp.pixel  # (E,)
        wsum = torch.zeros(H * W, dtype=features.dtype, device=features.device)
        for piece in _pieces(E, step):  # in order: the same sums as one index_add_
            _check_stop(should_stop)
            wsum.index_add_(0, pix[piece], w_all[piece])  # (HW,)
        hole = wsum < settings.hole_weight_threshold  # (HW,)
        inv = torch.where(hole, 0.0, 1.0 / wsum.clamp_min(settings.hole_weight_threshold))  # (HW,)
        nw = None  # (E,) entry weights normalised per pixel, 0 at holes (when not simply w * inv)
        if sp.back_weight is not None:
            nw = _blend_weights(sp, w_all, inv, hole, H * W, settings.hole_weight_threshold, step, should_stop)
    table = features if features.is_contiguous() else features.contiguous()
    if torch.is_grad_enabled() and features.requires_grad:
        with torch.no_grad():
            pix_e, pt_e, w_e = _kept_entries(sp, w_all, inv, step, should_stop, nw)
            pix_index, pix_offsets, pix_weights = _pixel_bags(pix_e, pt_e, w_e, 0, H * W)
            # Point-major bags for the gradient: the taps of each surviving point
            # (weight 0 where not kept), none for culled points.
            if nw is None:
                nw = w_all * inv.index_select(0, pix)  # (E,) weights normalised per pixel, 0 at holes
            if sp.taps:
                pt_index = pix.view(sp.taps, M).t().reshape(-1)  # (E,)
                pt_weights = nw.view(sp.taps, M).t().reshape(-1)
            else:
                by_point = torch.sort(sp.entry_point, stable=True).indices  # (E,)
                pt_index, pt_weights = pix.index_select(0, by_point), nw.index_select(0, by_point)
            counts = torch.bincount(sp.entry_point, minlength=N)  # (N,)
            pt_offsets = _offsets(counts)  # (N + 1,)
        out = _SparseSplat.apply(table, pix_index, pix_offsets, pix_weights, pt_index, pt_offsets, pt_weights)
    elif sp.corner00 is not None and C <= CORNER_PATH_MAX_CHANNELS:
        with torch.no_grad():
            out = _accumulate_by_corner(sp, inv, table, W, H * W, step, should_stop, nw)
    else:
        with torch.no_grad():
            pix_e, pt_e, w_e = _kept_entries(sp, w_all, inv, step, should_stop, nw)
            out = _accumulate(pix_e, pt_e, w_e, table, H * W, step, should_stop)
    image = out.view(H, W, C).permute(2, 0, 1)  # (C, H, W), channels-last memory
    hole = hole.view(H, W)
    depth = torch.where(hole, math.inf, sp.depth.to(features.dtype))
    return Fragments(image, wsum.view(H, W), depth, hole)


def _blend_weights(sp: _Splats, w_all: torch.Tensor, inv: torch.Tensor, hole: torch.Tensor, n_pixels: int,
                   threshold: float, step: Optional[int], should_stop: Optional[Callable[[], bool]]) -> torch.Tensor:
    """(E,) entry weights of ``blend_coverage``: ``coverage * front + (1 - coverage) * behind`` per pixel.

    A pixel's coverage is the sum of its front entries' ``cover`` (the tent's value at the tap, so a
    surface of points one splat half-width apart covers 1), at most 1; where the
    surface behind has a kept weight of at least ``threshold``, the front's normalised weights are
    scaled by the coverage and the behind's by the rest; elsewhere the front alone is normalised.
    """
    dt = w_all.dtype
    cov = torch.zeros(n_pixels, dtype=dt, device=w_all.device)
    wback = torch.zeros(n_pixels, dtype=dt, device=w_all.device)
    pix = sp.pixel
    back, cover = sp.back_weight.to(dt), sp.cover.to(dt)
    for piece in _pieces(pix.shape[0], step):  # in order, as the weight sums
        _check_stop(should_stop)
        cov.index_add_(0, pix[piece], cover[piece])
        wback.index_add_(0, pix[piece], back[piece])
    blended = (wback >= threshold) & ~hole  # (HW,)
    alpha = torch.where(blended, cov.clamp(max=1.0), 1.0)
    inv_back = torch.where(blended, (1.0 - alpha) / wback.clamp_min(threshold), 0.0)
    return w_all * (inv * alpha).index_select(0, pix) + back * inv_back.index_select(0, pix)


def _kept_entries(sp: _Splats, w_all: torch.Tensor, inv: torch.Tensor, step: Optional[int],
                  should_stop: Optional[Callable[[], bool]], nw: Optional[torch.Tensor] = None):
    """The kept entries, in entry order (cache friendly): pixel (E',) int64, feature row (E',) int32 and
    weight normalised per pixel (E',) (0 at holes; ``nw`` (E,) when given, else ``w_all * inv``). int32
    sorts and gathers faster; indices are < 2**28 (MAX_IMAGE_SIDE**2) and N < 2**31."""
    E = sp.pixel.shape[0]
    pt_all = sp.entry_point.int()  # (E,)
    pix_l, pt_l, w_l = [], [], []
    for piece in _pieces(E, step):
        _check_stop(should_stop)
        e = sp.kept[piece].nonzero().squeeze(1) + piece.start  # (e,) ascending
        pix_c = sp.pixel.index_select(0, e)
        pix_l.append(pix_c)
        pt_l.append(pt_all.index_select(0, e))
        w_l.append(w_all.index_select(0, e) * inv.index_select(0, pix_c) if nw is None else nw.index_select(0, e))
    return tuple(t[0] if len(t) == 1 else torch.cat(t) for t in (pix_l, pt_l, w_l))


def _accumulate_by_corner(sp: _Splats, inv: torch.Tensor, table: torch.Tensor, W: int, n_pixels: int,
                          step: Optional[int], should_stop: Optional[Callable[[], bool]],
                          nw: Optional[torch.Tensor] = None) -> torch.Tensor:
    """(n_pixels, C) weighted feature sums at supersample 1 (inference only, bilinear 4-tap splats: the
    entries are (4, M) corner-major), with one sort of the M points.

    The points are sorted (stably) by the output pixel of their corner 00; corner
    (dy, dx) lands on that pixel + dy W + dx, so the same order is pixel-major
    for every corner: four pixel-major bag lists from one sort of M keys (not
    4M), summed per pixel. With ``step``, the pixels are done in bands (each a
    slice of the four lists, ``should_stop`` checked before each); the bags are
    the same, so the sums are identical.
    """
    _check_stop(should_stop)
    M = sp.point.shape[0]
    kept4, weight4 = sp.kept.view(4, M), sp.weight.view(4, M) if nw is None else nw.view(4, M)
    order = torch.sort(sp.corner00.int(), stable=True).indices  # (M,)
    o_sorted = sp.corner00.index_select(0, order)  # (M,) ascending
    pt_sorted = sp.point.int().index_select(0, order)
    lists = []
    for c, off in enumerate((0, 1, W, W + 1)):
        _check_stop(should_stop)
        e = kept4[c].index_select(0, order).nonzero().squeeze(1)  # (e,) ascending
        pix = o_sorted.index_select(0, e) + off  # (e,) ascending, in [0, n_pixels)
        w = weight4[c].index_select(0, order).index_select(0, e).to(table.dtype)
        if nw is None:
            w = w * inv.index_select(0, pix)
        lists.append((pix, pt_sorted.index_select(0, e), w))
    E = sum(int(p.shape[0]) for p, _, _ in lists)
    n_bands = 1 if step is None else max(1, -(-E // step))
    band_px = -(-n_pixels // n_bands) if n_pixels else 1
    out = torch.empty(n_pixels, table.shape[1], dtype=table.dtype, device=table.device)
    for lo in range(0, n_pixels, band_px):
        hi = min(lo + band_px, n_pixels)
        if n_bands > 1:
            _check_stop(should_stop)
        acc = None
        for pix, idx, w in lists:
            a, b = (int(v) for v in torch.searchsorted(pix, torch.tensor([lo, hi], device=pix.device)))
            offsets = _offsets(torch.bincount(pix[a:b] - lo, minlength=hi - lo), torch.int32)
            part = _bag_sum(idx[a:b], table, offsets, w[a:b])  # (hi - lo, C)
            acc = part if acc is None else acc.add_(part)
        out[lo:hi] = acc
    return out


def _pixel_bags(pix_e: torch.Tensor, pt_e: torch.Tensor, w_e: torch.Tensor, lo: int, hi: int):
    """Bags of the entries of pixels lo..hi-1 (all entries must lie there), pixel-major, each bag in entry order:
    (feature rows (E,) int32, offsets (hi - lo + 1,) int32, weights (E,))."""
    order = torch.sort(pix_e.int(), stable=True).indices  # (E,) pixel-major
    offsets = _offsets(torch.bincount(pix_e - lo, minlength=hi - lo), torch.int32)  # (hi - lo + 1,)
    return pt_e.index_select(0, order), offsets, w_e.index_select(0, order)


def _accumulate(pix_e: torch.Tensor, pt_e: torch.Tensor, w_e: torch.Tensor, table: torch.Tensor, n_pixels: int,
                step: Optional[int], should_stop: Optional[Callable[[], bool]]) -> torch.Tensor:
    """(n_pixels, C): per pixel, the weighted sum of its entries' feature rows (inference only).

    With ``step``, in bands of consecutive pixels holding about ``step`` entries
    each (``should_stop`` checked before each band); a pixel's bag holds the
    same entries in the same order as in one pass, so the sums are identical.
    """
    E = pix_e.shape[0]
    if step is None or E <= step:
        _check_stop(should_stop)
        return _bag_sum_bags(_pixel_bags(pix_e, pt_e, w_e, 0, n_pixels), table)
    n_bands = -(-E // step)
    band_px = -(-n_pixels // n_bands)
    out = torch.empty(n_pixels, table.shape[1], dtype=table.dtype, device=table.device)
    band = torch.div(pix_e, band_px, rounding_mode="floor").int()  # (E,) band of each entry
    for k in range(n_bands):
        _check_stop(should_stop)
        lo, hi = k * band_px, min((k + 1) * band_px, n_pixels)
        if lo >= hi:
            break
        sel = (band == k).nonzero().squeeze(1)  # (e,) ascending: the entries keep their order
        bags = _pixel_bags(pix_e.index_select(0, sel), pt_e.index_select(0, sel), w_e.index_select(0, sel), lo, hi)
        out[lo:hi] = _bag_sum_bags(bags, table)
    return out


def _bag_sum_bags(bags, table: torch.Tensor) -> torch.Tensor:
    index, offsets, weights = bags
    return _bag_sum(index, table, offsets, weights)


_WARM: Optional[threading.Thread] = None
_WARM_LOCK = threading.Lock()


def warm_up_async() -> None:
    """Import Numba and load (or, the first time on a machine, compile) the compiled path's kernels
    (:mod:`.rasterize_fast`) in a daemon thread, once per process, so the first frame does not wait for
    them; the stages that call this (the style prefetch, ``Stylized3DPhoto``) run while the photo's depth,
    LDI or geometry are being built."""
    global _WARM
    with _WARM_LOCK:
        if _WARM is None:
            _WARM = threading.Thread(target=_warm_up, name="stylize3d-raster-warm-up", daemon=True)
            _WARM.start()


def wait_warm(timeout: Optional[float] = None) -> None:
    """Start the warm-up if needed (:func:`warm_up_async`) and wait until the kernels are loaded."""
    warm_up_async()
    _WARM.join(timeout)


def _warm_up() -> None:
    try:
        if not rasterize_fast.available():
            return
        K = torch.tensor([[2.0, 0.0, 1.0], [0.0, 2.0, 1.0], [0.0, 0.0, 1.0]])
        with torch.inference_mode():  # one point: each kernel runs once with the real argument types
            rasterize_fast.rasterize_fast(torch.tensor([[0.0, 0.0, 1.0]]), torch.ones(1, 1), K,
                                          RasterSettings(2, 2))
    except Exception:  # noqa: BLE001 (a failed warm-up is only a slower first frame; the render reports)
        return
