"""Colour transfer of the points' own colours towards a style (Reinhard et al. 2001, in CIE L*a*b*).

The detail path (:mod:`.stylize3d`) rasterizes every point's colour beside the
learned features, and the decoder's colour transform recolours it. With
``ModelConfig.detail_transfer`` those colours are first moved to the style's
colour statistics, once per photo and style, on the points themselves::

    lab' = (lab - mean_c) * g + mean_t,   g = 1 + s (clip(std_s / std_c, 0, MAX_GAIN) - 1),
                                          mean_t = mean_c + s (mean_s - mean_c)

per L*, a*, b* channel, with ``mean_c, std_c`` over the photo's points,
``mean_s, std_s`` over the style image's pixels and ``s`` the style strength
(0: the colours are unchanged). The gain of L* is at least
:data:`MIN_LIGHTNESS_GAIN` (1): a style with less lightness contrast than the
photo takes its palette and mean lightness, but the photo keeps its contrast,
i.e. its detail (held-out pairs of ``stylize3d bench quality --quick``, strength
1, before the gamut mapping: sharpness 0.57x -> 0.89x the plain render, Lab
distance 1.39x -> 1.97x the 2D network's; ``docs/quality.md``). Being a per-point recolouring it is the same
in every view (consistent by construction) and keeps every edge of the photo;
the learned model adds the style's texture and local colour on top. Colours
that land outside the sRGB gamut keep their lightness and hue and lose chroma
(:func:`gamut_map`) instead of being clipped channel by channel.

The conversion is OpenCV's float sRGB <-> L*a*b* (D65), as
:func:`~stylize3d_core.models.losses.rgb_to_lab`. No gradients flow through it:
it recolours inputs, at inference and in training alike.
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np
import torch

from .. import threads as _threads
from ..checks import check_range

MAX_GAIN = 3.0
"""Largest std ratio applied: a flat photo is not blown up into noise."""

MIN_LIGHTNESS_GAIN = 1.0
"""Smallest gain of L*: the photo's lightness contrast (its detail) is never reduced."""

_EPS = 1e-3
"""Added to the photo's std (L* units of 0-100): a constant channel gets a finite gain (then capped)."""

_MAX_STYLE_PIXELS = 1 << 18
"""Style images are subsampled to at most this many pixels for their statistics."""


class LabStats(NamedTuple):
    """Mean and std of L*, a*, b* (each a float32 array of 3)."""

    mean: np.ndarray
    std: np.ndarray


def _to_lab(rgb: np.ndarray) -> np.ndarray:
    """(n, 3) float in [0, 1] -> (n, 3) float32 L*a*b*."""
    x = np.nan_to_num(np.asarray(rgb, np.float32).reshape(-1, 1, 3), nan=0.0).clip(0.0, 1.0)
    return cv2.cvtColor(x, cv2.COLOR_RGB2Lab).reshape(-1, 3)


def lab_stats(rgb) -> LabStats:
    """Colour statistics of colours (n, 3) or an image (h, w, 3) / (3, h, w) tensor, values in [0, 1]."""
    if isinstance(rgb, torch.Tensor):
        t = rgb.detach().float().cpu()
        if t.dim() == 3 and t.shape[0] == 3 and t.shape[-1] != 3:
            t = t.permute(1, 2, 0)
        rgb = t.numpy()
    x = np.asarray(rgb, np.float32).reshape(-1, 3)
    if x.shape[0] > _MAX_STYLE_PIXELS:
        x = x[:: -(-x.shape[0] // _MAX_STYLE_PIXELS)]
    lab = _to_lab(x)
    return LabStats(lab.mean(0).astype(np.float32), lab.std(0).astype(np.float32))


def mix_stats(a: LabStats, b: LabStats, t: float) -> LabStats:
    """Linear mix of two styles' statistics (t = 0: ``a``, 1: ``b``)."""
    return LabStats((1 - t) * a.mean + t * b.mean, (1 - t) * a.std + t * b.std)


_LAB_WHITE = np.array([0.950456, 1.0, 1.088754], np.float32)  # D65, as OpenCV
_XYZ_TO_LINEAR = np.array([[3.240479, -1.53715, -0.498535],
                           [-0.969256, 1.875991, 0.041556],
                           [0.055648, -0.204043, 1.057311]], np.float32)


def _linear_rgb(lab: np.ndarray) -> np.ndarray:
    """(n, 3) L*a*b* -> linear sRGB, unclipped (outside [0, 1] = out of the sRGB gamut).

    Written column by column with products instead of ``**3`` and ``@``: numpy's (n, 3) @ (3, 3) and
    float powers are ~10x slower on a few hundred thousand colours.
    """
    lab = np.asarray(lab, np.float32)
    fy = (lab[:, 0] + 16.0) / 116.0
    d = 6.0 / 29.0
    xyz = []
    for f, white in ((fy + lab[:, 1] / 500.0, _LAB_WHITE[0]), (fy, _LAB_WHITE[1]), (fy - lab[:, 2] / 200.0, _LAB_WHITE[2])):
        v = f * f * f
        low = f <= d
        if low.any():
            v[low] = (3 * d * d) * (f[low] - 4.0 / 29.0)
        xyz.append(v * white)
    m = _XYZ_TO_LINEAR
    out = np.empty((lab.shape[0], 3), np.float32)
    for i in range(3):
        out[:, i] = xyz[0] * m[i, 0] + xyz[1] * m[i, 1] + xyz[2] * m[i, 2]
    return out


_GAMUT_STEPS = 8
"""Bisection steps of :func:`gamut_map` (the chroma scale to 1/256)."""


def _kernels():
    """The compiled colour map (None where Numba is missing: the numpy lines then, the same colours)."""
    return _threads.compiled(__package__ + "._kernels")


def warm_up() -> None:
    """Load the compiled colour map (Numba's cache) with one colour, so a photo's first frame does not wait."""
    k = _kernels()
    if k is not None:
        one = np.zeros((1, 3), np.float32)
        k.transfer(one, one[0], np.ones(3, np.float32), one[0], _LAB_WHITE, _XYZ_TO_LINEAR, 1, 0, 1, one.copy())


def gamut_map(lab: np.ndarray, steps: int = _GAMUT_STEPS) -> np.ndarray:
    """Bring L*a*b* colours (n, 3) into the sRGB gamut by reducing their chroma (a*, b*) only, keeping L*.

    A transferred highlight or shadow can ask for a chroma that no sRGB colour has at
    its lightness; clipping each RGB channel would then change its hue (a white rim
    turning cyan). Here the chroma of such colours is scaled down, by bisection, to
    the largest that fits (grey always fits).
    """
    out = lab.copy()
    lin = _linear_rgb(out)
    bad = np.flatnonzero(((lin < -1e-4) | (lin > 1.0 + 1e-4)).any(axis=1))
    if bad.size == 0:
        return out
    sub = out[bad]
    lo = np.zeros(bad.size, np.float32)  # scales known to fit
    hi = np.ones(bad.size, np.float32)  # scales known not to
    for _ in range(steps):
        mid = (lo + hi) / 2
        trial = np.concatenate([sub[:, :1], sub[:, 1:] * mid[:, None]], axis=1)
        rgb = _linear_rgb(trial)
        fits = ((rgb >= -1e-4) & (rgb <= 1.0 + 1e-4)).all(axis=1)
        lo = np.where(fits, mid, lo)
        hi = np.where(fits, hi, mid)
    out[bad, 1:] = sub[:, 1:] * lo[:, None]
    return out


_CHUNK = 1 << 17
"""Colours mapped at once by :class:`ColourTransfer` (a chunk's temporaries stay in the cache)."""


class ColourTransfer:
    """The points' colours (N, 3) in [0, 1], ready to be moved towards any style (see the module docstring).

    Their L*a*b* values and statistics are computed once; each call then costs
    one affine map and one conversion back to sRGB.
    """

    compiled = True
    """Map with the compiled kernel where Numba imports (False: the numpy reference; the same colours)."""

    def __init__(self, rgb: torch.Tensor) -> None:
        self.rgb = rgb.detach().float().clamp(0.0, 1.0)
        src = self.rgb.cpu().numpy()
        n = src.shape[0]
        self._lab = np.empty((n, 3), np.float32)
        starts = range(0, n, _CHUNK)
        moments = [None] * len(starts)

        def part(j: int) -> None:  # a chunk's L*a*b* and its float64 count, mean and sum of squared deviations
            a = starts[j]
            lab = self._lab[a:a + _CHUNK]
            lab[:] = _to_lab(src[a:a + _CHUNK])
            mean = lab.mean(0, dtype=np.float64)
            moments[j] = (lab.shape[0], mean, np.square(lab - mean).sum(0))

        if len(starts) > 1:  # numpy and OpenCV free the GIL on arrays this large
            list(_threads.pool().map(part, range(len(starts))))
        elif n:
            part(0)
        # the chunks' moments combined (Chan et al.), in float64: the statistics (and so the colours) do not
        # depend on the order of the points beyond float64 rounding, far below the float32 they are kept in
        count, mean, m2 = 0, np.zeros(3, np.float64), np.zeros(3, np.float64)
        for c, m, q in moments:
            delta = m - mean
            total = count + c
            mean = mean + delta * (c / total)
            m2 = m2 + q + delta * delta * (count * c / total)
            count = total
        self.stats = LabStats(mean.astype(np.float32), np.sqrt(m2 / max(count, 1)).astype(np.float32))

    def __call__(self, style: LabStats, strength: float = 1.0) -> torch.Tensor:
        """(N, 3) float32 in [0, 1], finite, on the colours' device; strength 0 returns the colours."""
        strength = check_range(strength, "strength", 0.0, 1.0)
        if strength == 0.0 or self._lab.shape[0] == 0:
            return self.rgb
        c = self.stats
        ratio = np.clip(np.nan_to_num(style.std / (c.std + _EPS), nan=1.0), 0.0, MAX_GAIN)
        ratio[0] = max(ratio[0], MIN_LIGHTNESS_GAIN)
        gain = 1.0 + strength * (ratio - 1.0)
        target = c.mean + strength * (np.nan_to_num(style.mean, nan=0.0) - c.mean)
        gain32, target32 = gain.astype(np.float32), target.astype(np.float32)
        n = self._lab.shape[0]
        back = np.empty((n, 3), np.float32)

        kernels = _kernels() if self.compiled else None
        mean32 = np.asarray(c.mean, np.float32)

        def part(a: int) -> None:  # each colour's own map: chunks give the same colours, in cache, on both cores
            lab = self._lab[a:a + _CHUNK]
            if kernels is not None:  # one pass per colour, the same bits as the numpy lines below
                out = np.empty_like(lab)
                kernels.transfer(lab, mean32, gain32, target32, _LAB_WHITE, _XYZ_TO_LINEAR, _GAMUT_STEPS,
                                 0, lab.shape[0], out)
            else:
                out = (lab - c.mean) * gain32 + target32
                out[:, 0] = out[:, 0].clip(0.0, 100.0)
                out[:, 1:] = out[:, 1:].clip(-127.0, 127.0)
                out = gamut_map(out, _GAMUT_STEPS)
            rgb = cv2.cvtColor(out.astype(np.float32).reshape(-1, 1, 3), cv2.COLOR_Lab2RGB).reshape(-1, 3)
            back[a:a + _CHUNK] = np.nan_to_num(rgb, nan=0.0).clip(0.0, 1.0)

        starts = range(0, n, _CHUNK)
        if len(starts) == 1:
            part(0)
        else:  # numpy and OpenCV free the GIL on arrays this large
            list(_threads.pool().map(part, starts))
        return torch.from_numpy(back).to(self.rgb.device)


def transfer_colours(rgb: torch.Tensor, style: LabStats, strength: float = 1.0) -> torch.Tensor:
    """Colours (N, 3) in [0, 1] moved towards ``style``'s L*a*b* statistics: ``ColourTransfer(rgb)(style, strength)``."""
    return ColourTransfer(rgb)(style, strength)


__all__ = ["ColourTransfer", "LabStats", "gamut_map", "MAX_GAIN", "lab_stats", "mix_stats", "transfer_colours", "warm_up"]
