"""Procedural textures: style images for the style bank and surfaces of procedural scenes.

Every generator takes a seeded ``numpy.random.Generator`` and an image size
``(h, w)`` and returns an (h, w, 3) float32 image in [0, 1]; the same generator
state gives the same image. Colours come from random palettes (HSV with a
random hue, saturation and value) so textures are not biased to one hue.

Kinds (:data:`TEXTURE_KINDS`):

* ``noise``: coloured fractal value noise (octaves of bicubic-upsampled random
  grids) mapped through a 2-4 colour palette; sometimes one noise per channel.
* ``stripes``: oriented stripes (square or sine profile, wobbly edges).
* ``checker``: a rotated checkerboard with nearly sharp edges.
* ``brush``: brush-stroke-like oriented noise: fine coloured noise smeared by
  line kernels along a smoothly varying orientation field.
* ``voronoi``: Voronoi cells with jittered palette colours and optional dark seams.
* ``gradient``: linear or radial colour gradient through 2-3 colours.
* ``constant``: one colour (an edge case: a style with zero variance).
"""

from __future__ import annotations

import math
from typing import Callable, Dict, Sequence, Tuple

import cv2
import numpy as np

from ..checks import check_shape
from ..errors import InputError

Size = Tuple[int, int]

TEXTURE_KINDS = ("noise", "stripes", "checker", "brush", "voronoi", "gradient", "constant")
"""Every texture kind :func:`make_texture` knows."""

SCENE_TEXTURE_KINDS = ("noise", "stripes", "checker", "brush", "voronoi")
"""Kinds with enough detail to show parallax on the surfaces of procedural scenes."""


def _check_size(size: Size) -> Tuple[int, int]:
    try:
        h, w = int(size[0]), int(size[1])
    except (TypeError, ValueError, IndexError) as e:
        raise InputError("size", f"expected (h, w), got {size!r}") from e
    if not (1 <= h <= 8192 and 1 <= w <= 8192):
        raise InputError("size", f"sides must be in [1, 8192], got {(h, w)}")
    return h, w


def hsv_to_rgb(hsv: np.ndarray) -> np.ndarray:
    """HSV (..., 3) in [0, 1] -> RGB (..., 3) float32 in [0, 1]."""
    h, s, v = hsv[..., 0] * 6.0, hsv[..., 1], hsv[..., 2]
    k = (np.array([5.0, 3.0, 1.0]) + h[..., None]) % 6.0  # (..., 3)
    rgb = v[..., None] - v[..., None] * s[..., None] * np.clip(np.minimum(k, 4.0 - k), 0.0, 1.0)
    return rgb.astype(np.float32)


def random_palette(rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` random colours (n, 3) float32: hues spread around a random start."""
    hue = (rng.random() + np.arange(n) / n + rng.uniform(-0.08, 0.08, n)) % 1.0
    sat = rng.uniform(0.15, 1.0, n)
    val = rng.uniform(0.15, 1.0, n)
    return hsv_to_rgb(np.stack([hue, sat, val], axis=1))


def colour_map(t: np.ndarray, palette: np.ndarray) -> np.ndarray:
    """Map t (h, w) in [0, 1] piecewise-linearly through the colours (n, 3) -> (h, w, 3)."""
    n = palette.shape[0]
    x = np.clip(t, 0.0, 1.0) * (n - 1)
    i0 = np.minimum(np.floor(x).astype(np.int64), n - 2) if n > 1 else np.zeros(t.shape, np.int64)
    frac = (x - i0)[..., None] if n > 1 else np.zeros(t.shape + (1,))
    i1 = np.minimum(i0 + 1, n - 1)
    return ((1.0 - frac) * palette[i0] + frac * palette[i1]).astype(np.float32)


def _normalise(x: np.ndarray) -> np.ndarray:
    lo, hi = float(x.min()), float(x.max())
    return np.zeros_like(x) if hi - lo < 1e-12 else (x - lo) / (hi - lo)


def fractal_noise(rng: np.random.Generator, size: Size, scale: float, octaves: int = 4) -> np.ndarray:
    """Value noise (h, w) in [0, 1]: bicubic-upsampled random grids, cell ``scale`` px, halved per octave."""
    h, w = _check_size(size)
    out = np.zeros((h, w), np.float32)
    amp = 1.0
    for o in range(octaves):
        cell = max(1.0, scale / 2**o)
        gh, gw = int(math.ceil(h / cell)) + 3, int(math.ceil(w / cell)) + 3
        grid = rng.random((gh, gw)).astype(np.float32)
        up = cv2.resize(grid, (int(round(gw * cell)), int(round(gh * cell))), interpolation=cv2.INTER_CUBIC)
        oy, ox = int(rng.integers(0, max(1, up.shape[0] - h + 1))), int(rng.integers(0, max(1, up.shape[1] - w + 1)))
        out += amp * up[oy : oy + h, ox : ox + w]
        amp *= 0.5
    return _normalise(out)


def _coords(h: int, w: int, angle: float) -> Tuple[np.ndarray, np.ndarray]:
    """Pixel-centre coordinates rotated by ``angle`` (radians): along, across (h, w)."""
    y, x = np.mgrid[0:h, 0:w].astype(np.float32) + 0.5
    c, s = math.cos(angle), math.sin(angle)
    return x * c + y * s, -x * s + y * c


def noise_texture(rng: np.random.Generator, size: Size) -> np.ndarray:
    """Coloured fractal noise (see the module docstring)."""
    h, w = _check_size(size)
    scale = float(np.exp(rng.uniform(math.log(3.0), math.log(max(4.0, max(h, w) / 3.0)))))
    octaves = int(rng.integers(1, 5))
    if rng.random() < 0.25:  # independent noise per channel, tinted
        rgb = np.stack([fractal_noise(rng, (h, w), scale, octaves) for _ in range(3)], axis=2)
        tint = random_palette(rng, 2)
        return np.clip(tint[0] + rgb * (tint[1] - tint[0] + 0.5), 0.0, 1.0).astype(np.float32)
    return colour_map(fractal_noise(rng, (h, w), scale, octaves), random_palette(rng, int(rng.integers(2, 5))))


def stripes_texture(rng: np.random.Generator, size: Size) -> np.ndarray:
    """Oriented stripes with a square or sine profile and slightly wobbly edges."""
    h, w = _check_size(size)
    along, across = _coords(h, w, rng.uniform(0.0, math.pi))
    period = rng.uniform(5.0, max(6.0, min(h, w) / 3.0))
    wobble = rng.uniform(0.0, 0.3) * period * (fractal_noise(rng, (h, w), period * 3.0, 2) - 0.5)
    phase = 2.0 * math.pi * (across + wobble) / period + rng.uniform(0.0, 2.0 * math.pi)
    wave = np.sin(phase)
    if rng.random() < 0.6:  # square profile, edges about a pixel wide
        wave = np.clip(wave * period / 3.0, -1.0, 1.0)
    return colour_map(0.5 + 0.5 * wave, random_palette(rng, int(rng.integers(2, 4))))


def checker_texture(rng: np.random.Generator, size: Size) -> np.ndarray:
    """A rotated checkerboard of two colours with nearly sharp (about a pixel wide) edges."""
    h, w = _check_size(size)
    a, b = _coords(h, w, rng.uniform(0.0, math.pi / 2.0))
    period = rng.uniform(6.0, max(7.0, min(h, w) / 3.0))
    v = np.sin(math.pi * a / period) * np.sin(math.pi * b / period)
    t = np.clip(0.5 + v * period / 2.0, 0.0, 1.0)
    pal = random_palette(rng, 2)
    return colour_map(t, pal)


def brush_texture(rng: np.random.Generator, size: Size) -> np.ndarray:
    """Brush-stroke-like oriented noise (see the module docstring)."""
    h, w = _check_size(size)
    fine = fractal_noise(rng, (h, w), rng.uniform(2.0, 6.0), 2)
    base = colour_map(fine, random_palette(rng, int(rng.integers(2, 5))))  # (h, w, 3)
    field = fractal_noise(rng, (h, w), max(h, w) / 2.0, 1) * math.pi * rng.uniform(0.5, 2.0) + rng.uniform(0, math.pi)
    length = int(rng.integers(7, 26)) | 1
    n_dir = 6
    out = np.zeros_like(base)
    weight_sum = np.zeros((h, w, 1), np.float32)
    for k in range(n_dir):
        theta = math.pi * k / n_dir
        kernel = np.zeros((length, length), np.float32)
        c = length // 2
        dx, dy = math.cos(theta) * c, math.sin(theta) * c
        cv2.line(kernel, (int(round(c - dx)), int(round(c - dy))), (int(round(c + dx)), int(round(c + dy))), 1.0, 1)
        smeared = cv2.filter2D(base, -1, kernel / kernel.sum(), borderType=cv2.BORDER_REFLECT)
        diff = np.angle(np.exp(2j * (field - theta))) / 2.0  # (h, w) orientation difference in (-pi/2, pi/2]
        wk = np.exp(-((diff / (math.pi / n_dir)) ** 2) * 2.0).astype(np.float32)[..., None]
        out += wk * smeared
        weight_sum += wk
    out /= np.maximum(weight_sum, 1e-6)
    lo, hi = np.percentile(out, [1.0, 99.0])  # smearing averages the contrast away: stretch it back
    return np.clip((out - lo) / max(hi - lo, 1e-3), 0.0, 1.0).astype(np.float32)


def voronoi_texture(rng: np.random.Generator, size: Size) -> np.ndarray:
    """Voronoi cells with jittered palette colours, sometimes with dark seams."""
    h, w = _check_size(size)
    n = int(rng.integers(6, 80))
    seeds = rng.random((n, 2)) * np.array([w, h])  # (n, 2) x, y
    y, x = np.mgrid[0:h, 0:w].astype(np.float32) + 0.5
    d2 = (x[..., None] - seeds[:, 0]) ** 2 + (y[..., None] - seeds[:, 1]) ** 2  # (h, w, n)
    two = np.argsort(d2, axis=2)[..., :2] if n > 1 else np.zeros((h, w, 2), np.int64)  # (h, w, 2)
    nearest = two[..., 0]  # (h, w)
    pal = random_palette(rng, int(rng.integers(2, 6)))
    colours = np.clip(pal[rng.integers(0, len(pal), n)] + rng.normal(0.0, 0.06, (n, 3)), 0.0, 1.0)
    out = colours[nearest].astype(np.float32)  # (h, w, 3)
    if n > 1 and rng.random() < 0.5:  # dark seams: distance to the bisector of the two nearest seeds
        d_a = np.take_along_axis(d2, two[..., :1], 2)[..., 0]
        d_b = np.take_along_axis(d2, two[..., 1:], 2)[..., 0]
        gap = (d_b - d_a) / (2.0 * np.linalg.norm(seeds[two[..., 0]] - seeds[two[..., 1]], axis=-1) + 1e-9)
        seam = np.clip(gap / rng.uniform(0.5, 1.5), 0.0, 1.0)[..., None]
        out = out * seam + (1.0 - seam) * rng.uniform(0.0, 0.25)
    return out.astype(np.float32)


def gradient_texture(rng: np.random.Generator, size: Size) -> np.ndarray:
    """A linear or radial colour gradient through 2-3 random colours."""
    h, w = _check_size(size)
    if rng.random() < 0.5:
        along, _ = _coords(h, w, rng.uniform(0.0, 2.0 * math.pi))
        t = _normalise(along)
    else:
        y, x = np.mgrid[0:h, 0:w].astype(np.float32) + 0.5
        cx, cy = rng.uniform(0, w), rng.uniform(0, h)
        t = _normalise(np.hypot(x - cx, y - cy))
    return colour_map(t, random_palette(rng, int(rng.integers(2, 4))))


def constant_texture(rng: np.random.Generator, size: Size) -> np.ndarray:
    """One random colour everywhere (zero variance)."""
    h, w = _check_size(size)
    return np.broadcast_to(random_palette(rng, 1)[0], (h, w, 3)).astype(np.float32)


_GENERATORS: Dict[str, Callable[[np.random.Generator, Size], np.ndarray]] = {
    "noise": noise_texture,
    "stripes": stripes_texture,
    "checker": checker_texture,
    "brush": brush_texture,
    "voronoi": voronoi_texture,
    "gradient": gradient_texture,
    "constant": constant_texture,
}


def make_texture(kind: str, rng: np.random.Generator, size: Size) -> np.ndarray:
    """A texture of ``kind`` (one of :data:`TEXTURE_KINDS`): (h, w, 3) float32 in [0, 1]."""
    if kind not in _GENERATORS:
        raise InputError("kind", f"must be one of {', '.join(map(repr, TEXTURE_KINDS))}; got {kind!r}")
    out = _GENERATORS[kind](rng, size)
    check_shape(out, kind, (size[0], size[1], 3))
    return np.ascontiguousarray(np.clip(out, 0.0, 1.0), dtype=np.float32)


def random_texture(
    rng: np.random.Generator, size: Size, kinds: Sequence[str] = SCENE_TEXTURE_KINDS
) -> Tuple[str, np.ndarray]:
    """A texture of a kind drawn uniformly from ``kinds``: (kind, (h, w, 3) image)."""
    if len(kinds) == 0:
        raise InputError("kinds", "needs at least one texture kind")
    kind = str(kinds[int(rng.integers(0, len(kinds)))])
    return kind, make_texture(kind, rng, size)
