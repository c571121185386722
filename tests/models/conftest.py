import numpy as np
import pytest

from stylize3d_core.depth.types import DepthMap
from stylize3d_core.scene.photo3d import Photo3D

CLOUD_SIZE = (40, 48)
"""(H, W) of the photo behind the ``cloud`` fixture."""


@pytest.fixture(scope="module")
def cloud():
    """(PointTensors, fov) of a small random photo with a depth step, CLOUD_SIZE pixels."""
    g = np.random.default_rng(0)
    rgb = g.random((*CLOUD_SIZE, 3), dtype=np.float32)
    depth = np.ones(CLOUD_SIZE, np.float32)
    depth[10:30, 12:36] = 0.5
    p = Photo3D.build(rgb, DepthMap(depth, np.ones_like(depth, bool), "metric", "test"))
    return p.points.to_tensors(), p.fov_y_deg


@pytest.fixture(scope="module")
def cloud_size():
    """(H, W) of the ``cloud`` fixture's photo."""
    return CLOUD_SIZE
