"""Colour and sharpness statistics of images: the quality suite's diagnostics (Lab statistics against a
style, a sharpness ratio), which the suite reports beside its measures but no longer steers by."""

from __future__ import annotations

import math

import cv2
import numpy as np

from ..checks import check_shape
from ..errors import InputError

_SRGB_TO_XYZ = np.array([[0.412453, 0.357580, 0.180423],
                         [0.212671, 0.715160, 0.072169],
                         [0.019334, 0.119193, 0.950227]])
"""Linear sRGB to CIE XYZ (D65), OpenCV's matrix."""

_WHITE = np.array([0.950456, 1.0, 1.088754])
"""D65 white point (Xn, Yn, Zn), OpenCV's."""


def _check_rgb(image: np.ndarray, name: str) -> np.ndarray:
    a = np.asarray(image)
    check_shape(a, name, (None, None, 3))
    if not np.issubdtype(a.dtype, np.floating):
        raise InputError(name, f"expected a float image in [0, 1], got {a.dtype}")
    if a.shape[0] < 1 or a.shape[1] < 1:
        raise InputError(name, f"is empty: {a.shape}")
    if not np.isfinite(a).all():
        raise InputError(name, "contains NaN or infinite values")
    return a


def srgb_to_lab(rgb: np.ndarray) -> np.ndarray:
    """sRGB (H, W, 3) float in [0, 1] -> CIE L*a*b* (H, W, 3) float64 (D65; L in [0, 100]).

    The sRGB transfer curve is undone (``c / 12.92`` up to 0.04045, else
    ``((c + 0.055) / 1.055) ** 2.4``), then XYZ by OpenCV's matrix, normalised by
    the white point, and ``f(t) = t ** (1/3)`` above ``0.008856`` (else
    ``7.787 t + 16 / 116``): ``L = 116 f(Y) - 16``, ``a = 500 (f(X) - f(Y))``,
    ``b = 200 (f(Y) - f(Z))``. Colours outside [0, 1] are clipped first.
    """
    c = np.clip(_check_rgb(rgb, "image").astype(np.float64), 0.0, 1.0)
    lin = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    xyz = (lin @ _SRGB_TO_XYZ.T) / _WHITE  # (H, W, 3)
    f = np.where(xyz > 0.008856, np.cbrt(xyz), 7.787 * xyz + 16.0 / 116.0)
    return np.stack([116.0 * f[..., 1] - 16.0, 500.0 * (f[..., 0] - f[..., 1]), 200.0 * (f[..., 1] - f[..., 2])], -1)


def lab_stats(rgb: np.ndarray) -> np.ndarray:
    """(6,) float64: mean L, a, b and population std L, a, b of an image's pixels in CIE L*a*b*."""
    lab = srgb_to_lab(rgb).reshape(-1, 3)
    return np.concatenate([lab.mean(0), lab.std(0)])


def lab_distance(image: np.ndarray, style: np.ndarray) -> float:
    """Euclidean norm of ``lab_stats(image) - lab_stats(style)`` (Lab units; 0 for equal statistics).

    ``style`` may be an image or its (6,) :func:`lab_stats`.
    """
    ref = np.asarray(style, np.float64)
    if ref.shape != (6,):
        ref = lab_stats(style)
    elif not np.isfinite(ref).all():
        raise InputError("style statistics", "contain NaN or infinite values")
    return float(np.linalg.norm(lab_stats(image) - ref))


# ----------------------------------------------------------------------------- sharpness


def sharpness(rgb: np.ndarray) -> float:
    """Standard deviation of the Laplacian of the grey image (H, W, 3) in [0, 1] (higher = sharper)."""
    import cv2

    a = _check_rgb(rgb, "image")
    grey = cv2.cvtColor(np.ascontiguousarray(a, dtype=np.float32), cv2.COLOR_RGB2GRAY)
    return float(cv2.Laplacian(grey, cv2.CV_32F).std())


def sharpness_ratio(image: np.ndarray, reference: np.ndarray) -> float:
    """``sharpness(image) / sharpness(reference)`` of two views of one size; nan when the reference is flat."""
    if np.shape(image) != np.shape(reference):
        raise InputError("image", f"is {np.shape(image)} but its reference view is {np.shape(reference)}")
    ref = sharpness(reference)
    return sharpness(image) / ref if ref > 1e-12 else math.nan


# ----------------------------------------------------------------------------- consistency, shared warps


__all__ = ["lab_distance", "lab_stats", "sharpness", "sharpness_ratio", "srgb_to_lab"]
