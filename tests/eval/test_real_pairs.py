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
    board, decode_verdicts, edge_f1, hidden_views, style_embedding_distance, warp_split, write_boards,
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
