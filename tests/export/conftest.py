"""Fixtures of the export tests: a small 3D photo with a near square in front of a far wall."""

import numpy as np
import pytest

from stylize3d_core.depth.types import DepthMap
from stylize3d_core.scene.photo3d import Photo3D


@pytest.fixture(scope="module")
def photo3d() -> Photo3D:
    g = np.random.default_rng(0)
    h, w = 48, 64
    rgb = np.empty((h, w, 3), np.float32)
    rgb[:] = (0.2, 0.4, 0.8)  # blue wall
    rgb += 0.1 * g.random((h, w, 3), dtype=np.float32)
    depth = np.full((h, w), 2.0, np.float32)
    depth[12:36, 20:44] = 1.0  # a near red square
    rgb[12:36, 20:44] = (0.85, 0.15, 0.1)
    return Photo3D.build(np.clip(rgb, 0, 1), DepthMap(depth, np.ones_like(depth, bool), "metric", "test"))


@pytest.fixture(scope="module")
def square_mask() -> np.ndarray:
    m = np.zeros((48, 64), bool)
    m[12:36, 20:44] = True
    return m
