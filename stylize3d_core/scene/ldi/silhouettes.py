"""Silhouette pixels: the foreground's share of a mixed pixel, unmixed colours and sub-pixel edges."""

from __future__ import annotations

from typing import Optional, Tuple

import numpy as np



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
