"""A depth prior that needs no learned weights: the default depth source.

What it assumes -- cues that hold for ordinary photos, combined as *nearness*,
an inverse depth in [0, 1] where 1 is nearest:

1. **Ground plane.** Below a horizon row the scene is a floor or the ground
   seen from eye level, so its inverse depth grows linearly from the horizon
   to the bottom edge (exact for flat ground and a level camera). Surfaces
   above the horizon that are not sky stand at a constant "backdrop" distance.
2. **Sky / flat backdrop.** Low-texture regions touching the top edge (sky, a
   plain wall, a studio background) are the farthest thing in the photo. They
   also give the horizon (where the sky ends). A photo with (almost) no sky --
   an aerial or downward view, a close-up, a wall -- has no horizon to find:
   its layout is one smooth ramp from ``open_ramp`` at the top to 1 at the bottom.
3. **Haze** (outdoor scenes only, weighted by how much sky there is): the
   dark-channel prior (He et al. 2009) gives the transmission ``t``; ``-log t``
   grows with distance.
4. **Defocus.** Sharp regions are near the focal plane, which in most photos
   is on the subject; blurred ones are farther. Measured by the re-blur
   gradient ratio (contrast-independent), with a small weight.
5. **Salient foreground** (:mod:`.foreground`), only where the prior is sure.
   Saliency (OpenCV spectral residual + colour contrast against the photo's
   border + a centre prior) seeds GrabCut on a ~200 px copy; ground taken for
   foreground is removed, holes and narrow gaps are closed. Each blob gets a
   confidence (:func:`.foreground.object_confidence`: its area, the frame edges
   it touches, the colour step across its outline, its saliency against the
   rest; ground-shaped blobs -- a road or a deck narrowing into the distance --
   get 0). Blobs below ``min_confidence`` are not lifted: they keep the smooth
   background, so a slope, an aerial view or a blob GrabCut cut out of one
   surface stays smooth instead of becoming a flat card. A lifted object stands
   on the ground at its lowest pixel in each column (Hoiem's "pop-up" rule), a
   gap nearer than the background around it, and is rounded by the square root
   of the distance from its outline (outline below the ground contact, middle
   above), gap and rounding scaled by its confidence.
6. **Edges.** Object outlines are snapped to the photo's colour edges at full
   resolution by a joint-bilateral majority vote (the bilateral median of a
   binary mask) of the smoothed soft mask, so depth edges stay sharp steps
   on the photo's edges, not on the small copy's pixel staircase; the smooth background cues
   go through a guided filter (``cv2.ximgproc.guidedFilter``).

Nearness becomes depth with ``depth = 1 / (1/far_ratio + (1 - 1/far_ratio) n)``,
so depth lies in [1, far_ratio] (default 6), kind "relative": always finite and
positive, whatever the photo (constant, tiny, noisy, out-of-range values).

Where it fails: it never knows absolute scale; photos looking up (a ceiling
is not modelled); tilted horizons; several subjects at different depths;
GrabCut joining a subject with similar-coloured things behind it (the
motorcycle with the red crates on the shelf) or with the ground beside it (a
sign on a plain lifted with a slab of the plain); a dark low-texture region
reaching the top edge (a bridge's ceiling, a night sky over a dark city) taken
for sky, with a step at its edge; subjects the confidence refuses (a lighthouse
whose blob takes in the rocks across the frame, a ferris wheel spanning the
bottom): they stay in the smooth background, flat but not torn. The sheet
``docs/depth_prior_sheet.png`` shows it on real photos.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple, Optional

import cv2
import numpy as np

from ..checks import check_range
from ..threads import beside
from ._util import check_rgb, nearness_to_depth, normalise_percentiles, resize_long_side, resize_to
from .foreground import foreground_objects, grabcut_foreground, saliency_map, snap_mask_to_edges


@dataclass(frozen=True)
class PriorSettings:
    """Settings of the built-in depth prior (defaults tuned on the bundled samples)."""

    work_size: int = 384
    """Longer side (pixels) of the copy the cues are computed on."""
    grabcut_size: int = 200
    """Longer side of the copy GrabCut runs on (GrabCut is the slowest step)."""
    grabcut_iterations: int = 4
    """GrabCut iterations."""
    far_ratio: float = 6.0
    """Depth of the farthest point divided by that of the nearest (depth lies in [1, far_ratio])."""
    horizon: Optional[float] = None
    """Horizon row as a fraction of the height from the top; None = from the sky, else ``default_horizon``."""
    default_horizon: float = 0.45
    """Horizon used when there is no sky to find it from."""
    backdrop_nearness: float = 0.18
    """Nearness of non-sky surfaces above the horizon (sky is 0, the bottom edge 1)."""
    haze_weight: float = 0.25
    """Weight of the dark-channel haze cue (scaled by how much sky there is)."""
    defocus_weight: float = 0.15
    """Weight of the defocus cue."""
    foreground: bool = True
    """Find a salient foreground object with GrabCut and pop it out."""
    foreground_pop: float = 0.1
    """Least nearness gap between a foreground object and the background around it."""
    bulge: float = 0.12
    """Rounding of a foreground object: its outline sits this much below its ground contact, its
    middle this much above (by the square root of the distance from the outline)."""
    min_confidence: float = 0.35
    """Objects the prior is less sure of than this (see :func:`.foreground.object_confidence`) are
    not lifted: they keep the smooth background depth."""
    open_ramp: float = 0.1
    """Nearness at the top edge of a photo with no sky (an aerial or downward view, a close-up, a
    wall): its layout is one smooth ramp from this at the top to 1 at the bottom."""
    min_object_area: float = 0.01
    """Foreground objects smaller than this fraction of the photo are dropped."""
    min_edge_contrast: float = 8.0
    """Objects whose outline shows a median colour step (CIELAB Delta E) below this are dropped."""
    max_foreground_area: float = 0.8
    """A foreground covering more than this fraction of the photo is rejected (GrabCut failed)."""
    edge_radius: float = 0.008
    """Guided-filter radius for the background cues, as a fraction of the photo's longer side."""
    edge_eps: float = 1e-3
    """Guided-filter regularisation (smaller = follows image edges more closely)."""
    edge_sigma_color: float = 0.08
    """Colour scale (photo in [0, 1]) of the joint bilateral filter that snaps object outlines to edges."""

    def __post_init__(self) -> None:
        check_range(self.work_size, "work_size", 32, 4096)
        check_range(self.grabcut_size, "grabcut_size", 32, 4096)
        check_range(self.grabcut_iterations, "grabcut_iterations", 1, 50)
        check_range(self.far_ratio, "far_ratio", 1.0, 1e4, inclusive=False)
        if self.horizon is not None:
            check_range(self.horizon, "horizon", 0.0, 0.95)
        check_range(self.default_horizon, "default_horizon", 0.0, 0.95)
        check_range(self.backdrop_nearness, "backdrop_nearness", 0.0, 1.0)
        check_range(self.haze_weight, "haze_weight", 0.0, 1.0)
        check_range(self.defocus_weight, "defocus_weight", 0.0, 1.0)
        check_range(self.foreground_pop, "foreground_pop", 0.0, 1.0)
        check_range(self.bulge, "bulge", 0.0, 1.0)
        check_range(self.min_confidence, "min_confidence", 0.0, 1.0)
        check_range(self.open_ramp, "open_ramp", 0.0, 1.0)
        check_range(self.min_object_area, "min_object_area", 0.0, 1.0)
        check_range(self.min_edge_contrast, "min_edge_contrast", 0.0, 200.0)
        check_range(self.max_foreground_area, "max_foreground_area", 0.0, 1.0)
        check_range(self.edge_radius, "edge_radius", 0.0, 0.2)
        check_range(self.edge_eps, "edge_eps", 1e-8, 1.0)
        check_range(self.edge_sigma_color, "edge_sigma_color", 1e-3, 10.0)


class PriorResult(NamedTuple):
    """Depth from the prior and the cues behind it (all at the photo's size)."""

    depth: np.ndarray
    """(H, W) float32 relative depth in [1, far_ratio]."""
    nearness: np.ndarray
    """(H, W) float32 inverse depth in [0, 1], 1 = nearest."""
    foreground: np.ndarray
    """(H, W) bool foreground objects (popped out in front of the background)."""
    sky: np.ndarray
    """(H, W) bool sky / flat backdrop mask."""
    horizon: float
    """Horizon row as a fraction of the height from the top."""


# --------------------------------------------------------------------------- cues


def _texture(grey: np.ndarray) -> np.ndarray:
    """Local gradient magnitude (h, w), smoothed."""
    g = cv2.GaussianBlur(grey, (0, 0), 1.0)
    gx = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3)
    return cv2.GaussianBlur(np.sqrt(gx * gx + gy * gy), (0, 0), 2.0)


def sky_mask(rgb: np.ndarray, texture: np.ndarray) -> np.ndarray:
    """Low-texture regions (h, w) bool connected to the top edge, covering >= 2 % of the image."""
    h, w = texture.shape
    low = (texture < 0.03).astype(np.uint8)
    low = cv2.morphologyEx(low, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
    n, labels, stats, _ = cv2.connectedComponentsWithStats(low, connectivity=4)
    keep = np.zeros(n, bool)
    top_labels = np.unique(labels[0])
    for lab in top_labels:
        if lab != 0 and stats[lab, cv2.CC_STAT_AREA] >= 0.02 * h * w:
            keep[lab] = True
    return keep[labels]


def estimate_horizon(sky: np.ndarray, default: float) -> float:
    """Horizon (fraction of height) where the sky ends; ``default`` when there is little sky."""
    h, w = sky.shape
    if sky.mean() < 0.05:
        return default
    # Length of the sky run from the top of each column.
    run = np.where(sky.all(axis=0), h, np.argmin(sky, axis=0))  # (w,)
    run = run[run > 0]
    if run.size < 0.2 * w:
        return default
    return float(np.clip(np.percentile(run, 75) / h, 0.2, 0.9))


def haze_nearness(rgb: np.ndarray, patch: int) -> np.ndarray:
    """Nearness (h, w) in [0, 1] from the dark-channel prior (1 = least haze = nearest)."""
    kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (patch, patch))
    dark = cv2.erode(rgb.min(axis=2), kernel)
    flat = dark.ravel()
    top = np.argsort(flat)[-max(1, flat.size // 1000):]
    airlight = np.maximum(rgb.reshape(-1, 3)[top].mean(axis=0), 0.05)  # (3,)
    t = 1.0 - 0.95 * cv2.erode((rgb / airlight).min(axis=2).astype(np.float32), kernel)
    haze_depth = -np.log(np.clip(t, 0.05, 1.0))
    haze_depth = cv2.GaussianBlur(haze_depth.astype(np.float32), (0, 0), patch / 2.0)
    return 1.0 - normalise_percentiles(haze_depth)


def _grad(grey: np.ndarray) -> np.ndarray:
    gx = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3)
    return np.sqrt(gx * gx + gy * gy)


def focus_measure(grey: np.ndarray, sigma: float) -> np.ndarray:
    """Sharpness (h, w) in [0, 1] (1 = in focus) by the re-blur gradient ratio.

    At an edge blurred by a Gaussian of width s, re-blurring by s0 divides the
    gradient by about sqrt(1 + s0^2/s^2): the ratio is large at sharp edges and
    near 1 at blurred ones, whatever the contrast. The ratio is averaged with the
    gradient as confidence weight (normalised convolution) over ``sigma``.
    """
    g1 = _grad(grey)
    g2 = _grad(cv2.GaussianBlur(grey, (0, 0), 1.0))
    ratio = g1 / (g2 + 1e-3)
    num = cv2.GaussianBlur(ratio * g1, (0, 0), sigma)
    den = cv2.GaussianBlur(g1, (0, 0), sigma)
    return normalise_percentiles(num / (den + 1e-3))


# --------------------------------------------------------------------------- composition


def _layout_nearness(h: int, w: int, horizon: float, backdrop: float) -> np.ndarray:
    """Ground plane below the horizon, constant backdrop above: (h, w) in [backdrop, 1]."""
    y = (np.arange(h, dtype=np.float32) + 0.5) / h
    ground = np.clip((y - horizon) / max(1.0 - horizon, 1e-3), 0.0, 1.0)
    col = backdrop + (1.0 - backdrop) * ground  # (h,)
    return np.repeat(col[:, None], w, axis=1)


def _ramp_nearness(h: int, w: int, top: float) -> np.ndarray:
    """Nearness (h, w) growing linearly from ``top`` at the top edge to 1 at the bottom."""
    y = (np.arange(h, dtype=np.float32) + 0.5) / h
    return np.repeat((top + (1.0 - top) * y)[:, None], w, axis=1)


def _guided(guide: np.ndarray, src: np.ndarray, radius: int, eps: float) -> np.ndarray:
    if radius < 1:
        return src
    return cv2.ximgproc.guidedFilter(guide, src.astype(np.float32), radius, eps)


def estimate_prior(rgb: np.ndarray, settings: PriorSettings = PriorSettings()) -> PriorResult:
    """Estimate relative depth for a photo with the built-in prior.

    Args:
        rgb: (H, W, 3) float photo in [0, 1] (not modified).
        settings: see :class:`PriorSettings`.
    Returns:
        :class:`PriorResult` with depth (H, W) in [1, far_ratio], finite and positive.
    """
    s = settings
    photo = check_rgb(rgb)
    H, W = photo.shape[:2]
    small = resize_long_side(photo, s.work_size)  # (h, w, 3)
    h, w = small.shape[:2]
    grey = cv2.cvtColor(small, cv2.COLOR_RGB2GRAY)

    texture = _texture(grey)
    sky = sky_mask(small, texture)
    horizon = s.horizon if s.horizon is not None else estimate_horizon(sky, s.default_horizon)
    open_view = s.horizon is None and sky.mean() < 0.05
    if open_view:  # no sky, no horizon: one smooth ramp, no kink at an assumed horizon
        layout = _ramp_nearness(h, w, s.open_ramp)
    else:
        layout = _layout_nearness(h, w, horizon, s.backdrop_nearness)  # (h, w)
    focus = focus_measure(grey, max(h, w) / 50)

    outdoor = float(np.clip(sky.mean() / 0.15, 0.0, 1.0))
    background = layout.copy()
    if outdoor > 0 and s.haze_weight > 0:
        patch = max(3, round(max(h, w) / 40) | 1)
        background += s.haze_weight * outdoor * (haze_nearness(small, patch) - 0.5)
    background += s.defocus_weight * (focus - 0.5)
    background = np.clip(background, 0.02, 1.0)
    background[sky] = 0.0
    background = cv2.GaussianBlur(background, (0, 0), max(h, w) / 100)
    # the full-resolution guided upsampling of the background runs in a thread of its own beside the
    # foreground's GrabCut and outline snapping (OpenCV frees the GIL)
    guided = beside(_guided, photo, resize_to(background, (H, W)), round(s.edge_radius * max(H, W)), s.edge_eps)

    fg_small = np.zeros((h, w), np.float32)
    obj_values = np.zeros((h, w), np.float32)
    gh, gw = h, w
    if s.foreground:
        sal = saliency_map(small, focus)
        gsmall = resize_long_side(small, s.grabcut_size)
        gh, gw = gsmall.shape[:2]
        fg_gc = grabcut_foreground(
            gsmall, resize_to(sal, (gh, gw)), resize_to(sky.astype(np.uint8), (gh, gw), nearest=True) > 0,
            s.grabcut_iterations,
        )
        fg = resize_to(fg_gc.astype(np.uint8), (h, w), nearest=True) > 0
        if fg.mean() <= s.max_foreground_area:
            lab = cv2.cvtColor(cv2.GaussianBlur(small, (0, 0), 1.5), cv2.COLOR_RGB2Lab)  # (h, w, 3)
            obj_values, kept = foreground_objects(
                fg, background, layout, lab, min_area=s.min_object_area, min_edge_contrast=s.min_edge_contrast,
                pop=s.foreground_pop, bulge=s.bulge, saliency=sal, min_confidence=s.min_confidence,
            )
            fg_small = kept.astype(np.float32)
    # Full resolution: upsample, snap the object outlines to the photo's edges.
    near_full = guided.result()
    matte = np.zeros((H, W), bool)
    if fg_small.any():
        snap = max(2, round(1.5 * max(H, W) / max(gh, gw)))
        # a smooth soft mask (no staircase from the small copies) for the snap to move onto the edges
        soft = cv2.GaussianBlur(fg_small, (0, 0), 1.0)
        matte = snap_mask_to_edges(resize_to(soft, (H, W)), photo, snap, s.edge_sigma_color)
        near_full = np.where(matte, resize_to(obj_values, (H, W)), near_full)
    peak = float(near_full.max())
    near_full = np.clip(near_full / max(peak, 1.0), 0.0, 1.0).astype(np.float32)
    sky_full = resize_to(sky.astype(np.uint8), (H, W), nearest=True) > 0
    return PriorResult(nearness_to_depth(near_full, s.far_ratio), near_full, matte, sky_full, float(horizon))
