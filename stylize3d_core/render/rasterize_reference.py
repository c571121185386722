"""Slow, obvious reference of :func:`stylize3d_core.render.rasterize.rasterize_points`.

Python loops over points and pixels, float64 throughout; for tests on small
inputs only. Semantics (see the fast module's docstring) are spelled out step
by step: cull, splat each point bilinearly onto its 2 x 2 (sub-)pixels, find the
front depth per (sub-)pixel (set by taps of weight >= the hole threshold), keep the
contributions within the relative depth tolerance of it, pool sub-pixels into output pixels, normalise.

The image is built as ``A @ features`` with a dense (H*W, N) coefficient matrix
``A``, so autograd gives the reference gradient with respect to the features.
"""

from __future__ import annotations

import math
from collections import defaultdict

import torch

from ..checks import check_shape
from ..errors import InputError
from .raster_settings import Fragments, RasterSettings
from .splat import CORE_WEIGHT, MAX_SPLAT_SCALE


def rasterize_points_reference(
    points_cam: torch.Tensor, features: torch.Tensor, K: torch.Tensor, settings: RasterSettings,
    point_size=None, point_alpha=None,
) -> Fragments:
    """Reference rasterizer: same arguments and result as ``rasterize_points``.

    Args:
        points_cam: (N, 3) points in the camera frame.
        features: (N, C) features (gradients flow to them).
        K: (3, 3) intrinsics at the output size.
        settings: the raster settings.
        point_size: optional (N,) footprint of each point in scene units (grown splats).
        point_alpha: optional (N,) opacity of each point (``blend_coverage``: scales its taps' coverage).
    Returns:
        Fragments with image (C, H, W), weight (H, W), depth (H, W), hole (H, W),
        computed in float64 and returned in the features' dtype.
    """
    check_shape(points_cam, "points_cam", (None, 3))
    check_shape(features, "features", (points_cam.shape[0], None))
    check_shape(K, "K", (3, 3))
    if not torch.isfinite(K).all():
        raise InputError("K", "contains NaN or infinite values")
    s = settings.supersample
    H, W = settings.height, settings.width
    Hs, Ws = H * s, W * s
    N, C = features.shape
    k = K.detach().double().tolist()
    fx, fy, cx, cy = k[0][0] * s, k[1][1] * s, k[0][2] * s, k[1][2] * s

    # 1. Splat: sub-pixel (i, j) -> list of (point, weight, depth).
    received = defaultdict(list)
    sizes = [None] * N if point_size is None else point_size.detach().double().tolist()
    opacity = [1.0] * N if point_alpha is None else point_alpha.detach().double().tolist()
    for n, ((x, y, z), size) in enumerate(zip(points_cam.detach().double().tolist(), sizes)):
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
            continue
        if z <= settings.near_clip:
            continue
        # half-width of the tent: 1 (bilinear), or the point's footprint in raster pixels
        half = 1.0 if size is None else min(MAX_SPLAT_SCALE, fx / s * size / z)  # output pixels
        half = 1.0 if half < 1.0 + 1e-3 else half  # bilinear
        a = fx * x / z + cx - 0.5
        b = fy * y / z + cy - 0.5
        if not (-half < a < Ws - 1 + half and -half < b < Hs - 1 + half):
            continue
        r = math.ceil(half)
        x0, y0 = math.floor(a), math.floor(b)
        cols = [(j, max(0.0, 1.0 - abs(j - a) / half)) for j in range(x0 + 1 - r, x0 + r + 1)]
        rows = [(i, max(0.0, 1.0 - abs(i - b) / half)) for i in range(y0 + 1 - r, y0 + r + 1)]
        sx, sy = 1.0, 1.0
        if r > 1:  # normalised: every point deposits a total weight of 1
            sx, sy = sum(w for _, w in cols), sum(w for _, w in rows)
        for i, wy in rows:
            for j, wx in cols:
                w = wx * wy / (sx * sy)
                tent = wx * wy * opacity[n]  # blend_coverage: the tap's share of its pixel
                if w > 0 and 0 <= i < Hs and 0 <= j < Ws:
                    received[(i, j)].append((n, w, z, half == 1.0 or w >= CORE_WEIGHT / half**2, tent))

    # 2. Z-buffer per sub-pixel, keep the front surface, pool into output pixels.
    A = torch.zeros(H * W, N, dtype=torch.float64)
    wsum = torch.zeros(H * W, dtype=torch.float64)
    B = torch.zeros(H * W, N, dtype=torch.float64)  # blend_coverage: the surface behind the front
    wback = torch.zeros(H * W, dtype=torch.float64)
    cover = torch.zeros(H * W, dtype=torch.float64)
    depth = torch.full((H * W,), math.inf, dtype=torch.float64)
    def sets_front(w, core):
        # a tap too faint to show its point alone (below the hole threshold) does not hide what is
        # behind; with soft edges, only core taps set the front
        return w >= settings.hole_weight_threshold and (core or not settings.soft_edges)

    # the least depth of the front-setting contributions (inf where none), and the own front:
    # that, or the least depth of all where a (sub-)pixel has no front-setting contribution
    strong = {key: min([z for _, w, z, core, _ in c if sets_front(w, core)] or [math.inf])
              for key, c in received.items()}
    own_front = {key: strong[key] if strong[key] < math.inf else min(z for _, _, z, _, _ in c)
                 for key, c in received.items()}
    tol = 1.0 + settings.depth_tolerance
    blend = settings.blend_coverage and s == 1 and point_size is not None  # see RasterSettings.blend_coverage
    for (i, j), contributions in received.items():
        zmin = own_front[(i, j)]
        if s == 2:  # visibility splatting: also the nearest front-setting depth of the 3 x 3 neighbourhood
            zmin = min([zmin] + [strong.get((i + di, j + dj), math.inf) for di in (-1, 0, 1) for dj in (-1, 0, 1)])
        p = (i // s) * W + (j // s)
        depth[p] = min(float(depth[p]), own_front[(i, j)])
        # blend_coverage: the next surface's front, set by the front-setting taps behind the front band
        z2 = min([z for _, w, z, core, _ in contributions if z > zmin * tol and sets_front(w, core)] or [math.inf])
        for n, w, z, _, tent in contributions:
            if z * tol < zmin:
                continue  # a nearer surface's faint taps (soft edges: its fringe) give way to the front
            if z <= zmin * tol:
                A[p, n] += w
                wsum[p] += w
                cover[p] += tent
            elif blend and z2 <= z * tol and z <= z2 * tol:
                B[p, n] += w
                wback[p] += w

    # 3. Normalise; holes get zero. With blend_coverage, a partly covered front over the surface behind.
    hole = wsum < settings.hole_weight_threshold
    for p in range(H * W):
        if hole[p]:
            A[p] = 0.0
            depth[p] = math.inf
        elif blend and wback[p] >= settings.hole_weight_threshold:
            alpha = min(1.0, float(cover[p]))
            A[p] = A[p] / wsum[p] * alpha + B[p] / wback[p] * (1.0 - alpha)
        else:
            A[p] /= wsum[p]
    image = (A @ features.double()).T.reshape(C, H, W)
    dtype = features.dtype
    return Fragments(image.to(dtype), wsum.reshape(H, W).to(dtype), depth.reshape(H, W).to(dtype), hole.reshape(H, W))
