import math

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
    path = save_checkpoint(tmp_path_factory.mktemp("m") / "m.safetensors", Stylize3DModel(ModelConfig.lite()), 2, {})
    g = np.random.default_rng(0)
    rgb = g.random((48, 64, 3), dtype=np.float32)
    depth = np.ones((48, 64), np.float32)
    depth[12:36, 16:48] = 0.5
    p = Photo3D.build(rgb, DepthMap(depth, np.ones_like(depth, bool), "metric", "test"))
    return Stylized3DPhoto(p, path, StylizeSettings(strength=1.0, bfloat16=False))  # exact comparisons: float32


def test_render_full_and_preview(stylized):
    cam = Cameras.identity(stylized.photo.fov_y_deg)
    full = stylized.render(cam, 48, 64)
    prev = stylized.render(cam, 24, 32, preview=True)
    assert full.shape == (48, 64, 3) and prev.shape == (24, 32, 3)
    assert np.isfinite(full).all() and full.min() >= 0 and full.max() <= 1


def test_style_and_strength_change_the_frame(stylized):
    cam = Cameras.identity(stylized.photo.fov_y_deg)
    stylized.set_style(None)
    base = stylized.render(cam, 48, 64)
    g = np.random.default_rng(1)
    stylized.set_style(g.random((64, 64, 3), dtype=np.float32))
    styled = stylized.render(cam, 48, 64)
    assert stylized.has_style and not np.allclose(base, styled)
    stylized.set_strength(0.0)
    assert np.allclose(stylized.render(cam, 48, 64), base, atol=1e-6)
    stylized.set_strength(1.0)
    assert np.allclose(stylized.render(cam, 48, 64), styled, atol=1e-6)
    # A constant-colour style (zero variance) stays finite.
    stylized.set_style(np.full((32, 32, 3), 0.3, np.float32))
    assert np.isfinite(stylized.render(cam, 48, 64)).all()


def test_frames_and_bad_input(stylized):
    cams = Cameras.create(np.stack([np.eye(4)] * 2), stylized.photo.fov_y_deg)
    frames = list(stylized.frames(cams, 24, 32))
    assert len(frames) == 2 and np.allclose(frames[0], frames[1])
    with pytest.raises(InputError):
        stylized.set_strength(2.0)
    with pytest.raises(InputError):
        stylized.set_style(np.full((8, 8, 3), np.nan, np.float32))
    with pytest.raises(InputError):
        StylizeSettings(supersample=3)


def test_render_stops_between_stages_when_asked(stylized):
    """``should_stop`` is checked before rasterizing, inside the rasterizer and between the decoder's strips."""
    from dataclasses import replace

    from stylize3d_core.errors import RenderInterrupted

    s = stylized
    cam = Cameras.identity(s.photo.fov_y_deg)
    calls = []

    def stop_after(n):
        def check():
            calls.append(1)
            return len(calls) > n
        return check

    # no border margin: the frame decoded is the 32 x 48 asked for (a convolution run in strips can differ from
    # the whole in the last bit, ~3e-8, by oneDNN's choice of kernel for the size and width)
    before, s.settings = s.settings, replace(s.settings, border_margin=0)
    try:
        with pytest.raises(RenderInterrupted):
            s.render(cam, 32, 48, should_stop=stop_after(0))
        assert len(calls) == 1
        for n in (1, 3):  # stopped inside the rasterizer or the decoder
            calls.clear()
            with pytest.raises(RenderInterrupted):
                s.render(cam, 32, 48, should_stop=stop_after(n))
            assert len(calls) == n + 1
        calls.clear()
        full = s.render(cam, 32, 48, should_stop=lambda: calls.append(1) and False)
        assert len(calls) > 3  # checked at every stage
        np.testing.assert_allclose(full, s.render(cam, 32, 48), rtol=0, atol=1e-6)  # checking changes nothing
        assert not s.model.decoder.out_rgb._forward_pre_hooks
    finally:
        s.settings = before


def test_mixing_two_styles_blends_the_stylizer_outputs(stylized):
    cam = Cameras.identity(stylized.photo.fov_y_deg)
    g = np.random.default_rng(3)
    a, b = g.random((32, 32, 3), dtype=np.float32), np.full((32, 32, 3), 0.9, np.float32)
    stylized.set_strength(1.0)
    stylized.set_style(b)
    only_b = stylized.render(cam, 48, 64)
    stylized.set_style(a)
    only_a = stylized.render(cam, 48, 64)
    stylized.set_second_style(b)
    assert np.allclose(stylized.render(cam, 48, 64), only_a, atol=1e-6)  # mix 0: the first style
    stylized.set_mix(1.0)
    assert np.allclose(stylized.render(cam, 48, 64), only_b, atol=1e-5)  # mix 1: the second
    stylized.set_mix(0.5)
    half = stylized.render(cam, 48, 64)
    assert not np.allclose(half, only_a, atol=1e-3) and not np.allclose(half, only_b, atol=1e-3)
    with pytest.raises(InputError):
        stylized.set_mix(1.5)
    stylized.set_second_style(None)
    assert np.allclose(stylized.render(cam, 48, 64), only_a, atol=1e-6)


def test_render_stops_inside_the_rasterizer_between_chunks(stylized, monkeypatch):
    """With small chunks, a stop that comes while rasterizing is honoured there (not after it),
    and a render that is not stopped is the same frame as the one-shot rasterization's."""
    from stylize3d_core.errors import RenderInterrupted
    from stylize3d_core.render import rasterize

    s = stylized
    cam = Cameras.identity(s.photo.fov_y_deg)
    one_shot = s.render(cam, 32, 48)
    monkeypatch.setattr(rasterize, "CHUNK_POINTS", 256)  # the cloud has ~3500 points: > 10 chunks
    calls = []
    chunked = s.render(cam, 32, 48, should_stop=lambda: calls.append(1) and False)
    assert np.array_equal(chunked, one_shot)
    n_decoder = len(s.model.decoder.skips) + len(s.model.decoder.downs) + len(s.model.decoder.ups) + 2
    assert len(calls) - 1 - n_decoder > 2 * (s.num_points // 256)  # two passes over the chunks, at least
    for n in (2, 5, 9):
        calls.clear()

        def stop():
            calls.append(1)
            return len(calls) > n

        with pytest.raises(RenderInterrupted, match="rasteriz"):
            s.render(cam, 32, 48, should_stop=stop)
        assert len(calls) == n + 1


def test_plain_renderer_stops_between_chunks_and_is_unchanged(stylized, monkeypatch):
    from stylize3d_core.errors import RenderInterrupted
    from stylize3d_core.render import rasterize
    from stylize3d_core.render.plain import PlainRenderer

    plain = PlainRenderer(stylized.photo.points)
    cam = Cameras.identity(stylized.photo.fov_y_deg)
    one_shot = plain.render(cam, 32, 48)
    monkeypatch.setattr(rasterize, "CHUNK_POINTS", 256)
    assert np.array_equal(plain.render(cam, 32, 48, should_stop=lambda: False), one_shot)
    calls = []

    def stop():
        calls.append(1)
        return len(calls) > 4

    with pytest.raises(RenderInterrupted, match="rasteriz"):
        plain.render(cam, 32, 48, should_stop=stop)
    assert len(calls) == 5


def test_plain_renderer_grown_splats_chunked_are_unchanged(stylized, monkeypatch):
    """Magnified (grown splats, soft edges) full frames and previews: chunked == one shot, to the bit."""
    from stylize3d_core.render import rasterize
    from stylize3d_core.render.plain import PlainRenderer

    plain = PlainRenderer(stylized.photo.points)
    assert plain._size is not None  # a PointCloud: splats grow with magnification
    cam = Cameras.identity(stylized.photo.fov_y_deg / 3.0)  # 3x zoom: splats of several tap counts
    for preview in (False, True):
        one_shot = plain.rasterize(cam, 32, 48, preview=preview)
        image = plain.render(cam, 32, 48, preview=preview)
        monkeypatch.setattr(rasterize, "CHUNK_POINTS", 256)
        chunked = plain.rasterize(cam, 32, 48, preview=preview, should_stop=lambda: False)
        for a, b in zip(one_shot, chunked):
            assert torch.equal(a, b)
        assert np.array_equal(plain.render(cam, 32, 48, preview=preview, should_stop=lambda: False), image)
        monkeypatch.undo()


def test_style_features_are_cached_per_encoder(stylized):
    from stylize3d_core.models.style_features import StyleEncoder
    from stylize3d_core.stylize import StyleFeatureCache, style_feature_cache, style_tensor

    encoder = StyleEncoder()
    cache = style_feature_cache(encoder)
    assert style_feature_cache(encoder) is cache and len(cache) == 0
    g = np.random.default_rng(5)
    style = g.random((40, 48, 3), dtype=np.float32)
    cam = Cameras.identity(stylized.photo.fov_y_deg)
    stylized._style_encoder, before = encoder, stylized._style_encoder
    try:
        stylized.set_style(style)
        first = stylized.render(cam, 24, 32)
        assert (cache.misses, cache.hits) == (1, 0)
        stylized.set_style(style.copy())  # same pixels, another array: a hit, the same frame
        assert (cache.misses, cache.hits) == (1, 1)
        np.testing.assert_array_equal(stylized.render(cam, 24, 32), first)
    finally:
        stylized._style_encoder = before
    # the cached maps are the encoder's own
    with torch.inference_mode():
        fresh = encoder(style_tensor(style)).maps
    for m, f in zip(cache.features(style_tensor(style)).maps, fresh):
        torch.testing.assert_close(m, f, rtol=0, atol=0)
    # another style misses; a bfloat16 autocast is another key; the oldest entry goes first
    small = StyleFeatureCache(encoder, size=2)
    t1, t2, t3 = (style_tensor(g.random((32, 32, 3), dtype=np.float32)) for _ in range(3))
    small.features(t1), small.features(t2)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        k_bf16 = StyleFeatureCache.key(t1)
    assert k_bf16 != StyleFeatureCache.key(t1)
    small.features(t3)
    assert len(small) == 2 and small.misses == 3
    small.features(t1)  # evicted: computed again
    assert small.misses == 4
    with pytest.raises(InputError):
        StyleFeatureCache(encoder, size=0)


def test_final_points_per_pixel_keeps_a_prefix(stylized):
    from dataclasses import replace

    cam = Cameras.identity(stylized.photo.fov_y_deg)
    before = stylized.settings
    try:
        full = stylized.render(cam, 12, 16)
        stylized.settings = replace(before, final_points_per_pixel=100.0)  # more than there are: every point
        np.testing.assert_array_equal(stylized.render(cam, 12, 16), full)
        stylized.settings = replace(before, final_points_per_pixel=1.0, preview_points_per_pixel=1.0,
                                    preview_border_margin=before.border_margin)
        subset = stylized.render(cam, 12, 16)
        # the model's view is the same prefix as a preview of the same density (supersample 1); the palette
        # maps differ (a preview's is fitted on its own subset, a full frame's on every point)
        model_view = (lambda preview: stylized._render_model(cam, 12, 16, preview=preview, should_stop=None))
        np.testing.assert_array_equal(model_view(False).numpy(), model_view(True).numpy())
        assert np.isfinite(subset).all() and not np.array_equal(subset, full)
    finally:
        stylized.settings = before
    with pytest.raises(InputError):
        StylizeSettings(final_points_per_pixel=0.1)


def test_detail_transfer_moves_the_frame_to_the_style_colours(stylized):
    """A new lite model starts at the identity colour transform: a stylized frame shows the points' colours
    moved to the style's L*a*b* statistics, scaled by the strength."""
    from stylize3d_core.models.colour_transfer import lab_stats

    assert stylized.model.config.detail_transfer and stylized.model.config.decoder.transform_channels == 3
    cam = Cameras.identity(stylized.photo.fov_y_deg)
    g = np.random.default_rng(5)
    style = (np.array([0.8, 0.25, 0.1], np.float32) + 0.05 * g.standard_normal((40, 40, 3))).clip(0, 1)
    target = lab_stats(style).mean
    stylized.set_style(None)
    base = lab_stats(stylized.render(cam, 48, 64)).mean
    stylized.set_style(style.astype(np.float32))
    try:
        far = np.linalg.norm(base - target)
        stylized.set_strength(1.0)
        full = np.linalg.norm(lab_stats(stylized.render(cam, 48, 64)).mean - target)
        stylized.set_strength(0.5)
        half = np.linalg.norm(lab_stats(stylized.render(cam, 48, 64)).mean - target)
    finally:
        stylized.set_strength(1.0)
    assert full < 0.25 * far and full < half < far  # not all the way: saturated reds out of gamut lose chroma


def test_palette_map_is_one_colour_matrix_for_every_view(stylized):
    from stylize3d_core.models.checkpoint import Checkpoint
    from stylize3d_core.models.palette import apply_palette

    p = stylized.photo
    g = np.random.default_rng(5)
    style = np.kron(g.random((4, 4, 3)), np.ones((8, 8, 1))).astype(np.float32) * 0.6
    checkpoint = Checkpoint(stylized.model, 2, {})
    on = Stylized3DPhoto(p, checkpoint, StylizeSettings(strength=1.0))
    off = Stylized3DPhoto(p, checkpoint, StylizeSettings(strength=1.0, match_palette=False))
    for s in (on, off):
        s.set_style(style)
    moved = np.eye(4)
    moved[0, 3] = 0.05
    cams = Cameras.create(np.stack([np.eye(4), moved]), p.fov_y_deg)
    a0, a1 = on.render(cams[0], 48, 64), on.render(cams[1], 48, 64)
    pal = on.palette
    assert pal is not None and off.palette is None
    b0, b1 = off.render(cams[0], 48, 64), off.render(cams[1], 48, 64)
    assert on.palette is pal  # fitted once, used for every view
    for a, b in ((a0, b0), (a1, b1)):
        want = apply_palette(torch.from_numpy(b).permute(2, 0, 1), pal.matrix).permute(1, 2, 0).numpy()
        assert np.abs(a - want).max() < 1e-5
    assert np.abs(a0 - b0).max() > 0.01  # it did recolour
    on.set_strength(0.5)
    on.render(cams[0], 24, 32, preview=True)
    assert on.palette is not None and not np.array_equal(on.palette.matrix, pal.matrix)  # refitted
    on.set_strength(0.0)
    off.set_strength(0.0)
    assert np.array_equal(on.render(cams[0], 48, 64), off.render(cams[0], 48, 64))  # strength 0: no palette
    assert on.palette is None
    with pytest.raises(InputError):
        StylizeSettings(match_palette="yes")


def test_previews_fit_their_palette_map_on_their_own_point_subset(stylized):
    """A preview's map is fitted on the preview render itself (its point subset), a full frame's on every
    point: both kept per size, and a preview of the own view has the statistics its map reached."""
    from stylize3d_core.geometry.camera import Cameras as Cams
    from stylize3d_core.models.checkpoint import Checkpoint
    from stylize3d_core.models.palette import _stats, _to_lab

    p = stylized.photo
    g = np.random.default_rng(8)
    on = Stylized3DPhoto(p, Checkpoint(stylized.model, 2, {}),
                         StylizeSettings(strength=1.0, preview_points_per_pixel=0.5))
    on.set_style(g.random((16, 16, 3)).astype(np.float32))
    own = Cams.identity(p.fov_y_deg)
    prev = on.render(own, 48, 64, preview=True)
    pal_prev = on.palette
    on.render(own, 48, 64)
    pal_full = on.palette
    assert {k[:3] for k in on._palettes} == {(48, 64, True), (48, 64, False)} and pal_prev is not pal_full
    assert not np.array_equal(pal_prev.matrix, pal_full.matrix)  # another point set, another fit
    got = _stats(_to_lab(prev.reshape(-1, 3)))  # the preview is the render the map was fitted on
    assert np.abs(np.asarray(got.mean) - np.asarray(pal_prev.after.mean)).max() < 0.5
    on.render(own, 48, 64, preview=True)
    assert on.palette is pal_prev  # cached
    from dataclasses import replace

    on.settings = replace(on.settings, preview_points_per_pixel=2.0)  # another subset: fitted again
    on.render(own, 48, 64, preview=True)
    assert on.palette is not pal_prev and len(on._palettes) == 3


def test_palette_map_is_fitted_per_render_size(stylized):
    """The model's colours depend on the render size, so each size gets its own map, fitted on the own view
    at that size, and reused for every view of that size."""
    from stylize3d_core.geometry.camera import Cameras as Cams
    from stylize3d_core.models.checkpoint import Checkpoint
    from stylize3d_core.models.palette import _stats, _to_lab

    p = stylized.photo
    g = np.random.default_rng(6)
    style = np.kron(g.random((4, 4, 3)), np.ones((8, 8, 1))).astype(np.float32) * 0.6
    on = Stylized3DPhoto(p, Checkpoint(stylized.model, 2, {}), StylizeSettings(strength=1.0))
    on.set_style(style)
    own = Cams.identity(p.fov_y_deg)
    small, big = on.render(own, 24, 32, preview=True), on.render(own, 60, 80)
    pal_big = on.palette
    on.render(own, 24, 32)
    pal_small = on.palette
    assert pal_small is not pal_big and not np.array_equal(pal_small.matrix, pal_big.matrix)
    on.render(own, 60, 80)
    assert on.palette is pal_big  # cached per size
    # each size's own view reaches the aimed-at statistics (what the map was fitted for)
    for img, pal in ((small, pal_small), (big, pal_big)):
        got = _stats(_to_lab(img.reshape(-1, 3)))
        assert np.abs(np.asarray(got.mean) - np.asarray(pal.target.mean)).max() < 1.5
    on.set_strength(0.5)  # a new target: every size is fitted again
    on.render(own, 60, 80)
    assert on.palette is not pal_big


def test_bfloat16_decoding_setting(stylized):
    from dataclasses import replace

    # A camera moved far enough to see past the canvas: the untrained decoder's covered pixels are the
    # detail colours exactly (its colour transform is the identity), its U-Net shows in the holes only.
    pose = np.eye(4, dtype=np.float32)
    pose[0, 3] = 0.5
    cam = Cameras.create(pose[None], stylized.photo.fov_y_deg)
    before = stylized.settings
    try:
        stylized.settings = replace(before, bfloat16=False)
        ref = stylized.render(cam, 48, 64)
        stylized.settings = replace(before, bfloat16=True)
        assert stylized.settings.decode_bfloat16
        out = stylized.render(cam, 48, 64)
    finally:
        stylized.settings = before
    assert out.dtype == np.float32 and np.isfinite(out).all()
    mse = float(np.mean((out.astype(np.float64) - ref) ** 2))
    assert 0 < mse and 10 * np.log10(1 / mse) > 40  # the same frame up to bfloat16 rounding
    with pytest.raises(InputError, match="bfloat16"):
        StylizeSettings(bfloat16="yes")


def test_decoder_runtime_setting(stylized):
    """ONNX Runtime (the default for large frames where it imports) and torch give the same frames and previews."""
    from dataclasses import replace

    from stylize3d_core.models.decoder_onnx import AUTO_PIXELS_PER_THREAD, onnx_threads
    from stylize3d_core.threads import torch_threads

    cam = Cameras.identity(stylized.photo.fov_y_deg)
    moved = Cameras.create(np.array([[1, 0, 0, 0.05], [0, 1, 0, 0.02], [0, 0, 1, 0], [0, 0, 0, 1]], np.float32)[None],
                           stylized.photo.fov_y_deg)
    before = stylized.settings
    assert before.decoder_runtime == "auto" and before.decode_onnx()
    with torch_threads(2):
        with onnx_threads(1):  # auto: ONNX Runtime for large frames only
            assert before.decode_onnx(AUTO_PIXELS_PER_THREAD) and not before.decode_onnx(AUTO_PIXELS_PER_THREAD - 1)
        with onnx_threads(2):
            assert not before.decode_onnx(AUTO_PIXELS_PER_THREAD) and before.decode_onnx(2 * AUTO_PIXELS_PER_THREAD)
    with torch_threads(1), onnx_threads(2):  # more threads than torch's: ONNX Runtime at any size
        assert before.decode_onnx(1)
    assert not replace(before, decoder_runtime="torch").decode_onnx()
    assert replace(before, decoder_runtime="onnxruntime").decode_onnx(1)
    out = {}
    try:
        for runtime in ("torch", "onnxruntime"):
            stylized.settings = replace(before, decoder_runtime=runtime)
            assert stylized.settings.decode_onnx(48 * 64) == (runtime == "onnxruntime")
            out[runtime] = [stylized.render(c, 48, 64, preview=p) for c in (cam, moved) for p in (False, True)]
        stylized.settings = replace(before, decoder_runtime="onnxruntime", bfloat16=True)
        assert not stylized.settings.decode_onnx()  # bfloat16 decoding is torch's
    finally:
        stylized.settings = before
    for a, b in zip(out["torch"], out["onnxruntime"]):
        assert np.abs(a - b).max() <= 2e-5
    with pytest.raises(InputError, match="decoder_runtime"):
        StylizeSettings(decoder_runtime="tensorrt")


def test_onnx_threads_context():
    from stylize3d_core.models.decoder_onnx import _LOCAL, onnx_threads

    assert getattr(_LOCAL, "threads", None) is None
    with onnx_threads(2):
        assert _LOCAL.threads == 2
        with onnx_threads(None):
            assert _LOCAL.threads is None
        assert _LOCAL.threads == 2
    assert _LOCAL.threads is None
    for bad in (0, -1, 1.5, True):
        with pytest.raises(InputError):
            with onnx_threads(bad):
                pass


def test_border_margin_rounds_to_the_decoder_stride_and_respects_the_fov_limit():
    from stylize3d_core.geometry.camera import MAX_FOV_DEG
    from stylize3d_core.stylize import _with_margin

    cam = Cameras.identity(60.0)
    same, m = _with_margin(cam, 100, 0, 4)
    assert same is cam and m == 0
    wide, m = _with_margin(cam, 100, 6, 4)
    assert m == 8
    # the same focal length: tan(fov/2) grows by (H + 2m) / H
    ratio = math.tan(math.radians(float(wide.fov_y_deg[0])) / 2) / math.tan(math.radians(30.0))
    assert ratio == pytest.approx(116 / 100)
    assert torch.equal(wide.cam_to_world, cam.cam_to_world)
    _, m = _with_margin(Cameras.identity(MAX_FOV_DEG - 0.5), 100, 8, 4)
    assert m == 0  # no margin fits under the FOV limit
    with pytest.raises(InputError):
        StylizeSettings(border_margin=-1)
    with pytest.raises(InputError):
        StylizeSettings(preview_border_margin=True)


def test_border_margin_decodes_the_frame_edge_as_its_inside():
    """The U-Net's zero padding can change a frame's outermost pixels (a coloured rim); with the margin a
    frame's edge matches the same pixels decoded inside a larger frame (the reference: a frame 16 pixels
    wider on each side), and is never further from it than without the margin."""
    from stylize3d_core.io.images import load_image
    from stylize3d_core.pipeline import PhotoSpec, load_photo3d
    from stylize3d_core.resources import resolve_model, sample_photo, style_image
    from stylize3d_core.stylize import _with_margin

    p3d = load_photo3d(PhotoSpec(photo=str(sample_photo()), depth="prior", max_size=192))
    st = Stylized3DPhoto(p3d, resolve_model("lite"), StylizeSettings(border_margin=0, match_palette=False,
                                                                      bfloat16=False))
    st.set_style(load_image(str(style_image()), max_size=128).rgb)
    cam = Cameras.identity(p3d.fov_y_deg)
    h, w = 64, 96
    wide, m = _with_margin(cam, h, 16, 4)
    ref = st.render(wide, h + 2 * m, w + 2 * m)[m:-m, m:-m]
    plain = st.render(cam, h, w)
    st.settings = StylizeSettings(border_margin=8, match_palette=False, bfloat16=False)
    guarded = st.render(cam, h, w)
    rim = np.ones((h, w), bool)
    rim[3:-3, 3:-3] = False
    err_plain = float(np.abs(plain - ref)[rim].mean())
    err_guarded = float(np.abs(guarded - ref)[rim].mean())
    print(f"edge error against the inside decoding: {255 * err_plain:.2f} levels without the margin, "
          f"{255 * err_guarded:.2f} with it")
    assert err_guarded < 1 / 255 and err_guarded <= err_plain + 1e-6


def test_a_model_that_makes_non_finite_features_is_refused_once(tmp_path):
    """The renderer checks the dense features once when they are made (the rasterizer is told they are
    finite, frame after frame): weights far too large, finite themselves, are refused there, naming the
    checkpoint."""
    torch.manual_seed(0)
    model = Stylize3DModel(ModelConfig.lite())
    with torch.no_grad():
        for p in model.encoder.parameters():
            p.mul_(1e15)
    path = save_checkpoint(tmp_path / "huge.safetensors", model, 2, {})
    g = np.random.default_rng(1)
    rgb = g.random((24, 32, 3), dtype=np.float32)
    depth = np.ones((24, 32), np.float32)
    photo = Photo3D.build(rgb, DepthMap(depth, np.ones_like(depth, bool), "metric", "test"))
    st = Stylized3DPhoto(photo, path, StylizeSettings(bfloat16=False))
    with pytest.raises(InputError, match="NaN or infinite features"):
        st.render(Cameras.identity(photo.fov_y_deg), 24, 32)


def test_point_order_made_while_the_geometry_waits_gives_the_same_frames(stylized, monkeypatch, tmp_path):
    """Stylized3DPhoto builds the point order and the colour transfer's colours while the geometry waits for
    the FPS worker (made slow here so that the wait comes): the same frames as when no wait came."""
    import time

    import stylize3d_core.models.scene_geometry as sg

    path = save_checkpoint(tmp_path / "m.safetensors", Stylize3DModel(ModelConfig.lite()), 2, {})
    settings = StylizeSettings(strength=1.0, bfloat16=False)
    import stylize3d_core.stylize as stylize_module

    real_prepare = stylize_module.prepare_geometry
    with monkeypatch.context() as m:  # no wait: the order after the geometry, the transfer when first asked
        m.setattr(stylize_module, "prepare_geometry", lambda *a, while_waiting=None, **k: real_prepare(*a, **k))
        plain = Stylized3DPhoto(stylized.photo, path, settings)
    real = sg._fps_level
    monkeypatch.setattr(sg, "_fps_level", lambda *a: (time.sleep(0.2), real(*a))[1])
    waited = Stylized3DPhoto(stylized.photo, path, settings)
    assert plain._transfer is None  # no wait came: made when first asked, as before
    assert (waited._transfer is not None) == waited.model.config.detail_transfer
    assert torch.equal(plain._order, waited._order) and torch.equal(plain._xyz, waited._xyz)
    style = np.random.default_rng(3).random((32, 32, 3), dtype=np.float32)
    cam = Cameras.identity(stylized.photo.fov_y_deg)
    plain.set_style(style)
    waited.set_style(style)
    assert np.array_equal(plain.render(cam, 48, 64), waited.render(cam, 48, 64))
