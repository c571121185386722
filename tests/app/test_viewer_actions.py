"""The window's controllers (app/viewer/actions.py) against a stand-in window: no X server, no widgets.

The controllers use the window only through its small surface (state, panel,
session, worker, post, set_status/set_busy, view_changed, request_render, ...),
so a plain object with those attributes runs them.
"""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace
from typing import Any, List

import pytest

from stylize3d_app.viewer.actions import CameraPathController, ExportController, PhotoController
from stylize3d_app.viewer.orbit import OrbitScene
from stylize3d_app.viewer.state import PhotoInfo, ViewState
from stylize3d_core.errors import InputError
from stylize3d_core.geometry.trajectories import static
from stylize3d_core.pipeline import PhotoSpec

INFO = PhotoInfo("p.jpg", (30, 40), 1200, 60.0, "prior", OrbitScene(centre_depth=0.7), 0.1)


class FakeWorker:
    def __init__(self) -> None:
        self.tasks: List[Any] = []

    def submit(self, name, fn, on_done=None, on_error=None, key=None):
        self.tasks.append((name, fn, on_done, on_error))


class FakeWindow:
    def __init__(self, state: ViewState) -> None:
        self.state = state
        self.worker = FakeWorker()
        self.session = SimpleNamespace(load_photo=lambda spec: ("built", spec))
        self.panel = SimpleNamespace(preview_path=SimpleNamespace(text="Preview (C)"),
                                     key_preview=SimpleNamespace(text="Preview (full quality)"))
        self.status: List[str] = []
        self.renders: List[Any] = []
        self.changes = 0
        self.errors: List[str] = []

    def post(self, fn):
        fn()

    def set_status(self, text):
        self.status.append(text)

    def set_busy(self, text, fraction=None):
        if text is not None:
            self.status.append(text)

    def show_error(self, what, e):
        self.errors.append(f"{what}: {e}")

    def view_changed(self):
        self.changes += 1

    def request_render(self, preview, camera=None):
        self.renders.append((preview, camera))


def test_photo_options_wait_for_the_next_photo_or_rebuild_the_open_one():
    w = FakeWindow(ViewState())
    photos = PhotoController(w)
    photos.set_depth("prior")
    photos.set_refine_depth("guided")
    assert w.state.spec.depth == "prior" and w.state.spec.refine_depth == "guided" and w.state.spec.photo is None
    assert w.status[-1] == "Depth edges: guided" and w.worker.tasks == []
    with pytest.raises(InputError, match="relief"):
        photos.change_spec("never shown", relief=100.0)
    assert w.state.spec.relief == 1.0
    # With a photo open, a new option rebuilds it on the worker; the state changes once it is built.
    w.state = replace(w.state, spec=replace(w.state.spec, photo="p.jpg"), photo_info=INFO)
    photos.change_spec("unused", relief=2.0)
    (name, fn, _on_done, _on_error), = w.worker.tasks
    assert name == "open photo" and w.state.spec.relief == 1.0
    built, spec = fn()
    assert spec == replace(w.state.spec, relief=2.0)


def test_camera_path_preview_requests_each_camera_once_then_stops():
    w = FakeWindow(ViewState(photo_info=INFO))
    paths = CameraPathController(w)
    paths.toggle_preview()
    pb = w.state.playback
    assert paths.playing and len(pb.cameras) == w.state.export.frames
    assert w.panel.preview_path.text == "Stop preview (C)"
    w.state = replace(w.state, playback=replace(pb, cameras=static(3), start=0.0, fps=10.0))
    for now in (0.0, 0.05, 0.1, 0.15, 0.2):
        paths.step(now)
    assert [r[0] for r in w.renders] == [True, True, True]  # cameras 0, 1, 2: previews, once each
    assert w.state.playback.index == 2 and w.changes == 0
    paths.step(0.3)
    assert w.state.playback is None and not paths.playing and w.changes == 1
    assert w.panel.preview_path.text == "Preview (C)"


@pytest.mark.parametrize("available, stylized, expected", [
    (False, True, False), (True, True, True), (True, False, False),
])
def test_export_needs_a_photo_and_uses_the_one_rule_for_stylized(tmp_path, available, stylized, expected):
    w = FakeWindow(ViewState())
    w.panel.cancel, w.panel.export = SimpleNamespace(enabled=False), SimpleNamespace(enabled=True)
    w.worker.serve_pending_render = lambda: None
    w.session.export = lambda job, progress, between: job
    exports = ExportController(w, CameraPathController(w))
    with pytest.raises(InputError, match="open a photo first"):
        exports.start_export(str(tmp_path / "out.mp4"))
    assert not exports.exporting
    w.state = replace(w.state, photo_info=INFO, stylize_available=available, stylized=stylized)
    dest = exports.start_export(str(tmp_path / "out"))
    assert dest.endswith("out.mp4") and exports.exporting and w.panel.cancel.enabled
    with pytest.raises(InputError, match="already running"):
        exports.start_export(str(tmp_path / "again.mp4"))
    (name, fn, on_done, _on_error), = w.worker.tasks
    job = fn()
    assert name == "export" and job.stylized is expected and len(job.cameras) == w.state.export.frames


def test_keyframe_edits_are_pure_and_keep_durations_with_their_keyframe():
    import numpy as np

    from stylize3d_app.viewer import keyframe_edit as KE
    from stylize3d_core.errors import InputError
    from stylize3d_core.geometry.camera import Cameras

    def cam(x: float, fov: float = 60.0) -> Cameras:
        m = np.eye(4)
        m[0, 3] = x
        return Cameras.create(m, fov)

    kp = KE.add_keyframe(None, cam(0.0), 1.0)
    kp = KE.add_keyframe(kp, cam(0.1), 2.0)
    kp = KE.add_keyframe(kp, cam(0.05), 3.0, after=0)  # inserted after the first
    xs = [k.cam_to_world[0, 3] for k in kp.keyframes]
    assert xs == [0.0, 0.05, 0.1] and kp.durations_s == (1.0, 3.0, 2.0)
    moved = KE.move_keyframe(kp, 2, -5)  # clamped to the start
    assert [k.cam_to_world[0, 3] for k in moved.keyframes] == [0.1, 0.0, 0.05] and moved.durations_s == (2.0, 1.0, 3.0)
    assert KE.set_keyframe_fov(kp, 1, 40.0).keyframes[1].fov_y_deg == 40.0
    assert KE.set_keyframe_duration(kp, 2, 0.5).durations_s == (1.0, 3.0, 0.5)
    assert KE.set_loop(kp, True).loop and KE.set_loop(None, True) is None
    assert len(KE.delete_keyframe(kp, 0).keyframes) == 2
    assert KE.delete_keyframe(KE.add_keyframe(None, cam(0.0)), 0) is None
    labels = KE.keyframe_labels(KE.set_loop(kp, True))
    assert len(labels) == 3 and labels[-1].endswith("to the first") and labels[0].startswith("1: fov 60")
    with pytest.raises(InputError, match="no keyframe 4"):
        KE.delete_keyframe(kp, 3)
    with pytest.raises(InputError):
        KE.set_keyframe_duration(kp, 0, 0.0)


def _depth_panel(w: FakeWindow) -> None:
    from stylize3d_app.viewer import panel as P

    w.panel.depth = SimpleNamespace(selected_index=0)
    w.panel.depth_download = SimpleNamespace(text=P.DOWNLOAD_LABEL, enabled=True)


def test_depth_anything_is_offered_for_download_until_its_weights_are_cached(monkeypatch, tmp_path):
    """Choosing Depth Anything without its weights points at the Download button; the button downloads on a
    thread of its own (a stand-in for the hub writes the cache's layout), reports the bytes in the status
    line, then makes it the depth source; a failed download keeps the button and shows the error."""
    pytest.importorskip("transformers")
    import huggingface_hub

    from stylize3d_core.depth import depth_anything as da

    monkeypatch.setenv("HF_HUB_CACHE", str(tmp_path / "cache"))
    monkeypatch.delenv("HF_HUB_OFFLINE", raising=False)
    monkeypatch.setattr(da, "_check_reachable", lambda endpoint: None)
    w = FakeWindow(ViewState())
    _depth_panel(w)
    photos = PhotoController(w)
    photos.show_depth_model()
    assert w.panel.depth_download.enabled
    photos.set_depth("depth-anything")
    assert w.state.spec.depth != "depth-anything" and w.worker.tasks == []
    assert "Download Depth Anything" in w.status[-1] and w.panel.depth.selected_index == 0

    def offline(repo_id, **kw):
        raise OSError("no route to host")

    monkeypatch.setattr(huggingface_hub, "snapshot_download", offline)
    photos.download_depth_model()
    photos._download.join(10)
    assert "no route to host" in w.errors[-1] and w.panel.depth_download.enabled

    import threading

    go = threading.Event()

    def hub(repo_id, revision=None, cache_dir=None, tqdm_class=None, **kw):
        go.wait(10)  # until the test has seen the button while the download runs
        bar = tqdm_class(total=200, unit="B", disable=True)
        folder = tmp_path / "cache" / ("models--" + repo_id.replace("/", "--")) / "snapshots" / revision
        folder.mkdir(parents=True)
        bar.update(100)
        (folder / "config.json").write_text("{}")
        bar.update(100)
        return str(folder)

    monkeypatch.setattr(huggingface_hub, "snapshot_download", hub)
    photos.download_depth_model()
    assert w.panel.depth_download.text.startswith("Downloading") and not w.panel.depth_download.enabled
    photos.download_depth_model()  # a second click while it runs starts nothing
    go.set()
    photos._download.join(10)
    assert any(s.endswith("... 50 %") for s in w.status) and any(s.endswith("... 100 %") for s in w.status)
    assert w.state.spec.depth == "depth-anything" and da.cached_folder() is not None
    assert w.panel.depth_download.text == "Depth Anything downloaded" and not w.panel.depth_download.enabled
    assert w.panel.depth.selected_index == 4
