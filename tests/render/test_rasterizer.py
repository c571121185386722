"""PointRasterizer: a raster smaller than the frame it stands for (``frame=``) covers the frame's extent."""

from __future__ import annotations

import pytest
import torch

from stylize3d_core.errors import InputError
from stylize3d_core.geometry.camera import Cameras, unproject
from stylize3d_core.render.rasterize import RasterSettings
from stylize3d_core.render.rasterizer import PointRasterizer


def _point_at(u: float, v: float, cam: Cameras, frame) -> torch.Tensor:
    """(1, 3) world point that projects to (u, v) of a ``frame``-sized image of ``cam`` (identity pose)."""
    K = cam.intrinsics(*frame, dtype=torch.float64)[0]
    return unproject(torch.tensor([[u, v]], dtype=torch.float64), torch.tensor([2.0], dtype=torch.float64), K).float()


@pytest.mark.parametrize("frame,small", [((20, 30), (10, 15)), ((21, 31), (11, 16)), ((40, 64), (10, 16))])
def test_small_raster_of_a_frame_lines_up_with_bilinear_upsampling(frame, small):
    """A point at frame pixel coordinates (u, v) lands at (u w / W, v h / H) of the small raster: the
    grid that ``F.interpolate(align_corners=False)`` maps onto the frame."""
    cam = Cameras.identity(50.0)
    (H, W), (h, w) = frame, small
    i, j = 3, 5  # the small raster's pixel whose centre the point hits
    u, v = (j + 0.5) * W / w, (i + 0.5) * H / h
    xyz = _point_at(u, v, cam, frame)
    frags = PointRasterizer(RasterSettings(height=h, width=w))(xyz, torch.ones(1, 1), cam, frame=frame)
    assert frags.weight[i, j].item() == pytest.approx(1.0, abs=1e-4)
    assert frags.weight.sum().item() == pytest.approx(1.0, abs=1e-5)
    same = PointRasterizer(RasterSettings(height=H, width=W))(xyz, torch.ones(1, 1), cam, frame=frame)
    plain = PointRasterizer(RasterSettings(height=H, width=W))(xyz, torch.ones(1, 1), cam)
    assert torch.equal(same.weight, plain.weight)  # frame = the raster's own size: unchanged


def test_bad_frame():
    cam = Cameras.identity(50.0)
    with pytest.raises(InputError, match="frame"):
        PointRasterizer(RasterSettings(height=4, width=4))(torch.zeros(1, 3), torch.ones(1, 1), cam, frame=(0, 8))
