"""The rasterizer's tensor path: each point's taps and the z-buffer test (:func:`splat_points`), and the
sparse pixel-by-point sums that blend the kept taps (:func:`accumulate` and the functions beside it). The rules
they implement are described in :mod:`stylize3d_core.render.rasterize`."""

from __future__ import annotations

import math
from typing import Callable, Dict, List, NamedTuple, Optional

import torch
import torch.nn.functional as F

from ..errors import RenderInterrupted
from ..geometry.camera import project
from .raster_settings import RasterSettings

CORE_WEIGHT = 0.24
"""With ``soft_edges``, a tap whose weight is at least this (divided by the splat's
squared half-width) sets its pixel's front depth: the tap nearest a point weighs >= 1/4."""

GROWN = 1.0 + 1e-3
"""A footprint below this many pixels is splatted bilinearly (rounding must not add taps)."""

MAX_SPLAT_SCALE = 4.0
"""Largest splat half-width, in (sub-)pixels: a point magnified more covers at most 8 x 8 pixels."""


class Splats(NamedTuple):
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



def check_stop(should_stop: Optional[Callable[[], bool]]) -> None:
    if should_stop is not None and should_stop():
        raise RenderInterrupted("render stopped while rasterizing")


def point_chunks(n: int, step: Optional[int]) -> List[slice]:
    """Consecutive slices covering range(n), ``step`` long (one slice if None); one empty slice if n == 0."""
    if step is None or n <= step:
        return [slice(0, n)]
    return [slice(i, min(i + step, n)) for i in range(0, n, step)]


def row_sum(t: torch.Tensor) -> torch.Tensor:
    """(1, m): the sum of the rows of (k, m) ``t``, added in row order, column by column."""
    total = t[0].clone()
    for k in range(1, t.shape[0]):
        total += t[k]
    return total[None]



@torch.no_grad()
def splat_points(points_cam: torch.Tensor, K: torch.Tensor, settings: RasterSettings, point_size=None,
           should_stop: Optional[Callable[[], bool]] = None, chunk: Optional[int] = None,
           point_alpha: Optional[torch.Tensor] = None) -> Splats:
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
    for piece in point_chunks(points_cam.shape[0], chunk):
        check_stop(should_stop)
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
            half = torch.where(half < GROWN, 1.0, half.clamp(max=MAX_SPLAT_SCALE))  # ~1 stays bilinear
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
                wx = wx / row_sum(wx)
                wy = wy / row_sum(wy)
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
        check_stop(should_stop)
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
            check_stop(should_stop)
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
                check_stop(should_stop)
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
    return Splats(cat1(survivors), cat(entry_point, torch.long), cat(pixel, torch.long), cat(weight, dtype),
                   cat(kept, torch.bool), depth.clone(), taps, c00,
                   cat(back_w, dtype) if blend else None, cat(cover, dtype) if blend else None)


def bag_sum(index: torch.Tensor, table: torch.Tensor, offsets: torch.Tensor, weights: torch.Tensor):
    """(B, C): bag b is ``sum_k weights[k] * table[index[k]]`` over ``offsets[b] <= k < offsets[b + 1]``."""
    return F.embedding_bag(index, table, offsets, mode="sum", per_sample_weights=weights, include_last_offset=True)


class SparseSplat(torch.autograd.Function):
    """``out = S @ features`` for a sparse S given in both row- and column-major bags."""

    @staticmethod
    def forward(ctx, features, pix_index, pix_offsets, pix_weights, pt_index, pt_offsets, pt_weights):
        ctx.save_for_backward(pt_index, pt_offsets, pt_weights)
        # Detached, embedding_bag skips the bookkeeping for its own backward.
        return bag_sum(pix_index, features.detach(), pix_offsets, pix_weights)  # (HW, C)

    @staticmethod
    def backward(ctx, grad):
        pt_index, pt_offsets, pt_weights = ctx.saved_tensors
        grad_features = bag_sum(pt_index, grad.contiguous(), pt_offsets, pt_weights)  # (N, C)
        return grad_features, None, None, None, None, None, None


def bag_offsets(counts: torch.Tensor, dtype: torch.dtype = torch.long) -> torch.Tensor:
    """(B + 1,) exclusive prefix sum of (B,) counts."""
    out = torch.zeros(counts.numel() + 1, dtype=dtype, device=counts.device)
    torch.cumsum(counts, dim=0, out=out[1:])
    return out



def blend_weights(sp: Splats, w_all: torch.Tensor, inv: torch.Tensor, hole: torch.Tensor, n_pixels: int,
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
    for piece in point_chunks(pix.shape[0], step):  # in order, as the weight sums
        check_stop(should_stop)
        cov.index_add_(0, pix[piece], cover[piece])
        wback.index_add_(0, pix[piece], back[piece])
    blended = (wback >= threshold) & ~hole  # (HW,)
    alpha = torch.where(blended, cov.clamp(max=1.0), 1.0)
    inv_back = torch.where(blended, (1.0 - alpha) / wback.clamp_min(threshold), 0.0)
    return w_all * (inv * alpha).index_select(0, pix) + back * inv_back.index_select(0, pix)


def kept_entries(sp: Splats, w_all: torch.Tensor, inv: torch.Tensor, step: Optional[int],
                  should_stop: Optional[Callable[[], bool]], nw: Optional[torch.Tensor] = None):
    """The kept entries, in entry order (cache friendly): pixel (E',) int64, feature row (E',) int32 and
    weight normalised per pixel (E',) (0 at holes; ``nw`` (E,) when given, else ``w_all * inv``). int32
    sorts and gathers faster; indices are < 2**28 (MAX_IMAGE_SIDE**2) and N < 2**31."""
    E = sp.pixel.shape[0]
    pt_all = sp.entry_point.int()  # (E,)
    pix_l, pt_l, w_l = [], [], []
    for piece in point_chunks(E, step):
        check_stop(should_stop)
        e = sp.kept[piece].nonzero().squeeze(1) + piece.start  # (e,) ascending
        pix_c = sp.pixel.index_select(0, e)
        pix_l.append(pix_c)
        pt_l.append(pt_all.index_select(0, e))
        w_l.append(w_all.index_select(0, e) * inv.index_select(0, pix_c) if nw is None else nw.index_select(0, e))
    return tuple(t[0] if len(t) == 1 else torch.cat(t) for t in (pix_l, pt_l, w_l))


def accumulate_by_corner(sp: Splats, inv: torch.Tensor, table: torch.Tensor, W: int, n_pixels: int,
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
    check_stop(should_stop)
    M = sp.point.shape[0]
    kept4, weight4 = sp.kept.view(4, M), sp.weight.view(4, M) if nw is None else nw.view(4, M)
    order = torch.sort(sp.corner00.int(), stable=True).indices  # (M,)
    o_sorted = sp.corner00.index_select(0, order)  # (M,) ascending
    pt_sorted = sp.point.int().index_select(0, order)
    lists = []
    for c, off in enumerate((0, 1, W, W + 1)):
        check_stop(should_stop)
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
            check_stop(should_stop)
        acc = None
        for pix, idx, w in lists:
            a, b = (int(v) for v in torch.searchsorted(pix, torch.tensor([lo, hi], device=pix.device)))
            offsets = bag_offsets(torch.bincount(pix[a:b] - lo, minlength=hi - lo), torch.int32)
            part = bag_sum(idx[a:b], table, offsets, w[a:b])  # (hi - lo, C)
            acc = part if acc is None else acc.add_(part)
        out[lo:hi] = acc
    return out


def pixel_bags(pix_e: torch.Tensor, pt_e: torch.Tensor, w_e: torch.Tensor, lo: int, hi: int):
    """Bags of the entries of pixels lo..hi-1 (all entries must lie there), pixel-major, each bag in entry order:
    (feature rows (E,) int32, offsets (hi - lo + 1,) int32, weights (E,))."""
    order = torch.sort(pix_e.int(), stable=True).indices  # (E,) pixel-major
    offsets = bag_offsets(torch.bincount(pix_e - lo, minlength=hi - lo), torch.int32)  # (hi - lo + 1,)
    return pt_e.index_select(0, order), offsets, w_e.index_select(0, order)


def accumulate(pix_e: torch.Tensor, pt_e: torch.Tensor, w_e: torch.Tensor, table: torch.Tensor, n_pixels: int,
                step: Optional[int], should_stop: Optional[Callable[[], bool]]) -> torch.Tensor:
    """(n_pixels, C): per pixel, the weighted sum of its entries' feature rows (inference only).

    With ``step``, in bands of consecutive pixels holding about ``step`` entries
    each (``should_stop`` checked before each band); a pixel's bag holds the
    same entries in the same order as in one pass, so the sums are identical.
    """
    E = pix_e.shape[0]
    if step is None or E <= step:
        check_stop(should_stop)
        return bag_sum_bags(pixel_bags(pix_e, pt_e, w_e, 0, n_pixels), table)
    n_bands = -(-E // step)
    band_px = -(-n_pixels // n_bands)
    out = torch.empty(n_pixels, table.shape[1], dtype=table.dtype, device=table.device)
    band = torch.div(pix_e, band_px, rounding_mode="floor").int()  # (E,) band of each entry
    for k in range(n_bands):
        check_stop(should_stop)
        lo, hi = k * band_px, min((k + 1) * band_px, n_pixels)
        if lo >= hi:
            break
        sel = (band == k).nonzero().squeeze(1)  # (e,) ascending: the entries keep their order
        bags = pixel_bags(pix_e.index_select(0, sel), pt_e.index_select(0, sel), w_e.index_select(0, sel), lo, hi)
        out[lo:hi] = bag_sum_bags(bags, table)
    return out


def bag_sum_bags(bags, table: torch.Tensor) -> torch.Tensor:
    index, offsets, weights = bags
    return bag_sum(index, table, offsets, weights)
