"""The viewer's compute side without a window (app/viewer/session.py).

These are the exact calls the window makes on its worker thread: render the
view (plain or through the model), re-style, change the strength, export, and
hand the frame to Open3D as an ``o3d.geometry.Image``.
"""

from __future__ import annotations

import os

import numpy as np
import open3d as o3d
import pytest

import stylize3d_app.viewer.session as session_mod
from stylize3d_app.viewer.orbit import HOME, OrbitPose, pose_camera
from stylize3d_app.viewer.session import (
    NO_MODEL, SAMPLE_PHOTO, SAMPLE_STYLE, ExportJob, ViewerSession, colour_jump, display_image,
)
from stylize3d_core.render.plain import frame_size
from stylize3d_core.errors import InputError
from stylize3d_core.pipeline import PhotoSpec
from stylize3d_core.geometry.trajectories import circle
from stylize3d_core.io.video import ExportCancelled
from stylize3d_core.render.plain import PREVIEW_MIN_POINTS, preview_point_count

MAX_SIZE = 160


@pytest.fixture(scope="module")
def plain() -> ViewerSession:
    s = ViewerSession(model=None)
    s.load_photo(PhotoSpec(str(SAMPLE_PHOTO), "prior", max_size=MAX_SIZE))
    return s


def render(s: ViewerSession, pose=HOME, side=128, preview=False, stylized=False) -> np.ndarray:
    cam = pose_camera(pose, s.info.scene, s.info.fov_y_deg)
    H, W = frame_size(s.info.size, side)
    return s.render(cam, H, W, preview=preview, stylized=stylized)


def test_plain_view_is_the_photo_and_orbit_shows_parallax(plain):
    info = plain.info
    assert max(info.size) == MAX_SIZE and info.n_points > info.size[0] * info.size[1]
    assert 0 < info.scene.near_depth <= info.scene.centre_depth
    img = render(plain)
    hw = frame_size(info.size, 128)
    assert img.shape == (*hw, 3) and img.dtype == np.float32
    assert np.isfinite(img).all() and img.min() >= 0 and img.max() <= 1 and img.std() > 0.05
    # Seen from the photo's own camera, the view is the photo (resized).
    photo = display_image(plain.photo.rgb, hw).astype(np.float32) / 255
    assert np.abs(img - photo).mean() < 0.05
    moved = render(plain, OrbitPose(yaw_deg=6.0))
    assert np.abs(moved - img).mean() > 0.02


def test_refined_depth_rebuilds_the_photo_with_aligned_edges(plain):
    s = ViewerSession(model=None)
    s.load_photo(PhotoSpec(str(SAMPLE_PHOTO), "prior", max_size=MAX_SIZE, refine_depth="bilateral_median"))
    assert s.info.size == plain.info.size
    assert "prior" in s.photo.depth.source
    refined, raw = s.photo.depth.depth, plain.photo.depth.depth
    assert refined.shape == raw.shape and np.isfinite(refined).all()
    assert not np.allclose(refined, raw)  # the edges moved
    with pytest.raises(InputError, match="refine_depth"):  # the spec refuses it before any work
        s.load_photo(PhotoSpec(str(SAMPLE_PHOTO), "prior", max_size=MAX_SIZE, refine_depth="median"))
    assert s.photo.depth.depth is refined  # the failed load kept the refined photo


def test_preview_renders_a_point_subset(plain):
    assert preview_point_count(10**6, 100, 100, 2.0) == 20000  # 2 points per output pixel
    assert preview_point_count(10**6, 10, 10, 2.0) == PREVIEW_MIN_POINTS
    assert preview_point_count(1000, 100, 100, 2.0) == 1000
    full = render(plain, side=96)
    prev = render(plain, side=96, preview=True)
    assert prev.shape == full.shape and np.isfinite(prev).all()
    assert np.abs(prev - full).mean() < 0.05  # holes of the subset are filled


def test_no_model_shows_the_plain_photo(monkeypatch, plain, tmp_path):
    monkeypatch.setattr(session_mod, "DEFAULT_MODEL", tmp_path / "missing.safetensors")
    s = ViewerSession(model=None)
    s.photo, s.info, s._plain = plain.photo, plain.info, plain._plain
    r = s.prepare_stylized()
    assert not r.available and r.message == NO_MODEL and not s.can_stylize
    s.load_style(str(SAMPLE_STYLE))  # kept for later, no error
    np.testing.assert_array_equal(render(s, stylized=True), render(s, stylized=False))


def test_bad_files_keep_what_was_loaded(plain, tmp_path):
    info, photo = plain.info, plain.photo
    broken = tmp_path / "broken.jpg"
    broken.write_bytes(b"\xff\xd8\xff\xe0 not really a jpeg")
    for bad in (tmp_path / "missing.jpg", broken):
        with pytest.raises(InputError, match=bad.name):
            plain.load_photo(PhotoSpec(str(bad), "prior", max_size=MAX_SIZE))
        assert plain.info is info and plain.photo is photo
    with pytest.raises(InputError, match="depth"):
        plain.load_photo(PhotoSpec(str(SAMPLE_PHOTO), "nosuchsource:x", max_size=MAX_SIZE))
    with pytest.raises(InputError, match="missing.png"):
        plain.load_style(str(tmp_path / "missing.png"))
    assert plain.info is info and plain.style_path is None


@pytest.mark.parametrize("name, content", [("missing.safetensors", None), ("bad.safetensors", b"not a checkpoint")])
def test_bad_model_file_is_an_error(tmp_path, plain, name, content):
    path = tmp_path / name
    if content is not None:
        path.write_bytes(content)
    s = ViewerSession(model=str(path))
    s.photo, s.info, s._plain = plain.photo, plain.info, plain._plain
    with pytest.raises(InputError, match=name):
        s.prepare_stylized()
    assert not s.can_stylize
    assert render(s, stylized=True).std() > 0.05  # the plain view still works


@pytest.mark.slow
def test_stylized_view_restyle_reuses_the_encoding(untrained):
    s = ViewerSession(model=str(untrained))
    s.load_photo(PhotoSpec(str(SAMPLE_PHOTO), "prior", max_size=MAX_SIZE))
    r = s.prepare_stylized()
    assert r.available and "stage 1" in r.message and s.can_stylize
    base = render(s, stylized=True)
    assert base.shape == (*frame_size(s.info.size, 128), 3) and np.isfinite(base).all()
    assert np.abs(base - render(s, stylized=False)).mean() > 0.02  # through the model, not the plain colours
    encoded = s._stylized
    s.load_style(str(SAMPLE_STYLE))
    assert s._stylized is encoded  # a new style re-uses the encoded point cloud
    styled = render(s, stylized=True)
    s.set_strength(0.0)
    unstyled = render(s, stylized=True)
    np.testing.assert_allclose(unstyled, base, atol=1e-5)  # strength 0 = no style
    assert np.abs(styled - unstyled).max() > 1e-4
    moved = render(s, OrbitPose(yaw_deg=6.0), stylized=True, preview=True)
    assert np.isfinite(moved).all() and moved.shape == base.shape


def test_export_writes_atomically_and_cancels_cleanly(plain, tmp_path):
    cams = circle(4, fov_y_deg=plain.info.fov_y_deg)
    size = frame_size(plain.info.size, 64)
    calls, between = [], []
    out = plain.export(ExportJob(str(tmp_path / "clip.mp4"), cams, size, 8.0, False),
                       progress=lambda done, total: calls.append((done, total)),
                       between_frames=lambda: between.append(1))
    assert out.stat().st_size > 0 and calls[-1] == (4, 4) and len(between) == 4
    frames = plain.export(ExportJob(str(tmp_path / "frames") + "/", cams, size, 8.0, False))
    assert sorted(p.name for p in frames.iterdir()) == [f"frame_{i:04d}.png" for i in range(4)]

    def cancel(done, total):
        if done == 2:
            raise ExportCancelled("cancelled")

    with pytest.raises(ExportCancelled):
        plain.export(ExportJob(str(tmp_path / "cancelled.gif"), cams, size, 8.0, False), progress=cancel)
    assert sorted(os.listdir(tmp_path)) == ["clip.mp4", "frames"]  # no half-written file left behind


def test_display_image_and_open3d_handoff():
    rgb = np.zeros((4, 6, 3), np.float32)
    rgb[0, 0] = [np.nan, np.inf, -np.inf]
    rgb[1, 1] = [0.5, 1.5, -0.5]
    u8 = display_image(rgb, (4, 6))
    assert u8.dtype == np.uint8 and u8.flags.c_contiguous
    assert u8[0, 0].tolist() == [0, 255, 0] and u8[1, 1].tolist() == [128, 255, 0]
    big = display_image(np.full((4, 6, 3), 0.25, np.float32), (8, 12))
    assert big.shape == (8, 12, 3) and np.all(big == 64)
    # The hand-off to the window: an o3d.geometry.Image holding the same pixels.
    img = o3d.geometry.Image(big)
    np.testing.assert_array_equal(np.asarray(img), big)


def test_split_view_puts_before_left_and_after_right():
    import numpy as np

    from stylize3d_app.viewer.session import split_view

    before, after = np.zeros((4, 10, 3), np.float32), np.ones((4, 10, 3), np.float32) * 0.5
    out = split_view(before, after, 0.3)
    assert (out[:, :3] == 0).all() and (out[:, 4:] == 0.5).all() and (out[:, 3] == 0.9).all()
    assert (split_view(before, after, 0.0) == after).all() and (split_view(before, after, 1.0) == before).all()
    import pytest

    from stylize3d_core.errors import InputError

    with pytest.raises(InputError, match="shapes"):
        split_view(before, after[:, :5], 0.5)


def test_previews_are_colour_matched_to_the_full_frame(untrained):
    s = ViewerSession(model=str(untrained))
    s.load_photo(PhotoSpec(str(SAMPLE_PHOTO), "prior", max_size=MAX_SIZE))
    s.prepare_stylized()
    s.load_style(str(SAMPLE_STYLE))
    cam = pose_camera(OrbitPose(yaw_deg=2.0), s.info.scene, s.info.fov_y_deg)
    full_hw, prev_hw = frame_size(s.info.size, 160), frame_size(s.info.size, 48)
    before = s.render_view(cam, prev_hw, full_hw, preview=True, stylized=True).image.astype(np.float32)
    assert s.colour_gain is None
    half = s.render_view(cam, frame_size(s.info.size, 80), full_hw, preview=False, stylized=True, calibrate=False)
    assert s.colour_gain is None and half.image.shape == (*full_hw, 3)  # a progressive level leaves the gain
    full = s.render_view(cam, full_hw, full_hw, preview=False, stylized=True).image.astype(np.float32)
    assert s.colour_gain is not None and s.colour_gain.shape == (3,)
    after = s.render_view(cam, prev_hw, full_hw, preview=True, stylized=True).image.astype(np.float32)
    # the gain's contract, in the renderer's float colours: a preview times the gain has the full frame's mean
    prev_f = s.render(cam, *prev_hw, preview=True, stylized=True).reshape(-1, 3)
    full_f = s.render(cam, *full_hw, preview=False, stylized=True).reshape(-1, 3)
    gained = np.clip(prev_f * s.colour_gain, 0.0, 1.0)
    jump_f_before = np.abs(prev_f.mean(0) - full_f.mean(0)).mean()
    jump_f_after = np.abs(gained.mean(0) - full_f.mean(0)).mean()
    assert jump_f_after <= jump_f_before and jump_f_after < 1e-4, (jump_f_before, jump_f_after)
    # what the window shows: the gained preview, within 8-bit rounding of the full frame (the untrained model's
    # near-uniform frames already differ by hundredths of a level, so rounding, not colour, rules at that size)
    jump_before = np.abs(before.mean((0, 1)) - full.mean((0, 1))).mean()
    jump_after = np.abs(after.mean((0, 1)) - full.mean((0, 1))).mean()
    assert jump_after < 0.5 and jump_before < 1.0, (jump_before, jump_after)


def test_the_photos_clean_camera_range_bounds_the_orbit(plain):
    from dataclasses import replace

    from stylize3d_app.viewer.orbit import OrbitLimits, clamp_pose
    from stylize3d_core.geometry.camera_range import CameraRange

    rng = plain.info.camera_range
    assert rng == plain.photo.camera_range  # what the LDI reports it covers cleanly
    assert plain.info.range_scale == pytest.approx(plain.photo.ldi.range_scale)
    assert rng == CameraRange().scaled(plain.info.range_scale)  # (the default LDI settings' range, scaled)
    assert isinstance(rng, CameraRange) and 0 <= rng.max_yaw_deg <= CameraRange().max_yaw_deg
    limits = OrbitLimits.from_range(rng, deg_per_pixel=0.05)
    wild = clamp_pose(OrbitPose(yaw_deg=80.0, pitch_deg=-80.0, pan_x=5.0, dolly=-9.0), plain.info.scene, limits)
    assert wild.yaw_deg == pytest.approx(rng.max_yaw_deg) and wild.pitch_deg == pytest.approx(-rng.max_pitch_deg)
    assert wild.pan_x == pytest.approx(rng.max_pan)
    assert wild.dolly == pytest.approx(rng.min_dolly * plain.info.scene.centre_depth)
    narrow = OrbitLimits.from_range(replace(rng, max_yaw_deg=1.0))  # a narrower range: a tighter clamp
    assert clamp_pose(OrbitPose(yaw_deg=80.0), plain.info.scene, narrow).yaw_deg == pytest.approx(1.0)


def test_colour_jump_known_values():
    before = np.zeros((4, 6, 3), np.uint8)
    after = before.copy()
    after[..., 0] = 12  # red up by 12 everywhere: means differ by 12 in one channel of three
    assert colour_jump(before, after) == pytest.approx((4.0, 4.0))
    after[:2, :, 1] = 30  # green up by 30 on the top half only, red unchanged
    after[:2, :, 0] = 0
    mean_diff, pixel_diff = colour_jump(before, after)
    assert mean_diff == pytest.approx((6 + 15) / 3) and pixel_diff == pytest.approx((6 + 15) / 3)
    after = np.full((4, 6, 3), 50, np.uint8)
    after[:, :3] = 0  # same mean colour as 25 everywhere, but every pixel 25 away from it
    assert colour_jump(np.full((4, 6, 3), 25, np.uint8), after) == pytest.approx((0.0, 25.0))
    with pytest.raises(InputError, match="shapes differ"):
        colour_jump(before, np.zeros((4, 5, 3), np.uint8))


def test_view_frames_keep_their_size_and_report_stage_times(plain):
    cam = pose_camera(OrbitPose(yaw_deg=3.0), plain.info.scene, plain.info.fov_y_deg)
    times = {}
    f = plain.render_view(cam, (32, 48), None, preview=True, stylized=False, timings=times)
    assert f.image.shape == (32, 48, 3) and f.image.dtype == np.uint8 and f.rendered_size == (32, 48)
    assert set(times) == {"render", "split", "convert", "resize"} and all(v >= 0 for v in times.values())
    big = plain.render_view(cam, (32, 48), (64, 96), preview=True, stylized=False)
    assert big.image.shape == (64, 96, 3)


def test_the_original_above_the_photos_size_is_rendered_at_it_and_scaled_up(plain):
    """Past one point per pixel the plain splats' seams show as a faint dot grid; the view renders the
    original at the photo's size and scales it up instead."""
    import cv2

    cam = pose_camera(OrbitPose(yaw_deg=3.0), plain.info.scene, plain.info.fov_y_deg)
    h, w = plain.info.size
    big = (2 * h, 2 * w)
    up = plain.render_original(cam, big, preview=False)
    native = plain.render(cam, h, w, preview=False, stylized=False)
    assert up.shape == (*big, 3) and np.isfinite(up).all()
    np.testing.assert_allclose(up, cv2.resize(native, (2 * w, 2 * h), interpolation=cv2.INTER_LINEAR), atol=1e-6)
    small = frame_size(plain.info.size, 64)  # at or below the photo's size: rendered as asked
    np.testing.assert_array_equal(plain.render_original(cam, small, preview=False),
                                  plain.render(cam, *small, preview=False, stylized=False))


def test_shown_as_scales_a_preview_to_the_full_frame():
    from stylize3d_app.viewer.session import shown_as

    small = np.zeros((2, 3, 3), np.uint8)
    small[:, :] = [10, 200, 40]
    out = shown_as(small, (8, 12, 3))
    assert out.shape == (8, 12, 3) and (out == [10, 200, 40]).all()
    assert shown_as(small, small.shape) is small


def test_the_shipped_model_shows_a_stylized_view_before_its_learned_inputs_are_made(plain):
    """prepare_stylized leaves the shipped model's geometry and features to prepare_model_features (the viewer's
    task after the first stylized frame); the frames are the same before and after."""
    s = ViewerSession()
    s.load_photo(PhotoSpec(str(SAMPLE_PHOTO), "prior", max_size=MAX_SIZE))
    s.load_style(str(SAMPLE_STYLE))
    assert s.prepare_stylized().available
    first = render(s, stylized=True)
    assert not s._stylized.prepared  # the home view is covered: the points' painted colours
    s.prepare_model_features()
    assert s._stylized.prepared
    np.testing.assert_array_equal(render(s, stylized=True), first)
    s.prepare_model_features()  # a second call (a repeated task) costs nothing and changes nothing
    np.testing.assert_array_equal(render(s, stylized=True), first)
