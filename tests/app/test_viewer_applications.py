"""The viewer's Applications menu (app/viewer/applications.py, app/viewer/layers.py) without a window.

The controller runs against a stand-in window whose worker runs each task at
once on the calling thread, with a real :class:`~stylize3d_app.viewer.session.ViewerSession`
(the sample photo, an untrained model) and the real camera-path and export
controllers: each menu action's library call is made and its files read back.
The window itself is driven by ``test_viewer_applications_gui`` at the end (Xvfb).
"""

from __future__ import annotations

import json
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
from PIL import Image

import stylize3d_app.viewer.applications as A
from stylize3d_app.viewer.layers import ViewerLayers
from stylize3d_app.viewer.orbit import HOME, OrbitPose, pose_camera
from stylize3d_app.viewer.session import SAMPLE_PHOTO, SAMPLE_STYLE, ViewerSession
from stylize3d_core.errors import InputError
from stylize3d_core.eval.multiview import procedural_views
from stylize3d_core.export.camera_paths import camera_path_format, read_camera_path
from stylize3d_core.export.splat import read_splat_ply, read_vertex_properties
from stylize3d_core.export.web_page import read_page
from stylize3d_core.multiview import save_views
from stylize3d_core.pipeline import PhotoSpec
from stylize3d_core.render.plain import frame_size

from viewer_app_helpers import MAX_SIZE, StandInWindow, SyncWorker  # tests/support: the controllers' stand-in window
import viewer_gui_helpers as gui_helpers  # tests/support: the shared Xvfb fixture and viewer runner
from viewer_gui_helpers import display  # noqa: F401 (a fixture)

@pytest.fixture(scope="module")
def session(untrained) -> ViewerSession:
    s = ViewerSession(str(untrained))
    s.load_photo(PhotoSpec(str(SAMPLE_PHOTO), "prior", max_size=MAX_SIZE))
    s.load_style(str(SAMPLE_STYLE))
    assert s.prepare_stylized().available
    return s


@pytest.fixture
def window(session) -> StandInWindow:
    session.layers = None
    session.set_strength(0.8)
    return StandInWindow(session)


def _render(s: ViewerSession, pose=HOME, stylized=True):
    cam = pose_camera(pose, s.info.scene, s.info.fov_y_deg)
    h, w = s.info.size
    return cam, s.render(cam, h, w, preview=False, stylized=stylized)


def _centre_mask(size) -> np.ndarray:
    h, w = size
    m = np.zeros((h, w), bool)
    m[h // 4: 3 * h // 4, w // 3: 2 * w // 3] = True
    return m


# -- the menu and small pure helpers ------------------------------------------------------------
def test_every_menu_item_has_a_callback(window):
    callbacks = window.applications.menu_callbacks()
    assert sorted(callbacks) == list(range(A.MENU_VIEWS, A.MENU_HTML + 1))


def test_rectangle_fractions_become_pixels():
    assert A.rect_pixels((100, 200), (0.2, 0.1, 0.8, 1.0)) == (40, 10, 120, 90)
    assert A.rect_pixels((100, 200), (-1, 0, 2, 0.5)) == (0, 0, 200, 50)  # clamped to the photo
    with pytest.raises(InputError, match="rectangle is empty"):
        A.rect_pixels((100, 200), (0.6, 0.1, 0.4, 0.9))
    with pytest.raises(InputError, match="four fractions"):
        A.rect_pixels((100, 200), (0.1, 0.2))


def test_destinations():
    assert A.point_destination("cloud") == "cloud.ply" and A.point_destination("a.PLY") == "a.PLY"
    with pytest.raises(InputError, match="must end in .ply"):
        A.point_destination("cloud.obj")
    assert A.video_destination("loop") == "loop.mp4" and A.video_destination("x.webp") == "x.webp"
    with pytest.raises(InputError, match=r"\.mp4, \.gif, \.webp"):
        A.video_destination("loop.avi")
    assert A.page_destination("photo") == "photo.html" and A.page_destination("p.HTM") == "p.HTM"
    with pytest.raises(InputError, match="must end in .html or .htm"):
        A.page_destination("photo.ply")


def test_export_settings_follow_the_dialog_choices(window):
    c = window.applications
    c.eye_distance, c.stereo_layout, c.stereo_loop = 0.02, "half", True
    sbs = c.export_settings("sbs")
    assert (sbs.export, sbs.stereo_layout, sbs.eye_distance, sbs.loop) == ("sbs", "half", 0.02, True)
    loop = c.export_settings("loop")
    assert loop.export == "video" and loop.loop
    assert c.export_settings("splat").export == "splat"
    with pytest.raises(InputError, match="unknown export 'obj'"):
        c.export_settings("obj")


# -- layered stylization ------------------------------------------------------------------------
def test_layered_view_keeps_the_foreground_in_every_view(session):
    session.layers = None
    plain_views, full_views, cams = [], [], []
    poses = (HOME, OrbitPose(yaw_deg=5.0), OrbitPose(yaw_deg=-4.0, pitch_deg=3.0))
    for pose in poses:
        cam, full = _render(session, pose)
        cams.append(cam)
        full_views.append(full)
        plain_views.append(_render(session, pose, stylized=False)[1])
    session.layers = ViewerLayers(session.photo, session.info.path, _centre_mask(session.info.size), 0.0, "test")
    assert session.layers.foreground_strength is None  # 0 = the original colours
    h, w = session.info.size
    for cam, plain, full in zip(cams, plain_views, full_views):
        layered = session.render(cam, h, w, preview=False, stylized=True)
        cov = session.layers.renderer(session._stylized, session.strength).coverage(cam, h, w)
        fg, bg = cov > 0.999, cov <= 0.0
        assert fg.sum() > 0.1 * h * w and bg.sum() > 0.3 * h * w
        # the foreground: the photo's own colours, less what a coverage just under 1 lets through from behind
        assert (np.abs(layered[fg] - plain[fg]) <= (1.0 - cov[fg])[:, None] + 1e-5).all()
        assert np.abs(layered[bg] - full[bg]).max() < 1e-5  # the background: stylized
        assert np.abs(full[fg] - plain[fg]).mean() > 0.02  # (stylizing does change the foreground)
    session.layers = None


def test_layered_background_follows_the_strength_slider(session):
    session.layers = ViewerLayers(session.photo, session.info.path, _centre_mask(session.info.size), None, "t")
    h, w = session.info.size
    cam = pose_camera(HOME, session.info.scene, session.info.fov_y_deg)
    cov = session.layers.renderer(session._stylized, session.strength).coverage(cam, h, w)
    bg = cov <= 0.0
    session.render(cam, h, w, preview=False, stylized=True)
    session.set_strength(0.3)
    layered = session.render(cam, h, w, preview=False, stylized=True)
    layers, session.layers = session.layers, None
    at_03 = session.render(cam, h, w, preview=False, stylized=True)
    assert np.abs(layered[bg] - at_03[bg]).max() < 1e-5
    session.layers = layers.with_strength(0.5)  # a stylized foreground: no longer the photo's colours
    half = session.render(cam, h, w, preview=False, stylized=True)
    plain = session.render(cam, h, w, preview=False, stylized=False)
    fg = cov > 0.999
    assert np.abs(half[fg] - plain[fg]).mean() > 0.01
    session.layers = None
    session.set_strength(0.8)


def test_mask_file_sizes(window, tmp_path):
    s = window.session
    h, w = s.info.size
    good = tmp_path / "mask.png"
    Image.fromarray(_centre_mask((h, w)).astype(np.uint8) * 255).save(good)
    window.applications.load_mask(str(good))
    assert not window.errors and s.layers is not None
    assert s.layers.fraction == pytest.approx(_centre_mask((h, w)).mean())
    assert "Foreground from mask.png" in window.status and "original colours" in window.status
    file_h, file_w = Image.open(SAMPLE_PHOTO).size[::-1]
    at_file = tmp_path / "mask_file_size.png"
    Image.fromarray(_centre_mask((file_h, file_w)).astype(np.uint8) * 255).save(at_file)
    window.applications.load_mask(str(at_file))
    assert not window.errors and s.layers.mask.shape == (h, w)
    wrong = tmp_path / "wrong.png"
    Image.fromarray(np.full((17, 23), 255, np.uint8)).save(wrong)
    window.applications.load_mask(str(wrong))
    assert len(window.errors) == 1
    e = window.errors[0]
    assert "wrong.png" in e and "23x17" in e and f"{file_w}x{file_h}" in e and "photo's size" in e
    window.applications.load_mask(str(tmp_path / "missing.png"))
    assert "mask file not found" in window.errors[-1]
    window.applications.clear_mask()
    assert s.layers is None and window.applications.mask_source is None


def test_grabcut_and_foreground_strength(window):
    c, s = window.applications, window.session
    c.grabcut((0.25, 0.05, 0.75, 1.0), 0.0)
    assert not window.errors, window.errors
    assert 0.05 < s.layers.fraction < 0.6 and s.layers.source == "GrabCut"
    assert c.rect == (0.25, 0.05, 0.75, 1.0) and "GrabCut" in window.status
    c.set_foreground_strength(0.4)
    assert s.layers.foreground_strength == pytest.approx(0.4) and "strength 0.40" in window.status
    with pytest.raises(InputError, match="rectangle is empty"):
        c.grabcut((0.5, 0.5, 0.5, 0.9))
    c.grabcut((0.0, 0.0, 1.0, 1.0))
    assert "whole photo" in window.errors[-1]
    s.layers = None


def test_mask_follows_a_rebuild_of_the_same_photo(untrained):
    s = ViewerSession(str(untrained))
    s.load_photo(PhotoSpec(str(SAMPLE_PHOTO), "prior", max_size=MAX_SIZE))
    mask = _centre_mask(s.info.size)
    s.layers = ViewerLayers(s.photo, s.info.path, mask, None, "m")
    s.load_photo(PhotoSpec(str(SAMPLE_PHOTO), "prior", max_size=MAX_SIZE, relief=2.0))  # a new LDI
    assert s.layers is not None and s.layers.photo is s.photo
    assert s.layers.points.sum() == mask.sum()  # layer-0 pixels only: the hidden layer is background
    s.load_photo(PhotoSpec(str(SAMPLE_PHOTO), "prior", max_size=MAX_SIZE - 16))  # another size
    assert s.layers is None


# -- exports ------------------------------------------------------------------------------------
def test_point_exports(window, tmp_path):
    c, n = window.applications, len(window.session.photo.points)
    c.start_export("ply", str(tmp_path / "cloud"))
    assert not window.errors, window.errors
    props = read_vertex_properties(tmp_path / "cloud.ply")
    assert len(props["x"]) == n and {"red", "green", "blue"} <= set(props)
    c.start_export("splat", str(tmp_path / "splats.ply"))
    cloud = read_splat_ply(tmp_path / "splats.ply")
    assert len(cloud.xyz) == n and np.isfinite(cloud.scale).all()
    assert window.stats["last_export"].endswith("splats.ply")
    with pytest.raises(InputError, match="must end in .ply"):
        c.start_export("ply", str(tmp_path / "cloud.obj"))


def test_web_page_export(window, tmp_path):
    c, photo = window.applications, window.session.photo
    dest = Path(c.start_export("html", str(tmp_path / "page")))
    assert not window.errors, window.errors
    assert dest.name == "page.html"
    meta, q, rgb = read_page(dest)
    assert meta["count"] == len(q) == len(rgb) == len(photo.points)
    assert len(meta["trajectory"]["cam_to_world"]) == len(window.paths.export_cameras())
    assert meta["title"] == Path(window.session.info.path).stem
    before = dest.read_bytes()
    with pytest.raises(InputError, match="must end in .html or .htm"):
        c.start_export("html", str(tmp_path / "page.ply"))
    assert dest.read_bytes() == before


def gif_frame_count(path, size, fps) -> float:
    """Frames a GIF shows, counted by time: the writer merges identical neighbours into a longer one."""
    with Image.open(path) as gif:
        assert gif.size == size
        durations = [(gif.seek(i), gif.info["duration"])[1] for i in range(gif.n_frames)]
    return sum(durations) * fps / 1000


def test_stereo_and_loop_videos(window, tmp_path):
    c = window.applications
    H, W = frame_size(window.session.info.size, 64)
    fps = window.state.export.fps
    c.stereo_layout, c.eye_distance, c.stereo_loop = "full", 0.01, False
    c.start_export("sbs", str(tmp_path / "sbs.gif"))
    assert not window.errors, window.errors
    # a GIF writer merges identical neighbours into one longer frame, so count frames by their time
    assert gif_frame_count(tmp_path / "sbs.gif", (2 * W, H), fps) == 4
    c.stereo_layout, c.stereo_loop = "half", True
    c.start_export("sbs", str(tmp_path / "sbs_half.gif"))
    assert gif_frame_count(tmp_path / "sbs_half.gif", (W, H), fps) == 6  # 2n - 2 frames
    c.stereo_loop = False
    c.start_export("anaglyph", str(tmp_path / "ana.gif"))
    assert gif_frame_count(tmp_path / "ana.gif", (W, H), fps) == 4
    ana = iio.imread(tmp_path / "ana.gif", index=None)[..., :3].astype(np.float32)
    assert np.abs(ana[..., 0] - ana[..., 1]).mean() > 1.0
    c.start_export("loop", str(tmp_path / "loop.gif"))
    assert gif_frame_count(tmp_path / "loop.gif", (W, H), fps) == 6
    c.eye_distance = 0.9  # far past half the nearest surface's depth
    c.start_export("anaglyph", str(tmp_path / "inside.gif"))
    assert "camera" in window.errors[-1] and not (tmp_path / "inside.gif").exists()
    assert not c.window.exports.exporting


def test_export_cancel_writes_nothing(window, tmp_path):
    c = window.applications
    c.stereo_loop = False

    def cancel_during(name, fn, on_done=None, on_error=None, key=None):
        window.exports.cancel()  # Cancel pressed before the first frame
        SyncWorker.submit(window.worker, name, fn, on_done, on_error, key)

    window.worker.submit = cancel_during
    c.start_export("anaglyph", str(tmp_path / "cancelled.gif"))
    assert "cancelled" in window.status and not window.errors
    assert not (tmp_path / "cancelled.gif").exists() and list(tmp_path.iterdir()) == []


def test_camera_paths_in_both_formats(window, tmp_path):
    c = window.applications
    c.save_path(str(tmp_path / "path.json"), "stylize3d")
    c.save_path(str(tmp_path / "traj.json"), "open3d")
    assert camera_path_format(tmp_path / "path.json") == "stylize3d"
    assert camera_path_format(tmp_path / "traj.json") == "open3d"
    a, b = read_camera_path(tmp_path / "path.json"), read_camera_path(tmp_path / "traj.json")
    assert len(a.cameras) == len(b.cameras) == 4
    assert np.allclose(a.cameras.cam_to_world.numpy(), b.cameras.cam_to_world.numpy(), atol=1e-6)
    with pytest.raises(InputError, match="must end in .json"):
        c.save_path(str(tmp_path / "traj.txt"), "open3d")


# -- opening: multi-view, stereo cards ------------------------------------------------------------
def test_multi_view_file_opens_merged(untrained, tmp_path):
    data = procedural_views(3)
    path = save_views(tmp_path / "views", data.views)
    s = ViewerSession(str(untrained))
    s.load_photo(PhotoSpec(str(SAMPLE_PHOTO), "prior", max_size=MAX_SIZE))
    w = StandInWindow(s)
    w.applications.open_views(str(path), centre=1)
    assert not w.errors, w.errors
    info, spec = w.loaded[-1]
    assert Path(spec.photo).name == "view1.png" and Path(info.path).name == "view1.png"
    h, wd = data.views[1].rgb.shape[:2]  # 96 x 128, read at the viewer's max size
    assert max(info.size) == MAX_SIZE and info.size[0] * wd == info.size[1] * h
    assert info.n_points > info.size[0] * info.size[1]  # the merged views' points, not one photo layer
    assert "3 views merged" in w.status
    doc = json.loads(path.read_text())
    doc["views"] = doc["views"][:2] + [{"image": "view2.png", "depth": "view2_depth.npy"}]  # a view with no pose
    bad = path.parent / "bad_views.json"
    bad.write_text(json.dumps(doc))
    w.applications.open_views(str(bad), centre=0)
    assert "bad_views.json" in w.errors[-1]
    with pytest.raises(InputError, match="must be 0 to 2"):
        w.applications._views = [object()] * 3
        w.applications.merge_views(5)


def test_stereo_cards_open_with_their_depth_specs(window, tmp_path):
    c = window.applications
    c.open_card("card.png", cross_eyed=False)
    c.open_card("card.png", cross_eyed=True)
    assert [(s.photo, s.depth) for s in window.loaded] == [("card.png", "stereo:card"), ("card.png", "stereo:card:cross")]
    assert A.photo_file_size(window.session, "stereo:card") == window.session.info.size


def test_actions_need_a_photo(untrained):
    s = ViewerSession(str(untrained))
    w = StandInWindow(s)
    with pytest.raises(InputError, match="open a photo first"):
        w.applications.start_export("ply", "x.ply")
    with pytest.raises(InputError, match="open a photo first"):
        w.applications.grabcut(A.DEFAULT_RECT)
    with pytest.raises(InputError, match="open a photo first"):
        A.layers_from_file(s, "m.png", 0.0)


# -- the window under Xvfb ----------------------------------------------------------------------
@pytest.mark.gui
@pytest.mark.slow
def test_viewer_applications_gui(display, untrained, tmp_path):
    """The real window: GrabCut from the Applications menu's dialog, a layered view, a half-width
    side-by-side export and a baked PLY through the menu's Save dialogs, then the mask cleared."""
    steps = [
        {"op": "load_sample"},
        {"op": "wait_idle", "timeout": 180},
        {"op": "app_menu", "item": "MENU_GRABCUT", "ok": True,
         "fields": {"left": 0.25, "top": 0.05, "right": 0.75, "bottom": 1.0, "strength": 0.0},
         "grab": str(tmp_path / "grabcut_dialog.png")},
        {"op": "wait_idle", "timeout": 180},
        {"op": "screenshot", "path": str(tmp_path / "layered.png")},
        {"op": "set_export", "frames": 4, "size": 96, "fps": 8},
        {"op": "app_menu", "item": "MENU_SBS", "ok": True, "fields": {"layout": 1, "eye_distance": 0.01},
         "save_as": str(tmp_path / "sbs.mp4")},
        {"op": "app_menu", "item": "MENU_PLY", "save_as": str(tmp_path / "cloud.ply")},
        {"op": "app_menu", "item": "MENU_ANAGLYPH", "ok": True, "fields": {"eye_distance": 0.9},
         "save_as": str(tmp_path / "inside.mp4")},
        {"op": "expect_error", "contains": "camera"},
        {"op": "app_menu", "item": "MENU_MASK_CLEAR"},
        {"op": "wait_idle", "timeout": 180},
        {"op": "screenshot", "path": str(tmp_path / "cleared.png")},
        {"op": "quit"},
    ]
    code, report = gui_helpers.run_viewer(display, tmp_path, steps, ["--model", str(untrained)])
    gui_helpers.check_ran(code, report)
    assert "GrabCut" in gui_helpers.step(report, "app_menu", 0)["result"]["status"]
    assert [e for e in report["errors"] if "camera" in e] and len(report["errors"]) == 1, report["errors"]
    sbs = iio.imread(tmp_path / "sbs.mp4", index=None)
    assert sbs.shape[0] == 4 and sbs.shape[2] == 96  # half width: the two eyes squeezed into one frame
    assert len(read_vertex_properties(tmp_path / "cloud.ply")["x"]) > 10_000
    assert not (tmp_path / "inside.mp4").exists()
    layered, cleared = (np.asarray(Image.open(tmp_path / n).convert("RGB"), np.float32) for n in
                        ("layered.png", "cleared.png"))
    h, w = layered.shape[:2]
    diff = np.abs(layered - cleared).mean(-1)
    centre = diff[h // 4: 3 * h // 4, 3 * w // 8: 5 * w // 8].mean()
    edges = np.concatenate([diff[:, : w // 8].ravel(), diff[:, -w // 8:].ravel()]).mean()
    assert centre > 3 * edges + 2.0, (centre, edges)  # only the foreground changed
