"""The border: the photo extended beyond its frame, with a hidden layer where an edge comes near it."""

from __future__ import annotations

from typing import Optional, Tuple

import cv2
import numpy as np

from ...geometry.camera import NEAR_DEPTH
from .._fill import push_pull
from .layers import LDISettings


def _edges_near_frame(fg: np.ndarray, pad: int) -> bool:
    """Whether a foreground edge comes within ``pad`` pixels of the photo's frame (something in
    front may be cut by it; with none, e.g. a slanted plane, the border needs no hidden layer)."""
    k = min(pad, min(fg.shape) // 2)
    return bool(fg[:k].any() or fg[-k:].any() or fg[:, :k].any() or fg[:, -k:].any())


def _border(
    rgb: np.ndarray, nd: np.ndarray, fg: np.ndarray, pad: int, s: LDISettings,
) -> Tuple[np.ndarray, np.ndarray, Optional[Tuple[np.ndarray, np.ndarray, np.ndarray]]]:
    """The canvas's colour and disparity with a border of ``pad`` (:func:`_extend_border`) and the border's
    hidden samples (:func:`_border_hidden`: mask (Hc, Wc), their colours (n, 3) and depths (n,); None
    where it has none)."""
    rgb0, nd0 = _extend_border(rgb, nd, pad)
    outer = None
    if pad > 0 and _edges_near_frame(fg, pad):
        outer = _border_hidden(rgb, nd, nd0, pad, s)
    return rgb0, nd0, outer


def _border_hidden(
    rgb: np.ndarray, nd: np.ndarray, nd0: np.ndarray, pad: int, s: LDISettings,
) -> Optional[Tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Hidden background in the border, behind foreground that the frame's edge cuts: the mask (Hc, Wc) of
    the border pixels that get a hidden sample, their colours (n, 3) and depths (n,); None if none do.

    The border's layer 0 continues whatever reaches the frame's edge, a tower cut by it
    too; a camera that looks past the edge then sees the tower's continuation with
    nothing behind it. The photo's background pixels (within ``disparity_jump`` of the
    farthest ``nd`` within ``pad`` of them) are continued into the border the same way
    (push-pull); border pixels whose layer 0 is in front of that continuation by more
    than ``disparity_jump`` get it as a hidden sample.
    """
    h, w = nd.shape
    k = 2 * pad + 1
    far = cv2.erode(nd, np.ones((k, k), np.uint8), borderType=cv2.BORDER_REPLICATE)
    background = (nd - far <= s.disparity_jump).astype(np.float32)  # (H, W)
    if background.all():
        return None  # nothing in front of anything: the border's layer 0 is background already
    values = np.zeros((h + 2 * pad, w + 2 * pad, 4), np.float32)
    weight = np.zeros((h + 2 * pad, w + 2 * pad), np.float32)
    inner = (slice(pad, pad + h), slice(pad, pad + w))
    values[inner] = np.concatenate([rgb, nd[..., None]], axis=2)
    weight[inner] = background
    filled = push_pull(values, weight)  # (Hc, Wc, 4) the background continued
    outside = np.ones(nd0.shape, bool)
    outside[inner] = False
    add = outside & (nd0 - filled[..., 3] > s.disparity_jump) & (filled[..., 3] > 0)
    return add, np.clip(filled[..., :3][add], 0.0, 1.0), NEAR_DEPTH / filled[..., 3][add]


def _extend_border(rgb: np.ndarray, nd: np.ndarray, pad: int) -> Tuple[np.ndarray, np.ndarray]:
    """Canvas colour (Hc, Wc, 3) and normalised disparity (Hc, Wc) with a border of ``pad``."""
    if pad == 0:
        return rgb.copy(), nd.copy()
    h, w = nd.shape
    values = np.zeros((h + 2 * pad, w + 2 * pad, 4), np.float32)
    weight = np.zeros((h + 2 * pad, w + 2 * pad), np.float32)
    inner = (slice(pad, pad + h), slice(pad, pad + w))
    values[inner] = np.concatenate([rgb, nd[..., None]], axis=2)
    weight[inner] = 1.0
    filled = push_pull(values, weight)  # (Hc, Wc, 4)
    replicated = cv2.copyMakeBorder(nd, pad, pad, pad, pad, cv2.BORDER_REPLICATE)
    nd_c = np.minimum(filled[..., 3], replicated)  # never nearer than the photo's border pixel
    rgb_c = np.clip(filled[..., :3], 0.0, 1.0)
    rgb_c[inner] = rgb
    nd_c[inner] = nd
    return np.ascontiguousarray(rgb_c), np.ascontiguousarray(nd_c)
