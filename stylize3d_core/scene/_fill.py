"""Private numpy / OpenCV helpers of the layered depth image (the ``ldi`` package).

Nothing here validates its input: the public functions of ``ldi`` do.
"""

from __future__ import annotations

from typing import List, NamedTuple, Optional, Sequence, Tuple, Union

import cv2
import numpy as np

_ALPHA_GAIN = 4.0
"""Push-pull: a pixel whose blurred source density is >= 1/_ALPHA_GAIN keeps its own estimate."""


def cross_median(x: np.ndarray) -> np.ndarray:
    """Median of each pixel and its 4 neighbours (a 5-point "+" window), edges replicated.

    Unlike a 3x3 box median it keeps the corners of rectangles and 2-pixel-wide
    structures, yet removes single-pixel outliers (speckle).

    Args:
        x: (H, W) float32.
    Returns:
        (H, W) float32, a new array.
    """
    p = np.pad(x, 1, mode="edge")
    c = p[1:-1, 1:-1]
    a, b = p[:-2, 1:-1], p[2:, 1:-1]  # up, down
    d, e = p[1:-1, :-2], p[1:-1, 2:]  # left, right
    # median(a, b, d, e, c) = median3(c, max(min(a,b), min(d,e)), min(max(a,b), max(d,e)))
    lo = np.maximum(np.minimum(a, b), np.minimum(d, e))
    hi = np.minimum(np.maximum(a, b), np.maximum(d, e))
    return np.maximum(np.minimum(c, lo), np.minimum(np.maximum(c, lo), hi))


def push_pull(values: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Fill pixels of zero weight from the weighted ones (pyramid normalised convolution).

    Push: Gaussian pyramids (``cv2.pyrDown``) of ``weight * values`` and of
    ``weight``, until every coarse pixel has some support. Pull: from the coarsest
    level down, each pixel keeps its own normalised estimate where its blurred
    source density is high and takes the upsampled coarser estimate
    (``cv2.pyrUp``) where it is low. Pixels of weight 1 keep their value exactly;
    far from any source the fill is a blur whose radius grows with the distance.
    Cost is linear in the number of pixels. Output values are convex combinations
    of source values.

    Args:
        values: (H, W, C) float32, C <= 4.
        weight: (H, W) float32 in [0, 1]; at least one pixel > 0.
    Returns:
        (H, W, C) float32 filled values.
    """
    w = weight.astype(np.float32)
    wv = values.astype(np.float32) * w[..., None]  # (H, W, C)
    wvs: List[np.ndarray] = [wv]
    ws: List[np.ndarray] = [w]
    while ws[-1].min() <= 1e-6 and min(ws[-1].shape) > 1:
        wvs.append(_as3(cv2.pyrDown(wvs[-1])))
        ws.append(cv2.pyrDown(ws[-1]))
    est = wvs[-1] / np.maximum(ws[-1], 1e-12)[..., None]
    for k in range(len(ws) - 2, -1, -1):
        h, w_ = ws[k].shape
        up = _as3(cv2.pyrUp(est, dstsize=(w_, h)))
        if k == 0:  # full size: only the pixels with some weight differ from the upsampled fill
            w0 = ws[0]
            np.copyto(up, values, where=(w0 >= 1.0)[..., None])  # weight 1: the pixel's own value
            rows, cols = np.nonzero((w0 > 0) & (w0 < 1.0))  # fractional weights (rare): blend
            a = w0[rows, cols][:, None]
            up[rows, cols] = a * values[rows, cols] + (1.0 - a) * up[rows, cols]
            return up.astype(np.float32, copy=False)
        own = wvs[k] / np.maximum(ws[k], 1e-12)[..., None]
        alpha = np.minimum(ws[k] * _ALPHA_GAIN, 1.0)[..., None]
        est = alpha * own + (1.0 - alpha) * up
    return est.astype(np.float32, copy=False)  # a single level: every pixel had weight


def _as3(x: np.ndarray) -> np.ndarray:
    """OpenCV drops a trailing channel axis of size 1: put it back."""
    return x[..., None] if x.ndim == 2 else x


class TornGraph(NamedTuple):
    """Connected regions of an image whose 4-neighbour links are cut at discontinuities.

    Attributes:
        labels: (H, W) int32 region id of every pixel, from 1.
        areas: (R,) int64 pixel count of every region id (``areas[0]`` = 0, unused).
    """

    labels: np.ndarray
    areas: np.ndarray


def torn_regions(cut_h: np.ndarray, cut_v: np.ndarray) -> TornGraph:
    """Regions of pixels connected through links that are not cut.

    The pixel graph is drawn on a (2H-1, 2W-1) grid: pixels at even
    coordinates, the link between two 4-neighbours at the odd coordinate between
    them (1 = linked), diagonal cells 0; ``cv2.connectedComponents`` with
    4-connectivity then gives the regions.

    Args:
        cut_h: (H, W-1) bool, True where pixels (i, j) and (i, j+1) are torn apart.
        cut_v: (H-1, W) bool, True where pixels (i, j) and (i+1, j) are torn apart.
    """
    h, w = cut_v.shape[0] + 1, cut_h.shape[1] + 1
    grid = np.zeros((2 * h - 1, 2 * w - 1), np.uint8)
    grid[::2, ::2] = 1
    grid[::2, 1::2] = ~cut_h
    grid[1::2, ::2] = ~cut_v
    _, lab = cv2.connectedComponents(grid, connectivity=4, ltype=cv2.CV_32S)
    labels = np.ascontiguousarray(lab[::2, ::2])  # (H, W)
    return TornGraph(labels, np.bincount(labels.ravel()))


def ring_min(values: np.ndarray, labels: np.ndarray, selected: np.ndarray) -> np.ndarray:
    """Per selected region, the minimum of ``values`` over its outer 4-neighbours.

    Args:
        values: (H, W) float32.
        labels: (H, W) int32 region ids.
        selected: (R,) bool, the regions to measure.
    Returns:
        (R,) float32; +inf for regions that are not selected or have no neighbour.
    """
    out = np.full(selected.shape[0], np.inf, np.float32)
    pairs: List[Tuple[slice, slice, slice, slice]] = [
        (slice(None), slice(None, -1), slice(None), slice(1, None)),
        (slice(None), slice(1, None), slice(None), slice(None, -1)),
        (slice(None, -1), slice(None), slice(1, None), slice(None)),
        (slice(1, None), slice(None), slice(None, -1), slice(None)),
    ]
    for r0, c0, r1, c1 in pairs:
        lab_in, lab_out = labels[r0, c0], labels[r1, c1]
        hit = selected[lab_in] & (lab_in != lab_out)
        np.minimum.at(out, lab_in[hit], values[r1, c1][hit])
    return out


def nearest_index(targets: np.ndarray) -> np.ndarray:
    """For every pixel, the index of the nearest True pixel of ``targets`` (L2, 5x5 mask).

    The index counts the True pixels in raster order, so ``values[targets][index]``
    copies, to every pixel, the value of its nearest target. ``targets`` must hold
    at least one True pixel.

    Returns:
        (H, W) int32 indices into ``values[targets]``.
    """
    not_target = np.where(targets, 0, 255).astype(np.uint8)
    _, labels = cv2.distanceTransformWithLabels(not_target, cv2.DIST_L2, 5, labelType=cv2.DIST_LABEL_PIXEL)
    # DIST_LABEL_PIXEL numbers the zero pixels from 1 in raster order, as boolean indexing orders them
    return labels - 1


def box_clusters(mask: np.ndarray, pad: int) -> List[Tuple[slice, slice, np.ndarray]]:
    """Group the True pixels of ``mask`` into clusters and return padded boxes.

    Pixels closer than about ``2 * pad`` end up in the same cluster (measured on
    a coarse grid of cells of ``pad // 2`` pixels, so this is cheap). Each entry
    is ``(rows, cols, members)`` with ``members`` (h, w) bool: the pixels of
    ``mask`` inside the box that belong to this cluster. Every box reaches at
    least ``pad`` pixels beyond its members (clipped to the image); boxes may
    overlap, the clusters' members do not, and members of two clusters are
    more than ``pad`` pixels apart.
    """
    h, w = mask.shape
    cell = max(1, pad // 2)
    gh, gw = -(-h // cell), -(-w // cell)
    padded = np.zeros((gh * cell, gw * cell), bool)
    padded[:h, :w] = mask
    coarse = padded.reshape(gh, cell, gw, cell).any(axis=(1, 3)).astype(np.uint8)  # (gh, gw)
    reach = 2 * (-(-pad // cell)) + 1
    grown = cv2.dilate(coarse, np.ones((reach, reach), np.uint8))
    n, lab, stats, _ = cv2.connectedComponentsWithStats(grown, connectivity=8)
    lab_full = np.repeat(np.repeat(lab, cell, axis=0), cell, axis=1)[:h, :w]  # (H, W)
    boxes = []
    for k in range(1, n):
        x, y, bw, bh = stats[k, :4]
        # the grown component already reaches >= pad pixels beyond its members
        rows = slice(y * cell, min(h, (y + bh) * cell))
        cols = slice(x * cell, min(w, (x + bw) * cell))
        members = mask[rows, cols] & (lab_full[rows, cols] == k)
        if members.any():
            boxes.append((rows, cols, members))
    return boxes


_R2_NOISE, _R2_SMOOTH = 0.25, 0.6
"""Damped fits: no gradient at an R^2 up to _R2_NOISE (noise-like texture), all of it from _R2_SMOOTH."""


class LinearFit(NamedTuple):
    """Per-pixel weighted linear fit ``v(q) ~ mean + grad . (q - centre)`` (see :func:`local_linear_fit`).

    Attributes:
        mean: (H, W, C) float64 weighted mean of the values near each pixel.
        centre: (H, W, 2) float64 weighted mean position (x = column, y = row) of those sources.
        grad: (H, W, C, 2) float64 gradient (d/dx, d/dy) of the fit.
        support: (H, W) float64 blurred weight (0 where no source is near).
        trust: (H, W, C) float64 in [0, 1], how far the plane explains the values near each
            pixel (1 where the channel is not damped; see :func:`local_linear_fit`).
        index: None (the fields are images, as above), or (H, W) int32: the fields are
            compact, row ``index[y, x]`` holding pixel (y, x)'s values (-1: not fitted). A fit
            asked for at some pixels only (``where``) is compact: its image-sized fields were
            ~150 bytes a pixel, almost all zeros, and on a photo's first LDI their fresh pages
            cost ~0.3 s of the 1 MP sample's 0.6 s.
    """

    mean: np.ndarray
    centre: np.ndarray
    grad: np.ndarray
    support: np.ndarray
    trust: Optional[np.ndarray] = None
    index: Optional[np.ndarray] = None

    def at(self, rows, cols) -> "LinearFit":
        """The fit at pixels (rows, cols) (arrays, or a mask's ``np.nonzero``): compact fields of one row
        per pixel (``index`` None), as a fitted pixel's values; pixels a compact fit does not hold are
        an error."""
        if self.index is None:
            pick = (rows, cols)
        else:
            pick = self.index[rows, cols]
            if pick.size and int(pick.min()) < 0:
                raise ValueError("the fit does not hold some of these pixels")
        return LinearFit(self.mean[pick], self.centre[pick], self.grad[pick], self.support[pick],
                         None if self.trust is None else self.trust[pick])


def local_linear_fit(
    values: np.ndarray, weight: np.ndarray, sigma: float, ridge: Union[float, Sequence[float]] = 0.02,
    damp: Union[bool, Sequence[bool]] = False, where: Optional[np.ndarray] = None,
) -> LinearFit:
    """Moving least squares: at every pixel, the plane fitted to the weighted values around it.

    Gaussian-weighted (``sigma`` pixels) moments of the weighted pixels give the
    centroid, the position covariance and the value-position covariance; the
    gradient solves the 2x2 normal equations with ``ridge * sigma**2`` added to
    the diagonal (sources on a line give no gradient across it). A plane is
    reproduced exactly (up to the ridge's shrinkage) wherever the sources span
    2D: the disparity ``1 / z`` of a planar surface is affine in the image, so
    ``mean + grad . (p - centre)`` continues a plane's depth past its sources.

    Args:
        values: (H, W, C) float.
        weight: (H, W) float in [0, 1].
        sigma: Gaussian radius in pixels.
        ridge: regularisation, relative to ``sigma**2``: one value, or one per channel (the
            position moments are shared, so fitting channels together costs less).
        damp: (one, or one per channel) scale the gradient by the fit's R^2 (the share of the values' local variance
            the plane explains), from 0 at ``_R2_NOISE`` to 1 at ``_R2_SMOOTH``: noise-like
            texture gets no gradient, smooth shading keeps it.
        where: (H, W) bool, the pixels whose fit is wanted (all by default; with it the fit is
            compact, see :class:`LinearFit`'s ``index``). Few
            of them (a window of taps each costs less than blurring the image): the moments are
            summed over each one's window (:func:`_sparse_fit`, the same Gaussian taps);
            else they are blurred over the whole image and the fit is solved there only.
    """
    h, w = weight.shape
    if where is not None:
        n = int(np.count_nonzero(where))
        taps = _gaussian_taps(sigma).size ** 2
        if n * taps <= _WINDOW_COST * h * w:
            return _sparse_fit(values, weight, sigma, ridge, damp, where)
    wt = weight.astype(np.float32)
    v = values.astype(np.float32)
    y, x = np.mgrid[:h, :w].astype(np.float32)
    x -= w / 2.0
    y -= h / 2.0
    idx = np.nonzero(where) if where is not None else (slice(None), slice(None))

    def g(a: np.ndarray) -> np.ndarray:  # blurred over the whole image, kept where asked
        return _as3(cv2.GaussianBlur(a, (0, 0), sigma, borderType=cv2.BORDER_CONSTANT))[idx]

    s0 = g(wt)[..., 0]
    inv = 1.0 / np.maximum(s0, 1e-12)
    mx, my = g(wt * x)[..., 0] * inv, g(wt * y)[..., 0] * inv
    cxx = g(wt * x * x)[..., 0] * inv - mx * mx
    cxy = g(wt * x * y)[..., 0] * inv - mx * my
    cyy = g(wt * y * y)[..., 0] * inv - my * my
    wv = v * wt[..., None]
    mv = g(wv) * inv[..., None]  # (H, W, C), or (N, C) where asked
    cvx = g(wv * x[..., None]) * inv[..., None] - mv * mx[..., None]
    cvy = g(wv * y[..., None]) * inv[..., None] - mv * my[..., None]
    grad, keep = _solve_planes(cxx, cxy, cyy, cvx, cvy, lambda: g(wv * v) * inv[..., None] - mv * mv,
                               ridge, damp, sigma, np.float32)
    fields = (mv, np.stack([mx + w / 2.0, my + h / 2.0], axis=-1), grad, s0, keep)
    return LinearFit(*fields) if where is None else _compact(fields, (h, w), idx)


def _solve_planes(
    cxx: np.ndarray, cxy: np.ndarray, cyy: np.ndarray, cvx: np.ndarray, cvy: np.ndarray, variance,
    ridge: Union[float, Sequence[float]], damp: Union[bool, Sequence[bool]], sigma: float, dtype,
) -> Tuple[np.ndarray, np.ndarray]:
    """The gradients (..., C, 2) of the fits from their centred moments (positions (...), values
    (..., C)), and the damping kept (..., C): :func:`local_linear_fit`'s normal equations.
    ``variance()`` gives the values' centred variance (..., C), asked for only when a channel is damped."""
    c = cvx.shape[-1]
    lam = np.broadcast_to(np.asarray(ridge, dtype), (c,)) * sigma * sigma  # (C,)
    a, b, d = cxx[..., None] + lam, cxy[..., None], cyy[..., None] + lam  # (..., C)
    det = np.maximum(a * d - b * b, 1e-12)
    gx = (d * cvx - b * cvy) / det
    gy = (a * cvy - b * cvx) / det
    damped = np.broadcast_to(np.asarray(damp, bool), (c,))
    keep = np.ones_like(gx)
    if damped.any():  # keep the gradient where the plane explains the local variance, drop it on noise
        r2 = (gx * cvx + gy * cvy) / np.maximum(variance(), 1e-12)  # R^2 of the (ridge-shrunk) fit
        keep = np.clip((r2 - _R2_NOISE) / (_R2_SMOOTH - _R2_NOISE), 0.0, 1.0)
        keep[..., ~damped] = 1.0
        gx, gy = gx * keep, gy * keep
    return np.stack([gx, gy], axis=-1), keep


def _compact(fields, size: Tuple[int, int], idx) -> LinearFit:
    """A compact :class:`LinearFit` of image size ``size`` from fields given at the pixels ``idx``."""
    return LinearFit(*fields, index=_index_map(size, idx))


def _index_map(size: Tuple[int, int], idx) -> np.ndarray:
    """(H, W) int32: k at the k-th pixel of ``idx`` (rows, cols), -1 elsewhere."""
    index = np.full(tuple(size), -1, np.int32)
    index[idx] = np.arange(len(idx[0]), dtype=np.int32)
    return index


_WINDOW_COST = 2
"""The fit sums its windows directly when that touches at most this many values per image pixel
(it blurs ~22 image-sized channels otherwise)."""


def _gaussian_taps(sigma: float) -> np.ndarray:
    """The 1D kernel ``cv2.GaussianBlur`` uses for a float image at ``sigma`` (ksize from sigma)."""
    ksize = int(round(sigma * 4 * 2 + 1)) | 1
    return cv2.getGaussianKernel(ksize, sigma, cv2.CV_64F)[:, 0]


_WINDOW_CHUNK = 512
"""Pixels whose windows are summed at once (the temporaries stay in the cache)."""


def _sparse_fit(
    values: np.ndarray, weight: np.ndarray, sigma: float, ridge: Union[float, Sequence[float]],
    damp: Union[bool, Sequence[bool]], where: np.ndarray,
) -> LinearFit:
    """:func:`local_linear_fit` at the pixels of ``where`` by direct sums over their windows.

    The window is ``cv2.GaussianBlur``'s kernel at ``sigma`` with zeros beyond the image
    (``BORDER_CONSTANT``), so the moments are the blurred ones; they are taken about each
    pixel (float32 sums of at most a few hundred taps), so the fit is the same up to rounding.
    """
    h, w = weight.shape
    c = values.shape[-1]
    g1 = _gaussian_taps(sigma)
    r = g1.size // 2
    off = np.arange(-r, r + 1, dtype=np.int32)
    dyi, dxi = (a.ravel() for a in np.meshgrid(off, off, indexing="ij"))  # (T,) tap offsets
    dx, dy = dxi.astype(np.float32), dyi.astype(np.float32)
    kern = np.outer(g1, g1).ravel().astype(np.float32)  # (T,)
    basis = np.stack([np.ones_like(dx), dx, dy, dx * dx, dx * dy, dy * dy], axis=1)  # (T, 6)
    wflat = weight.astype(np.float32, copy=False).ravel()
    vflat = values.astype(np.float32, copy=False).reshape(h * w, c)
    rows, cols = np.nonzero(where)
    n = rows.size
    pos = np.empty((n, 6), np.float64)  # sums of w, w dx, w dy, w dx^2, w dx dy, w dy^2
    val = np.empty((n, 4, c), np.float64)  # sums of w v, w v dx, w v dy, w v^2
    for a in range(0, n, _WINDOW_CHUNK):
        b = min(n, a + _WINDOW_CHUNK)
        rr = rows[a:b, None].astype(np.int32) + dyi[None]  # (B, T)
        cc = cols[a:b, None].astype(np.int32) + dxi[None]
        inside = (rr >= 0) & (rr < h) & (cc >= 0) & (cc < w)  # zeros beyond the image
        flat = np.clip(rr, 0, h - 1) * w + np.clip(cc, 0, w - 1)  # np.take: far faster than 2D indexing
        k = kern[None] * np.where(inside, np.take(wflat, flat), np.float32(0.0))  # (B, T) tap weights
        vq = np.take(vflat, flat, axis=0)  # (B, T, C)
        pos[a:b] = k @ basis
        kk = k[:, None, :] * basis[None, :, :3].transpose(0, 2, 1)  # (B, 3, T): k, k dx, k dy
        val[a:b, :3] = np.matmul(kk, vq)
        np.square(vq, out=vq)
        val[a:b, 3] = np.matmul(k[:, None, :], vq)[:, 0]
    s0 = pos[:, 0]
    inv = 1.0 / np.maximum(s0, 1e-12)
    ox, oy = pos[:, 1] * inv, pos[:, 2] * inv  # the centroid's offset from the pixel
    cxx = pos[:, 3] * inv - ox * ox
    cxy = pos[:, 4] * inv - ox * oy
    cyy = pos[:, 5] * inv - oy * oy
    mv = val[:, 0] * inv[:, None]  # (N, C)
    cvx = val[:, 1] * inv[:, None] - mv * ox[:, None]
    cvy = val[:, 2] * inv[:, None] - mv * oy[:, None]
    grad, keep = _solve_planes(cxx, cxy, cyy, cvx, cvy, lambda: val[:, 3] * inv[:, None] - mv * mv,
                               ridge, damp, sigma, np.float64)
    return _compact((mv, np.stack([cols + ox, rows + oy], axis=-1), grad, s0, keep), (h, w), (rows, cols))


def split_fit(fit: LinearFit, channels: slice) -> LinearFit:
    """The fit of some of its channels (the positions and support are shared)."""
    trust = fit.trust[..., channels] if fit.trust is not None else None
    return LinearFit(fit.mean[..., channels], fit.centre, fit.grad[..., channels, :], fit.support, trust, fit.index)


def anchored(fit: LinearFit, values: np.ndarray, where: Optional[np.ndarray] = None) -> LinearFit:
    """The fit re-centred on every pixel's own value, as far as the plane explains its neighbourhood.

    A continuation from source ``q`` then starts at ``fit(q) + trust(q) (v(q) - fit(q))``: the
    pixel's own value where the local plane explains the values (smooth shading, a plane's
    disparity: the window mean of a curved signal is biased by its curvature, e.g. a receding
    ground's fast-changing rows), the fit's value on noise-like texture (no speckle copied).

    Args:
        fit: a :func:`local_linear_fit` of ``values``.
        values: (H, W, C) the fitted values.
        where: (H, W) bool, the pixels to re-centre (all by default; 0 elsewhere).
    """
    h, w = values.shape[:2]
    if where is None:
        where = np.ones((h, w), bool)
    idx = np.nonzero(where)
    y, x = idx[0].astype(np.float64), idx[1].astype(np.float64)
    q = fit.at(*idx)
    mean, centre, grad = q.mean, q.centre, q.grad
    at_q = mean + grad[..., 0] * (x - centre[..., 0])[..., None] + grad[..., 1] * (y - centre[..., 1])[..., None]
    trust = q.trust if q.trust is not None else 1.0
    anchor_q = at_q + trust * (values[idx].astype(np.float64) - at_q)
    new_centre_q = np.stack([x, y], axis=-1)
    if fit.index is not None:  # compact in, compact out: the re-centred pixels only
        return LinearFit(anchor_q, new_centre_q, q.grad, q.support, q.trust, _index_map((h, w), idx))
    anchor = np.zeros(fit.mean.shape, np.float64)
    anchor[idx] = anchor_q
    new_centre = np.zeros(fit.centre.shape, np.float64)
    new_centre[idx] = new_centre_q
    return LinearFit(anchor, new_centre, fit.grad, fit.support, fit.trust)


def extrapolate(
    fit: LinearFit, nearest: np.ndarray, targets: np.ndarray, max_step: float, where: Optional[np.ndarray] = None
) -> np.ndarray:
    """Continue, to every pixel, the linear fit of its nearest source (``nearest_index`` of them).

    ``value(p) = mean(q) + grad(q) . (p - centre(q))`` with ``q`` the nearest source;
    the step ``grad . (p - centre)`` is clipped to ``[-max_step, max_step]`` per channel.

    Args:
        fit: the fit over the sources.
        nearest: (H, W) int indices into the True pixels of ``targets`` (the sources).
        targets: (H, W) bool, the sources.
        where: (H, W) bool, the pixels to compute (all by default; 0 elsewhere).
    Returns:
        (H, W, C) float32.
    """
    h, w = nearest.shape
    out = np.zeros((h, w, fit.mean.shape[-1]), np.float32)
    rows, cols = np.nonzero(where) if where is not None else np.nonzero(np.ones((h, w), bool))
    tr, tc = np.nonzero(targets)
    k = nearest[rows, cols]
    at = np.stack([tr[k], tc[k]], axis=1)  # (N, 2) the nearest source of each pixel
    out[rows, cols] = continue_at(fit, at, (rows.astype(np.float64), cols.astype(np.float64)), max_step)
    return out


def scan_nearest(targets: np.ndarray, where: Optional[np.ndarray] = None) -> np.ndarray:
    """For every pixel, the nearest True pixel of ``targets`` along its row and column, each way.

    Args:
        targets: (H, W) bool.
        where: (H, W) bool, the pixels wanted (all by default).
    Returns:
        (4, H, W, 2) int64 (row, col) of the nearest target to the left, right, above and
        below (the pixel itself when it is one); -1 where there is none that way. With
        ``where``: (4, N, 2) for its N pixels in raster order.
    """
    h, w = targets.shape
    cols = np.arange(w, dtype=np.int32)[None, :]
    rows = np.arange(h, dtype=np.int32)[:, None]
    left = np.maximum.accumulate(np.where(targets, cols, -1), axis=1)
    right = np.minimum.accumulate(np.where(targets, cols, w)[:, ::-1], axis=1)[:, ::-1]
    up = np.maximum.accumulate(np.where(targets, rows, -1), axis=0)
    down = np.minimum.accumulate(np.where(targets, rows, h)[::-1], axis=0)[::-1]
    if where is None:
        pr, pc = np.broadcast_to(rows, (h, w)), np.broadcast_to(cols, (h, w))
        pick = (slice(None), slice(None))
    else:
        pr, pc = np.nonzero(where)
        pick = (pr, pc)
    out = np.full((4,) + pr.shape + (2,), -1, np.int64)
    for k, (r, c, ok) in enumerate((
        (pr, left[pick], left[pick] >= 0), (pr, right[pick], right[pick] < w),
        (up[pick], pc, up[pick] >= 0), (down[pick], pc, down[pick] < h),
    )):
        out[k, ..., 0] = np.where(ok, r, -1)
        out[k, ..., 1] = np.where(ok, c, -1)
    return out


def continue_at(fit: LinearFit, at: np.ndarray, pixels: Tuple[np.ndarray, np.ndarray], max_step: float) -> np.ndarray:
    """The linear fit at source pixels ``at`` (N, 2) (row, col) continued to ``pixels`` (rows, cols).

    Returns:
        (N, C) float64 ``mean + clip(grad . (p - centre), -max_step, max_step)``.
    """
    q = fit.at(at[:, 0], at[:, 1])
    mean, centre, grad = q.mean, q.centre, q.grad  # (N, C), (N, 2), (N, C, 2)
    dx = (pixels[1] - centre[:, 0])[:, None]
    dy = (pixels[0] - centre[:, 1])[:, None]
    return mean + np.clip(grad[..., 0] * dx + grad[..., 1] * dy, -max_step, max_step)
