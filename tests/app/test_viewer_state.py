"""The viewer's state and scheduling rules (app/viewer/state.py): pure functions, no window."""

from __future__ import annotations

from dataclasses import replace

import pytest
import torch

from app.viewer.orbit import HOME, OrbitPose, OrbitScene, cam_to_world
from app.viewer.state import (
    VIEWER_MAX_SIZE, ExportSettings, PhotoInfo, Playback, PreviewSettings, ViewState,
    adapt_preview_long_side, clamp_state_pose, export_destination, fov_range, full_frame_size, playback_frame,
    shows_stylized, trajectory_cameras, user_choices, view_camera, view_fov,
)
from stylize3d_core.errors import InputError
from stylize3d_core.geometry.trajectories import TrajectorySettings, make_trajectory, static
from stylize3d_core.pipeline import PhotoSpec
from stylize3d_core.render.plain import frame_size

SCENE = OrbitScene(centre_depth=0.7)


def test_defaults_are_valid_and_bad_values_refused():
    s = ViewState()
    assert s.pose == HOME and s.stylized and s.strength == 0.8 and s.export == ExportSettings()
    with pytest.raises(InputError, match="strength"):
        ViewState(strength=1.5)
    with pytest.raises(InputError, match="trajectory"):
        ViewState(trajectory=TrajectorySettings(name="spiral"))
    with pytest.raises(InputError, match="view fov"):
        ViewState(view_fov=0.0)
    assert s.spec.refine_depth is None
    assert ViewState(spec=PhotoSpec(refine_depth="guided")).spec.refine_depth == "guided"
    with pytest.raises(InputError, match="refine_depth"):
        ViewState(spec=replace(s.spec, refine_depth="median"))
    assert s.spec.max_size == VIEWER_MAX_SIZE and s.spec.photo is None
    with pytest.raises(InputError, match="spec"):
        ViewState(spec="photo.jpg")


@pytest.mark.parametrize("kwargs, match", [
    (dict(format="avi"), "export format"), (dict(size=8), "export size"), (dict(size=512.5), "export size"),
    (dict(frames=0), "export frames"), (dict(fps=0.0), "export fps"), (dict(format="gif", fps=60.0), "export fps"),
])
def test_bad_export_settings(kwargs, match):
    with pytest.raises(InputError, match=match):
        ExportSettings(**kwargs)


def test_view_camera_and_fov():
    s = ViewState()
    cam = view_camera(s, SCENE, 50.0)
    torch.testing.assert_close(cam.cam_to_world[0], torch.eye(4, dtype=torch.float64))
    assert float(cam.fov_y_deg[0]) == 50.0 and view_fov(s, 50.0) == 50.0
    s = replace(s, view_fov=40.0, pose=OrbitPose(yaw_deg=3.0))
    cam = view_camera(s, SCENE, 50.0)
    assert float(cam.fov_y_deg[0]) == 40.0
    torch.testing.assert_close(cam.cam_to_world[0], torch.from_numpy(cam_to_world(s.pose, SCENE)))
    assert fov_range(60.0) == (30.0, 90.0)
    assert fov_range(100.0) == (50.0, 120.0)


def test_sizes():
    assert frame_size((300, 451), 256) == (170, 256)
    assert frame_size((451, 300), 256) == (256, 170)
    # Fits the view, keeps the aspect, capped, even.
    assert full_frame_size((300, 450), (500, 700), 768) == (466, 700)  # width-limited, under the cap
    assert full_frame_size((300, 450), (2000, 3000), 768) == (512, 768)
    assert full_frame_size((400, 300), (500, 1000), 768) == (500, 376)  # height-limited
    h, w = full_frame_size((123, 457), (333, 777), 768)
    assert h % 2 == 0 and w % 2 == 0 and w <= 777 and h <= 333
    with pytest.raises(InputError):
        frame_size((0, 10), 64)


def test_preview_size_adapts_to_the_time_budget():
    p = PreviewSettings(target_preview_s=0.1, max_preview_long_side=384)
    assert adapt_preview_long_side(256, 0.1, p) == 256  # on target: keep
    assert adapt_preview_long_side(256, 0.11, p) == 256  # within 20 %: keep (no flicker)
    smaller = adapt_preview_long_side(256, 0.4, p)
    assert smaller < 256 and smaller % 16 == 0 and smaller >= 256 / 1.5 - 16
    larger = adapt_preview_long_side(256, 0.02, p)
    assert 256 < larger <= 256 * 1.25 + 16 and larger % 16 == 0
    assert adapt_preview_long_side(p.min_preview_long_side, 5.0, p) == p.min_preview_long_side
    assert adapt_preview_long_side(p.max_preview_long_side, 0.001, p) == p.max_preview_long_side
    assert adapt_preview_long_side(256, float("nan"), p) == 256
    # Repeated slow frames converge to the floor, fast ones to the cap.
    side = 256
    for _ in range(20):
        side = adapt_preview_long_side(side, 1.0, p)
    assert side == p.min_preview_long_side
    with pytest.raises(InputError):
        PreviewSettings(preview_long_side=50, min_preview_long_side=96)


def test_export_destination():
    assert export_destination("out.mp4", "mp4") == "out.mp4"
    assert export_destination("out", "mp4") == "out.mp4"
    assert export_destination("out.gif", "mp4") == "out.mp4"
    assert export_destination("clip.MP4", "mp4") == "clip.MP4"
    assert export_destination("a/b.mp4", "gif") == "a/b.gif"
    assert export_destination("frames", "png") == "frames/"
    assert export_destination("frames/", "png") == "frames/"
    assert export_destination("frames.png", "png") == "frames/"
    with pytest.raises(InputError):
        export_destination("x", "avi")


def test_trajectory_cameras_follow_the_view():
    s = ViewState(export=ExportSettings(frames=12), trajectory=TrajectorySettings(name="swing"))
    cams = trajectory_cameras(s, SCENE, 50.0)
    ref = make_trajectory(TrajectorySettings(name="swing", n_frames=12, fov_y_deg=50.0))
    torch.testing.assert_close(cams.cam_to_world, ref.cam_to_world)
    assert len(cams) == 12 and torch.all(cams.fov_y_deg == 50.0)
    moved = trajectory_cameras(replace(s, pose=OrbitPose(yaw_deg=4.0), view_fov=45.0), SCENE, 50.0)
    assert torch.all(moved.fov_y_deg == 45.0)
    assert not torch.allclose(moved.cam_to_world, cams.cam_to_world)
    loaded = static(5, fov_y_deg=30.0)
    assert trajectory_cameras(replace(s, use_loaded_path=True), SCENE, 50.0, loaded) is loaded
    with pytest.raises(InputError, match="no camera path"):
        trajectory_cameras(replace(s, use_loaded_path=True), SCENE, 50.0)


def test_clamp_state_pose():
    s = ViewState(pose=OrbitPose(yaw_deg=90.0))
    assert clamp_state_pose(s, SCENE).pose.yaw_deg == 8.0


def test_one_rule_says_whether_the_stylized_view_is_shown():
    info = PhotoInfo("p.jpg", (30, 40), 1200, 60.0, "prior", SCENE, 0.1)
    s = ViewState()
    assert not shows_stylized(s)  # no photo
    s = replace(s, photo_info=info)
    assert not shows_stylized(s)  # the model is not ready (or there is none)
    s = replace(s, stylize_available=True)
    assert shows_stylized(s)
    assert not shows_stylized(replace(s, stylized=False))  # the user asked for the original
    assert not shows_stylized(replace(s, photo_info=None))


def test_playback_plays_each_camera_at_its_time_then_ends():
    cams = static(5)
    pb = Playback(cams, start=100.0, fps=10.0)
    assert pb.index == -1
    assert [playback_frame(pb, 100.0 + t) for t in (0.0, 0.05, 0.11, 0.25, 0.49)] == [0, 0, 1, 2, 4]
    assert playback_frame(pb, 100.51) is None and playback_frame(pb, 200.0) is None
    assert playback_frame(pb, 99.0) == 0  # a clock read just before the start shows the first camera
    with pytest.raises(InputError, match="playback fps"):
        Playback(cams, 0.0, 0.0)


def test_user_choices_leave_out_what_was_loaded():
    info = PhotoInfo("p.jpg", (30, 40), 1200, 60.0, "prior", SCENE, 0.1)
    s = ViewState(photo_info=info, stylize_available=True, playback=Playback(static(2), 0.0, 30.0))
    c = user_choices(s)
    assert c.photo_info is None and c.playback is None and c.loaded_path is None
    assert c.stylize_available and c.spec == s.spec and c.pose == s.pose


def test_wheel_up_moves_forwards_unless_inverted():
    from app.viewer.state import wheel_ticks

    assert wheel_ticks(1.0) == 1.0 and wheel_ticks(-2.0) == -2.0
    assert wheel_ticks(1.0, invert=True) == -1.0


def test_export_progress_text_estimates_the_time_left():
    from app.viewer.state import export_progress_text

    assert export_progress_text(0, 90, 0.4) == "Exporting 0/90 frames, 0:00 elapsed"
    assert export_progress_text(10, 90, 20.0) == "Exporting 10/90 frames, 0:20 elapsed, about 2:40 left"
    assert export_progress_text(90, 90, 75.0) == "Exporting 90/90 frames, 1:15 elapsed"


def test_typed_paths_absolute_home_and_relative(tmp_path):
    import os

    from app.viewer.state import resolve_typed_path

    assert resolve_typed_path("/tmp/x.mp4", str(tmp_path)) == "/tmp/x.mp4"
    assert resolve_typed_path("  clips/x.mp4 ", str(tmp_path)) == str(tmp_path / "clips" / "x.mp4")
    assert resolve_typed_path("../y.png", str(tmp_path / "a")) == str(tmp_path / "y.png")
    assert resolve_typed_path("~/z.json", None) == os.path.join(os.path.expanduser("~"), "z.json")
    assert resolve_typed_path("frames/", str(tmp_path)).endswith("/frames/")
    with pytest.raises(InputError, match="file name"):
        resolve_typed_path("   ", None)


def test_recent_files_most_recent_first_without_duplicates():
    from app.viewer.state import push_recent

    r = ()
    for p in ("a.jpg", "b.jpg", "a.jpg", "c.jpg"):
        r = push_recent(r, p, limit=2 if p == "c.jpg" else 8)
    assert r == ("c.jpg", "a.jpg")
    with pytest.raises(InputError):
        ViewState(mix=1.5)
