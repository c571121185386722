"""Stylized3DPhoto with split-resolution decoding (StylizeSettings.decode_scale / preview_decode_scale)."""

from dataclasses import replace

import numpy as np
import pytest
import torch

from stylize3d_core.depth.types import DepthMap
from stylize3d_core.errors import InputError
from stylize3d_core.geometry.camera import Cameras
from stylize3d_core.models.checkpoint import save_checkpoint
from stylize3d_core.models.stylize3d import ModelConfig, Stylize3DModel
from stylize3d_core.scene.photo3d import Photo3D
from stylize3d_core.stylize import Stylized3DPhoto, StylizeSettings


@pytest.fixture(scope="module")
def stylized(tmp_path_factory):
    torch.manual_seed(0)
    model = Stylize3DModel(ModelConfig.lite())  # a new decoder: the identity colour transform
    path = save_checkpoint(tmp_path_factory.mktemp("m") / "m.safetensors", model, 2, {})
    g = np.random.default_rng(0)
    rgb = g.random((48, 64, 3), dtype=np.float32)
    depth = np.ones((48, 64), np.float32)
    depth[12:36, 16:48] = 0.5
    p = Photo3D.build(rgb, DepthMap(depth, np.ones_like(depth, bool), "metric", "test"))
    s = Stylized3DPhoto(p, path, StylizeSettings(strength=1.0))
    s.set_style(g.random((32, 32, 3), dtype=np.float32))
    return s


def test_split_frames_match_the_full_decode_where_points_land(stylized):
    """With the identity transform covered pixels are the detail colours either way; only holes differ."""
    cam = Cameras.identity(stylized.photo.fov_y_deg)
    base = stylized.settings
    full = stylized.render(cam, 48, 64)
    stylized.settings = replace(base, decode_scale=2)
    try:
        split = stylized.render(cam, 48, 64)
        assert split.shape == full.shape and np.isfinite(split).all() and 0 <= split.min() <= split.max() <= 1
        assert not np.array_equal(split, full)  # the U-Net ran at another size ...
        np.testing.assert_allclose(np.median(np.abs(split - full)), 0.0, atol=1e-5)  # ... and shows in holes only
        prev_full = stylized.render(cam, 24, 32, preview=True)
        stylized.settings = replace(base, preview_decode_scale=2)
        assert np.array_equal(stylized.render(cam, 48, 64), full)  # previews only
        prev = stylized.render(cam, 24, 32, preview=True)
        assert prev.shape == prev_full.shape and np.isfinite(prev).all()
    finally:
        stylized.settings = base


@pytest.mark.parametrize("field", ["decode_scale", "preview_decode_scale"])
def test_bad_decode_scales(field):
    for bad in (0, 9, 2.0, True):
        with pytest.raises(InputError, match=field):
            StylizeSettings(**{field: bad})
