"""Normalised device coordinates (NDC) of a point cloud, as in the paper (Sec. 3.1).

The model sees the point cloud in NDC so it does not depend on the depth scale.
Points are in a camera frame (see :mod:`stylize3d_core.geometry.camera`: +z
forward). With ``n = 0.99 * min z`` and ``f = max(q95(z), 2 n)``::

    x' = x * cot(fov_y / 2) / (a * z)
    y' = y * cot(fov_y / 2) / z
    z' = (f + n) / (f - n) - 2 f n / ((f - n) z)

where ``a = W / H`` is the aspect ratio. Points of the photo land in
``x', y' in [-1, 1]`` (border extensions slightly outside), the near plane at
``z' = -1`` and the 95th depth percentile at ``z' <= 1``; farther points go
beyond 1 (nothing is clipped).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch

from ..checks import check_finite, check_shape
from ..errors import InputError
from .camera import check_fov


class NDCParams(NamedTuple):
    """Parameters of one NDC mapping (all Python floats)."""

    near: float
    far: float
    aspect: float  # W / H
    cot_half_fov: float  # cot(fov_y / 2)


def ndc_params(z: torch.Tensor, fov_y_deg: float, aspect: float) -> NDCParams:
    """NDC parameters for a point cloud with depths ``z`` (N,), all > 0."""
    check_shape(z, "z", (None,))
    if z.numel() == 0:
        raise InputError("points", "the point cloud is empty")
    check_finite(z, "z")
    zmin = float(z.min())
    if zmin <= 0:
        raise InputError("z", f"all depths must be positive for NDC, min is {zmin}")
    if not aspect > 0 or not math.isfinite(aspect):
        raise InputError("aspect", f"must be positive, got {aspect}")
    near = 0.99 * zmin
    # The 95th percentile as the k-th smallest depth (torch.quantile has an input size limit, 16M;
    # kthvalue needs no full sort): the same value as sorting and indexing.
    k = min(z.numel() - 1, int(round(0.95 * (z.numel() - 1))))
    q95 = float(torch.kthvalue(z.double(), k + 1).values)
    far = max(q95, 2.0 * near)
    cot = 1.0 / math.tan(math.radians(check_fov(fov_y_deg)) / 2.0)
    return NDCParams(near, far, float(aspect), cot)


def to_ndc(points: torch.Tensor, p: NDCParams) -> torch.Tensor:
    """Camera-frame points (N, 3) -> NDC points (N, 3). Does not modify ``points``."""
    check_shape(points, "points", (None, 3))
    x, y, z = points.unbind(-1)
    n, f = p.near, p.far
    xn = x * p.cot_half_fov / (p.aspect * z)
    yn = y * p.cot_half_fov / z
    zn = (f + n) / (f - n) - 2.0 * f * n / ((f - n) * z)
    return torch.stack([xn, yn, zn], dim=-1)


def from_ndc(points_ndc: torch.Tensor, p: NDCParams) -> torch.Tensor:
    """Inverse of :func:`to_ndc`: NDC points (N, 3) -> camera-frame points (N, 3)."""
    check_shape(points_ndc, "points_ndc", (None, 3))
    xn, yn, zn = points_ndc.unbind(-1)
    n, f = p.near, p.far
    z = 2.0 * f * n / ((f + n) - (f - n) * zn)
    x = xn * p.aspect * z / p.cot_half_fov
    y = yn * z / p.cot_half_fov
    return torch.stack([x, y, z], dim=-1)
