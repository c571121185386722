"""The trained checkpoint shipped in assets/model really stylizes (a behaviour check, not a golden image)."""

from pathlib import Path

import numpy as np
import pytest
import torch

from stylize3d_core.geometry.trajectories import circle
from stylize3d_core.io.images import load_image
from stylize3d_core.models.checkpoint import load_checkpoint
from stylize3d_core.models.losses import style_distance
from stylize3d_core.pipeline import DEFAULT_MODEL, PhotoSpec, load_photo3d
from stylize3d_core.render.plain import PlainRenderer
from stylize3d_core.stylize import Stylized3DPhoto, StylizeSettings

ROOT = Path(__file__).resolve().parents[1]


def _t(img):
    return torch.from_numpy(img).permute(2, 0, 1)[None]


@pytest.fixture(scope="module")
def scene():
    ck = load_checkpoint(DEFAULT_MODEL)
    p3d = load_photo3d(PhotoSpec(str(ROOT / "assets/samples/coffee.jpg"), max_size=256))
    return ck, p3d


def test_checkpoint_is_a_trained_lite_stage2_model(scene):
    ck, _ = scene
    assert ck.model.config.name == "lite" and ck.stage == 2
    assert ck.info["iterations"] > 0 and ck.info["hours"] > 0


def test_stylized_views_move_towards_the_style(scene):
    ck, p3d = scene
    style = load_image(ROOT / "assets/styles/painting_style19_chelsea.jpg", max_size=256).rgb
    stylized = Stylized3DPhoto(p3d, ck, StylizeSettings(strength=1.0))
    stylized.set_style(style)
    cam = circle(90, fov_y_deg=p3d.fov_y_deg)[10]
    ours = stylized.render(cam, 128, 192)
    plain = PlainRenderer(p3d.points).render(cam, 128, 192)
    assert np.isfinite(ours).all()
    with torch.no_grad():
        d_ours = float(style_distance(_t(ours), _t(style)))
        d_plain = float(style_distance(_t(plain), _t(style)))
    assert d_ours < 0.9 * d_plain, (d_ours, d_plain)
    # Strength 0 brings the photo back: much closer to the plain render than the stylized view is.
    stylized.set_strength(0.0)
    photo_like = stylized.render(cam, 128, 192)
    assert np.abs(photo_like - plain).mean() < np.abs(ours - plain).mean()


def _hard_styles():
    yy, xx = np.mgrid[0:300, 0:400].astype(np.float32)
    line = np.ones((300, 400, 3), np.float32)
    line[(np.abs((xx - 1.3 * yy) % 60) < 2) | (np.abs(np.hypot(xx - 200, yy - 150) - 90) < 1.5)] = 0.0
    sketch = np.repeat(np.clip(0.93 + 0.05 * np.sin(xx / 9.0) * np.cos(yy / 13.0), 0, 1)[..., None], 3, 2)
    photo = load_image(ROOT / "assets/samples/chelsea.jpg").rgb
    huge = np.asarray(np.kron(load_image(ROOT / "assets/styles/vangogh_starry_night.jpg", max_size=500).rgb,
                              np.ones((10, 10, 1), np.float32)))  # 5000 px on the long side
    return {"black": np.zeros((64, 64, 3), np.float32), "white": np.ones((64, 64, 3), np.float32),
            "line drawing": line, "near-white sketch": sketch, "photo": photo,
            "16x16": np.random.default_rng(0).random((16, 16, 3)).astype(np.float32), "huge": huge}


@pytest.mark.parametrize("name", list(_hard_styles()))
def test_hard_styles_give_a_readable_scene(scene, name):
    """A flat, faint, tiny or huge style never gives a flat, blank or black frame: the scene's structure
    (the plain view's grey gradients) stays visible in the stylized view."""
    ck, p3d = scene
    stylized = Stylized3DPhoto(p3d, ck, StylizeSettings(strength=1.0))
    stylized.set_style(_hard_styles()[name])
    cam = circle(90, fov_y_deg=p3d.fov_y_deg)[10]
    ours = stylized.render(cam, 128, 192)
    plain = PlainRenderer(p3d.points).render(cam, 128, 192)
    assert np.isfinite(ours).all() and ours.min() >= 0 and ours.max() <= 1
    grey, ref = ours.mean(2), plain.mean(2)
    assert 0.08 < grey.mean() < 0.92 and grey.std() > 0.05, (grey.mean(), grey.std())
    gy, gx = np.gradient(grey)
    ry, rx = np.gradient(ref)
    corr = np.corrcoef(np.hypot(gx, gy).ravel(), np.hypot(rx, ry).ravel())[0, 1]
    assert corr > 0.2, corr  # the photo's edges are among the frame's (a line style adds strokes of its own)
