"""Filling invalid depth pixels from their nearest valid neighbour.

Nearest-valid never blends a foreground and a background value into a
"flying" depth between them, as averaging or diffusion would at a depth edge;
every depth source that has holes (depth files, stereo, ONNX networks, the
prior's foreground mask, edge alignment) fills them this way.
"""

from __future__ import annotations

import cv2
import numpy as np


def fill_nearest(values: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Give every invalid pixel the value of its nearest valid pixel (Euclidean, 5x5 chamfer).

    Args:
        values: (H, W) float; only entries where ``valid`` is True are read.
        valid: (H, W) bool with at least one True.
    Returns:
        (H, W) float32, equal to ``values`` where valid.
    """
    if valid.all():
        return values.astype(np.float32)
    zeros_at_valid = np.where(valid, 0, 255).astype(np.uint8)
    _, labels = cv2.distanceTransformWithLabels(zeros_at_valid, cv2.DIST_L2, 5, labelType=cv2.DIST_LABEL_PIXEL)
    lut = np.zeros(int(labels.max()) + 1, np.float32)  # label of each valid pixel -> its value
    lut[labels[valid]] = values[valid]
    return lut[labels]
