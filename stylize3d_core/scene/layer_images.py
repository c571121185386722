"""Images of a layered depth image's two layers, and reading them back onto the LDI's points.

A 2D operation on an LDI (painting it with the style prior, or the
stylize-then-bake baseline) works on two canvas images (Hc, Wc, 3):

* layer 0: ``ldi.rgb`` (the photo and its border extension);
* layer 1: :func:`hidden_layer_image` (the hidden layer's colours where it
  exists, layer 0's elsewhere, so the 2D operation sees their context).

:func:`layer_colours` gives every point the colour of its own pixel in its own
layer's image. Images are float, channels last.
"""

from __future__ import annotations

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
