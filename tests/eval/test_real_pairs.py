"""Measures for real pairs: edge F1, style-embedding distance, the disoccluded warp split, blind boards."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from stylize3d_core.depth.types import DepthMap
from stylize3d_core.errors import InputError
from stylize3d_core.eval.consistency import short_range_pairs
from stylize3d_core.eval.quality import view_geometries, warp_rmse
from stylize3d_core.eval.real_pairs import (
    board, decode_verdicts, edge_f1, hidden_views, seam_board, seam_crop, style_embedding_distance, warp_split,
    write_boards,
)
from stylize3d_core.geometry.trajectories import TrajectorySettings, make_trajectory
from stylize3d_core.io.images import load_image
from stylize3d_core.models.style_prior import StylePrior, StylePriorSettings
from stylize3d_core.render.plain import PlainRenderer
from stylize3d_core.scene.photo3d import Photo3D

H, W = 48, 64


def _squares(shift=0):
    img = np.full((60, 80, 3), 0.2, np.float32)
    img[15 + shift:45 + shift, 20:60] = 0.9
    return img


def test_edge_f1_known_values():
    ref = _squares()
    assert edge_f1(ref, ref) == pytest.approx(1.0)
    assert edge_f1(_squares(shift=1), ref) == pytest.approx(1.0)  # within the tolerance
    assert edge_f1(_squares(shift=8), ref) < 0.6
    assert edge_f1(np.full_like(ref, 0.5), ref) == 0.0  # no edges where the reference has some
    assert math.isnan(edge_f1(ref, np.full_like(ref, 0.5)))
    with pytest.raises(InputError):
        edge_f1(ref, ref[:-1])


def test_style_embedding_distance_is_zero_for_the_painting_itself():
    prior = StylePrior(StylePriorSettings(size=128, threads=1))
    painting = _squares()
    vec = prior.style_vector(painting)
    assert style_embedding_distance(painting, vec, prior) == pytest.approx(0.0, abs=1e-5)
    assert style_embedding_distance(np.full_like(painting, 0.5), vec, prior) > 0.1


@pytest.fixture(scope="module")
def photo3d():
    g = np.random.default_rng(0)
    rgb = g.random((H, W, 3), dtype=np.float32)
    depth = np.ones((H, W), np.float32)
    depth[12:36, 16:48] = 0.5
    return Photo3D.build(rgb, DepthMap(depth, np.ones_like(depth, bool), "metric", "test"))


def test_warp_split_over_all_pixels_equals_warp_rmse_and_finds_the_hidden_layer(photo3d):
    cams = make_trajectory(TrajectorySettings(name="swing", n_frames=6, x=0.05, fov_y_deg=photo3d.fov_y_deg))
    frames = {"plain": list(PlainRenderer(photo3d.points).frames(cams, H, W))}
    frames["noisy"] = [np.clip(f + np.random.default_rng(k).normal(0, 0.05, f.shape), 0, 1).astype(np.float32)
                       for k, f in enumerate(frames["plain"])]
    geoms = view_geometries(photo3d.points.xyz, cams, H, W)
    hidden = hidden_views(photo3d, cams, H, W)
    assert hidden[0].dtype == torch.bool and hidden[0].shape == (H, W)
    assert any(h.any() for h in hidden)  # moving sideways reveals the layer behind the box
    assert all(h.float().mean() < 0.3 for h in hidden)
    pairs = short_range_pairs(len(cams))
    split = warp_split(frames, cams, geoms, hidden, pairs)
    ref = warp_rmse(frames, cams, geoms, pairs)
    for m in frames:
        assert split.all[m] == pytest.approx(ref[m], rel=1e-6)
    assert split.all["noisy"] > split.all["plain"]


def test_boards_and_their_key_round_trip(tmp_path):
    photo, painting = _squares(), np.random.default_rng(1).random((30, 50, 3)).astype(np.float32)
    a = np.zeros((40, 60, 3), np.float32)
    b = np.ones((40, 60, 3), np.float32)
    pairs = [{"name": f"p{k}", "photo": photo, "painting": painting, "ours": a, "base": b} for k in range(6)]
    key_path = write_boards(tmp_path / "boards", pairs, ("ours", "base"), seed=3)
    key = json.loads(key_path.read_text())
    assert key_path.parent == tmp_path and len(key["boards"]) == 6
    assert {e["A"] for e in key["boards"]} == {"ours", "base"}  # both orders occur
    for e in key["boards"]:
        img = load_image(tmp_path / "boards" / e["board"]).rgb
        bottom = img[-40:]
        left_is_black = bottom[30:, 30:55].mean() < 0.2  # below the letter's label
        assert left_is_black == (e["A"] == "ours")  # the key says which frame sits on the left
    verdicts = {e["board"]: {"pick": "A" if e["A"] == "ours" else "B", "style": "="} for e in key["boards"]}
    tally = decode_verdicts(key_path, verdicts)
    assert tally["pick"] == {"ours": 6, "base": 0} and tally["style"] == {"ours": 0, "base": 0}
    with pytest.raises(InputError):
        board(photo, painting, a, b[:-1])


def test_seam_crop_finds_the_frame_and_window_with_most_hidden_pixels():
    masks = [np.zeros((60, 90), bool) for _ in range(3)]
    masks[0][5:9, 5:9] = True  # 16 pixels
    masks[2][40:55, 60:80] = True  # 300 pixels, the most
    t, y0, x0 = seam_crop(masks, size=32)
    assert t == 2
    assert y0 <= 40 and y0 + 32 >= 55 and x0 <= 60 and x0 + 32 >= 80  # the window holds all of it
    assert 0 <= y0 <= 60 - 32 and 0 <= x0 <= 90 - 32  # inside the frame
    assert seam_crop([np.zeros((20, 20), bool)]) is None
    assert seam_crop([masks[0]], size=8, min_pixels=17) is None  # 16 hidden pixels are too few
    assert seam_crop([], size=8) is None
    # a crop larger than the frame is as large as its shorter side allows (60 x 60 here)
    t, y0, x0 = seam_crop([masks[2]], size=500)
    assert (t, y0) == (0, 0) and 20 <= x0 <= 30


def test_seam_board_layout_and_order(tmp_path):
    ref = [np.full((10, 12, 3), 0.5, np.float32)] * 2
    dark, light = [np.zeros((10, 12, 3), np.float32)] * 2, [np.ones((10, 12, 3), np.float32)] * 2
    img = seam_board(ref, dark, light, scale=3, gap=4)
    assert img.shape == (2 * 30 + 4, 3 * 36 + 2 * 4, 3)
    row2 = img[34:]  # the second row carries no labels
    assert np.allclose(row2[:, :36], 0.5) and np.allclose(row2[:, 40:76], 0.0) and np.allclose(row2[:, 80:], 1.0)
    with pytest.raises(InputError):
        seam_board(ref, dark[:1], light)
    with pytest.raises(InputError):
        seam_board([], [], [])
    with pytest.raises(InputError):
        seam_board(ref, [np.zeros((9, 12, 3), np.float32)] * 2, light)
    pairs = [{"name": f"p{k}", "plain": ref, "ours": dark, "base": light} for k in range(4)]
    key_path = write_boards(tmp_path / "seams", pairs, ("ours", "base"), seed=5,
                            compose=lambda pair, a, b: seam_board(pair["plain"], pair[a], pair[b], scale=3, gap=4))
    for e in json.loads(key_path.read_text())["boards"]:
        got = load_image(tmp_path / "seams" / e["board"]).rgb
        assert (got[40:, 40:76].mean() < 0.1) == (e["A"] == "ours")
