"""Stylized3DPhoto defers the learned parts' inputs (geometry, content and style features) to the first view
with an uncovered pixel, for models whose covered pixels are their points' colours; every frame is the one
the eager path renders."""

from dataclasses import replace

import numpy as np
import pytest
import torch

from stylize3d_core.depth.types import DepthMap
from stylize3d_core.geometry.camera import Cameras
from stylize3d_core.geometry.trajectories import circle
from stylize3d_core.models.checkpoint import load_checkpoint, save_checkpoint
from stylize3d_core.models.stylize3d import ModelConfig, Stylize3DModel
from stylize3d_core.resources import resolve_model
from stylize3d_core.scene.photo3d import Photo3D
from stylize3d_core.stylize import Stylized3DPhoto, StylizeSettings

H, W = 48, 64
SETTINGS = StylizeSettings(bfloat16=False, prior_size=128)


@pytest.fixture(scope="module")
def photo():
    y, x = np.mgrid[0:H, 0:W].astype(np.float32)
    rgb = np.stack([0.5 + 0.4 * np.sin(x / 4), 0.5 + 0.4 * np.cos(y / 5), 0.3 + 0.2 * (x > 32)], -1)
    depth = np.ones((H, W), np.float32)
    depth[12:36, 16:48] = 0.5
    return Photo3D.build(rgb.astype(np.float32), DepthMap(depth, np.ones_like(depth, bool), "metric", "test"))


@pytest.fixture(scope="module")
def checkpoint():
    return load_checkpoint(resolve_model(None))


@pytest.fixture(scope="module")
def style():
    g = np.random.default_rng(5)
    return np.repeat(np.repeat(g.random((8, 8, 3), dtype=np.float32), 8, 0), 8, 1)


class Eager:
    """The reference: every view through the whole model (rasterized features, the decoder), prepared first."""

    def __init__(self, photo, checkpoint):
        self.s = Stylized3DPhoto(photo, checkpoint, SETTINGS)

    def __getattr__(self, name):
        return getattr(self.s, name)

    def render(self, camera, height, width, preview=False):
        self.s.prepare()
        rgb = self.s._render_model(camera, height, width, preview=preview, should_stop=None)
        assert self.s.palette is None  # the prior paints the palette: nothing after the model
        return rgb.permute(1, 2, 0).contiguous().numpy()


def _pair(photo, checkpoint, style):
    lazy, eager = Stylized3DPhoto(photo, checkpoint, SETTINGS), Eager(photo, checkpoint)
    eager.s.prepare()
    for s in (lazy, eager):
        s.set_style(style)
    return lazy, eager


def _far_camera(fov):
    """A camera moved far to the side and back: the view sees past the canvas's border (uncovered pixels)."""
    c2w = np.eye(4)
    c2w[0, 3], c2w[2, 3] = 0.6, -0.4
    return Cameras.create(c2w[None], fov)


def test_covered_views_need_no_learned_features_and_match_the_eager_frames(photo, checkpoint, style):
    lazy, eager = _pair(photo, checkpoint, style)
    assert lazy.has_style and eager.has_style
    cams = [Cameras.identity(photo.fov_y_deg)] + [circle(8, fov_y_deg=photo.fov_y_deg)[k] for k in (0, 3)]
    for cam in cams:
        for preview in (False, True):
            a = lazy.render(cam, H, W, preview=preview)
            b = eager.render(cam, H, W, preview=preview)
            np.testing.assert_array_equal(a, b)
    assert not lazy.prepared and eager.s.prepared
    assert "geometry" not in lazy.timings and "geometry" in eager.s.timings
    lazy.set_strength(0.4)  # strength and removal of the style stay on the colours
    eager.set_strength(0.4)
    np.testing.assert_array_equal(lazy.render(cams[0], H, W), eager.render(cams[0], H, W))
    lazy.set_style(None)
    eager.set_style(None)
    np.testing.assert_array_equal(lazy.render(cams[0], H, W), eager.render(cams[0], H, W))
    assert not lazy.prepared and not lazy.has_style


def test_an_uncovered_pixel_prepares_the_learned_parts(photo, checkpoint, style):
    lazy, eager = _pair(photo, checkpoint, style)
    far = _far_camera(photo.fov_y_deg)
    home = Cameras.identity(photo.fov_y_deg)
    assert lazy.needs_learned_parts(far, H, W) and not lazy.needs_learned_parts(home, H, W)
    assert not lazy.needs_learned_parts(home, H, W, preview=True)
    assert not lazy.prepared  # asking does not prepare
    lazy.settings = replace(SETTINGS, supersample=2)  # a supersampled frame runs the U-Net; a preview does not
    assert lazy.needs_learned_parts(home, H, W) and not lazy.needs_learned_parts(home, H, W, preview=True)
    lazy.settings = SETTINGS
    want = eager.render(far, H, W)
    got = lazy.render(far, H, W)
    assert lazy.prepared and "geometry" in lazy.timings
    np.testing.assert_array_equal(got, want)
    assert np.isfinite(got).all()
    # a second style set after preparing runs the stylizer at once, as the eager instance does
    other = np.full((32, 32, 3), 0.3, np.float32)
    other[::4] = 0.9
    lazy.set_style(other)
    eager.set_style(other)
    np.testing.assert_array_equal(lazy.render(far, H, W), eager.render(far, H, W))


def test_styles_set_before_preparing_are_stylized_when_prepared(photo, checkpoint, style):
    lazy, eager = _pair(photo, checkpoint, style)
    second = np.full((32, 32, 3), 0.7, np.float32)
    for s in (lazy, eager):
        s.set_second_style(second)
        s.set_mix(0.5)
    assert lazy._stylized is None and lazy._stylized2 is None  # nothing of the stylizer ran yet
    geometry = lazy.geometry  # asking for the geometry prepares
    assert geometry is not None and lazy.prepared
    eager.s.prepare()
    torch.testing.assert_close(lazy._stylized, eager.s._stylized, rtol=0, atol=0)
    torch.testing.assert_close(lazy._stylized2, eager.s._stylized2, rtol=0, atol=0)
    far = _far_camera(photo.fov_y_deg)
    np.testing.assert_array_equal(lazy.render(far, H, W), eager.render(far, H, W))


def test_models_whose_decoder_changes_covered_pixels_prepare_at_once(photo, tmp_path):
    torch.manual_seed(0)
    path = save_checkpoint(tmp_path / "plain.safetensors", Stylize3DModel(ModelConfig.lite()), 2, {})
    s = Stylized3DPhoto(photo, path, SETTINGS)
    assert s.prepared and "geometry" in s.timings
    assert s.needs_learned_parts(Cameras.identity(photo.fov_y_deg), H, W)  # every view runs the decoder


def test_a_prepared_instance_still_renders_covered_views_from_the_colours(photo, checkpoint, style):
    """After prepare (the viewer's idle task) and after a view with uncovered pixels, covered views keep the
    3-channel raster of the colours: the same pixels as the whole model."""
    lazy, eager = _pair(photo, checkpoint, style)
    lazy.prepare()
    assert lazy.prepared and lazy._dense is not None
    far = _far_camera(photo.fov_y_deg)
    np.testing.assert_array_equal(lazy.render(far, H, W), eager.render(far, H, W))
    home = Cameras.identity(photo.fov_y_deg)
    want = eager.render(home, H, W)  # (the two instances share the checkpoint's model: render it first)
    calls = []
    original = lazy.model.render_view
    lazy.model.render_view = lambda *a, **k: calls.append(1) or original(*a, **k)
    try:
        np.testing.assert_array_equal(lazy.render(home, H, W), want)
        assert not calls  # the covered view did not go through the model's raster and decoder
        lazy.render(far, H, W)
        assert calls  # the view with uncovered pixels did
    finally:
        del lazy.model.render_view
