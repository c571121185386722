"""Tests of the per-view 2D baseline (plain 3D photo rendered, each frame stylized on its own)."""

from __future__ import annotations

import numpy as np
import pytest
from skimage import data as skdata

from stylize3d_core.depth.types import DepthMap
from stylize3d_core.errors import InputError
from stylize3d_core.eval.baseline import baseline_frames, make_engine, stylize_frames_2d
from stylize3d_core.eval.consistency import consistency_metrics
from stylize3d_core.geometry.trajectories import circle, ken_burns
from stylize3d_core.render.plain import PlainRenderer
from stylize3d_core.scene.photo3d import Photo3D

S = 128


@pytest.fixture(scope="module")
def photo():
    rgb = skdata.astronaut()[::4, ::4].astype(np.float32) / 255.0  # (128, 128, 3)
    yy = np.linspace(0, 1, rgb.shape[0], dtype=np.float32)[:, None]
    depth = np.broadcast_to(1.0 + yy, rgb.shape[:2]).astype(np.float32).copy()  # a tilted floor-like plane
    return Photo3D.build(rgb, DepthMap(depth, np.ones_like(depth, bool), "metric", "test"))


@pytest.fixture(scope="module")
def style():
    return skdata.coffee()[::4, ::4].astype(np.float32) / 255.0


@pytest.fixture(scope="module")
def engine():
    return make_engine()


def test_baseline_frames_are_stylized_plain_frames(photo, style, engine):
    cams = circle(2)
    frames = baseline_frames(photo, cams, S, S, style, engine=engine)
    plain = list(PlainRenderer(photo.points).frames(cams, S, S))
    assert len(frames) == 2
    for f, p in zip(frames, plain):
        assert f.shape == (S, S, 3) and f.dtype == np.float32 and np.isfinite(f).all()
        assert f.min() >= 0 and f.max() <= 1
        assert np.abs(f - p).mean() > 0.05  # the 2D network changed the frame
    # Other sizes and aspect ratios come back at the frame size.
    wide = baseline_frames(photo, cams[:1], 64, 96, style, engine=engine)
    assert wide[0].shape == (64, 96, 3)


def test_baseline_is_less_consistent_than_the_plain_frames(photo, style, engine):
    cams = ken_burns(2)
    plain = list(PlainRenderer(photo.points).frames(cams, S, S))
    styled = baseline_frames(photo, cams, S, S, style, engine=engine)
    ours = consistency_metrics(photo.points.xyz, plain, cams, [(0, 1)])
    base = consistency_metrics(photo.points.xyz, styled, cams, [(0, 1)])
    assert base.n_covisible == ours.n_covisible
    assert base.rmse > 1.3 * ours.rmse and base.feature_distance > 2 * ours.feature_distance


def test_stylize_frames_2d_inputs_are_checked(style, engine):
    frame = np.full((40, 40, 3), 0.5, np.float32)
    before = frame.copy()
    out = stylize_frames_2d([frame], style, engine=engine)
    assert out[0].shape == (40, 40, 3) and np.array_equal(frame, before)
    with pytest.raises(InputError):
        stylize_frames_2d([np.zeros((16, 40, 3), np.float32)], style, engine=engine)
    with pytest.raises(InputError):
        stylize_frames_2d([np.full((40, 40, 3), np.nan, np.float32)], style, engine=engine)
    with pytest.raises(InputError):
        stylize_frames_2d([(frame * 255).astype(np.uint8)], style, engine=engine)
    with pytest.raises(InputError):
        stylize_frames_2d([frame], style[:10], engine=engine)
    with pytest.raises(InputError):
        stylize_frames_2d([frame], style, strength=1.5, engine=engine)


def test_baseline_frames_bad_inputs(photo, style):
    with pytest.raises(InputError):
        baseline_frames(photo.points, circle(2), S, S, style)
    with pytest.raises(InputError):
        baseline_frames(photo, "circle", S, S, style)
    with pytest.raises(InputError):
        baseline_frames(photo, circle(2), 16, S, style)
