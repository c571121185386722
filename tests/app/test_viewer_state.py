"""The viewer's state and scheduling rules (app/viewer/state.py): pure functions, no window."""

from __future__ import annotations

from dataclasses import replace

import pytest
import torch

from stylize3d_app.viewer.orbit import HOME, OrbitPose, OrbitScene, cam_to_world
from stylize3d_app.viewer.state import (
    VIEWER_MAX_SIZE, VideoExport, PhotoInfo, Playback, PreviewSettings, ViewState, choose_preview_long_side,
    clamp_state_pose, clamp_trajectory, export_destination, fov_range, full_frame_size, playback_frame,
    preview_cost_model, resolve_open_path, shows_stylized, trajectory_cameras, trajectory_limits, user_choices,
    view_camera, view_fov,
)
from stylize3d_core.errors import InputError
from stylize3d_core.geometry.camera_range import CameraRange
from stylize3d_core.geometry.trajectories import TrajectorySettings, make_trajectory, static
from stylize3d_core.pipeline import PhotoSpec
from stylize3d_core.render.plain import frame_size

SCENE = OrbitScene(centre_depth=0.7)


def test_defaults_are_valid_and_bad_values_refused():
    s = ViewState()
    assert s.pose == HOME and s.stylized and s.strength == 1.0 and s.export == VideoExport()
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
        VideoExport(**kwargs)


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


def test_preview_cost_model_fits_fixed_and_per_pixel_parts():
    # Exact data of t = 0.01 + 2e-6 * side**2 at three sizes (repeated, with one spike at 128 px).
    samples = [(64, 0.01 + 2e-6 * 64 ** 2), (128, 0.01 + 2e-6 * 128 ** 2), (128, 5.0), (128, 0.01 + 2e-6 * 128 ** 2),
               (192, 0.01 + 2e-6 * 192 ** 2)]
    a, b = preview_cost_model(samples)
    assert a == pytest.approx(0.01, abs=1e-9) and b == pytest.approx(2e-6, rel=1e-6)  # medians per size
    a, b = preview_cost_model([(100, 0.05), (100, 0.07), (100, 0.06)])  # one size: all per pixel
    assert a == 0.0 and b == pytest.approx(0.06 / 100 ** 2)
    assert preview_cost_model([]) is None and preview_cost_model([(100, float("nan")), (0, 1.0)]) is None


def test_preview_size_is_chosen_from_the_measured_throughput():
    p = PreviewSettings(target_preview_s=0.04, min_preview_long_side=64, preview_long_side=128,
                        max_preview_long_side=384)
    cost = lambda side: 0.01 + 2e-6 * side ** 2  # noqa: E731  the budget fits sqrt(0.03 / 2e-6) = 122 px
    assert choose_preview_long_side([], 128, p) == 128  # nothing measured: keep
    assert choose_preview_long_side([(128, cost(128))], 128, p) == 128  # predicted 0.043 s: within 10 % over
    # Driven by its own measurements from either side, it settles within a step of 122 px and stays.
    for start in (64, 384):
        side, samples = start, []
        for _ in range(30):
            samples.append((side, cost(side)))
            side = choose_preview_long_side(samples, side, p)
        assert 112 <= side <= 128 and side % 8 == 0
        assert choose_preview_long_side(samples + [(side, cost(side))], side, p) == side
        assert 0.85 * 0.04 <= cost(side) <= 1.1 * 0.04
    # Damped: a single slow frame shrinks by at most 1.5x; a fast one grows by at most 1.25x.
    assert choose_preview_long_side([(240, 1.0)], 240, p) == 160
    assert choose_preview_long_side([(160, 1e-4)], 160, p) == 200
    # The fixed part alone over budget: down to the floor; tiny costs: up to the cap.
    side = 200
    for _ in range(10):
        side = choose_preview_long_side([(64, 0.06), (200, 0.2)], side, p)  # fixed part 0.044 s
    assert side == 64
    assert choose_preview_long_side([(384, 1e-4)], 384, p) == 384
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
    s = ViewState(export=VideoExport(frames=12), trajectory=TrajectorySettings(name="swing"))
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
    from stylize3d_app.viewer.state import wheel_ticks

    assert wheel_ticks(1.0) == 1.0 and wheel_ticks(-2.0) == -2.0
    assert wheel_ticks(1.0, invert=True) == -1.0


def test_export_progress_text_estimates_the_time_left():
    from stylize3d_app.viewer.state import export_progress_text

    assert export_progress_text(0, 90, 0.4) == "Exporting 0/90 frames, 0:00 elapsed"
    assert export_progress_text(10, 90, 20.0) == "Exporting 10/90 frames, 0:20 elapsed, about 2:40 left"
    assert export_progress_text(90, 90, 75.0) == "Exporting 90/90 frames, 1:15 elapsed"


def test_typed_paths_absolute_home_and_relative(tmp_path):
    import os

    from stylize3d_app.viewer.state import resolve_typed_path

    assert resolve_typed_path("/tmp/x.mp4", str(tmp_path)) == "/tmp/x.mp4"
    assert resolve_typed_path("  clips/x.mp4 ", str(tmp_path)) == str(tmp_path / "clips" / "x.mp4")
    assert resolve_typed_path("../y.png", str(tmp_path / "a")) == str(tmp_path / "y.png")
    assert resolve_typed_path("~/z.json", None) == os.path.join(os.path.expanduser("~"), "z.json")
    assert resolve_typed_path("frames/", str(tmp_path)).endswith("/frames/")
    with pytest.raises(InputError, match="file name"):
        resolve_typed_path("   ", None)


def test_recent_files_most_recent_first_without_duplicates():
    from stylize3d_app.viewer.state import push_recent

    r = ()
    for p in ("a.jpg", "b.jpg", "a.jpg", "c.jpg"):
        r = push_recent(r, p, limit=2 if p == "c.jpg" else 8)
    assert r == ("c.jpg", "a.jpg")
    with pytest.raises(InputError):
        ViewState(mix=1.5)


def test_trajectory_limits_follow_the_photos_camera_range():
    scene = OrbitScene(centre_depth=0.7, near_depth=1 / 3)
    full = trajectory_limits(CameraRange(), scene)
    assert full.max_xy == pytest.approx(0.1)  # the range's pan
    assert full.min_forward == pytest.approx(-0.3 * 0.7)
    assert full.max_forward == pytest.approx(min(0.6 * 0.7, 0.5 / 3))  # kept the near margin in front
    small = trajectory_limits(CameraRange().scaled(0.1), scene)  # a photo with a narrow clean range
    assert small.max_xy == pytest.approx(0.02) and small.max_forward == pytest.approx(0.05)  # the defaults stay
    assert small.min_forward == pytest.approx(-0.03 * 0.7)
    t = clamp_trajectory(TrajectorySettings(x=0.09, y=(-0.2, 0.05), z=(-0.5, 0.3)), small)
    assert t.x == pytest.approx(0.02) and t.y == pytest.approx((-0.02, 0.02))
    assert t.z == pytest.approx((-0.021, 0.05))
    assert clamp_trajectory(TrajectorySettings(z=0.3), small).z == pytest.approx((-0.021, 0.05))  # a: (-a, a)
    default = TrajectorySettings()
    assert clamp_trajectory(default, small) == replace(default, x=0.02, y=0.02, z=(0.0, 0.05))  # unchanged


def test_typed_paths_in_open_dialogs_must_name_an_existing_file(tmp_path, monkeypatch):
    (tmp_path / "photos").mkdir()
    photo = tmp_path / "photos" / "cat.jpg"
    photo.write_bytes(b"x")
    monkeypatch.setenv("HOME", str(tmp_path))
    assert resolve_open_path(str(photo), "/elsewhere") == str(photo)  # absolute: as it is
    assert resolve_open_path("cat.jpg", str(tmp_path / "photos")) == str(photo)  # relative to the folder
    assert resolve_open_path("../photos/./cat.jpg ", str(tmp_path / "photos")) == str(photo)
    assert resolve_open_path("~/photos/cat.jpg", None) == str(photo)  # ~ expanded
    with pytest.raises(InputError, match=r"dog\.jpg: no such file"):
        resolve_open_path("dog.jpg", str(tmp_path / "photos"))
    with pytest.raises(InputError, match="is a folder"):
        resolve_open_path(str(tmp_path / "photos") + "/", None)
    with pytest.raises(InputError, match="type a file name"):
        resolve_open_path("   ", None)


def test_status_lines_fit_one_line():
    from stylize3d_app.viewer.panel import LINE_CHAR_EM, fit_line

    em = 16.0
    width = 40 * LINE_CHAR_EM * em  # 40 characters
    assert fit_line("Ready (point cloud encoded in 4.2 s)", width, em) == "Ready (point cloud encoded in 4.2 s)"
    long = "3D photo ready in 12.3 s (depth: depth prior, built-in, narrowed range)"
    cut = fit_line(long, width, em)
    assert len(cut) == 40 and cut.endswith("...") and long.startswith(cut[:-3])
    assert fit_line("two\nlines", width, em) == "two lines"  # a newline would wrap it too
    assert len(fit_line(long, 1.0, em)) == 8  # never less than a few characters


class _CountingLabel:
    """A stand-in for gui.Label that records every attribute write (its text and tooltip)."""

    def __init__(self) -> None:
        self.__dict__.update(text="", tooltip="", writes=[])

    def __setattr__(self, name: str, value) -> None:
        self.writes.append((name, value))
        super().__setattr__(name, value)


def test_status_line_leaves_unchanged_labels_alone():
    from types import SimpleNamespace

    from stylize3d_app.viewer.panel import Panel, fit_line, set_if_changed

    label = _CountingLabel()
    assert set_if_changed(label, "text", "a") and not set_if_changed(label, "text", "a")
    assert label.writes == [("text", "a")]

    panel = SimpleNamespace(WIDTH_EM=Panel.WIDTH_EM, em=16.0)
    label = _CountingLabel()
    Panel.set_line(panel, label, "preview 192px 40ms")
    assert label.text == "preview 192px 40ms" and label.tooltip == ""
    assert label.writes == [("text", "preview 192px 40ms")]  # the tooltip was already empty
    Panel.set_line(panel, label, "preview 192px 40ms")  # the same text again (every frame while dragging)
    assert label.writes == [("text", "preview 192px 40ms")]
    long = "x" * 400
    Panel.set_line(panel, label, long)
    cut = fit_line(long, (Panel.WIDTH_EM - 1.5) * 16.0, 16.0)
    assert label.text == cut != long and label.tooltip == long and len(label.writes) == 3
    Panel.set_line(panel, label, long)
    assert len(label.writes) == 3
    Panel.set_line(panel, label, "short")
    assert label.text == "short" and label.tooltip == "" and len(label.writes) == 5


def test_the_viewer_export_takes_render_job_defaults_and_ranges():
    from stylize3d_core.pipeline import RenderJob

    job, e = RenderJob(), VideoExport()
    assert (e.size, e.frames, e.fps) == (job.size, job.frames, job.fps)
    VideoExport(size=16), VideoExport(size=4096), VideoExport(fps=240.0), VideoExport(frames=job.max_frames)
    for bad in (dict(size=15), dict(size=4097), dict(fps=240.5), dict(frames=job.max_frames + 1)):
        with pytest.raises(InputError):
            VideoExport(**bad)
