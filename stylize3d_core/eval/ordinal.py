"""Ordinal depth agreement: the share of pixel pairs a depth map puts in the right depth order.

Relative depth (the built-in prior, a monocular network) is known only up to an
unknown monotonic map, so it is scored by the order it gives pairs of pixels,
not by its values: for random pairs of pixels with ground truth whose true
disparities differ by more than ``margin``, the share where the nearer pixel
(larger disparity) also has the smaller predicted depth. A tie in the
prediction counts one half (a constant depth map scores 0.5, like a coin).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError


def ordinal_agreement(depth: np.ndarray, gt_disparity: np.ndarray, *, pairs: int = 200_000,
                      margin: float = 1.0, seed: int = 0) -> float:
    """Share in [0, 1] of random valid pixel pairs that ``depth`` orders like ``gt_disparity``.

    Args:
        depth: (H, W) predicted depth (smaller = nearer).
        gt_disparity: (H, W) ground-truth disparity (larger = nearer); non-finite = no ground truth.
        pairs: random pairs drawn (with a fixed ``seed``) among the pixels with ground truth.
        margin: pairs whose true disparities differ by at most this are left out.
        seed: random seed.
    """
    depth = np.asarray(depth, np.float64)
    gt = np.asarray(gt_disparity, np.float64)
    if depth.shape != gt.shape or depth.ndim != 2:
        raise InputError("depth", f"expected (H, W) maps of one shape, got {depth.shape} and {gt.shape}")
    valid = np.flatnonzero(np.isfinite(gt.ravel()) & np.isfinite(depth.ravel()))
    if valid.size < 2:
        raise InputError("gt_disparity", "fewer than two pixels with ground truth")
    rng = np.random.default_rng(seed)
    i = valid[rng.integers(0, valid.size, pairs)]
    j = valid[rng.integers(0, valid.size, pairs)]
    dg = gt.ravel()[i] - gt.ravel()[j]
    keep = np.abs(dg) > margin
    if not keep.any():
        raise InputError("gt_disparity", f"no pair differs by more than margin {margin}")
    dp = depth.ravel()[j][keep] - depth.ravel()[i][keep]  # > 0 where i is predicted nearer
    truth = np.sign(dg[keep])
    score = np.where(dp == 0, 0.5, (np.sign(dp) == truth).astype(np.float64))
    return float(score.mean())
