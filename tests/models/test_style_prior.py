"""The 2D style prior: the network with free spatial sizes, style vectors, painting, readability, bad inputs."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from stylize3d_core.errors import InputError
from stylize3d_core.models.style_prior import (
    STYLE_VECTOR_SIZE, StylePrior, StylePriorSettings, _free_spatial_dims, _model_bytes, interpolate_vectors,
    SCENE_SHARE, keep_readable, scene_contrast,
)


@pytest.fixture(scope="module")
def prior():
    return StylePrior(StylePriorSettings(size=128, threads=1))


def _stripes(h, w, period=8.0):
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    return np.stack([0.5 + 0.4 * np.sin(x / period), 0.5 + 0.4 * np.cos(y / period), np.full_like(x, 0.4)], -1)


def test_style_vector_is_stable_and_distinguishes_styles(prior):
    a = prior.style_vector(_stripes(96, 80))
    assert a.shape == (STYLE_VECTOR_SIZE,) and a.dtype == np.float32 and np.isfinite(a).all()
    np.testing.assert_array_equal(a, prior.style_vector(_stripes(96, 80)))
    b = prior.style_vector(np.full((64, 64, 3), 0.2, np.float32))
    assert np.linalg.norm(a - b) > 0.1


def test_paint_keeps_each_images_size_at_any_aspect(prior):
    vec = prior.style_vector(_stripes(64, 64))
    for h, w in ((50, 70), (130, 60), (33, 33)):
        img = _stripes(h, w, 5.0)
        out = prior.paint([img, img[::-1].copy()], vec)
        assert [o.shape for o in out] == [(h, w, 3)] * 2
        assert all(o.dtype == np.float32 and np.isfinite(o).all() and o.min() >= 0 and o.max() <= 1 for o in out)
        assert not np.allclose(out[0], img, atol=0.05)  # it painted something
    assert prior.work_size(300, 600) == (64, 128)  # long side settings.size, multiples of 4


def test_the_transformer_runs_at_other_sizes_than_its_declared_one():
    import onnx

    model = onnx.load_from_string(_free_spatial_dims(_model_bytes("models/arbitrary_transform.onnx"), "t"))
    dims = model.graph.input[0].type.tensor_type.shape.dim
    assert [d.dim_param or d.dim_value for d in dims] == [1, "height", "width", 3]
    with pytest.raises(InputError, match="ONNX"):
        _free_spatial_dims(b"not a graph", "broken.onnx")


def test_strength_interpolates_vectors():
    own, style = np.zeros(STYLE_VECTOR_SIZE, np.float32), np.ones(STYLE_VECTOR_SIZE, np.float32)
    np.testing.assert_allclose(interpolate_vectors(own, style, 0.25), 0.25)
    np.testing.assert_array_equal(interpolate_vectors(own, style, 1.0), style)


def test_flat_styles_still_show_the_scene(prior):
    """A constant black or white style makes the network paint an almost flat image; the prior keeps at least
    half the photo's lightness contrast, and the painted image still follows the photo's structure."""
    photo = _stripes(96, 128, 6.0)
    grey = lambda im: cv2.cvtColor(im, cv2.COLOR_RGB2LAB)[..., 0]  # noqa: E731
    for colour in (0.0, 1.0):
        vec = prior.style_vector(np.full((64, 64, 3), colour, np.float32))
        out = prior.paint([photo], vec)[0]
        assert grey(out).std() >= 0.5 * grey(photo).std() - 0.5
        assert np.corrcoef(grey(out).ravel(), grey(photo).ravel())[0, 1] > 0.5
        assert 5.0 < grey(out).mean() < 95.0


def _lightness(img):
    return cv2.cvtColor(np.clip(img, 0, 1).astype(np.float32), cv2.COLOR_RGB2LAB)[..., 0]


def test_scene_contrast_known_values():
    rng = np.random.default_rng(0)
    light = cv2.GaussianBlur(rng.random((48, 64)).astype(np.float32), (0, 0), 4.0) * 100.0
    assert scene_contrast(light, light) == pytest.approx(light.std(), rel=1e-5)
    assert scene_contrast(100.0 - light, light) == pytest.approx(-light.std(), rel=1e-5)
    assert scene_contrast(np.full_like(light, 40.0), light) == 0.0
    assert scene_contrast(light, np.full_like(light, 40.0)) == 0.0


def test_keep_readable_leaves_contrasty_paintings_of_the_scene_alone_and_fixes_flat_ones():
    ref = _stripes(40, 60)
    painted = np.clip(ref ** 1.3 * 1.1, 0, 1).astype(np.float32)  # other tones, the same scene
    np.testing.assert_array_equal(keep_readable([painted], ref, 0.5)[0], painted)
    flat = np.full((40, 60, 3), 0.02, np.float32)
    fixed = keep_readable([flat, flat], ref, 0.5)
    lab = cv2.cvtColor(fixed[0], cv2.COLOR_RGB2LAB)[..., 0]
    ref_std = cv2.cvtColor(ref, cv2.COLOR_RGB2LAB)[..., 0].std()
    assert lab.std() == pytest.approx(0.5 * ref_std, rel=0.1)
    np.testing.assert_array_equal(fixed[0], fixed[1])  # one map for every layer
    assert keep_readable([flat], ref, 0.0)[0] is not None


def test_bad_inputs(prior):
    with pytest.raises(InputError, match="16 pixels"):
        prior.style_vector(np.zeros((8, 40, 3), np.float32))
    with pytest.raises(InputError, match="NaN"):
        prior.style_vector(np.full((32, 32, 3), np.nan, np.float32))
    with pytest.raises(InputError, match="same size"):
        prior.paint([np.zeros((16, 16, 3)), np.zeros((16, 20, 3))], np.zeros(STYLE_VECTOR_SIZE))
    with pytest.raises(InputError, match="finite"):
        prior.paint([np.zeros((16, 16, 3))], np.zeros(7))
    with pytest.raises(InputError):
        StylePriorSettings(size=64)
    with pytest.raises(InputError):
        StylePriorSettings(min_contrast=2.0)
    assert prior.paint([], np.zeros(STYLE_VECTOR_SIZE)) == []


def test_keep_readable_adds_the_scene_under_strokes_that_ignore_it():
    """A contrasty painting whose strokes do not follow the photo (a line drawing) gets the photo's lightness
    detail up to SCENE_SHARE of the readable contrast; its strokes stay, its hue stays."""
    ref = _stripes(64, 96, 9.0)
    y, x = np.mgrid[0:64, 0:96].astype(np.float32)
    lines = np.where(((x + 2 * y) % 11.0) < 2.0, 0.05, 0.95).astype(np.float32)
    painted = np.stack([lines, lines, 0.9 * lines], -1)
    l_ref, l_in = _lightness(ref), _lightness(painted)
    need = SCENE_SHARE * 0.5 * l_ref.std()
    assert l_in.std() >= 0.5 * l_ref.std() and scene_contrast(l_in, l_ref) < 0.5 * need  # the case handled
    out = keep_readable([painted, painted], ref, 0.5)
    l_out = _lightness(out[0])
    assert scene_contrast(l_out, l_ref) >= 0.8 * need
    assert np.corrcoef(l_out.ravel(), l_in.ravel())[0, 1] > 0.8  # the strokes are still the frame's
    np.testing.assert_array_equal(out[0], out[1])  # one map for every layer
    assert np.isfinite(out[0]).all() and out[0].min() >= 0.0 and out[0].max() <= 1.0


def test_paint_at_another_size_keeps_the_images_size_and_paints_coarser_when_smaller(prior):
    vec = prior.style_vector(_stripes(64, 64))
    img = _stripes(120, 160, 6.0)
    assert prior.work_size(120, 160, 64) == (48, 64) and prior.work_size(120, 160) == (96, 128)
    small, same = prior.paint([img], vec, size=64)[0], prior.paint([img], vec)[0]
    assert small.shape == same.shape == (120, 160, 3)
    detail = lambda im: float(np.abs(cv2.Laplacian(im.mean(-1), cv2.CV_32F)).mean())  # noqa: E731
    assert detail(small) < detail(same)  # painted at 64 px and upsampled: coarser marks
    for bad in (2, 0, 5000, 64.0, True):
        with pytest.raises(InputError, match="size"):
            prior.paint([img], vec, size=bad)


def test_the_photo_is_painted_as_the_network_paints_it_whatever_the_border():
    # The border (the photo's edges stretched outward) must not change how the photo itself is painted:
    # the network normalises by statistics of the whole image, so the photo region is painted on its own.
    from dataclasses import replace

    from stylize3d_core.models.style_prior import paint_layer_images
    from stylize3d_core.scene.ldi import LDISettings, build_ldi

    prior = StylePrior(StylePriorSettings(size=160, threads=1))
    rgb = _stripes(96, 128, 4.0)
    depth = np.full((96, 128), 2.0, np.float32)
    depth[30:70, 40:90] = 1.0
    ldi = build_ldi(rgb, depth, LDISettings(band=0.2, border=0.25))
    assert ldi.pad > 16
    vec = prior.style_vector(np.random.default_rng(0).random((64, 64, 3)).astype(np.float32))
    layer0, layer1 = paint_layer_images(prior, ldi, vec)
    assert layer0.shape == layer1.shape == ldi.canvas_size + (3,)
    assert all(np.isfinite(x).all() and x.min() >= 0 and x.max() <= 1 for x in (layer0, layer1))
    dark = ldi.rgb.copy()
    outside = np.ones(ldi.canvas_size, bool)
    outside[ldi.photo_region] = False
    dark[outside] = 0.02  # a very different border
    other0, _ = paint_layer_images(prior, replace(ldi, rgb=dark), vec)
    assert np.array_equal(other0[ldi.photo_region], layer0[ldi.photo_region])
    assert not np.allclose(other0[outside], layer0[outside], atol=0.05)
    # the canvas painted whole, as before, paints the photo differently: the border pulls its statistics
    whole = prior.paint([ldi.rgb], vec)[0]
    assert float(np.abs(whole[ldi.photo_region] - layer0[ldi.photo_region]).mean()) > 0.01
    # without a border there is one painting
    flat = build_ldi(rgb, np.full((96, 128), 2.0, np.float32), LDISettings(border=0.0))
    assert flat.pad == 0
    np.testing.assert_array_equal(paint_layer_images(prior, flat, vec)[0], prior.paint([flat.rgb], vec)[0])


def test_without_a_hidden_layer_layer_zero_is_painted_once_for_both(monkeypatch):
    from stylize3d_core.models.style_prior import paint_layer_images
    from stylize3d_core.scene.layer_images import hidden_layer_image
    from stylize3d_core.scene.ldi import LDISettings, build_ldi

    prior = StylePrior(StylePriorSettings(size=128, threads=1))
    flat = build_ldi(_stripes(64, 80, 4.0), np.full((64, 80), 2.0, np.float32), LDISettings(border=0.2))
    assert not flat.hidden_mask.any() and flat.pad > 0
    vec = prior.style_vector(_stripes(48, 48))
    calls = []
    real = StylePrior.paint
    monkeypatch.setattr(StylePrior, "paint", lambda self, images, *a, **k: calls.append(len(images)) or real(self, images, *a, **k))
    layer0, layer1 = paint_layer_images(prior, flat, vec)
    assert calls == [1, 1]  # the canvas and the photo region, one image each
    np.testing.assert_array_equal(layer0, layer1)
    assert not np.shares_memory(layer0, layer1)  # two arrays: one may be changed alone
    # the same as painting the two identical images
    np.testing.assert_array_equal(hidden_layer_image(flat), flat.rgb)
    monkeypatch.undo()
    canvas = prior.paint([flat.rgb, flat.rgb], vec)
    assert np.array_equal(canvas[0], canvas[1])  # the network paints an image the same way each time
