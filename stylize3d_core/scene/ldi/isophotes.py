"""Colour continued across a hidden gap along the texture's isophotes: the two sides' profiles matched
(:func:`across_gap`, used by the hidden layer's crease rows)."""

from __future__ import annotations

import math
from typing import Tuple

import numpy as np

_MATCH_ROWS = 8
"""Rows on either side of a pixel over which the two sides' profiles are matched (:func:`across_gap`)."""
_MATCH_SHIFT = 12.0
"""Largest shift (rows) between the two sides' profiles, i.e. of an isophote across the gap."""
_MATCH_STEP = 0.25
"""Shifts tried, in rows."""
_MATCH_MIN = 4
"""Least number of matched rows for a shift to count."""
_MATCH_TIE = 2.0
"""Shifts whose mismatch is within this factor of the least count as matching (the smallest is taken)."""
_MATCH_FIT = 1.0
"""A match counts where its mean squared difference is at most this share of the profile's variance."""


ACROSS_REACH = _MATCH_ROWS + int(math.ceil(_MATCH_SHIFT)) + 2
"""Rows (either way) whose pixels :func:`across_gap` may read for one pixel's row."""


def across_gap(
    rgb: np.ndarray, source: np.ndarray, rows: np.ndarray, cols: np.ndarray, left: np.ndarray, right: np.ndarray,
) -> Tuple[np.ndarray, np.ndarray]:
    """Colour of pixels between two sources of one row, continued along the texture's isophotes.

    Pixel ``(r, c)`` lies between the sources ``(r, left)`` and ``(r, right)`` of a surface that
    runs on behind the foreground. The columns of sources at ``left`` and ``right`` (the gap's two
    sides) are profiles of the texture along the rows; where its isophotes cross the gap slanted,
    one profile is the other shifted by the rows an isophote climbs or falls across the gap. That
    shift is found per channel (the least squared difference of the two profiles over
    ``_MATCH_ROWS`` rows each side, at shifts up to ``_MATCH_SHIFT`` rows; of shifts about as good,
    the smallest: a periodic texture matches at every period), and the pixel takes the colours
    where its isophote meets the two sides (interpolated between rows), blended by inverse squared
    distance as the straight continuation along the row is: on a receding ground's compressed rows,
    a straight continuation crosses several rows' worth of texture.

    Only source pixels are read, and of the sides' columns only the rows where some of the given
    pixels lie between the same two columns (the rows that run on the same surface behind the
    foreground), so no foreground colour and no other surface (a wall above a ground's crease) is
    matched or copied. The shift is found once per row and pair of sides.

    Args:
        rgb: (h, w, C) colours.
        source: (h, w) bool, the background sources.
        rows, cols, left, right: (N,) int, the pixels and their two sources' columns.
    Returns:
        (N, C) float64 colours and (N,) bool: where both the match and a side's crossing were
        found (the colour is 0 elsewhere).
    """
    h, w = source.shape
    n, c = rows.size, rgb.shape[-1]
    if n == 0:
        return np.zeros((0, c)), np.zeros(0, bool)
    code = (rows.astype(np.int64) * w + left) * w + right  # (N,) the pixel's row and sides
    known, group = np.unique(code, return_inverse=True)  # G groups, one shift each
    g_row = (known // (w * w)).astype(np.int64)
    g_left, g_right = (known // w) % w, known % w
    k, s = _MATCH_ROWS, int(math.ceil(_MATCH_SHIFT))
    span = np.arange(-k - s - 1, k + s + 2)  # rows relative to the group's row, covering every shift
    zero = k + s + 1  # span index of that row
    yy = g_row[:, None] + span[None]  # (G, M)
    inside = (yy >= 0) & (yy < h)
    yc = np.clip(yy, 0, h - 1)
    same = (yc * w + g_left[:, None]) * w + g_right[:, None]  # the same sides on that row
    at = np.clip(np.searchsorted(known, same), 0, known.size - 1)
    surf = inside & (known[at] == same)
    ok_l = surf & source[yc, g_left[:, None]]  # (G, M)
    ok_r = surf & source[yc, g_right[:, None]]
    v_l = rgb[yc, g_left[:, None]].astype(np.float64)  # (G, M, C)
    v_r = rgb[yc, g_right[:, None]].astype(np.float64)
    shifts = np.arange(-_MATCH_SHIFT, _MATCH_SHIFT + 1e-9, _MATCH_STEP)
    shifts = shifts[np.argsort(np.abs(shifts), kind="stable")]  # in order of size
    near = np.arange(zero - k, zero + k + 1)  # the matched rows of the left profile
    cost = np.full((shifts.size, known.size, c), np.inf)
    for i, d in enumerate(shifts):
        i0 = near + int(math.floor(d))
        f = d - math.floor(d)
        r_at = (1.0 - f) * v_r[:, i0] + f * v_r[:, i0 + 1]  # (G, 2k+1, C)
        ok = ok_l[:, near] & ok_r[:, i0] & (ok_r[:, i0 + 1] | (f == 0.0))  # (G, 2k+1)
        count = ok.sum(axis=1)  # (G,)
        se = (np.where(ok[..., None], v_l[:, near] - r_at, 0.0) ** 2).sum(axis=1)  # (G, C)
        cost[i] = np.where((count >= _MATCH_MIN)[:, None], se / np.maximum(count, 1)[:, None], np.inf)
    least = cost.min(axis=0)  # (G, C)
    best = shifts[np.argmax(cost <= _MATCH_TIE * least[None] + 1e-6, axis=0)]  # (G, C)
    ok_near = ok_l[:, near]
    cnt = np.maximum(ok_near.sum(axis=1), 1)[:, None]
    mean = np.where(ok_near[..., None], v_l[:, near], 0.0).sum(axis=1) / cnt
    var = np.where(ok_near[..., None], (v_l[:, near] - mean[:, None]) ** 2, 0.0).sum(axis=1) / cnt  # (G, C)
    matched = (np.isfinite(least) & (least <= _MATCH_FIT * var + 1e-8))[group]  # (N, C)
    a = (cols - left).astype(np.float64)[:, None]
    b = (right - cols).astype(np.float64)[:, None]
    shift = best[group] / (a + b)  # (N, C) rows per column
    # the profiles' rows are relative to the pixel's own row (its group's)

    def crossing(v: np.ndarray, ok: np.ndarray, rel: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Profiles ``v`` (G, M, C) of the pixels' groups at fractional rows ``rel`` (N, C)."""
        y = zero + rel
        y0 = np.clip(np.floor(y).astype(np.int64), 0, span.size - 2)
        f = y - y0
        g, ch = group[:, None], np.arange(c)[None]
        val = (1.0 - f) * v[g, y0, ch] + f * v[g, y0 + 1, ch]
        good = ok[g, y0] & (ok[g, y0 + 1] | (f == 0.0))
        return val, good

    val_l, good_l = crossing(v_l, ok_l, -a * shift)
    val_r, good_r = crossing(v_r, ok_r, b * shift)
    w_l = np.where(good_l & matched, 1.0 / a**2, 0.0)
    w_r = np.where(good_r & matched, 1.0 / b**2, 0.0)
    total = w_l + w_r
    out = (w_l * val_l + w_r * val_r) / np.maximum(total, 1e-300)
    found = (total > 0).all(axis=1)
    return np.where(found[:, None], out, 0.0), found
