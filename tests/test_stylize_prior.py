"""Stylized3DPhoto with the 2D style prior: the painted colours reach the frame, strength and mixing, hard styles."""

import numpy as np
import pytest
import torch

from stylize3d_core.depth.types import DepthMap
from stylize3d_core.geometry.camera import Cameras
from stylize3d_core.models.checkpoint import save_checkpoint
from stylize3d_core.models.stylize3d import ModelConfig, Stylize3DModel
from stylize3d_core.scene.photo3d import Photo3D
from stylize3d_core.stylize import Stylized3DPhoto, StylizeSettings



@pytest.fixture(scope="module")
def with_prior(tmp_path_factory):
    """A style-prior model (random weights, identity colour transform) on a photo with a box in front."""
    from stylize3d_core.models.stylize3d import add_style_prior

    torch.manual_seed(0)
    model = add_style_prior(Stylize3DModel(ModelConfig.lite()))
    path = save_checkpoint(tmp_path_factory.mktemp("p") / "prior.safetensors", model, 2, {})
    y, x = np.mgrid[0:48, 0:64].astype(np.float32)
    rgb = np.stack([0.5 + 0.4 * np.sin(x / 4), 0.5 + 0.4 * np.cos(y / 5), 0.3 + 0.2 * (x > 32)], -1)
    depth = np.ones((48, 64), np.float32)
    depth[12:36, 16:48] = 0.5
    p = Photo3D.build(rgb.astype(np.float32), DepthMap(depth, np.ones_like(depth, bool), "metric", "test"))
    return Stylized3DPhoto(p, path, StylizeSettings(strength=1.0, bfloat16=False, prior_size=128))


def test_style_prior_colours_reach_the_frame(with_prior):
    """With the identity transform, the photo's own view shows the prior's painting of layer 0."""
    from stylize3d_core.models.style_prior import paint_layer_images

    s = with_prior
    cam = Cameras.identity(s.photo.fov_y_deg)
    g = np.random.default_rng(2)
    style = np.repeat(np.repeat(g.random((8, 8, 3), dtype=np.float32), 8, 0), 8, 1)
    s.set_style(style)
    frame = s.render(cam, 48, 64)
    ldi = s.photo.ldi
    painted = paint_layer_images(s._prior(), ldi, s._vector)[0]
    p = ldi.pad
    crop = painted[p:p + 48, p:p + 64]
    assert np.abs(frame - crop).mean() < 0.03  # the rasterized points carry their pixel's painted colour
    assert np.abs(frame - s.photo.rgb).mean() > 0.05  # and that is not the photo
    assert s.palette is None  # the prior paints the palette itself: no palette map


def test_style_prior_strength_mix_and_cache(with_prior):
    s = with_prior
    cam = Cameras.identity(s.photo.fov_y_deg)
    g = np.random.default_rng(3)
    s.set_style(g.random((64, 64, 3), dtype=np.float32))
    s.set_strength(1.0)
    full = s.render(cam, 48, 64)
    s.set_strength(0.0)
    photo_like = s.render(cam, 48, 64)
    assert np.abs(photo_like - s.photo.rgb).mean() < np.abs(full - s.photo.rgb).mean()
    s.set_strength(0.5)
    half = s.render(cam, 48, 64)
    assert not np.allclose(half, full, atol=1e-3)
    painted = len(s._painted)
    s.set_strength(1.0)
    np.testing.assert_allclose(s.render(cam, 48, 64), full, atol=1e-6)  # back to a kept painting
    assert len(s._painted) == painted
    s.set_second_style(np.full((32, 32, 3), 0.8, np.float32))
    s.set_mix(1.0)
    assert not np.allclose(s.render(cam, 48, 64), full, atol=1e-3)
    s.set_second_style(None)
    s.set_mix(0.0)


def test_style_prior_black_style_gives_a_readable_frame(with_prior):
    s = with_prior
    s.set_strength(1.0)
    s.set_style(np.zeros((64, 64, 3), np.float32))
    frame = s.render(Cameras.identity(s.photo.fov_y_deg), 48, 64)
    assert np.isfinite(frame).all()
    grey = frame.mean(-1)
    assert grey.std() > 0.3 * s.photo.rgb.mean(-1).std() and grey.mean() > 0.05
