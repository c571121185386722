"""Depth from a rectified stereo pair or a side-by-side stereo card (OpenCV SGBM).

The **left** image is the photo; the right one was taken from a camera shifted
to the right along the x axis (see ``geometry/camera.py``), so a left pixel at
column x appears in the right image at column ``x - d`` with disparity d >= 0.

Steps: semi-global block matching (``cv2.StereoSGBM``) on the colour pair; the
same matcher on the mirrored pair gives the right view's disparity, and a
left-right consistency check invalidates pixels whose two disparities disagree
by more than ``lr_max_diff`` (occlusions, mismatches); holes are filled along
each row with the smaller (farther) of the nearest valid disparities on either
side, as occluded pixels belong to the background; then
``depth = focal_px * baseline / disparity`` (kind "metric") when both are
known, else ``depth = d_ref / disparity`` with d_ref the 99th percentile of the
valid disparities (kind "relative", nearest surfaces at about 1). Disparities
are floored at ``d_ref / max_depth_ratio`` so that points at infinity (d = 0)
get a large but finite depth.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, NamedTuple, Optional, Tuple

import cv2
import numpy as np

from ..checks import check_choice, check_range
from ..errors import InputError
from ..io.images import to_uint8
from ._util import check_rgb, resize_long_side
from .fill import fill_nearest

_MODES = {"sgbm": cv2.STEREO_SGBM_MODE_SGBM, "3way": cv2.STEREO_SGBM_MODE_SGBM_3WAY, "hh": cv2.STEREO_SGBM_MODE_HH}


@dataclass(frozen=True)
class StereoSettings:
    """Settings of the stereo matcher and of the disparity -> depth conversion."""

    num_disparities: int = 0
    """Disparity search range in pixels (a multiple of 16); 0 = an eighth of the width, rounded up to 16."""
    min_disparity: int = 0
    """Smallest disparity searched (negative for pairs converging in front of infinity)."""
    block_size: int = 5
    """SGBM matching block size (odd, 3..11 for SGBM)."""
    uniqueness: int = 10
    """SGBM uniqueness ratio in percent (higher rejects more ambiguous matches)."""
    speckle_window: int = 100
    """Largest speckle (pixels) removed as noise; 0 turns speckle filtering off."""
    speckle_range: int = 2
    """Largest disparity variation within one speckle component."""
    mode: Literal["sgbm", "3way", "hh"] = "sgbm"
    """OpenCV SGBM mode: 5-direction "sgbm", faster "3way", 8-direction full-memory "hh"."""
    lr_max_diff: float = 1.0
    """Left-right consistency tolerance in pixels."""
    focal_px: Optional[float] = None
    """Focal length in pixels of the (left) photo at the size it is matched; with ``baseline``, depth is metric."""
    baseline: Optional[float] = None
    """Distance between the two cameras in metres."""
    max_depth_ratio: float = 100.0
    """Farthest depth / nearest (relative kind): floor on small disparities."""
    cross_eyed: bool = False
    """Side-by-side cards only: the right-eye view is on the left (cross-eyed viewing)."""
    min_card_correlation: float = 0.35
    """Side-by-side cards only: least band-pass correlation of the two halves to accept the image as a card
    (measured: 0.66 for the motorcycle pair, with or without noise; <= 0.16 for halves of ordinary photos)."""

    def __post_init__(self) -> None:
        check_range(self.num_disparities, "num_disparities", 0, 4096)
        if self.num_disparities % 16:
            raise InputError("num_disparities", f"must be a multiple of 16, got {self.num_disparities}")
        check_range(self.min_disparity, "min_disparity", -4096, 4096)
        check_range(self.block_size, "block_size", 1, 31)
        if self.block_size % 2 == 0:
            raise InputError("block_size", f"must be odd, got {self.block_size}")
        check_range(self.uniqueness, "uniqueness", 0, 100)
        check_range(self.speckle_window, "speckle_window", 0, 10_000)
        check_range(self.speckle_range, "speckle_range", 0, 1000)
        check_choice(self.mode, "mode", tuple(_MODES))
        check_range(self.lr_max_diff, "lr_max_diff", 0.0, 1000.0)
        if (self.focal_px is None) != (self.baseline is None):
            raise InputError("stereo", "give both focal_px and baseline for metric depth, or neither")
        if self.focal_px is not None:
            check_range(self.focal_px, "focal_px", 0.0, 1e6, inclusive=False)
            check_range(self.baseline, "baseline", 0.0, 1e6, inclusive=False)
        check_range(self.max_depth_ratio, "max_depth_ratio", 1.0, 1e6, inclusive=False)
        check_range(self.min_card_correlation, "min_card_correlation", -1.0, 1.0)


class StereoResult(NamedTuple):
    """Disparity of the left image."""

    disparity: np.ndarray
    """(H, W) float32 disparity in pixels, holes filled (>= min_disparity everywhere)."""
    valid: np.ndarray
    """(H, W) bool: matched and consistent left-to-right (before filling)."""


def _matcher(s: StereoSettings, num_disp: int) -> "cv2.StereoSGBM":
    cn = 3
    return cv2.StereoSGBM_create(
        minDisparity=s.min_disparity,
        numDisparities=num_disp,
        blockSize=s.block_size,
        P1=8 * cn * s.block_size**2,
        P2=32 * cn * s.block_size**2,
        disp12MaxDiff=-1,  # our own left-right check below
        uniquenessRatio=s.uniqueness,
        speckleWindowSize=s.speckle_window,
        speckleRange=s.speckle_range,
        mode=_MODES[s.mode],
    )


def fill_disparity_holes(disparity: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Fill invalid pixels (H, W) along rows with the smaller of the nearest valid values left and right.

    Rows with no valid pixel take their nearest valid pixel in 2-D; a 5x5 median
    then smooths the filled pixels only (valid pixels are kept as they are).
    """
    h, w = disparity.shape
    cols = np.arange(w)[None, :].repeat(h, axis=0)
    idx_left = np.maximum.accumulate(np.where(valid, cols, -1), axis=1)  # nearest valid at or left of x
    idx_right = np.minimum.accumulate(np.where(valid, cols, w)[:, ::-1], axis=1)[:, ::-1]
    rows = np.arange(h)[:, None]
    big = np.float32(np.inf)
    left_val = np.where(idx_left >= 0, disparity[rows, np.clip(idx_left, 0, w - 1)], big)
    right_val = np.where(idx_right < w, disparity[rows, np.clip(idx_right, 0, w - 1)], big)
    filled = np.minimum(left_val, right_val)
    filled = np.where(valid, disparity, filled)
    have = np.isfinite(filled)
    if not have.all():
        filled = fill_nearest(np.where(have, filled, 0).astype(np.float32), have)
    smooth = cv2.medianBlur(filled.astype(np.float32), 5)
    return np.where(valid, disparity, smooth).astype(np.float32)


def compute_disparity(left: np.ndarray, right: np.ndarray, settings: StereoSettings = StereoSettings()) -> StereoResult:
    """Disparity of ``left`` (H, W, 3) against ``right`` (H, W, 3), both float in [0, 1] and rectified."""
    s = settings
    lft, rgt = check_rgb(left, "left image"), check_rgb(right, "right image")
    if lft.shape != rgt.shape:
        raise InputError("stereo pair", f"left {lft.shape[:2]} and right {rgt.shape[:2]} images differ in size")
    h, w = lft.shape[:2]
    num_disp = s.num_disparities or max(16, int(np.ceil(w / 8 / 16)) * 16)
    if w - (s.min_disparity + num_disp) <= s.block_size // 2 + 1:
        raise InputError(
            "stereo pair",
            f"images {w} px wide are too narrow for disparities up to {s.min_disparity + num_disp} px "
            "(lower num_disparities)",
        )
    lu, ru = to_uint8(lft), to_uint8(rgt)
    matcher = _matcher(s, num_disp)
    disp_l = matcher.compute(lu, ru).astype(np.float32) / 16.0  # (H, W)
    # The right view's disparity: match the mirrored pair (mirrored right as the left image).
    disp_r = matcher.compute(np.ascontiguousarray(ru[:, ::-1]), np.ascontiguousarray(lu[:, ::-1]))
    disp_r = disp_r[:, ::-1].astype(np.float32) / 16.0
    matched_l = disp_l >= s.min_disparity
    xs = np.arange(w)[None, :] - np.round(disp_l).astype(np.int64)  # column in the right image
    inside = (xs >= 0) & (xs < w)
    dr = disp_r[np.arange(h)[:, None], np.clip(xs, 0, w - 1)]
    valid = matched_l & inside & (dr >= s.min_disparity) & (np.abs(dr - disp_l) <= s.lr_max_diff)
    if not valid.any():
        raise InputError("stereo pair", "no pixel could be matched between the two images (are they a rectified pair?)")
    filled = fill_disparity_holes(np.where(valid, disp_l, 0.0).astype(np.float32), valid)
    return StereoResult(np.maximum(filled, float(s.min_disparity)).astype(np.float32), valid)


def disparity_to_depth(disparity: np.ndarray, valid: np.ndarray, settings: StereoSettings) -> Tuple[np.ndarray, str]:
    """Disparity (H, W) in pixels -> (depth (H, W) float32 > 0, kind) (see the module docstring)."""
    s = settings
    ref = float(np.percentile(disparity[valid], 99)) if valid.any() else float(disparity.max())
    ref = max(ref, 1e-3)
    d = np.maximum(disparity.astype(np.float64), ref / s.max_depth_ratio)
    if s.focal_px is not None and s.baseline is not None:
        return (s.focal_px * s.baseline / d).astype(np.float32), "metric"
    return (ref / d).astype(np.float32), "relative"


def split_side_by_side(
    card: np.ndarray, settings: StereoSettings = StereoSettings(), name: str = "stereo card"
) -> Tuple[np.ndarray, np.ndarray]:
    """Split a side-by-side stereo card (H, W, 3) into its (left, right) views, each (H, W // 2, 3).

    The halves must look alike: the best normalised correlation of the two
    halves' details (band-passed) over horizontal shifts up to 15 % and vertical
    shifts up to 4 % of their size (on a small grey copy) must reach
    ``min_card_correlation``, or an
    :class:`InputError` naming ``name`` says that the image is not a card. The
    right view is shifted vertically by the offset found (cards are often
    mounted slightly out of line); the left view, the photo, is left as is.
    """
    img = check_rgb(card, name)
    h, w = img.shape[:2]
    if w < 1.2 * h:
        raise InputError(name, f"is {w}x{h} pixels; a side-by-side stereo card is much wider than tall")
    half = w // 2
    a, b = img[:, :half], img[:, w - half :]
    if settings.cross_eyed:
        a, b = b, a
    corr, dy = _halves_match(a, b)
    if corr < settings.min_card_correlation:
        raise InputError(
            name,
            f"does not look like a side-by-side stereo card: its two halves do not match "
            f"(best correlation {corr:.2f} < {settings.min_card_correlation:.2f})",
        )
    if dy:
        b = np.roll(b, -dy, axis=0)
        if dy > 0:
            b[-dy:] = b[-dy - 1 : -dy]
        else:
            b[:-dy] = b[-dy : -dy + 1]
    return np.ascontiguousarray(a), np.ascontiguousarray(b)


def _band_pass(grey: np.ndarray) -> np.ndarray:
    """Details between film grain and shading (difference of Gaussians, sigma 1 and 4 px).

    Smooth shading (a sky gradient) makes any two halves of a photo correlate;
    details only match when both halves show the same scene.
    """
    return cv2.GaussianBlur(grey, (0, 0), 1.0) - cv2.GaussianBlur(grey, (0, 0), 4.0)


def _halves_match(a: np.ndarray, b: np.ndarray) -> Tuple[float, int]:
    """Best normalised correlation of two views over small shifts, and the vertical shift (full-size pixels)."""
    sa, sb = (_band_pass(cv2.cvtColor(resize_long_side(v, 160), cv2.COLOR_RGB2GRAY)) for v in (a, b))
    h, w = sa.shape
    mx, my = max(1, int(0.15 * w)), max(1, int(0.04 * h))
    # Template: the centre of the left view; search it in the right view.
    tpl = sa[my : h - my, mx : w - mx]
    if tpl.std() < 1e-4 or sb.std() < 1e-4:
        return 0.0, 0
    scores = cv2.matchTemplate(sb, tpl, cv2.TM_CCOEFF_NORMED)  # (2my+1, 2mx+1)
    _, best, _, loc = cv2.minMaxLoc(scores)
    dy_small = loc[1] - my
    return float(best), int(round(dy_small * a.shape[0] / h))
