"""Depth from a scanned historical stereo card: two photos side by side on a mount.

A scanned card is not a rectified pair: the two prints sit in borders of the
mount (and a gap between them), were exposed and aged differently, and are
mounted slightly rotated and out of line. :func:`card_views` turns it into a
rectified pair in five steps:

1. **split**: the card's border colour is the median of its outer frame; the
   content of each half is the bounding box of the rows and columns where most
   pixels differ from it (``CardSettings.border_tolerance``), so mount borders
   and the central gap are cut away;
2. **exposure**: the right print's channels are given the mean and standard
   deviation of the left print's (a gain and an offset per channel);
3. **features**: SIFT keypoints matched with Lowe's ratio test, outliers
   removed by a RANSAC fundamental matrix; fewer than ``min_matches`` left is an
   :class:`InputError` saying the image is not a side-by-side card;
4. **rectification**: the similarity (rotation, scale, shift) that puts every
   match of the right print on the same row as in the left print is fitted by
   RANSAC on the rows alone (``y_left = a x_right + b y_right + t``: in a
   rectified pair only the columns differ, by the disparity); the right print
   is warped by it into the left print's frame, and shifted along the rows so
   that the farthest matches have a disparity of about ``margin_px`` (cards
   have no common "infinity": only relative depth is known). The left print,
   the photo that is browsed, is not warped: its pixels stay as scanned;
5. **depth**: the stereo matcher of :mod:`.stereo` (SGBM with a left-right
   check) over the disparity range of the matches, then relative depth.

The photo the depth belongs to is the cropped left print (``PhotoDepth.rgb``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import NamedTuple, Tuple

import cv2
import numpy as np

from ..checks import check_range
from ..errors import InputError, PathLike
from ..io.images import to_uint8
from ._util import check_rgb
from .stereo import StereoSettings, compute_disparity, disparity_to_depth
from .types import DepthMap, PhotoDepth


@dataclass(frozen=True)
class CardSettings:
    """Settings of :func:`card_views` and :func:`card_depth`."""

    border_tolerance: float = 0.08
    """A pixel is print, not mount, when a channel differs from the border colour by more than this."""
    min_content: float = 0.5
    """Least fraction of print pixels that makes a row or column part of the print."""
    min_matches: int = 25
    """Fewest consistent feature matches between the prints of a stereo card."""
    ratio: float = 0.75
    """Lowe's ratio test of the SIFT matches."""
    max_rotation_deg: float = 10.0
    """Largest rotation between the prints accepted."""
    margin_px: float = 2.0
    """Disparity given to the farthest matches (1st percentile) after rectification."""
    stereo: StereoSettings = StereoSettings()
    """The matcher's settings; its disparity range is set from the matches. With ``stereo.cross_eyed``
    the card's right print is the left eye's (the prints are swapped after splitting)."""

    def __post_init__(self) -> None:
        check_range(self.border_tolerance, "border_tolerance", 0.0, 1.0)
        check_range(self.min_content, "min_content", 0.0, 1.0)
        check_range(self.min_matches, "min_matches", 8, 100_000)
        check_range(self.ratio, "ratio", 0.1, 1.0)
        check_range(self.max_rotation_deg, "max_rotation_deg", 0.0, 45.0)
        check_range(self.margin_px, "margin_px", 0.0, 100.0)


class CardViews(NamedTuple):
    """A stereo card as a rectified pair (:func:`card_views`).

    Attributes:
        left: (H, W, 3) float32 the left print, cropped (the photo).
        right: (H, W, 3) float32 the right print, exposure-matched and warped onto the left one's rows.
        rotation_deg: rotation of the right print relative to the left one, in degrees.
        scale: its scale relative to the left one.
        matches: feature matches consistent with the rectification.
        disparity_range: (low, high) disparities of the matches after rectification, in pixels.
        boxes: the (top, bottom, left, right) crop of each print on the card, left eye first.
    """

    left: np.ndarray
    right: np.ndarray
    rotation_deg: float
    scale: float
    matches: int
    disparity_range: Tuple[float, float]
    boxes: Tuple[Tuple[int, int, int, int], Tuple[int, int, int, int]]


def _longest_run(flags: np.ndarray) -> Tuple[int, int]:
    """(start, end) of the longest run of True in a 1-D array ((0, 0) if none)."""
    best, start = (0, 0), None
    for i, f in enumerate(np.append(flags, False)):
        if f and start is None:
            start = i
        elif not f and start is not None:
            if i - start > best[1] - best[0]:
                best = (start, i)
            start = None
    return best


def print_box(half: np.ndarray, border: np.ndarray, s: CardSettings) -> Tuple[int, int, int, int]:
    """(top, bottom, left, right) of the print in one half of a card, given the mount's colour ``border``."""
    content = (np.abs(half - border[None, None, :]) > s.border_tolerance).any(axis=2)  # (H, W)
    content = cv2.morphologyEx(content.astype(np.uint8), cv2.MORPH_OPEN, np.ones((3, 3), np.uint8)).astype(bool)
    rows = _longest_run(content.mean(axis=1) >= s.min_content)
    cols = _longest_run(content.mean(axis=0) >= s.min_content)
    return rows[0], rows[1], cols[0], cols[1]


def split_card(card: np.ndarray, settings: CardSettings = CardSettings(), name: PathLike = "stereo card"):
    """The two prints of a card (left, right), their mount cut away, and their boxes on the card."""
    img = check_rgb(card, str(name))
    h, w = img.shape[:2]
    if w < 1.2 * h:
        raise InputError(name, f"is {w}x{h} pixels; a side-by-side stereo card is much wider than tall")
    frame = np.concatenate([img[:2].reshape(-1, 3), img[-2:].reshape(-1, 3), img[:, :2].reshape(-1, 3),
                            img[:, -2:].reshape(-1, 3)])
    border = np.median(frame, axis=0)
    half = w // 2
    prints, boxes = [], []
    for x0, part in ((0, img[:, :half]), (half, img[:, half:])):
        t, b, l, r = print_box(part, border, settings)
        if b - t < 16 or r - l < 16:
            raise InputError(name, "does not look like a side-by-side stereo card: a half holds no print "
                                   "(only the mount's colour)")
        prints.append(part[t:b, l:r])
        boxes.append((t, b, x0 + l, x0 + r))
    return prints[0], prints[1], (boxes[0], boxes[1])


def match_exposure(image: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """``image`` with each channel's mean and standard deviation set to ``reference``'s (clipped to [0, 1])."""
    m_i, s_i = image.reshape(-1, 3).mean(0), image.reshape(-1, 3).std(0)
    m_r, s_r = reference.reshape(-1, 3).mean(0), reference.reshape(-1, 3).std(0)
    gain = s_r / np.maximum(s_i, 1e-4)
    return np.clip((image - m_i) * gain + m_r, 0.0, 1.0).astype(np.float32)


def _matches(left: np.ndarray, right: np.ndarray, s: CardSettings) -> Tuple[np.ndarray, np.ndarray]:
    sift = cv2.SIFT_create(nfeatures=4000)
    gl, gr = (cv2.cvtColor(to_uint8(v), cv2.COLOR_RGB2GRAY) for v in (left, right))
    kl, dl = sift.detectAndCompute(gl, None)
    kr, dr = sift.detectAndCompute(gr, None)
    if dl is None or dr is None or len(kl) < 2 or len(kr) < 2:
        return np.zeros((0, 2)), np.zeros((0, 2))
    pairs = cv2.BFMatcher(cv2.NORM_L2).knnMatch(dl, dr, k=2)
    good = [p[0] for p in pairs if len(p) == 2 and p[0].distance < s.ratio * p[1].distance]
    pl = np.float64([kl[m.queryIdx].pt for m in good]).reshape(-1, 2)
    pr = np.float64([kr[m.trainIdx].pt for m in good]).reshape(-1, 2)
    if len(pl) >= 8:
        _, inl = cv2.findFundamentalMat(pl, pr, cv2.FM_RANSAC, 1.5, 0.999)
        if inl is not None:
            keep = inl.ravel().astype(bool)
            pl, pr = pl[keep], pr[keep]
    return pl, pr


def _fit_rows(pl: np.ndarray, pr: np.ndarray, threshold: float = 1.0, iterations: int = 500):
    """RANSAC fit of ``y_left = a x_right + b y_right + t``; (a, b, t) refined on the inliers, and the inliers."""
    g = np.random.default_rng(0)
    A = np.column_stack([pr[:, 0], pr[:, 1], np.ones(len(pr))])
    y = pl[:, 1]
    best = np.zeros(len(pr), bool)
    for _ in range(iterations):
        idx = g.choice(len(pr), 3, replace=False)
        try:
            p = np.linalg.solve(A[idx], y[idx])
        except np.linalg.LinAlgError:
            continue
        inl = np.abs(A @ p - y) < threshold
        if inl.sum() > best.sum():
            best = inl
    p, *_ = np.linalg.lstsq(A[best], y[best], rcond=None)
    return p, best


def card_views(card: np.ndarray, settings: CardSettings = CardSettings(), name: PathLike = "stereo card") -> CardViews:
    """Split, match and rectify a scanned stereo card (steps 1-4 of the module docstring)."""
    s = settings
    left, right, boxes = split_card(card, s, name)
    if s.stereo.cross_eyed:  # a cross-eyed card shows the left eye's print on the right
        left, right, boxes = right, left, (boxes[1], boxes[0])
    right = match_exposure(right, left)
    pl, pr = _matches(left, right, s)
    not_card = f"does not look like a side-by-side stereo card: its halves share only {{}} consistent features " \
               f"(at least {s.min_matches} needed)"
    if len(pl) < s.min_matches:
        raise InputError(name, not_card.format(len(pl)))
    (a, b, t), inl = _fit_rows(pl, pr)
    if inl.sum() < s.min_matches:
        raise InputError(name, not_card.format(int(inl.sum())))
    rotation = math.degrees(math.atan2(a, b))
    scale = math.hypot(a, b)
    if abs(rotation) > s.max_rotation_deg or not 0.5 < scale < 2.0:
        raise InputError(name, f"the prints differ by a rotation of {rotation:.1f} degrees and a scale of "
                               f"{scale:.2f}; at most {s.max_rotation_deg:g} degrees are accepted")
    x_base = pl[inl, 0] - (b * pr[inl, 0] - a * pr[inl, 1])  # x_left - rotated x_right, before the shift
    tx = float(np.percentile(x_base, 1)) - s.margin_px
    d = x_base - tx  # disparities of the matches after rectification
    M = np.array([[b, -a, tx], [a, b, t]], np.float64)  # right print -> left print's frame
    h, w = left.shape[:2]
    warped = cv2.warpAffine(right, M, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return CardViews(left, np.clip(warped, 0, 1).astype(np.float32), rotation, scale, int(inl.sum()),
                     (float(np.percentile(d, 1)), float(np.percentile(d, 99))), boxes)


def card_depth(card: np.ndarray, settings: CardSettings = CardSettings(), name: PathLike = "stereo card") -> PhotoDepth:
    """The left print of a stereo card and its relative depth (the five steps of the module docstring)."""
    views = card_views(card, settings, name)
    high = views.disparity_range[1]
    w = views.left.shape[1]
    num = int(math.ceil((1.25 * high + 8) / 16.0)) * 16
    num = max(16, min(num, (w // 2) // 16 * 16 or 16))
    stereo = replace(settings.stereo, num_disparities=num, min_disparity=0, focal_px=None, baseline=None)
    result = compute_disparity(views.left, views.right, stereo)
    depth, _ = disparity_to_depth(result.disparity, result.valid, stereo)
    source = (f"stereo card ({views.matches} matches, rotation {views.rotation_deg:+.2f} deg, "
              f"disparities {views.disparity_range[0]:.0f}-{views.disparity_range[1]:.0f} px)")
    return PhotoDepth(views.left, DepthMap(depth, result.valid, "relative", source))
