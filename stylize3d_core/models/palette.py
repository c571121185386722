"""Palette matching: one colour matrix, the same for every view, that gives the frames the style's colour statistics.

The detail path moves the points' colours to the style's L*a*b* statistics
(:mod:`.colour_transfer`), but the decoder's learned colour transform then mixes
them with the U-Net's smooth output, and on many styles the frames end up far
flatter and greyer than both the style and the transferred colours (a Voronoi
texture: lightness std 27 in the style, 25 in the transferred colours, 7 in the
frames). Palette matching corrects that after the model:

1. render the photo's own view small (:func:`fit_palette` takes its pixels);
2. move those pixels' L*a*b* mean and std to the target statistics (:func:`palette_target`:
   the photo's moved by the strength towards the style's), per channel, gains limited to
   ``[1 / max_gain, max_gain]`` and the lightness contrast of the frames not lowered by any
   pass (the passes together can lower it by a few percent; docs/quality.md) (their detail: a style flatter than the frames gives its palette and mean lightness,
   but the edges stay as sharp as the model made them),
   out-of-gamut colours brought in by chroma (:func:`~.colour_transfer.gamut_map`);
3. fit the affine map ``rgb -> M^T [rgb, 1]`` (a 4 x 3 matrix) from the pixels to
   their corrected colours by least squares, again and again (up to 8 passes: each corrects
   what the previous map left of the L*a*b* statistics).

Every frame is then ``clamp([rgb, 1] M)``: a global colour map, which adds no
view-dependent change of its own (it scales the differences the model's views
already have by its gain), and it costs one small matrix product per frame. An affine RGB map cannot follow every bend of the L*a*b*
correction; :func:`fit_palette` reports the statistics it reaches.
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np
import torch

from ..checks import check_range
from ..errors import InputError
from .colour_transfer import LabStats, _to_lab, gamut_map

MAX_PALETTE_GAIN = 6.0
"""Largest (and 1 / smallest) per-channel std gain of the correction."""

MAX_FIT_PIXELS = 1 << 13
"""Pixels used for the fit (a deterministic stride subsample beyond this)."""

_EPS = 1e-3
_CONVERGED = 1e-5
"""The fit stops when no entry of the map changes by more than this between passes."""


class Palette(NamedTuple):
    """A fitted palette map.

    Attributes:
        matrix: (4, 3) float32: ``out = clamp([rgb, 1] @ matrix, 0, 1)``.
        before: the L*a*b* statistics of the fitted pixels.
        after: their statistics after the map (what it reached of the target).
        target: the statistics aimed at.
    """

    matrix: np.ndarray
    before: LabStats
    after: LabStats
    target: LabStats


def palette_target(photo: LabStats, style: LabStats, strength: float) -> LabStats:
    """The statistics the palette map aims at: the photo's means and stds moved by ``strength``
    towards the style's (:func:`fit_palette` never lowers the frames' lightness contrast)."""
    s = check_range(strength, "strength", 0.0, 1.0)
    p_mean, p_std = np.asarray(photo.mean, np.float64), np.asarray(photo.std, np.float64)
    s_mean, s_std = np.nan_to_num(np.asarray(style.mean, np.float64)), np.nan_to_num(np.asarray(style.std, np.float64))
    return LabStats((p_mean + s * (s_mean - p_mean)).astype(np.float32), (p_std + s * (s_std - p_std)).astype(np.float32))


def _stats(lab: np.ndarray) -> LabStats:
    return LabStats(lab.mean(0, dtype=np.float64).astype(np.float32), lab.std(0, dtype=np.float64).astype(np.float32))


def _apply_np(x1: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    return (x1 @ matrix).clip(0.0, 1.0)


def fit_palette(pixels: np.ndarray, target: LabStats, *, max_gain: float = MAX_PALETTE_GAIN,
                min_lightness_gain: float = 1.0, passes: int = 8) -> Palette:
    """The palette map taking ``pixels`` (n, 3) (or an image (h, w, 3)), floats in [0, 1], to ``target``'s statistics.

    No pass scales the L* std by less than ``min_lightness_gain`` (1: the frames' lightness contrast,
    their detail, is kept where the style is flatter, within a few percent over all the passes; the
    style's palette and mean lightness still apply).

    Non-finite pixels are ignored; with no finite pixel, or a target that is not finite, the map is the identity.
    ``passes``: at most this many fits, each correcting what the previous map left of the statistics (it stops
    when the map stops changing). Each pass corrects what the previous one left; a few passes cost tens of
    milliseconds once per style.
    """
    check_range(max_gain, "max_gain", 1.0, 100.0)
    check_range(min_lightness_gain, "min_lightness_gain", 0.0, 1.0)
    if isinstance(passes, bool) or not isinstance(passes, int) or not 1 <= passes <= 8:
        raise InputError("passes", f"must be an integer from 1 to 8, got {passes!r}")
    x = np.asarray(pixels, np.float32).reshape(-1, 3)
    x = x[np.isfinite(x).all(axis=1)].clip(0.0, 1.0)
    if x.shape[0] > MAX_FIT_PIXELS:
        x = x[:: -(-x.shape[0] // MAX_FIT_PIXELS)]
    identity = np.vstack([np.eye(3), np.zeros((1, 3))]).astype(np.float32)
    t_mean, t_std = np.asarray(target.mean, np.float64), np.asarray(target.std, np.float64)
    if x.shape[0] == 0 or not (np.isfinite(t_mean).all() and np.isfinite(t_std).all()):
        empty = LabStats(np.zeros(3, np.float32), np.zeros(3, np.float32))
        before = _stats(_to_lab(x)) if x.shape[0] else empty
        return Palette(identity, before, before, target)
    x1 = np.hstack([x, np.ones((x.shape[0], 1), np.float32)]).astype(np.float64)  # (n, 4)
    before = _stats(_to_lab(x))
    gram = x1.T @ x1
    ridge = 1e-4 * x.shape[0]  # towards the identity: a flat image (a singular fit) keeps its colours
    matrix = identity.astype(np.float64)
    for _ in range(passes):
        cur = _apply_np(x1, matrix).astype(np.float32)
        lab = _to_lab(cur)
        s = _stats(lab)
        gain = np.clip(t_std / (s.std.astype(np.float64) + _EPS), 1.0 / max_gain, max_gain)
        gain[0] = max(gain[0], min_lightness_gain)
        want = (lab - s.mean) * gain.astype(np.float32) + t_mean.astype(np.float32)
        want[:, 0] = want[:, 0].clip(0.0, 100.0)
        want[:, 1:] = want[:, 1:].clip(-127.0, 127.0)
        want = gamut_map(want)
        y = cv2.cvtColor(want.reshape(-1, 1, 3), cv2.COLOR_Lab2RGB).reshape(-1, 3).clip(0.0, 1.0)
        new = np.linalg.solve(gram + ridge * np.eye(4), x1.T @ y.astype(np.float64) + ridge * identity)
        done = bool(np.isfinite(new).all() and np.abs(new - matrix).max() < _CONVERGED)
        matrix = new
        if done:
            break
    if not np.isfinite(matrix).all():
        return Palette(identity, before, before, target)
    matrix = matrix.astype(np.float32)
    after = _stats(_to_lab(_apply_np(x1.astype(np.float32), matrix)))
    return Palette(matrix, before, after, target)


def apply_palette(rgb: torch.Tensor, matrix: np.ndarray) -> torch.Tensor:
    """``rgb`` (3, H, W) float in [0, 1] through a palette ``matrix`` (4, 3): a new (3, H, W) float32 tensor in [0, 1]."""
    if rgb.dim() != 3 or rgb.shape[0] != 3:
        raise InputError("rgb", f"expected a (3, H, W) image, got {tuple(rgb.shape)}")
    m = torch.as_tensor(matrix, dtype=torch.float32, device=rgb.device)
    with torch.autocast(device_type=rgb.device.type, enabled=False):  # float32 under a bfloat16 autocast too
        out = torch.addmm(m[3][:, None], m[:3].T, rgb.float().reshape(3, -1))  # (3, H*W): M^T [rgb, 1]
    return out.clamp_(0.0, 1.0).reshape(rgb.shape)


__all__ = ["MAX_PALETTE_GAIN", "Palette", "apply_palette", "fit_palette", "palette_target"]
