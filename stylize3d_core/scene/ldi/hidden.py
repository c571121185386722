"""The hidden layer: background depth and colour continued behind each foreground edge."""

from __future__ import annotations

import math
from typing import Optional, Tuple

import cv2
import numpy as np

from ...threads import halves
from .._fill import (LinearFit, anchored, box_clusters, continue_at, extrapolate, local_linear_fit, nearest_index,
                     scan_nearest, split_fit)
from .isophotes import ACROSS_REACH as _ACROSS_REACH, across_gap
from .layers import LDISettings
from .silhouettes import _JOIN_CONTRAST, _JOIN_FOREGROUND, unmix_silhouette


_DEPTH_SIGMA = 1.0
"""Smoothing (pixels) of the hidden layer's continued depth: the seams between sources only. Wider
smoothing would blur the crease of a ground meeting a wall behind a card: the hidden points near the
crease would come out between the two planes and show the rows beside theirs from a moved camera."""

_DEPTH_RIDGE = 0.25
_COLOUR_RIDGE = 0.02
"""Ridge of the local linear fits of the background's disparity and colour (relative to
``fit_sigma**2``): small, so a continued plane keeps its slope (a shrunk slope would bring a
receding floor continued from below in front of the true one)."""

_DEPTH_STEP = 1.0
"""A continued background plane changes the disparity by at most this many ``disparity_jump``
(an estimated depth's gentle slopes, continued far, would open gaps in the hidden layer)."""

_SAME_SURFACE = 0.25
"""Continued background planes within this many ``disparity_jump`` of the nearest one are taken
for the same surface (the closest source of them gives the hidden pixel its colour)."""

_JOIN = 0.1
"""With ``hidden_depth="surface"``, a source joins the surface its row's or column's agreeing pair
continues when its own plane comes within this many ``disparity_jump`` of it (the wall just above
a card where the wall runs on behind it; not where the ground has already turned away from it)."""


_SOURCE_PAD = 3
"""Pixels beyond a hidden band's reach in which background sources are gathered (each side)."""

def _hidden_layer(
    rgb: np.ndarray, nd: np.ndarray, fg: np.ndarray, bg: np.ndarray, widths: np.ndarray, s: LDISettings
) -> Optional[Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """Hidden background behind the foreground edges, ``widths`` (H, W) pixels wide behind each.

    Returns:
        mask (H, W) bool, rgb (H, W, 3) float32 and nd (H, W) float32 of layer 1
        (valid where mask), and, with ``unmix_silhouettes``, the layer-0 pixels beside those
        edges on their background side that keep the background's depth (H, W) bool, their
        colours without the foreground's share (H, W, 3) float32 (see :func:`unmix_silhouette`),
        and the layer-0 nd (H, W) float32 of those that join the foreground instead (0
        elsewhere; layer 1 holds the background behind them); None when no band pixel was found.
    """
    h, w = nd.shape
    t = s.disparity_jump
    edges = fg & (widths > 0)
    max_width = int(math.ceil(widths.max()))
    ex = s.edge_exclusion_px
    exclusion = np.ones((2 * ex + 1, 2 * ex + 1), np.uint8)

    mask = np.zeros((h, w), bool)
    out_rgb = np.zeros((h, w, 3), np.float32)
    out_nd = np.zeros((h, w), np.float32)
    mask0 = np.zeros((h, w), bool)
    out_rgb0 = np.zeros((h, w, 3), np.float32)
    fore = np.zeros((h, w), np.float32)  # layer 0's new nd where a pixel joins the foreground (0 elsewhere)
    for rows, cols, members in box_clusters(edges, max_width + 2 * _SOURCE_PAD + ex + 4):
        ndc = nd[rows, cols]  # (h, w)
        rgbc = rgb[rows, cols]  # (h, w, 3)
        nearest_edge = nearest_index(members)  # (h, w)
        width = widths[rows, cols][members][nearest_edge]  # (h, w) width behind the nearest edge pixel
        band_px = int(math.ceil(width.max()))
        reach = band_px + 2 * _SOURCE_PAD + ex + 2  # background sources are looked for this far
        not_edge = np.where(members, 0, 255).astype(np.uint8)
        dist = cv2.distanceTransform(not_edge, cv2.DIST_L2, 5)  # (h, w) to the nearest edge pixel
        ref = ndc[members][nearest_edge]  # (h, w) nd of the nearest foreground-edge pixel
        local_min = cv2.erode(ndc, np.ones((2 * band_px + 3, 2 * band_px + 3), np.uint8))  # farthest nd nearby
        # foreground side only: a pixel clearly behind its nearest foreground edge is background,
        # unless it is the foreground of an edge of its own nearby (a middle layer: a tower's
        # base behind a pole, before the sky)
        window = np.ones((2 * band_px + 1, 2 * band_px + 1), np.uint8)
        own_fg = cv2.erode(np.where(members, ndc, np.float32(1e9)).astype(np.float32), window)  # (h, w)
        band = (dist <= width) & (width > 0) & (ndc - local_min > t) & ((ndc >= ref - t) | (own_fg <= ndc + t))
        if not band.any():
            continue
        # Anti-aliased pixels on either side of a tear mix foreground and background colours.
        mixed = cv2.dilate((fg[rows, cols] | bg[rows, cols]).astype(np.uint8), exclusion) > 0 if ex else members
        near = (dist <= reach) & ~band
        source = near & (ndc < ref - t) & ~mixed  # clearly behind the nearest foreground edge
        if not source.any():  # degenerate: nothing clearly behind; use the local background
            source = near & (ndc <= local_min + t) & ~mixed
        if not source.any():
            source = ~band & ~mixed
        if not source.any():
            source = ~band
        # every pixel takes the values of its nearest background source (no foreground can leak)
        nearest = nearest_index(source)  # (h, w)
        scan = scan_nearest(source, where=band) if s.hidden_depth == "surface" else None  # (4, N, 2)
        # layer 0's pixels just outside these edges (a 4-neighbour of one of them), on the background
        # side: their background colour is continued the same way, from the sources
        outside = (bg[rows, cols] & (dist < 1.5) & ~band) if s.unmix_silhouettes else np.zeros_like(band)
        # the fits are continued only from the sources some band pixel takes: its nearest, and in
        # "surface" mode the nearest along its row and column (a thin rim of the sources)
        used = _used_sources(nearest, source, band | outside, scan)
        srcw = source.astype(np.float32)
        lo = 0.5 * float(ndc[source].min())  # never much farther than anything seen
        nd_fit = None
        if s.hidden_depth != "nearest":  # one fit of the four channels (shared position moments)
            values = np.concatenate([ndc[..., None], rgbc], axis=2)
            both = local_linear_fit(values, srcw, s.fit_sigma, ridge=(_DEPTH_RIDGE,) + (_COLOUR_RIDGE,) * 3,
                                    damp=(False, True, True, True), where=used)
            both = anchored(both, values, where=used)
            nd_fit, col_fit = split_fit(both, slice(0, 1)), split_fit(both, slice(1, 4))
        else:
            col_fit = local_linear_fit(rgbc, srcw, s.fit_sigma, ridge=_COLOUR_RIDGE, damp=True, where=used)
        if nd_fit is not None:  # continue the background's local plane (nd is affine on it)
            bg_nd = np.maximum(extrapolate(nd_fit, nearest, source, _DEPTH_STEP * s.disparity_jump, band)[..., 0], lo)
            bg_nd = np.where(source, ndc, bg_nd)
        else:
            bg_nd = ndc[source][nearest]  # (h, w)
        chosen_rgb = None
        if s.hidden_depth == "surface":
            bg_nd, chosen_rgb = _nearest_surface(nd_fit, col_fit, source, band, ndc, bg_nd, lo, s, scan, nearest, rgbc)
        # smooth the seams of that fill within band + sources (normalised convolution)
        weight = (band | source).astype(np.float32)
        blur_nd = cv2.GaussianBlur(bg_nd * weight, (0, 0), _DEPTH_SIGMA) / np.maximum(
            cv2.GaussianBlur(weight, (0, 0), _DEPTH_SIGMA), 1e-6
        )
        behind = np.minimum(blur_nd, ndc - t)  # (h, w) strictly behind the foreground
        # The hidden layer is background-only (layer 0's pixels beside the edges: below).
        todo = band
        if chosen_rgb is not None:  # chosen with the surface
            colour = np.zeros(rgbc.shape, np.float32)
            colour[band] = chosen_rgb
        else:  # the background's colour and its gradient continued
            colour = np.clip(extrapolate(col_fit, nearest, source, s.max_colour_step, todo), 0.0, 1.0)
        sub_mask = mask[rows, cols]
        sub_mask |= band
        out_rgb[rows, cols][band] = colour[band]
        out_nd[rows, cols][band] = behind[band]
        if outside.any():
            pr, pc = np.nonzero(outside)
            if col_fit is not None:
                background = np.clip(extrapolate(col_fit, nearest, source, s.max_colour_step, outside)[pr, pc], 0.0, 1.0)
            else:
                background = rgbc[source][nearest[pr, pc]]  # the nearest source's colour
            unmixed, share, fore_rgb, fore_nd = unmix_silhouette(rgbc, ndc, (pr, pc), background, t)
            # mostly foreground (the depth's edge lies inside the colour's) across a colour edge: the
            # pixel joins the foreground with its colour, and the hidden layer gets the background
            # behind it
            edge = ((fore_rgb - background) ** 2).mean(axis=1) >= _JOIN_CONTRAST ** 2
            joins = (share > _JOIN_FOREGROUND) & edge  # (N,)
            gr, gc = pr + rows.start, pc + cols.start  # in the photo
            mask0[gr[~joins], gc[~joins]] = True
            out_rgb0[gr[~joins], gc[~joins]] = unmixed[~joins]
            j = gr[joins], gc[joins]
            fore[j] = fore_nd[joins]
            mask[j] = True
            out_rgb[j] = background[joins]
            out_nd[j] = ndc[pr[joins], pc[joins]]
    if not mask.any():
        return None
    return mask, out_rgb, out_nd, mask0, out_rgb0, fore


def _used_sources(
    nearest: np.ndarray, source: np.ndarray, band: np.ndarray, scan: Optional[np.ndarray]
) -> np.ndarray:
    """(h, w) bool: the sources a band pixel continues (its nearest; and its ``scan`` candidates,
    (4, N, 2) for the band's N pixels in raster order, where given)."""
    used = np.zeros_like(source)
    tr, tc = np.nonzero(source)
    k = nearest[band]
    used[tr[k], tc[k]] = True
    if scan is not None:
        ok = scan[..., 0] >= 0
        used[scan[..., 0][ok], scan[..., 1][ok]] = True
    return used


def _nearest_surface(
    nd_fit: LinearFit, col_fit: Optional[LinearFit], source: np.ndarray, band: np.ndarray, ndc: np.ndarray,
    fallback_nd: np.ndarray, lo: float, s: LDISettings, scan: np.ndarray, nearest: np.ndarray,
    rgbc: Optional[np.ndarray] = None,
) -> Tuple[np.ndarray, Optional[np.ndarray]]:
    """Hidden-layer disparity (h, w) and colour (N, 3) of the band's N pixels (raster order) or None.

    Every band pixel looks at the four background sources nearest along its row and column
    and continues their planes (and colour fits) to it; one that would come out in front of
    the foreground (or far beyond anything seen) is dropped. Where the two sources of a row
    or of a column agree (within ``_SAME_SURFACE`` jumps), the pixel takes the blend of the
    agreeing ones, weighted by inverse squared distance; pixels with no agreeing pair keep
    ``fallback_nd`` (and the Voronoi colour). ``scan`` is :func:`scan_nearest` of ``source`` at
    the band's pixels and ``nearest`` its :func:`nearest_index`.
    """
    br, bc = np.nonzero(band)
    cand = scan  # (4, N, 2)
    pix = (br.astype(np.float64), bc.astype(np.float64))
    limit = ndc[br, bc] - s.disparity_jump  # (N,)
    nds = np.full((4, len(br)), -np.inf)
    dist = np.abs(cand[..., 0] - br) + np.abs(cand[..., 1] - bc)  # (4, N) along the row or column

    def depth_of(k: int) -> None:  # candidate k's plane continued to its band pixels
        ok = cand[k, :, 0] >= 0
        nds[k, ok] = continue_at(nd_fit, cand[k][ok], (pix[0][ok], pix[1][ok]), _DEPTH_STEP * s.disparity_jump)[:, 0]

    halves(depth_of, 4)
    nds[(nds > limit) | (nds < lo)] = -np.inf  # in front of the foreground, or far beyond anything seen
    # A surface runs behind the foreground where the sources on opposite sides of the pixel (left
    # and right, or above and below) continue to the same disparity: the ground beside a card, on
    # its row, not the wall above it, whose plane the nearest source (just above the card) would
    # continue. Those pairs are blended by inverse squared distance (interpolated across the gap,
    # and continuous with the nearer source); a pixel with no agreeing pair keeps the nearest
    # source's plane (continued from one side alone, a surface is no more than a guess, and a
    # guess in front of the background beside it tears from it: on estimated depth the nearest
    # of the four continued planes opened holes).
    valid = np.isfinite(nds)
    finite = np.where(valid, nds, 0.0)
    agree = np.zeros((4, len(br)), bool)
    for a, b in ((0, 1), (2, 3)):
        pair = valid[a] & valid[b] & (np.abs(finite[a] - finite[b]) <= _SAME_SURFACE * s.disparity_jump)
        agree[a] |= pair
        agree[b] |= pair
    inv_d2 = 1.0 / np.maximum(dist, 1).astype(np.float64) ** 2  # (4, N)
    wts = np.where(agree, inv_d2, 0.0)
    total = wts.sum(axis=0)
    found = total > 0
    surface = (wts * finite).sum(axis=0) / np.maximum(total, 1e-300)  # (N,)
    # where that surface is the nearest source's own (a card on one wall), the nearest source's
    # continuation stays: it is the closest evidence, in any direction
    found &= np.abs(surface - fallback_nd[br, bc]) > _JOIN * s.disparity_jump
    # every source on that surface joins (the one just above a card, where the wall runs on behind it)
    on_it = valid & found[None] & (np.abs(finite - surface[None]) <= _JOIN * s.disparity_jump)
    wts = np.where(on_it | agree, inv_d2, 0.0)
    wts[:, ~found] = 0.0
    wts[:, found] /= wts[:, found].sum(axis=0)
    out = fallback_nd.copy()
    out[br[found], bc[found]] = (wts * finite).sum(axis=0)[found]
    if col_fit is None:
        return out, None
    terms = [None] * 4

    def colour_of(k: int) -> None:  # candidate k's weighted colour continued to its band pixels
        sel = wts[k] > 0
        if sel.any():
            terms[k] = (sel, wts[k, sel, None] * continue_at(col_fit, cand[k][sel], (pix[0][sel], pix[1][sel]),
                                                             s.max_colour_step))

    halves(colour_of, 4)
    rgb = np.zeros((len(br), 3))
    for term in terms:  # summed in candidate order, as one loop would
        if term is not None:
            rgb[term[0]] += term[1]
    if not found.all():  # no candidate: the Voronoi continuation
        rest = np.zeros_like(band)
        rest[br[~found], bc[~found]] = True
        fb = extrapolate(col_fit, nearest, source, s.max_colour_step, rest)
        rgb[~found] = fb[br[~found], bc[~found]]
    if rgbc is not None:
        _follow_isophotes(rgb, rgbc, source, br, bc, cand, agree, found, nearest, ndc, s.disparity_jump)
    return out, np.clip(rgb, 0.0, 1.0).astype(np.float32)


_MIX_FIT = 0.15
"""A row (column) beside the recoloured ones is taken for an anti-aliased crease where the two surfaces'
mix explains the gap's sides up to this share of their neighbours' difference (squared) ..."""
_CREASE_KINK = 0.05
"""... and where the disparity across it on the gap's sides bends by more than this many ``disparity_jump``
(a crease: the disparity is affine on each plane, so one receding plane is no crease)."""


def _follow_isophotes(
    rgb: np.ndarray, rgbc: np.ndarray, source: np.ndarray, br: np.ndarray, bc: np.ndarray, cand: np.ndarray,
    agree: np.ndarray, found: np.ndarray, nearest: np.ndarray, ndc: np.ndarray, jump: float,
) -> None:
    """Recolour, in place, the band pixels (``br``, ``bc``) that take a surface their row's or column's
    agreeing pair continues (``found``): with the colours where the texture's isophotes through them
    meet the gap's two sides (:func:`~.isophotes.across_gap`), not the pair's colours continued straight
    along the row or column. A pixel both pairs cover blends the two by inverse squared gap width.

    The row (column) just beside those, between the same two sides' neighbours, whose pixels continue
    a source beyond them (on the far side from the recoloured neighbour) lies on the crease between
    that source's surface and the recoloured one (a wall above a ground): its pixels are anti-aliased
    mixtures of the two.
    Where the gap's sides show such a mix (their pixel there lies between its two neighbours across
    the crease, up to ``_MIX_FIT``, and their disparity bends there, ``_CREASE_KINK``), the pixel takes the same mix of its own colour (the nearest
    source's surface continued) and of the recoloured surface's share, which follows the isophotes
    across the gap as the recoloured rows do (the sides' crease pixels less their other share,
    matched with those rows); where that share finds no match, its recoloured neighbour's colour."""
    acc = np.zeros(rgb.shape)
    total = np.zeros(len(br))
    h, w = source.shape
    edges = []
    for a, b in ((0, 1), (2, 3)):
        sel = found & agree[a] & agree[b]
        if not sel.any():
            continue
        # and every pixel between the same two sources (beside the card, nearer one of them than anything)
        key = (cand[a, :, 0].astype(np.int64) * w + cand[a, :, 1]) * (h * w) + cand[b, :, 0] * w + cand[b, :, 1]
        both = (cand[a, :, 0] >= 0) & (cand[b, :, 0] >= 0)
        sel = both & np.isin(key, key[sel])
        step = w * (h * w + 1) if a == 0 else h * w + 1  # the same sides one row (column) on
        pair = agree[a] & agree[b] & both & ~sel
        for sign in (1, -1):
            edge = pair & np.isin(key + sign * step, key[sel])
            if edge.any():
                edges.append((a, b, sign, edge, sel))
        if a == 0:  # left / right: along the rows
            col, ok = across_gap(rgbc, source, br[sel], bc[sel], cand[a, sel, 1], cand[b, sel, 1])
            gap = cand[b, sel, 1] - cand[a, sel, 1]
        else:  # above / below: the same along the columns
            col, ok = across_gap(rgbc.transpose(1, 0, 2), source.T, bc[sel], br[sel], cand[a, sel, 0], cand[b, sel, 0])
            gap = cand[b, sel, 0] - cand[a, sel, 0]
        wt = np.where(ok, 1.0 / np.maximum(gap, 1).astype(np.float64) ** 2, 0.0)
        acc[sel] += wt[:, None] * col
        total[sel] += wt
    done = total > 0
    rgb[done] = acc[done] / total[done, None]
    if not edges:
        return
    index = np.full(source.shape, -1, np.int64)
    index[br, bc] = np.arange(len(br))
    src_r, src_c = np.nonzero(source)  # ``nearest`` indexes these
    for a, b, sign, edge, sel in edges:
        # a row (column) between the same two sides next to the recoloured ones: where the surface
        # meets the nearest source's (a crease), its pixels are anti-aliased mixtures of the two;
        # the mix is measured on the gap's two sides and applied to the two colours beside the pixel
        k = np.nonzero(edge)[0]
        dr, dc = (sign, 0) if a == 0 else (0, sign)
        inner = index[br[k] + dr, bc[k] + dc]  # the recoloured neighbour
        num = np.zeros(k.size)
        den = np.zeros(k.size)
        sides = []
        # a crease: the pixel continues a source beyond it, on the far side from its recoloured neighbour
        q = nearest[br[k], bc[k]]
        usable = (inner >= 0) & (((src_r[q] - br[k]) * dr + (src_c[q] - bc[k]) * dc) < 0)
        for side in (a, b):
            sr, sc = cand[side, k, 0], cand[side, k, 1]
            ir, ic = sr + dr, sc + dc
            orow, ocol = sr - dr, sc - dc
            inside = (ir >= 0) & (ir < h) & (ic >= 0) & (ic < w) & (orow >= 0) & (orow < h) & (ocol >= 0) & (ocol < w)
            ir, ic, orow, ocol = (np.clip(ir, 0, h - 1), np.clip(ic, 0, w - 1), np.clip(orow, 0, h - 1),
                                  np.clip(ocol, 0, w - 1))
            ok = inside & source[ir, ic] & source[orow, ocol]
            v, v_in, v_out = rgbc[sr, sc], rgbc[ir, ic], rgbc[orow, ocol]
            sides.append((ok, v, v_in, v_out))
            # the disparity is affine on a plane: a crease between two shows as a kink
            ok &= np.abs(ndc[orow, ocol] - 2.0 * ndc[sr, sc] + ndc[ir, ic]) > _CREASE_KINK * jump
            num += np.where(ok, ((v - v_in) * (v_out - v_in)).sum(axis=1), 0.0)
            den += np.where(ok, ((v_out - v_in) ** 2).sum(axis=1), 0.0)
            usable &= ok
        usable &= den > 1e-6
        alpha = np.clip(num / np.maximum(den, 1e-12), 0.0, 1.0)[:, None]  # share of the other surface
        # a mixture: the sides' pixels lie between their two neighbours (texture is not)
        miss = sum(np.where(ok, ((v - v_in - alpha * (v_out - v_in)) ** 2).sum(axis=1), 0.0)
                   for ok, v, v_in, v_out in sides)
        usable &= miss <= _MIX_FIT * den
        k, alpha, inner = k[usable], alpha[usable], inner[usable]
        other = rgb[inner]
        if k.size:
            # the crease row's share of the recoloured surface, followed along its isophotes as well: the
            # sides' crease pixels less their other share, matched with the recoloured rows
            part = rgbc.copy()
            for side in (a, b):
                sr, sc = cand[side, k, 0], cand[side, k, 1]
                part[sr, sc] = (rgbc[sr, sc] - alpha * rgbc[sr - dr, sc - dc]) / np.maximum(1.0 - alpha, 0.1)
            # the recoloured rows (columns) within the profiles' reach of the crease, and the crease
            line = br if a == 0 else bc
            reach = np.zeros(max(h, w) + 1, bool)
            for at_line in np.unique(line[k]):
                reach[max(0, at_line - _ACROSS_REACH):at_line + _ACROSS_REACH + 1] = True
            pix = sel & reach[line]
            pix[k] = True
            if a == 0:
                col, ok = across_gap(part, source, br[pix], bc[pix], cand[a, pix, 1], cand[b, pix, 1])
            else:
                col, ok = across_gap(part.transpose(1, 0, 2), source.T, bc[pix], br[pix], cand[a, pix, 0],
                                     cand[b, pix, 0])
            at = np.cumsum(pix) - 1  # row of each pixel of ``pix`` in the results
            good = ok[at[k]] & (alpha[:, 0] < 0.9)
            other = np.where(good[:, None], np.clip(col[at[k]], 0.0, 1.0), other)
        rgb[k] = alpha * rgb[k] + (1.0 - alpha) * other
