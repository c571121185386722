"""RGB point cloud of a layered depth image: one point per LDI pixel.

Coordinates follow ``geometry/camera.py``: the world frame is the photo's camera
frame (+z forward, x right, y down) and the intrinsics are those of the *photo*
(``fy = fx = (H / 2) / tan(fov_y / 2)``, principal point at the photo's centre),
so the border of the LDI canvas back-projects to points just outside the photo's
view.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple, Optional, Tuple

import numpy as np
import torch

from ..checks import check_shape
from ..errors import InputError
from ..geometry.camera import check_fov, focal_from_fov
from .ldi import BORDER, INPAINTED, LDI, ORIGINAL

LABELS = (ORIGINAL, INPAINTED, BORDER)
"""Every point label: seen in the photo, hidden background, border extension."""


class PointTensors(NamedTuple):
    """A point cloud as torch tensors (see :meth:`PointCloud.to_tensors`).

    Attributes:
        xyz: (N, 3) float32 world (= photo camera) coordinates.
        rgb: (N, 3) float32 colours in [0, 1].
        label: (N,) uint8 point labels.
        alpha: (N,) float32 opacities in (0, 1], or None: every point opaque.
    """

    xyz: torch.Tensor
    rgb: torch.Tensor
    label: torch.Tensor
    alpha: Optional[torch.Tensor] = None


@dataclass(frozen=True)
class PointCloud:
    """Coloured points of a 3D photo.

    Attributes:
        xyz: (N, 3) float32 points in world coordinates (= the photo's camera frame).
        rgb: (N, 3) float32 colours in [0, 1].
        label: (N,) uint8, one of :data:`LABELS` per point.
        image_size: (H, W) of the photo the points come from.
        fov_y_deg: vertical field of view of the photo's camera, in degrees.
        alpha: (N,) float32 opacity of each point in (0, 1] (an anti-aliased silhouette's point covers
            part of its pixel, :attr:`~stylize3d_core.scene.ldi.LDI.alpha`; renderers that blend coverage
            show what lies behind through the rest), or None (default): every point opaque.
    """

    xyz: np.ndarray
    rgb: np.ndarray
    label: np.ndarray
    image_size: Tuple[int, int]
    fov_y_deg: float
    alpha: Optional[np.ndarray] = None

    def __post_init__(self) -> None:
        check_shape(self.xyz, "xyz", (None, 3))
        n = self.xyz.shape[0]
        check_shape(self.rgb, "rgb", (n, 3))
        check_shape(self.label, "label", (n,))
        for name, want in (("xyz", np.float32), ("rgb", np.float32), ("label", np.uint8)):
            if getattr(self, name).dtype != want:
                raise InputError(name, f"expected dtype {np.dtype(want)}, got {getattr(self, name).dtype}")
        if not np.isfinite(self.xyz).all():
            raise InputError("xyz", "contains NaN or infinite values")
        if not np.isfinite(self.rgb).all():
            raise InputError("rgb", "contains NaN or infinite values")
        if self.alpha is not None:
            check_shape(self.alpha, "alpha", (n,))
            if self.alpha.dtype != np.float32:
                raise InputError("alpha", f"expected dtype float32, got {self.alpha.dtype}")
            if n and not ((self.alpha > 0.0) & (self.alpha <= 1.0)).all():
                raise InputError("alpha", "opacities must lie in (0, 1] (no NaN)")
        if n and int(self.label.max()) > max(LABELS):
            raise InputError("label", f"values must be in {LABELS}, got {int(self.label.max())}")
        if len(self.image_size) != 2 or min(self.image_size) < 1:
            raise InputError("image_size", f"expected (H, W) > 0, got {self.image_size!r}")
        check_fov(self.fov_y_deg, "fov_y_deg")

    def __len__(self) -> int:
        return self.xyz.shape[0]

    def to_tensors(self) -> PointTensors:
        """The points as torch tensors (sharing memory with the arrays)."""
        return PointTensors(
            torch.from_numpy(self.xyz), torch.from_numpy(self.rgb), torch.from_numpy(self.label),
            None if self.alpha is None else torch.from_numpy(self.alpha),
        )

    def select(self, *labels: int) -> "PointCloud":
        """The points whose label is one of ``labels`` (e.g. ``pc.select(ORIGINAL, INPAINTED)``)."""
        for lab in labels:
            if lab not in LABELS:
                raise InputError("label", f"must be one of {LABELS}, got {lab!r}")
        keep = np.isin(self.label, np.asarray(labels, np.uint8))  # (N,)
        return PointCloud(self.xyz[keep], self.rgb[keep], self.label[keep], self.image_size, self.fov_y_deg,
                          None if self.alpha is None else self.alpha[keep])


def ldi_to_points(ldi: LDI, fov_y_deg: float) -> PointCloud:
    """Back-project every LDI pixel to a point.

    Layer 0 gives one point per canvas pixel (labels ORIGINAL / BORDER), in
    row-major order; layer 1 follows, one point per ``hidden_mask`` pixel
    (label INPAINTED). Canvas pixel ``(i, j)`` has the photo pixel coordinates
    ``(u, v) = (j - pad + 0.5, i - pad + 0.5)`` (plus layer 0's ``ldi.offset`` where it has one:
    silhouette points moved by a fraction of a pixel) and becomes
    ``((u - W/2) z / f, (v - H/2) z / f, z)`` with ``f = focal_from_fov(fov_y_deg, H)``. The
    cloud's ``alpha`` is layer 0's ``ldi.alpha`` (1 for the hidden layer), None where the LDI
    has none.

    Args:
        ldi: from :func:`~stylize3d_core.scene.ldi.build_ldi`.
        fov_y_deg: vertical field of view of the photo, in degrees.
    Returns:
        A :class:`PointCloud` of ``ldi.num_points`` points.
    """
    if not isinstance(ldi, LDI):
        raise InputError("ldi", f"expected an LDI, got {type(ldi).__name__}")
    fov = check_fov(fov_y_deg, "fov_y_deg")
    h, w = ldi.photo_size
    hc, wc = ldi.canvas_size
    f = focal_from_fov(fov, h)
    x_ray = ((np.arange(wc) - ldi.pad + 0.5 - w / 2.0) / f).astype(np.float32)  # (Wc,) x / z
    y_ray = ((np.arange(hc) - ldi.pad + 0.5 - h / 2.0) / f).astype(np.float32)  # (Hc,) y / z

    z0 = ldi.depth
    if ldi.offset is None:
        xyz0 = np.stack([x_ray[None, :] * z0, y_ray[:, None] * z0, z0], axis=2)  # (Hc, Wc, 3)
    else:
        xs = x_ray[None, :] + ldi.offset[..., 0] / np.float32(f)
        ys = y_ray[:, None] + ldi.offset[..., 1] / np.float32(f)
        xyz0 = np.stack([xs * z0, ys * z0, z0], axis=2)
    rows1, cols1 = np.nonzero(ldi.hidden_mask)
    z1 = ldi.hidden_depth[rows1, cols1]
    xyz1 = np.stack([x_ray[cols1] * z1, y_ray[rows1] * z1, z1], axis=1)  # (M, 3)
    xyz = np.concatenate([xyz0.reshape(-1, 3), xyz1]).astype(np.float32, copy=False)  # (N, 3)
    rgb = np.concatenate([ldi.rgb.reshape(-1, 3), ldi.hidden_rgb[rows1, cols1]]).astype(np.float32)
    label = np.concatenate([ldi.label.ravel(), np.full(rows1.size, INPAINTED, np.uint8)])
    alpha = None
    if ldi.alpha is not None:
        alpha = np.concatenate([ldi.alpha.ravel(), np.ones(rows1.size, np.float32)]).astype(np.float32, copy=False)
    return PointCloud(xyz, rgb, label, (h, w), fov, alpha)
