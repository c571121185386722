"""What the viewer window does besides showing the view, as three controllers it is composed of:

* :class:`PhotoController`: open photos and styles, the depth source and its
  edge alignment, the sample, and encoding the photo for the model;
* :class:`CameraPathController`: the trajectory, the camera-path preview
  (:class:`~stylize3d_app.viewer.state.Playback`), loading and saving camera paths;
* :class:`ExportController`: video export with progress and Cancel, screenshots.

They keep no app state of their own: everything lives in the window's
:class:`~stylize3d_app.viewer.state.ViewState`, which they replace (the export's cancel
event is the one exception: a thread handle, not state). They use the window
through its small public surface: ``state``, ``panel``, ``session``, ``worker``,
``post``, ``set_status``/``set_busy``, ``show_error``, ``view_changed``,
``request_render``, ``photo_changed``, ``final_frame`` and ``file_dialog``.

Their methods run on the GUI main thread; the work they start (reading files,
building the 3D photo, encoding, exporting) runs on the compute worker, whose
results come back through ``window.post`` (``post_to_main_thread``). Errors
become dialogs; what was loaded stays loaded.
"""

from __future__ import annotations

import functools
import os
import threading
import time
import traceback
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Optional

import open3d.visualization.gui as gui

from stylize3d_core.depth import depth_anything
from stylize3d_core.errors import InputError
from stylize3d_core.export.camera_paths import read_camera_path
from stylize3d_core.io.camera_path import CameraPath, save_camera_path
from stylize3d_core.io.keyframes import load_keyframes, save_keyframes
from stylize3d_core.io.images import save_image
from stylize3d_core.io.video import ExportCancelled
from stylize3d_core.render.plain import frame_size

from . import keyframe_edit as KE
from . import panel as P
from .host import ViewerHost
from .orbit import HOME
from .session import NO_MODEL, SAMPLE_PHOTO, SAMPLE_STYLE, ExportJob, StylizeInfo
from .state import (
    LOADED_PATH, VideoExport, PhotoInfo, Playback, TrajectoryLimits, clamp_trajectory, export_destination,
    export_progress_text, fov_range, path_source, playback_frame, screenshot_size, shows_stylized,
    trajectory_cameras, trajectory_limits, view_camera,
)

if TYPE_CHECKING:
    from stylize3d_core.pipeline import PhotoSpec


IMAGE_FILTERS = ((".jpg .jpeg .png .webp .tif .tiff", "Images (JPEG, PNG, WebP, TIFF)"), ("", "All files"))
DEPTH_FILTERS = ((".png .npy .pfm .tif .tiff .exr", "Depth (PNG16, NPY, PFM, TIFF, EXR)"), ("", "All files"))
JSON_FILTERS = ((".json", "Camera path (JSON)"), ("", "All files"))


def ui_callback(fn: Callable) -> Callable:
    """Wrap a GUI callback: an unexpected exception is shown in a dialog instead of killing the app."""

    @functools.wraps(fn)
    def wrapper(self: Any, *args: Any) -> Any:
        try:
            return fn(self, *args)
        except Exception as e:  # reported to the user; the session stays usable
            traceback.print_exc()
            self.show_error(fn.__name__.lstrip("_").replace("_", " "), e)
            widget_event = fn.__name__ in ("_on_mouse", "_on_view_key")
            return gui.Widget.EventCallbackResult.CONSUMED if widget_event else False

    return wrapper


class Controller:
    """One part of the window's behaviour (see the module docstring). Thread use: GUI main thread only."""

    def __init__(self, window: ViewerHost) -> None:
        self.window = window

    def show_error(self, what: str, error: BaseException) -> None:
        """Show ``error`` in the window's dialog (``ui_callback`` reports through this)."""
        self.window.show_error(what, error)

    def task_failed(self, name: str, e: BaseException) -> None:
        """A worker task failed: clear the progress, say so in the status line (not what the task was doing:
        "Building ..." would stay after the error dialog is gone) and show the error."""
        self.window.set_busy(f"{name[:1].upper()}{name[1:]} failed; what was open is kept", None)
        self.window.show_error(name, e)

    def submit(self, name: str, fn: Callable[[], Any], on_done: Callable[[Any], None], key: Optional[str] = None) -> None:
        """Run ``fn`` on the worker; ``on_done(result)`` (or the error dialog) follows on the main thread."""
        w = self.window
        w.worker.submit(name, fn, on_done=lambda r: w.post(lambda: on_done(r)),
                        on_error=lambda n, e: w.post(lambda: self.task_failed(n, e)), key=key)


def style_thumbnail(path: str, px: int = P.THUMB_PX):
    """A (px, px, 3) uint8 centre crop of an image file, for the style strip; None if it cannot be read."""
    import cv2
    import numpy as np

    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:
        return None
    h, w = bgr.shape[:2]
    side = min(h, w)
    crop = bgr[(h - side) // 2:(h - side) // 2 + side, (w - side) // 2:(w - side) // 2 + side]
    return np.ascontiguousarray(cv2.resize(crop, (px, px), interpolation=cv2.INTER_AREA)[:, :, ::-1])


BUNDLED_STYLES = tuple(sorted(str(p) for p in Path(str(SAMPLE_STYLE)).parent.glob("*.jpg")))
"""The style images shipped in ``assets/styles`` (the style strip shows them first)."""
MAX_STRIP = 12


class PhotoController(Controller):
    """Photos, styles, the depth source and its edge alignment, the sample, encoding for the model; recent
    photos, the style strip (bundled and recently used styles), a second style and its mix."""

    def __init__(self, window: ViewerHost) -> None:
        super().__init__(window)
        self._strip: list = []
        self._download: Optional[threading.Thread] = None  # the Depth Anything download, while it runs

    def build_strip(self) -> None:
        """Thumbnails of the bundled styles and the recently used ones (main thread, at start); the recent
        photos in the panel's picker."""
        for path in BUNDLED_STYLES + tuple(p for p in self.window.settings.recent_styles if os.path.isfile(p)):
            self._add_to_strip(path)
        self.show_recent()

    @property
    def recent_photos(self) -> tuple:
        """The recent photos, most recent first (kept in the settings file)."""
        return self.window.settings.recent_photos

    def show_recent(self) -> None:
        """List the recent photos in the panel's picker."""
        combo = self.window.panel.recent_photos
        combo.clear_items()
        combo.add_item(P.RECENT_PHOTOS)
        for path in self.recent_photos:
            combo.add_item(os.path.basename(path))
        combo.selected_index = 0

    def _add_to_strip(self, path: str) -> None:
        if path in self._strip or len(self._strip) >= MAX_STRIP:
            return
        thumb = style_thumbnail(path)
        if thumb is None:
            return
        self._strip.append(path)
        self.window.panel.add_style_thumbnail(thumb, os.path.basename(path), lambda: self.open_style(path))
        self.window.window.set_needs_layout()

    def open_photo(self, path: str, depth: Optional[str] = None) -> None:
        """Build the 3D photo of ``path`` on the worker with the state's photo spec (and ``depth``, if
        given); the current photo stays until the new one is built."""
        w = self.window
        spec = replace(w.state.spec, photo=str(path), depth=w.state.spec.depth if depth is None else depth)
        self.load(spec)

    def load(self, spec: "PhotoSpec") -> None:
        """Build the 3D photo ``spec`` describes on the worker; on success it becomes the state's spec."""
        w = self.window
        w.set_busy(f"Building the 3D photo of {os.path.basename(str(spec.photo))} ...", 0.1)
        session = w.session
        self.submit("open photo", lambda: session.load_photo(spec), lambda info: self._loaded(info, spec), key="photo")

    def _loaded(self, info: PhotoInfo, spec: "PhotoSpec") -> None:
        w = self.window
        w.remember(w.settings.with_photo(str(spec.photo)))
        w.state = replace(w.state, spec=spec, photo_info=info, stylize_available=False, pose=HOME, view_fov=None)
        p = w.panel
        h, wd = info.size
        p.photo_label.text = f"{os.path.basename(info.path)}  {wd}x{h}, {info.n_points:,} points"
        lo, hi = fov_range(info.fov_y_deg)
        p.fov.set_limits(lo, hi)
        p.fov.double_value = info.fov_y_deg
        p.fov_label.text = f"Field of view: {info.fov_y_deg:.1f} degrees"
        self.window.paths.set_limits(trajectory_limits(info.camera_range, info.scene))
        p.set_enabled(True)
        narrow = "" if info.range_scale >= 0.995 else f"; camera range {100 * info.range_scale:.0f} %"
        w.set_busy(f"3D photo ready in {info.seconds:.1f} s (depth: {info.depth_source}{narrow})", 0.5)
        w.photo_changed()  # requests the first (plain) frame
        p.model_label.text = "encoding the point cloud for the model ..."
        w.worker.submit("encode photo", w.session.prepare_stylized,
                        on_done=lambda r: w.post(lambda: self._stylize_ready(r)),
                        on_error=lambda name, e: w.post(lambda: self._stylize_failed(name, e)))

    def _set_stylize_available(self, available: bool, message: str) -> None:
        w = self.window
        w.state = replace(w.state, stylize_available=available)
        w.panel.set_line(w.panel.model_label, message)
        w.panel.stylized.enabled = available

    def _stylize_ready(self, r: StylizeInfo) -> None:
        self._set_stylize_available(r.available, r.message)
        self.window.set_busy(f"Ready (point cloud encoded in {r.seconds:.1f} s)" if r.available else "Ready", None)
        self.window.view_changed()

    def _stylize_failed(self, name: str, e: BaseException) -> None:
        self._set_stylize_available(False, NO_MODEL)
        self.task_failed(name, e)

    def open_style(self, path: str) -> None:
        """Read a style image on the worker and apply it (the encoded point cloud is re-used)."""
        w = self.window
        w.set_busy(f"Applying style {os.path.basename(path)} ...", 0.3)
        session = w.session
        self.submit("open style", lambda: session.load_style(path), lambda _hw: self._style_loaded(path), key="style")

    def _style_loaded(self, path: str) -> None:
        w = self.window
        w.state = replace(w.state, style=path)
        self._add_to_strip(str(path))
        if os.path.abspath(str(path)) not in BUNDLED_STYLES:  # (the strip always shows the bundled ones)
            w.remember(w.settings.with_style(str(path)))
        w.panel.style_label.text = os.path.basename(path)
        if w.state.stylize_available:
            w.set_busy("Style applied", None)
        elif w.session.checkpoint_path() is not None:  # the model is still loading or encoding: no NO_MODEL flash
            w.set_busy("Style chosen (shown once the model is ready)", None)
        else:
            w.set_busy(f"Style chosen ({NO_MODEL})", None)
        w.view_changed()

    @ui_callback
    def on_recent_photo(self, _text: str, index: int) -> None:
        if index >= 1:
            self.window.open_recent(self.recent_photos, index - 1, self.open_photo)

    def open_second_style(self, path: Optional[str]) -> None:
        """Read a second style image on the worker to mix with the first (None removes it)."""
        w = self.window
        session = w.session
        self.submit("open second style", lambda: session.load_second_style(path),
                    lambda _hw: self._style2_loaded(path), key="style2")

    def _style2_loaded(self, path: Optional[str]) -> None:
        w = self.window
        w.state = replace(w.state, style2=path)
        w.panel.style2_label.text = "no second style" if path is None else os.path.basename(path)
        w.set_status("Second style chosen: move Mix to blend" if path else "Second style removed")
        w.view_changed()

    def set_mix(self, value: float) -> None:
        """Mix of the two styles in [0, 1] (a re-blend on the worker, then a new frame)."""
        w = self.window
        w.set_blend("mix", w.panel.mix, value, w.session.set_mix)

    @ui_callback
    def on_open_style2(self) -> None:
        self.window.file_dialog(gui.FileDialog.OPEN, "Second style image", IMAGE_FILTERS, self.open_second_style)

    @ui_callback
    def on_mix(self, value: float) -> None:
        self.set_mix(value)

    def load_sample(self) -> None:
        """Open the bundled sample photo and style."""
        self.open_style(str(SAMPLE_STYLE))
        self.open_photo(str(SAMPLE_PHOTO))

    def change_spec(self, status: str, **changes: Any) -> None:
        """Change options of the photo spec (e.g. ``depth="prior"``) and rebuild the open photo with them;
        with no photo open, keep them for the next one and show ``status``."""
        w = self.window
        spec = replace(w.state.spec, **changes)  # InputError for a bad value: nothing changes
        if spec.photo is None:
            w.state = replace(w.state, spec=spec)
            w.set_status(status)
        else:
            self.load(spec)

    def set_refine_depth(self, method: Optional[str]) -> None:
        """Choose the depth-edge alignment (None: none) and rebuild the open photo with it."""
        self.change_spec(f"Depth edges: {method or 'as estimated'}", refine_depth=method)

    def set_depth(self, source: str) -> None:
        """Choose the depth source (a spec such as "prior" or a depth file) and rebuild the open photo with it.
        Depth Anything without its weights is not chosen: the status line points at the Download button."""
        if source == depth_anything.SPEC and depth_anything.cached_folder() is None:
            self.show_depth_model()
            self.show_depth_choice()
            self.window.set_status("Depth Anything's weights are not downloaded: click "
                                   f"\"{P.DOWNLOAD_LABEL}\" under Depth (once, needs the network)"
                                   if depth_anything.installed() else
                                   f"Depth Anything needs the depth extra: {depth_anything.EXTRA_HINT}")
            return
        self.change_spec(f"Depth source: {source}", depth=source)

    def show_depth_choice(self) -> None:
        """Show the state's depth source in the picker (a depth file shows as the picker's first entry)."""
        specs = [spec for spec, _ in P.DEPTH_CHOICES]
        depth = self.window.state.spec.depth
        self.window.panel.depth.selected_index = specs.index(depth) if depth in specs else 0

    def show_depth_model(self, downloading: bool = False) -> None:
        """The Download button: offered while the depth extra is installed and the weights are not cached."""
        button = self.window.panel.depth_download
        cached = depth_anything.cached_folder() is not None
        button.text = ("Downloading Depth Anything ..." if downloading else
                       "Depth Anything downloaded" if cached else P.DOWNLOAD_LABEL)
        button.enabled = not downloading and not cached and depth_anything.installed()

    def download_depth_model(self) -> None:
        """Download Depth Anything's pinned weights on a thread of their own, the progress in the status line;
        once they are in the cache, choose it as the depth source (the open photo is rebuilt with it)."""
        w = self.window
        if depth_anything.cached_folder() is not None:
            self.show_depth_model()
            self.set_depth(depth_anything.SPEC)
            return
        if self._download is not None and self._download.is_alive():
            return
        self.show_depth_model(downloading=True)
        w.set_busy("Downloading Depth Anything V2 Small (about 99 MB) ...", 0.0)
        shown = [-1]

        def progress(fraction: float) -> None:  # on the download thread: post only whole-percent changes
            percent = int(100 * fraction)
            if percent != shown[0]:
                shown[0] = percent
                w.post(lambda: w.set_busy(f"Downloading Depth Anything V2 Small ... {percent} %", fraction))

        def failed(name: str, e: BaseException) -> None:
            self.show_depth_model()
            self.task_failed(name, e)

        def run() -> None:
            try:
                depth_anything.download(progress=progress)
            except BaseException as e:  # noqa: BLE001 (InputError and anything else): a dialog, not a dead thread
                w.post(lambda: failed("download Depth Anything", e))
            else:
                w.post(self._depth_model_downloaded)

        # its own thread, not the compute worker's: the view keeps rendering through a long download
        self._download = threading.Thread(target=run, name="download Depth Anything", daemon=True)
        self._download.start()

    def _depth_model_downloaded(self) -> None:
        self.show_depth_model()
        self.window.set_busy("Depth Anything downloaded: it is the depth source now", None)
        self.set_depth(depth_anything.SPEC)
        self.window.panel.depth.selected_index = [spec for spec, _ in P.DEPTH_CHOICES].index(depth_anything.SPEC)

    # -- widget callbacks --------------------------------------------------------------
    @ui_callback
    def on_open_photo(self) -> None:
        self.window.file_dialog(gui.FileDialog.OPEN, "Open photo", IMAGE_FILTERS, self.open_photo,
                                recent=self.recent_photos)

    @ui_callback
    def on_open_style(self) -> None:
        self.window.file_dialog(gui.FileDialog.OPEN, "Open style image", IMAGE_FILTERS, self.open_style,
                                recent=self.window.settings.recent_styles)

    @ui_callback
    def on_sample(self) -> None:
        self.load_sample()

    @ui_callback
    def on_depth_choice(self, text: str, index: int) -> None:
        self.set_depth(P.DEPTH_CHOICES[index][0])

    @ui_callback
    def on_open_depth(self) -> None:
        self.window.file_dialog(gui.FileDialog.OPEN, "Open depth or disparity file", DEPTH_FILTERS, self.set_depth)

    @ui_callback
    def on_download_depth_model(self) -> None:
        self.download_depth_model()

    @ui_callback
    def on_refine_choice(self, text: str, index: int) -> None:
        self.set_refine_depth(P.REFINE_CHOICES[index][0])


class CameraPathController(Controller):
    """The trajectory, the camera-path preview in the view, loading and saving camera-path JSON."""

    def export_cameras(self):
        """The cameras the export (and the path preview) uses."""
        s = self.window.state
        if s.photo_info is None:
            raise InputError("photo", "open a photo first")
        loaded = s.loaded_path.cameras if s.loaded_path is not None else None
        return trajectory_cameras(s, s.photo_info.scene, s.photo_info.fov_y_deg, loaded)

    @ui_callback
    def on_trajectory(self, text: str, index: int) -> None:
        w = self.window
        if text == LOADED_PATH:
            w.state = replace(w.state, use_loaded_path=True, use_keyframes=False)
        else:
            w.state = replace(w.state, use_loaded_path=False, use_keyframes=False,
                              trajectory=replace(w.state.trajectory, name=text))
        self.refresh()

    @ui_callback
    def on_trajectory_params(self, _value: float) -> None:
        w = self.window
        p = w.panel
        t = replace(w.state.trajectory, x=float(p.amp_x.double_value), y=float(p.amp_y.double_value),
                    z=(0.0, float(p.forward.double_value)))
        w.state = replace(w.state, trajectory=t)

    def set_limits(self, limits: TrajectoryLimits) -> None:
        """Bound the trajectory's parameter fields by what the open photo shows cleanly
        (:func:`~stylize3d_app.viewer.state.trajectory_limits`) and clamp the trajectory into them."""
        w = self.window
        p = w.panel
        t = clamp_trajectory(w.state.trajectory, limits)
        w.state = replace(w.state, trajectory=t)
        p.amp_x.set_limits(0.0, limits.max_xy)
        p.amp_y.set_limits(0.0, limits.max_xy)
        p.forward.set_limits(limits.min_forward, limits.max_forward)
        for field, value in ((p.amp_x, t.x), (p.amp_y, t.y), (p.forward, t.z[1] if isinstance(t.z, tuple) else t.z)):
            if isinstance(value, (int, float)):
                field.double_value = float(value)

    # -- preview in the view ------------------------------------------------------------
    @property
    def playing(self) -> bool:
        return self.window.state.playback is not None

    @ui_callback
    def toggle_preview(self) -> None:
        """Play the export's camera path in the view (the Preview button), or stop it."""
        self.play(full=False)

    @ui_callback
    def on_preview_full(self) -> None:
        """Play the keyframe path at full quality (frames the worker cannot keep up with are skipped)."""
        w = self.window
        if not self.playing:
            w.state = replace(w.state, use_keyframes=w.state.keyframes is not None or w.state.use_keyframes)
            self.refresh()
        self.play(full=True)

    def play(self, full: bool) -> None:
        """Start (or stop, if playing) the camera-path preview; ``full`` renders full-quality frames."""
        w = self.window
        if w.state.photo_info is None:
            return
        if self.playing:
            self.stop()
            return
        pb = Playback(self.export_cameras(), time.monotonic(), w.state.export.fps, full=full)
        w.state = replace(w.state, playback=pb)
        w.panel.preview_path.text = "Stop preview (C)"
        w.panel.key_preview.text = "Stop preview"

    def step(self, now: float) -> None:
        """Tick: request the preview's camera for ``now``; stop at its end."""
        w = self.window
        pb = w.state.playback
        if pb is None:
            return
        if pb.full:  # full quality: every frame in turn, each once the one before is on screen
            if self._waiting:
                return
            i = pb.index + 1
            if i >= len(pb.cameras):
                self.stop()
                return
            w.state = replace(w.state, playback=replace(pb, index=i))
            self._waiting = True
            w.request_render(preview=False, camera=pb.cameras[i])
            return
        i = playback_frame(pb, now)
        if i is None:
            self.stop()
        elif i != pb.index:
            w.state = replace(w.state, playback=replace(pb, index=i))
            w.request_render(preview=not pb.full, camera=pb.cameras[i])

    def stop(self) -> None:
        """Stop the preview (if playing) and go back to the user's view."""
        w = self.window
        self._waiting = False
        if w.state.playback is not None:
            w.state = replace(w.state, playback=None)
            w.panel.preview_path.text = "Preview (C)"
            w.panel.key_preview.text = "Preview (full quality)"
            w.view_changed()

    # -- files --------------------------------------------------------------------------
    @ui_callback
    def on_load_path(self) -> None:
        self.window.file_dialog(gui.FileDialog.OPEN, "Load camera path", JSON_FILTERS, self.load_camera_path)

    def load_camera_path(self, path: str) -> None:
        """Read a camera-path JSON on the worker and use it for the preview and export."""
        self.submit("load camera path", lambda: read_camera_path(path), lambda cp: self._path_loaded(path, cp))

    def _path_loaded(self, path: str, cp: CameraPath) -> None:
        w = self.window
        p = w.panel
        if p.trajectory.number_of_items == len(p.trajectory_names):
            p.trajectory.add_item(LOADED_PATH)
        p.trajectory.selected_index = len(p.trajectory_names)
        fps = float(cp.fps) if cp.fps is not None else w.state.export.fps
        w.state = replace(w.state, loaded_path=cp, use_loaded_path=True,
                          export=replace(w.state.export, fps=min(fps, 240.0)))
        p.fps.double_value = w.state.export.fps
        w.state = replace(w.state, use_keyframes=False)
        self.refresh()
        w.set_status(f"Camera path {os.path.basename(path)}: {len(cp.cameras)} frames")

    # -- what the export follows; the keyframe editor -----------------------------------
    def refresh(self) -> None:
        """Show what the export follows: the trajectory's parameters only when it follows the trajectory."""
        w = self.window
        s, p = w.state, w.panel
        source = path_source(s)
        for n in (p.amp_x, p.amp_y, p.forward):
            n.enabled = source == "trajectory"
        p.use_keys.checked = s.use_keyframes
        if source == "keyframes":
            kp = s.keyframes
            p.path_info.text = ("following the keyframes: none yet" if kp is None else
                                f"following {len(kp.keyframes)} keyframes, {kp.duration_s:g} s")
        elif source == "loaded":
            n = 0 if s.loaded_path is None else len(s.loaded_path.cameras)
            p.path_info.text = f"following the camera path file ({n} frames)"
        else:
            p.path_info.text = ""
        labels = KE.keyframe_labels(s.keyframes)
        p.key_list.set_items(labels)
        if labels:
            i = min(max(0, self._selected), len(labels) - 1)
            self._selected = i
            p.key_list.selected_index = i
            k, d = s.keyframes.keyframes[i], s.keyframes.durations_s[i]
            p.key_fov.double_value = k.fov_y_deg
            p.key_seconds.double_value = d
        p.key_loop.checked = bool(s.keyframes is not None and s.keyframes.loop)
        for b in (p.key_up, p.key_down, p.key_delete, p.key_fov, p.key_seconds):
            b.enabled = bool(labels)

    _selected = 0
    _waiting = False  # a full-quality preview frame is requested and not shown yet

    def frame_shown(self) -> None:
        """A frame reached the view (or failed): the full-quality preview may request the next one."""
        self._waiting = False

    def edit_keyframes(self, kp) -> None:
        """Make ``kp`` the keyframe path (the export follows it) and show it."""
        w = self.window
        self.stop()
        w.state = replace(w.state, keyframes=kp, use_keyframes=kp is not None or w.state.use_keyframes)
        self.refresh()

    @ui_callback
    def add_keyframe(self) -> None:
        """Add the current view as a keyframe after the selected one (K)."""
        w = self.window
        s = w.state
        if s.photo_info is None:
            return
        cam = view_camera(s, s.photo_info.scene, s.photo_info.fov_y_deg)
        after = self._selected if s.keyframes is not None else None
        self._selected = 0 if s.keyframes is None else after + 1
        self.edit_keyframes(KE.add_keyframe(s.keyframes, cam, after=after))
        w.set_status(f"Keyframe {self._selected + 1} of {len(w.state.keyframes.keyframes)} added")

    @ui_callback
    def on_key_selected(self, _value: str, _double: bool) -> None:
        self._selected = max(0, self.window.panel.key_list.selected_index)
        self.refresh()

    @ui_callback
    def on_key_move(self, delta: int) -> None:
        s = self.window.state
        kp = KE.move_keyframe(s.keyframes, self._selected, delta)
        self._selected = max(0, min(len(kp.keyframes) - 1, self._selected + delta))
        self.edit_keyframes(kp)

    @ui_callback
    def on_key_delete(self) -> None:
        kp = KE.delete_keyframe(self.window.state.keyframes, self._selected)
        self._selected = max(0, self._selected - 1)
        self.edit_keyframes(kp)

    @ui_callback
    def on_key_fov(self, value: float) -> None:
        if self.window.state.keyframes is not None:
            self.edit_keyframes(KE.set_keyframe_fov(self.window.state.keyframes, self._selected, value))

    @ui_callback
    def on_key_seconds(self, value: float) -> None:
        if self.window.state.keyframes is not None:
            self.edit_keyframes(KE.set_keyframe_duration(self.window.state.keyframes, self._selected, value))

    @ui_callback
    def on_key_loop(self, checked: bool) -> None:
        self.edit_keyframes(KE.set_loop(self.window.state.keyframes, checked))

    @ui_callback
    def on_use_keys(self, checked: bool) -> None:
        w = self.window
        w.state = replace(w.state, use_keyframes=bool(checked))
        self.refresh()

    @ui_callback
    def on_load_keys(self) -> None:
        self.window.file_dialog(gui.FileDialog.OPEN, "Load keyframes", JSON_FILTERS, self.load_keyframes)

    def load_keyframes(self, path: str) -> None:
        """Read keyframes (or any camera path, as keyframes) on the worker and edit them."""
        self.submit("load keyframes", lambda: load_keyframes(path), lambda r: self._keys_loaded(path, r))

    def _keys_loaded(self, path: str, result) -> None:
        kp, _fps = result
        self._selected = 0
        self.edit_keyframes(kp)
        self.window.set_status(f"Keyframes {os.path.basename(path)}: {len(kp.keyframes)}")

    @ui_callback
    def on_save_keys(self) -> None:
        self.window.file_dialog(gui.FileDialog.SAVE, "Save keyframes", JSON_FILTERS, self.save_keyframes,
                                "keyframes.json")

    def save_keyframes(self, path: str) -> None:
        """Write the keyframes as camera-path JSON with their timing (on the worker)."""
        s = self.window.state
        if s.keyframes is None:
            raise InputError("keyframes", "add a keyframe first (Add keyframe, K)")
        kp, fps = s.keyframes, s.export.fps
        size = None if s.photo_info is None else frame_size(s.photo_info.size, s.export.size)
        self.submit("save keyframes", lambda: save_keyframes(path, kp, fps=fps, image_size=size),
                    lambda out: self.window.set_status(f"Saved {out}"))

    @ui_callback
    def on_save_path(self) -> None:
        self.window.file_dialog(gui.FileDialog.SAVE, "Save camera path", JSON_FILTERS, self.save_camera_path,
                                "camera_path.json")

    def save_camera_path(self, path: str) -> None:
        """Write the export's cameras as camera-path JSON (on the worker)."""
        s = self.window.state
        cams = self.export_cameras()
        fps, size = s.export.fps, frame_size(s.photo_info.size, s.export.size)
        self.submit("save camera path", lambda: save_camera_path(path, cams, fps=fps, image_size=size),
                    lambda out: self.window.set_status(f"Saved {out}"))


class ExportController(Controller):
    """Video export (progress, Cancel) and screenshots."""

    def __init__(self, window: ViewerHost, paths: CameraPathController) -> None:
        super().__init__(window)
        self.paths = paths
        self._cancel: Optional[threading.Event] = None  # set while an export runs

    @property
    def exporting(self) -> bool:
        return self._cancel is not None

    @ui_callback
    def on_export_params(self, *_args: Any) -> None:
        w = self.window
        p = w.panel
        fmt = P.EXPORT_FORMATS[max(0, p.format.selected_index)][0]
        try:
            e = VideoExport(format=fmt, size=int(p.size.int_value), frames=int(p.frames.int_value),
                               fps=float(p.fps.double_value))
        except InputError as err:
            w.show_error("export settings", err)
            return
        w.state = replace(w.state, export=e)

    @ui_callback
    def on_export(self) -> None:
        w = self.window
        if w.state.photo_info is None or self.exporting:
            return
        fmt = w.state.export.format
        w.file_dialog(gui.FileDialog.SAVE, f"Export ({fmt.upper()})", (), self.start_export,
                      export_destination("stylized.mp4", fmt).rstrip("/"))

    def start_export(self, path: str) -> str:
        """Export the camera path to ``path`` on the worker, with progress and Cancel; returns the destination."""
        w = self.window
        s = w.state
        if s.photo_info is None:
            raise InputError("photo", "open a photo first")
        if self.exporting:
            raise InputError("export", "an export is already running")
        e = s.export
        dest = export_destination(path, e.format)
        job = ExportJob(dest, self.paths.export_cameras(), frame_size(s.photo_info.size, e.size), e.fps,
                        shows_stylized(s))
        session = w.session
        return self.run_export(dest, f"Exporting {len(job.cameras)} frames to {dest} ...", len(job.cameras),
                               lambda progress, between: session.export(job, progress, between))

    def run_export(self, dest: str, text: str, n: int,
                   work: Callable[[Callable[[int, Optional[int]], None], Callable[[], object]], Any]) -> str:
        """Run ``work(progress, between_frames)`` on the worker as the export to ``dest`` (``n`` frames
        expected): progress on the bar, Cancel (``progress`` raises ExportCancelled once it is pressed),
        views rendered between frames (``between_frames``), the error dialog on failure. Returns ``dest``."""
        w = self.window
        if self.exporting:
            raise InputError("export", "an export is already running")
        cancel = self._cancel = threading.Event()
        t0 = time.monotonic()

        def progress(done: int, total: Optional[int]) -> None:
            if cancel.is_set():
                raise ExportCancelled(f"{dest}: export cancelled")
            text = export_progress_text(done, total or n, time.monotonic() - t0)
            w.post(lambda: w.set_busy(text, done / max(1, total or n)))

        w.panel.cancel.enabled = True
        w.panel.export.enabled = False
        w.set_busy(text, 0.0)
        worker = w.worker
        worker.submit("export", lambda: work(progress, worker.serve_pending_render),
                      on_done=lambda out: w.post(lambda: self._done(str(out), None)),
                      on_error=lambda name, err: w.post(lambda: self._done(dest, err)))
        return dest

    def _done(self, dest: str, error: Optional[BaseException]) -> None:
        w = self.window
        self._cancel = None
        w.panel.cancel.enabled = False
        w.panel.export.enabled = True
        if error is None:
            w.stats["last_export"] = dest
            w.set_busy(f"Exported {dest}", 1.0)
        elif isinstance(error, ExportCancelled):
            w.set_busy("Export cancelled; nothing was written", None)
        else:
            w.set_busy(None, None)
            w.show_error("export", error)

    def cancel(self) -> None:
        """Cancel the running export (nothing is written); the window is closing or the user asked."""
        if self._cancel is not None:
            self._cancel.set()

    @ui_callback
    def on_cancel(self) -> None:
        """The Cancel button: stop the running export (nothing is written)."""
        if self.exporting:
            self.cancel()
            self.window.set_status("Cancelling the export ...")

    @ui_callback
    def on_screenshot(self) -> None:
        if self.window.state.photo_info is None:
            return
        self.window.file_dialog(gui.FileDialog.SAVE, "Save screenshot (PNG)", ((".png", "PNG"),), self.save_screenshot,
                                "screenshot.png")

    def save_screenshot(self, path: str) -> None:
        """Save the view at the view's size on screen (or the panel's screenshot size): the frame on screen
        when it is final and of that size, else a fresh full-quality render."""
        w = self.window
        s = w.state
        if s.photo_info is None:
            raise InputError("photo", "open a photo first")
        path = path if path.lower().endswith((".png", ".jpg", ".jpeg", ".webp")) else path + ".png"
        f = w.image.frame
        size = screenshot_size(s.photo_info.size, (f.height, f.width), int(w.panel.shot_size.int_value))
        final = w.final_frame()
        if final is not None and final.image.shape[:2] == size:
            image = final.image
            job = lambda: save_image(path, image)  # noqa: E731
        else:
            cam = view_camera(s, s.photo_info.scene, s.photo_info.fov_y_deg)
            stylized, session = shows_stylized(s), w.session
            job = lambda: save_image(path, session.render(cam, size[0], size[1], preview=False, stylized=stylized))  # noqa: E731
        self.submit("screenshot", job, lambda _: w.set_status(f"Saved {path}"))
