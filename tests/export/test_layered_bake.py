"""Layered stylization keeps the foreground's colours in every frame; baking puts view colours on points."""

import numpy as np
import pytest
import torch

from stylize3d_core.errors import InputError
from stylize3d_core.export.bake import bake_cameras, bake_colours
from stylize3d_core.export.layered import LayeredRenderer, LayerSettings
from stylize3d_core.geometry.camera import Cameras
from stylize3d_core.geometry.trajectories import circle
from stylize3d_core.models.checkpoint import save_checkpoint
from stylize3d_core.models.stylize3d import ModelConfig, Stylize3DModel
from stylize3d_core.render.plain import PlainRenderer
from stylize3d_core.scene.ldi import INPAINTED
from stylize3d_core.scene.masks import point_mask
from stylize3d_core.stylize import Stylized3DPhoto, StylizeSettings


@pytest.fixture(scope="module")
def stylized(photo3d, tmp_path_factory):
    torch.manual_seed(0)
    path = save_checkpoint(tmp_path_factory.mktemp("m") / "m.safetensors", Stylize3DModel(ModelConfig.lite()), 2, {})
    s = Stylized3DPhoto(photo3d, path, StylizeSettings(strength=1.0))
    s.set_style(np.random.default_rng(1).random((64, 64, 3), dtype=np.float32))
    return s


def test_point_mask_follows_the_ldi(photo3d, square_mask):
    fg = point_mask(photo3d.ldi, square_mask)
    pts = photo3d.points
    assert fg.shape == (len(pts),) and fg.sum() == square_mask.sum()
    assert not fg[pts.label == INPAINTED].any()  # hidden background behind the square is background
    assert (pts.label == INPAINTED).any()
    z = pts.xyz[:, 2]
    assert z[fg].max() < z[~fg & (pts.label != INPAINTED)].min()  # exactly the near square's points


def test_foreground_keeps_its_colours_in_every_frame(photo3d, square_mask, stylized):
    fg = point_mask(photo3d.ldi, square_mask)
    layered = LayeredRenderer(photo3d, fg, stylized)
    plain = PlainRenderer(photo3d.points)
    cams = circle(5, fov_y_deg=photo3d.fov_y_deg)
    worst = 0.0
    for i in range(len(cams)):
        cov = layered.coverage(cams[i], 48, 64)
        inside = cov >= 0.999
        assert inside.sum() > 200  # the square is in view in every frame
        frame = layered.render(cams[i], 48, 64)
        assert np.isfinite(frame).all()
        worst = max(worst, float(np.abs(frame[inside] - plain.render(cams[i], 48, 64)[inside]).max()))
        styl = stylized.render(cams[i], 48, 64)
        back = cov <= 0.001
        assert np.allclose(frame[back], styl[back], atol=1e-6)  # the background is the stylized render
    assert worst < 1e-5
    own = layered.render(Cameras.identity(photo3d.fov_y_deg), 48, 64)
    assert np.abs(own[13:35, 21:43] - photo3d.rgb[13:35, 21:43]).mean() < 0.02  # the photo's own red square


def test_foreground_strength(photo3d, square_mask, stylized):
    fg = point_mask(photo3d.ldi, square_mask)
    layered = LayeredRenderer(photo3d, fg, stylized, foreground_strength=0.5)
    cam = Cameras.identity(photo3d.fov_y_deg)
    frame = layered.render(cam, 48, 64)
    stylized.set_strength(0.5)
    half = stylized.render(cam, 48, 64)
    stylized.set_strength(1.0)
    inside = layered.coverage(cam, 48, 64) >= 0.999
    assert np.allclose(frame[inside], half[inside], atol=1e-5)
    layered.render(cam, 48, 64)
    assert stylized.strength == 1.0  # the background's strength is back after each frame
    with pytest.raises(InputError, match="bool array"):
        LayeredRenderer(photo3d, np.zeros(3, bool), stylized)


def test_layered_render_stops_when_asked(photo3d, square_mask, stylized):
    from stylize3d_core.errors import RenderInterrupted

    layered = LayeredRenderer(photo3d, point_mask(photo3d.ldi, square_mask), stylized)
    with pytest.raises(RenderInterrupted):
        layered.render(Cameras.identity(photo3d.fov_y_deg), 24, 32, should_stop=lambda: True)


def test_layer_settings_bad_input():
    with pytest.raises(InputError, match="not both"):
        LayerSettings(mask="m.png", mask_rect="1,2,3,4")
    with pytest.raises(InputError, match="mask_rect"):
        LayerSettings(mask_rect="1,2,3")
    with pytest.raises(InputError, match="foreground_strength"):
        LayerSettings(foreground_strength=0.3)


def test_bake_plain_views_gives_the_points_their_colours(photo3d):
    pts = photo3d.points
    baked = bake_colours(pts.xyz, PlainRenderer(pts).render, bake_cameras(photo3d.fov_y_deg), photo3d.size)
    assert baked.rgb.shape == pts.rgb.shape and np.isfinite(baked.rgb).all()
    photo_pts = pts.label == 0
    assert (baked.view[photo_pts] == 0).mean() > 0.95  # the photo's own view first
    assert np.abs(baked.rgb[photo_pts] - pts.rgb[photo_pts]).mean() < 0.03
    hidden = pts.label == INPAINTED
    assert (baked.view[hidden] > 0).any()  # side views see behind the square
    with pytest.raises(InputError, match="no view"):
        away = np.eye(4)
        away[:3, :3] = np.diag([-1.0, 1.0, -1.0])  # looking backwards
        bake_colours(pts.xyz, PlainRenderer(pts).render, Cameras.create(away, 60.0), photo3d.size)
