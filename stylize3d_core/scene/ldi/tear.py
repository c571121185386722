"""Tearing the depth map at its edges: where the foreground ends and the hidden layer begins."""

from __future__ import annotations

from typing import Tuple

import cv2
import numpy as np

from .._fill import ring_min, torn_regions
from .layers import LDISettings


def _edges(nd: np.ndarray, jump: float) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Signed neighbour differences and cut maps: dx (H, W-1), dy (H-1, W), cut_h, cut_v."""
    dx = nd[:, 1:] - nd[:, :-1]
    dy = nd[1:, :] - nd[:-1, :]
    return dx, dy, np.abs(dx) > jump, np.abs(dy) > jump


def _tear(nd: np.ndarray, s: LDISettings) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flatten tiny islands, then find the foreground / background edge maps (H, W)."""
    h, w = nd.shape
    dx, dy, cut_h, cut_v = _edges(nd, s.disparity_jump)
    min_area = max(s.island_min_px, s.island_area * h * w)
    for _ in range(2):  # a second pass catches islands left behind by the first
        if not (cut_h.any() or cut_v.any()):
            break
        graph = torn_regions(cut_h, cut_v)
        small = graph.areas < min_area  # (R,)
        small[0] = False  # label 0 is unused
        if not small.any():
            break
        fill = ring_min(nd, graph.labels, small)  # (R,)
        small &= np.isfinite(fill)
        if not small.any():
            break
        flat = small[graph.labels]  # (H, W)
        nd = nd.copy()
        nd[flat] = fill[graph.labels[flat]]
        dx, dy, cut_h, cut_v = _edges(nd, s.disparity_jump)

    fg = np.zeros((h, w), bool)
    bg = np.zeros((h, w), bool)
    if not (cut_h.any() or cut_v.any()):
        return nd, fg, bg
    t = s.disparity_jump
    fg[:, 1:] |= dx > t
    bg[:, :-1] |= dx > t
    fg[:, :-1] |= dx < -t
    bg[:, 1:] |= dx < -t
    fg[1:, :] |= dy > t
    bg[:-1, :] |= dy > t
    fg[:-1, :] |= dy < -t
    bg[1:, :] |= dy < -t

    min_len = max(s.edge_min_px, s.edge_min_length * max(h, w))
    n, lab = cv2.connectedComponents((fg | bg).astype(np.uint8), connectivity=8, ltype=cv2.CV_32S)
    length = np.bincount(lab[fg], minlength=n)  # (n,) foreground-edge pixels per component
    keep = length >= min_len
    keep[0] = False
    kept = keep[lab]  # (H, W)
    return nd, fg & kept, bg & kept
