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
:data:`~stylize3d_core.render.splat.MAX_SPLAT_SCALE`) instead of ``1``, over the ``2 ceil(k)`` columns and rows nearest the point, with weights
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
everything else, and every call where Numba is missing, takes the tensor path in :mod:`~stylize3d_core.render.splat`.

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
from typing import Callable, Optional

import torch

from ..checks import check_shape
from ..errors import InputError, RenderInterrupted
from . import rasterize_fast
from .raster_settings import MAX_IMAGE_SIDE, RASTER_BACKENDS, Fragments, RasterSettings  # noqa: F401 (the rasterizer's API)
from .splat import (SparseSplat, accumulate, accumulate_by_corner, bag_offsets, blend_weights, check_stop, kept_entries,
                    pixel_bags, point_chunks, splat_points)


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



CORNER_PATH_MAX_CHANNELS = 16
"""At supersample 1, inference with at most this many channels (the plain renderer's colours) accumulates
per corner after one sort of the points (:func:`accumulate_by_corner`); wider features (the model's) are
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
    sp = splat_points(points_cam, K, settings, point_size, should_stop, chunk_points, point_alpha)
    M = sp.point.shape[0]
    E = sp.pixel.shape[0]
    step = None if chunk_points is None else 4 * chunk_points  # entries per step
    with torch.no_grad():
        w_all = sp.weight.to(features.dtype)  # (E,)
        pix = sp.pixel  # (E,)
        wsum = torch.zeros(H * W, dtype=features.dtype, device=features.device)
        for piece in point_chunks(E, step):  # in order: the same sums as one index_add_
            check_stop(should_stop)
            wsum.index_add_(0, pix[piece], w_all[piece])  # (HW,)
        hole = wsum < settings.hole_weight_threshold  # (HW,)
        inv = torch.where(hole, 0.0, 1.0 / wsum.clamp_min(settings.hole_weight_threshold))  # (HW,)
        nw = None  # (E,) entry weights normalised per pixel, 0 at holes (when not simply w * inv)
        if sp.back_weight is not None:
            nw = blend_weights(sp, w_all, inv, hole, H * W, settings.hole_weight_threshold, step, should_stop)
    table = features if features.is_contiguous() else features.contiguous()
    if torch.is_grad_enabled() and features.requires_grad:
        with torch.no_grad():
            pix_e, pt_e, w_e = kept_entries(sp, w_all, inv, step, should_stop, nw)
            pix_index, pix_offsets, pix_weights = pixel_bags(pix_e, pt_e, w_e, 0, H * W)
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
            pt_offsets = bag_offsets(counts)  # (N + 1,)
        out = SparseSplat.apply(table, pix_index, pix_offsets, pix_weights, pt_index, pt_offsets, pt_weights)
    elif sp.corner00 is not None and C <= CORNER_PATH_MAX_CHANNELS:
        with torch.no_grad():
            out = accumulate_by_corner(sp, inv, table, W, H * W, step, should_stop, nw)
    else:
        with torch.no_grad():
            pix_e, pt_e, w_e = kept_entries(sp, w_all, inv, step, should_stop, nw)
            out = accumulate(pix_e, pt_e, w_e, table, H * W, step, should_stop)
    image = out.view(H, W, C).permute(2, 0, 1)  # (C, H, W), channels-last memory
    hole = hole.view(H, W)
    depth = torch.where(hole, math.inf, sp.depth.to(features.dtype))
    return Fragments(image, wsum.view(H, W), depth, hole)




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
