"""Images of a layered depth image's two layers, and reading them back onto the LDI's points.

A 2D operation on an LDI (painting it with the style prior, or the
stylize-then-bake baseline) works on two canvas images (Hc, Wc, 3):

* layer 0: ``ldi.rgb`` (the photo and its border extension);
* layer 1: :func:`hidden_layer_image` (the hidden layer's colours where it
  exists, layer 0's elsewhere, so the 2D operation sees their context).

A 2D operation that depends on context (a style network) gives the hidden pixels
colours that need not continue layer 0's result on the surface the hidden layer
extends: a novel view would show a seam where the two meet.
:func:`match_hidden_seam` carries layer 0's result across that border.

:func:`layer_colours` gives every point the colour of its own pixel in its own
layer's image. Images are float, channels last.
"""

from __future__ import annotations

from typing import NamedTuple, Optional

import cv2
import numpy as np

from ..checks import check_shape
from ..errors import InputError
from ..geometry.camera import focal_from_fov
from .ldi import INPAINTED, LDI
from .pointcloud import PointCloud


def hidden_layer_image(ldi: LDI) -> np.ndarray:
    """(Hc, Wc, 3) the hidden layer's colours at their canvas pixels, layer 0's colours elsewhere.

    The layer-0 colours around the hidden pixels give the 2D network the
    context a painting of the hidden surface needs; only the hidden pixels are
    read back (:func:`layer_colours`).
    """
    if not isinstance(ldi, LDI):
        raise InputError("ldi", f"expected an LDI, got {type(ldi).__name__}")
    return np.where(ldi.hidden_mask[..., None], ldi.hidden_rgb, ldi.rgb).astype(np.float32)


JOIN_SIGMA = 8.0
"""Gaussian sigma, in canvas pixels, of the colour offset :func:`join_photo_painting` measures along the
photo's edge and carries into the border."""

JOIN_MARGIN = 16
"""Canvas pixels by which the photo region is mirrored outward before it is painted
(:func:`photo_with_margin`): the painting's own rim (the network sees zero padding at an image's edge)
falls in the margin, and the two paintings cross-fade over it."""


def join_margin(ldi: LDI) -> int:
    """The margin of :func:`photo_with_margin` for this LDI: :data:`JOIN_MARGIN`, at most its border."""
    if not isinstance(ldi, LDI):
        raise InputError("ldi", f"expected an LDI, got {type(ldi).__name__}")
    return min(JOIN_MARGIN, ldi.pad)


def photo_with_margin(ldi: LDI, image: np.ndarray) -> np.ndarray:
    """(H + 2 m, W + 2 m, 3) the photo region of a canvas image, mirrored outward by ``m =``
    :func:`join_margin` pixels: the image the photo region is painted from (a mirror keeps the photo's
    statistics; the border's own content would not)."""
    hc, wc = ldi.canvas_size
    check_shape(image, "image", (hc, wc, 3))
    rows, cols = ldi.photo_region
    m = join_margin(ldi)
    crop = np.ascontiguousarray(image[rows, cols], dtype=np.float32)
    return cv2.copyMakeBorder(crop, m, m, m, m, cv2.BORDER_REFLECT_101) if m else crop


def join_photo_painting(ldi: LDI, canvas_painting: np.ndarray, photo_painting: np.ndarray) -> np.ndarray:
    """(Hc, Wc, 3) one layer image's painting from two: ``photo_painting``, of the layer image's photo region
    alone (:func:`photo_with_margin`), inside the photo; ``canvas_painting``, of the whole canvas, in the
    border, shifted by the smooth colour offset between the two measured along the photo's edge (so the
    border continues the photo's colours); the two cross-fade over the margin.

    Why two paintings: the 2D network normalises its features by statistics of the whole image it paints;
    the border (the photo's edges stretched outward, a third of the canvas or more) pulls those statistics
    away from the photo's, and the photo comes out painted unlike the network paints the photo itself
    (``docs/quality.md`` measures it). Painted (nearly) alone, the photo gets the network's own rendering.
    """
    if not isinstance(ldi, LDI):
        raise InputError("ldi", f"expected an LDI, got {type(ldi).__name__}")
    hc, wc = ldi.canvas_size
    h, w = ldi.photo_size
    pad, m = ldi.pad, join_margin(ldi)
    check_shape(canvas_painting, "canvas_painting", (hc, wc, 3))
    check_shape(photo_painting, "photo_painting", (h + 2 * m, w + 2 * m, 3))
    out = np.asarray(canvas_painting, np.float32).copy()
    inner = np.asarray(photo_painting, np.float32)
    if pad == 0:
        return inner.copy()
    photo_rows, photo_cols = ldi.photo_region
    rows, cols = slice(pad - m, pad + h + m), slice(pad - m, pad + w + m)
    # the offset at the photo's edge (its edge rows and columns, smoothed), carried straight outward
    offset = cv2.GaussianBlur(inner[m:m + h, m:m + w] - out[photo_rows, photo_cols], (0, 0), JOIN_SIGMA,
                              borderType=cv2.BORDER_REFLECT_101)
    out = np.clip(out + cv2.copyMakeBorder(offset, pad, pad, pad, pad, cv2.BORDER_REPLICATE), 0.0, 1.0)
    # the photo painting's weight: 1 on the photo, falling linearly to 0 across the margin
    dy = np.maximum(np.maximum(m - np.arange(h + 2 * m), np.arange(h + 2 * m) - (h + m - 1)), 0)
    dx = np.maximum(np.maximum(m - np.arange(w + 2 * m), np.arange(w + 2 * m) - (w + m - 1)), 0)
    weight = np.clip(1.0 - np.maximum(dy[:, None], dx[None, :]) / float(m + 1), 0.0, 1.0)[..., None]
    out[rows, cols] = weight * inner + (1.0 - weight) * out[rows, cols]
    return out.astype(np.float32)


SEAM_SIGMA = 6.0
"""Gaussian sigma, in canvas pixels, over which :func:`match_hidden_seam` spreads the difference between
the two layer images from the border into the hidden layer (it fades out over about twice that)."""

SEAM_DEPTH_TOLERANCE = 0.1
"""A layer-0 pixel beside the hidden layer is on the surface the hidden layer continues (not on the
occluder in front of it) when its depth is at least ``1 - SEAM_DEPTH_TOLERANCE`` times the hidden depth
there."""


class SeamAnchors(NamedTuple):
    """What :func:`match_hidden_seam` needs of an LDI alone (the same for every painting of it):
    :func:`seam_anchors`."""

    hidden: np.ndarray  # (Hc, Wc) bool, the hidden layer's pixels
    anchor: np.ndarray  # (Hc, Wc) float32, 1 on the layer-0 pixels of the surface the hidden layer continues
    weight: np.ndarray  # (Hc, Wc) float32, the anchors smoothed by SEAM_SIGMA
    fade: np.ndarray  # (M,) float32, the correction's strength at each hidden pixel (``hidden`` order)


def seam_anchors(ldi: LDI) -> Optional[SeamAnchors]:
    """The seam of ``ldi`` between its hidden layer and the layer-0 pixels beside it (within 2 px) that are on
    the surface the hidden layer continues (:data:`SEAM_DEPTH_TOLERANCE`; the occluder's pixels beside it are
    never seen next to it), and how strongly each hidden pixel follows it; None where there is no such seam."""
    if not isinstance(ldi, LDI):
        raise InputError("ldi", f"expected an LDI, got {type(ldi).__name__}")
    hidden = ldi.hidden_mask
    if not hidden.any():
        return None
    near = _blur(hidden.astype(np.float32), 1.5)  # the hidden layer's neighbourhood, and its depth there
    hidden_depth = _blur(np.where(hidden, ldi.hidden_depth, 0.0).astype(np.float32), 1.5) / np.maximum(near, 1e-6)
    band = (cv2.dilate(hidden.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0) & ~hidden
    anchor = (band & (near > 1e-3) & (ldi.depth >= (1.0 - SEAM_DEPTH_TOLERANCE) * hidden_depth)).astype(np.float32)
    if not anchor.any():
        return None
    weight = _blur(anchor, SEAM_SIGMA)
    # full strength up to where the weight is that of a straight 2-pixel border SEAM_SIGMA away, then fading
    reference = 2.0 / (np.sqrt(2.0 * np.pi) * SEAM_SIGMA) * float(np.exp(-0.5))
    fade = (np.clip(weight / reference, 0.0, 1.0) * (weight > 1e-4))[hidden].astype(np.float32)
    return SeamAnchors(hidden, anchor, weight, fade)


def match_hidden_seam(ldi: LDI, layer0: np.ndarray, layer1: np.ndarray,
                      anchors: Optional[SeamAnchors] = None) -> np.ndarray:
    """``layer1`` (the processed :func:`hidden_layer_image`) continued seamlessly from ``layer0`` (the
    processed ``ldi.rgb``), both (Hc, Wc, 3) float in [0, 1]; returns a new float32 image.

    On the seam (:func:`seam_anchors`; pass them to paint one LDI several times) the difference
    ``layer0 - layer1`` is what a view would show as a step; it is spread into the hidden pixels by
    normalised Gaussian smoothing (:data:`SEAM_SIGMA`) and added to them, full at the border and fading to
    nothing about ``2 SEAM_SIGMA`` inside, so the hidden layer keeps its own processed texture and only its
    offset near the border changes. Pixels outside the hidden layer are returned unchanged; an LDI without
    a seam returns ``layer1`` as it is.
    """
    if not isinstance(ldi, LDI):
        raise InputError("ldi", f"expected an LDI, got {type(ldi).__name__}")
    hc, wc = ldi.canvas_size
    for name, img in (("layer0", layer0), ("layer1", layer1)):
        check_shape(img, name, (hc, wc, 3))
    out = np.array(layer1, dtype=np.float32)
    seam = seam_anchors(ldi) if anchors is None else anchors
    if seam is None:
        return out
    step = (np.asarray(layer0, np.float32) - out) * seam.anchor[..., None]
    spread = _blur(step, SEAM_SIGMA)[seam.hidden] / np.maximum(seam.weight[seam.hidden], 1e-6)[:, None]
    out[seam.hidden] = np.clip(out[seam.hidden] + spread * seam.fade[:, None], 0.0, 1.0)
    return out


def _blur(image: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian smoothing with zeros beyond the canvas (every channel of an (H, W, C) image)."""
    return cv2.GaussianBlur(image, (0, 0), sigma, borderType=cv2.BORDER_CONSTANT)


def layer_colours(points: PointCloud, ldi: LDI, layer0: np.ndarray, layer1: np.ndarray) -> np.ndarray:
    """(N, 3) float32: each point's colour read from the canvas image of its own layer.

    A point is projected into the photo's camera (the world frame), which puts it
    at the centre of its canvas pixel ``(row, col) = (v + pad, u + pad)``
    (:func:`~stylize3d_core.scene.pointcloud.ldi_to_points`); hidden points
    (label ``INPAINTED``) read ``layer1``, the others ``layer0``, both (Hc, Wc, 3).
    With ``layer0 = ldi.rgb`` and ``layer1 = hidden_layer_image(ldi)`` this gives back the points' colours.
    """
    if not isinstance(points, PointCloud):
        raise InputError("points", f"expected a PointCloud, got {type(points).__name__}")
    hc, wc = ldi.canvas_size
    for name, img in (("layer0", layer0), ("layer1", layer1)):
        check_shape(img, name, (hc, wc, 3))
    h, w = ldi.photo_size
    f = focal_from_fov(points.fov_y_deg, h)
    xyz = points.xyz.astype(np.float64)
    z = np.where(xyz[:, 2] > 1e-9, xyz[:, 2], 1e-9)
    col = np.clip(np.floor(f * xyz[:, 0] / z + w / 2.0 + ldi.pad), 0, wc - 1).astype(np.int64)
    row = np.clip(np.floor(f * xyz[:, 1] / z + h / 2.0 + ldi.pad), 0, hc - 1).astype(np.int64)
    hidden = points.label == INPAINTED
    out = np.asarray(layer0, np.float32)[row, col]
    out[hidden] = np.asarray(layer1, np.float32)[row[hidden], col[hidden]]
    return out


__all__ = ["hidden_layer_image", "layer_colours"]
