"""The one result type every depth source returns."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from ..checks import check_shape
from ..errors import InputError

DepthKind = Literal["metric", "relative"]


@dataclass(frozen=True)
class DepthMap:
    """A depth map aligned with a photo.

    Attributes:
        depth: (H, W) float32 depth (z along the camera axis, see
            ``geometry/camera.py``), finite and > 0 at *every* pixel: invalid
            pixels have already been filled from their valid neighbours.
        valid: (H, W) bool, True where the source gave a real value (before filling).
        kind: "metric" when the values are in a known unit (stereo with a
            known baseline, phone depth), "relative" when only their ratios mean
            something (priors, monocular networks).
        source: a short human-readable description, e.g. "file:scene.png (disparity)".
    """

    depth: np.ndarray
    valid: np.ndarray
    kind: DepthKind
    source: str

    def __post_init__(self) -> None:
        check_shape(self.depth, "depth", (None, None))
        check_shape(self.valid, "valid", self.depth.shape)
        if self.depth.dtype != np.float32:
            raise InputError("depth", f"expected float32, got {self.depth.dtype}")
        if self.valid.dtype != np.bool_:
            raise InputError("valid", f"expected bool, got {self.valid.dtype}")
        if not np.isfinite(self.depth).all() or not (self.depth > 0).all():
            raise InputError(self.source, "depth map must be finite and positive everywhere after filling")
        if self.kind not in ("metric", "relative"):
            raise InputError("kind", f"must be 'metric' or 'relative', got {self.kind!r}")

    @property
    def shape(self) -> tuple:
        return self.depth.shape


@dataclass(frozen=True)
class PhotoDepth:
    """What a depth source returns: the photo and its depth, pixel for pixel.

    Attributes:
        rgb: (H, W, 3) float32 in [0, 1], the photo the depth belongs to: the
            loaded image itself, except for a side-by-side stereo card, whose
            left view it is (the card is split once, by the source).
        depth_map: its :class:`DepthMap`, of the same (H, W).
    """

    rgb: np.ndarray
    depth_map: DepthMap

    def __post_init__(self) -> None:
        check_shape(self.rgb, "rgb", (None, None, 3))
        if self.rgb.shape[:2] != self.depth_map.shape:
            raise InputError(self.depth_map.source, f"depth map is {self.depth_map.shape} (H, W) but the photo "
                                                    f"it belongs to is {self.rgb.shape[:2]}")
