"""A synthetic scanned stereo card of a known scene, to test and show ``depth/stereo_card.py``.

The scene is a photo (scikit-image's astronaut, or any image) with a known
depth: a near box at half the depth of the rest. The left print is the photo;
the right print is the scene rendered (``render/plain.py``) from a camera
``baseline`` scene units to the right, then rotated, darkened and lifted (as a
scanned card is: unequal exposure, mounted out of line), and both are mounted
on a cream card with borders and a gap.
"""

from __future__ import annotations

from typing import NamedTuple, Optional, Tuple

import cv2
import numpy as np

from ..depth.types import DepthMap
from ..geometry.camera import Cameras
from ..render.plain import PlainRenderer
from ..scene.photo3d import Photo3D

NEAR_BOX = (slice(60, 200), slice(70, 170))
"""Rows and columns of the near box in the 240 x 240 scene (depth 1 before a background at 2)."""
MOUNT_RGB = (0.86, 0.8, 0.68)


class SyntheticCard(NamedTuple):
    """The card (H, W, 3) float32, the true left view, its depth, and the left print's (top, bottom, left, right)."""

    card: np.ndarray
    left: np.ndarray
    depth: np.ndarray
    left_box: Tuple[int, int, int, int]


def synthetic_card(rotation_deg: float = 1.5, gain: float = 0.75, offset: float = 0.08, baseline: float = 0.03,
                   drop_px: int = 4, photo: Optional[np.ndarray] = None, seed: int = 0) -> SyntheticCard:
    """Make the card (see the module docstring); ``photo`` (any size, float in [0, 1]) replaces the astronaut."""
    if photo is None:
        import skimage.data

        photo = skimage.data.astronaut() / 255.0
    rgb = cv2.resize(np.asarray(photo, np.float32), (240, 240), interpolation=cv2.INTER_AREA)
    depth = np.full((240, 240), 2.0, np.float32)
    depth[NEAR_BOX] = 1.0
    p3d = Photo3D.build(rgb, DepthMap(depth, np.ones_like(depth, bool), "metric", "synthetic"))
    pose = np.eye(4)
    pose[0, 3] = baseline
    right = PlainRenderer(p3d.points).render(Cameras.create(pose, p3d.fov_y_deg), 240, 240)
    right = cv2.warpAffine(right, cv2.getRotationMatrix2D((120, 120), rotation_deg, 1.0), (240, 240),
                           borderMode=cv2.BORDER_REFLECT)
    right = np.clip(right * gain + offset, 0, 1)
    card = np.empty((280, 536, 3), np.float32)
    card[:] = MOUNT_RGB
    card[20:260, 20:260] = rgb
    card[20 + drop_px:260 + drop_px, 276:516] = right
    noise = 0.01 * np.random.default_rng(seed).standard_normal(card.shape)
    return SyntheticCard(np.clip(card + noise, 0, 1).astype(np.float32), rgb, depth, (20, 260, 20, 260))
