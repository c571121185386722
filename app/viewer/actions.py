"""What the viewer window does besides showing the view: open photos and styles, camera paths, export.

:class:`WindowActions` is a mixin of :class:`~app.viewer.window.ViewerWindow`
(it holds no state of its own). Its methods run on the GUI main thread; the
work they start (reading files, building the 3D photo, encoding, exporting)
runs on the compute worker, whose results come back through ``self._post``
(``post_to_main_thread``). Errors become dialogs; what was loaded stays loaded.
"""

from __future__ import annotations

import functools
import os
import threading
import time
import traceback
from dataclasses import replace
from typing import Any, Callable, Optional

import open3d.visualization.gui as gui

from stylize3d_core.errors import InputError
from stylize3d_core.io.camera_path import CameraPath, load_camera_path, save_camera_path
from stylize3d_core.io.images import save_image
from stylize3d_core.io.video import ExportCancelled
from stylize3d_core.render.plain import frame_size

from . import panel as P
from .orbit import HOME
from .session import NO_MODEL, SAMPLE_PHOTO, SAMPLE_STYLE, ExportJob, PhotoInfo, StylizeInfo
from .state import (
    LOADED_PATH, ExportSettings, export_destination, fov_range, trajectory_cameras, view_camera,
)

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


class WindowActions:
    """Photo, style, depth, camera-path, export and screenshot actions of the viewer window (a mixin).

    Thread use: GUI main thread only; the work runs on the compute worker.
    """

    # -- photo, depth, style, model ------------------------------------------------------
    def open_photo(self, path: str, depth: Optional[str] = None) -> None:
        """Load a photo on the worker (the current photo stays until the new one is built)."""
        depth = self.state.depth if depth is None else depth
        s = self.state
        self._set_busy(f"Building the 3D photo of {os.path.basename(path)} ...", 0.1)
        self.worker.submit(
            "open photo", lambda: self.session.load_photo(path, depth, max_size=s.max_size, fov=s.photo_fov,
                                                          refine_depth=s.refine_depth),
            on_done=lambda info: self._post(lambda: self._on_photo_loaded(info, depth)),
            on_error=lambda name, e: self._post(lambda: self._on_task_failed(name, e)), key="photo")

    def _on_photo_loaded(self, info: PhotoInfo, depth: str) -> None:
        self.info = info
        self.state = replace(self.state, photo=info.path, depth=depth, pose=HOME, view_fov=None)
        self.stylize_available = False
        p = self.panel
        h, w = info.size
        p.photo_label.text = f"{os.path.basename(info.path)}  {w}x{h}, {info.n_points:,} points"
        lo, hi = fov_range(info.fov_y_deg)
        p.fov.set_limits(lo, hi)
        p.fov.double_value = info.fov_y_deg
        p.set_enabled(True)
        self._set_busy(f"3D photo ready in {info.seconds:.1f} s (depth: {info.depth_source})", 0.5)
        self._display_hw = (0, 0)
        self._update_display_size()  # requests the first (plain) frame
        p.model_label.text = "encoding the point cloud for the model ..."
        self.worker.submit("encode photo", self.session.prepare_stylized,
                           on_done=lambda r: self._post(lambda: self._on_stylize_ready(r)),
                           on_error=lambda name, e: self._post(lambda: self._on_stylize_failed(name, e)))

    def _on_stylize_ready(self, r: StylizeInfo) -> None:
        self.stylize_available = r.available
        self.panel.model_label.text = r.message
        self.panel.stylized.enabled = r.available
        self._set_busy(f"Ready (point cloud encoded in {r.seconds:.1f} s)" if r.available else "Ready", None)
        self._view_changed()

    def _on_stylize_failed(self, name: str, e: BaseException) -> None:
        self.stylize_available = False
        self.panel.model_label.text = NO_MODEL
        self.panel.stylized.enabled = False
        self._set_busy(None, None)
        self.show_error(name, e)

    def _on_task_failed(self, name: str, e: BaseException) -> None:
        self._set_busy(None, None)
        self.show_error(name, e)

    def open_style(self, path: str) -> None:
        """Read a style image on the worker and apply it (the encoded point cloud is re-used)."""
        self._set_busy(f"Applying style {os.path.basename(path)} ...", 0.3)
        self.worker.submit("open style", lambda: self.session.load_style(path),
                           on_done=lambda hw: self._post(lambda: self._on_style_loaded(path)),
                           on_error=lambda name, e: self._post(lambda: self._on_task_failed(name, e)), key="style")

    def _on_style_loaded(self, path: str) -> None:
        self.state = replace(self.state, style=path)
        self.panel.style_label.text = os.path.basename(path)
        self._set_busy("Style applied" if self.stylize_available else f"Style chosen ({NO_MODEL})", None)
        self._view_changed()

    @ui_callback
    def _on_open_photo(self) -> None:
        self._file_dialog(gui.FileDialog.OPEN, "Open photo", IMAGE_FILTERS, self.open_photo)

    @ui_callback
    def _on_open_style(self) -> None:
        self._file_dialog(gui.FileDialog.OPEN, "Open style image", IMAGE_FILTERS, self.open_style)

    @ui_callback
    def _on_sample(self) -> None:
        self.load_sample()

    def load_sample(self) -> None:
        """Open the bundled sample photo and style."""
        self.open_style(str(SAMPLE_STYLE))
        self.open_photo(str(SAMPLE_PHOTO))

    @ui_callback
    def _on_depth_choice(self, text: str, index: int) -> None:
        self._set_depth(P.DEPTH_CHOICES[index][0])

    @ui_callback
    def _on_open_depth(self) -> None:
        self._file_dialog(gui.FileDialog.OPEN, "Open depth or disparity file", DEPTH_FILTERS, self._set_depth)

    @ui_callback
    def _on_refine_choice(self, text: str, index: int) -> None:
        self.set_refine_depth(P.REFINE_CHOICES[index][0])

    def set_refine_depth(self, method: Optional[str]) -> None:
        """Choose the depth-edge alignment (None: none) and rebuild the open photo with it."""
        self.state = replace(self.state, refine_depth=method)
        if self.state.photo is None:
            self._set_status(f"Depth edges: {method or 'as estimated'}")
        else:
            self.open_photo(self.state.photo)

    def _set_depth(self, spec: str) -> None:
        if self.state.photo is None:
            self.state = replace(self.state, depth=spec)
            self._set_status(f"Depth source: {spec}")
        else:
            self.open_photo(self.state.photo, depth=spec)

    def _file_dialog(self, mode, title: str, filters, on_done: Callable[[str], None]) -> None:
        dlg = gui.FileDialog(mode, title, self.window.theme)
        for ext, desc in filters:
            dlg.add_filter(ext, desc)

        def done(path: str) -> None:
            self.window.close_dialog()
            try:
                on_done(path)
            except Exception as e:  # reported to the user; the session stays usable
                self.show_error(title, e)

        dlg.set_on_cancel(self.window.close_dialog)
        dlg.set_on_done(done)
        self.window.show_dialog(dlg)

    # -- camera path: trajectory, preview, load / save -----------------------------------------
    @ui_callback
    def _on_trajectory(self, text: str, index: int) -> None:
        if text == LOADED_PATH:
            self.state = replace(self.state, use_loaded_path=True)
        else:
            self.state = replace(self.state, use_loaded_path=False, trajectory=replace(self.state.trajectory, name=text))

    @ui_callback
    def _on_trajectory_params(self, _value: float) -> None:
        p = self.panel
        t = replace(self.state.trajectory, x=float(p.amp_x.double_value), y=float(p.amp_y.double_value),
                    z=(0.0, float(p.forward.double_value)))
        self.state = replace(self.state, trajectory=t)

    def export_cameras(self):
        """The cameras the export (and the path preview) uses."""
        if self.info is None:
            raise InputError("photo", "open a photo first")
        loaded = self.loaded_path.cameras if self.loaded_path is not None else None
        return trajectory_cameras(self.state, self.info.scene, self.info.fov_y_deg, loaded)

    @ui_callback
    def _on_preview_path(self) -> None:
        if self.info is None:
            return
        if self._playback is not None:
            self._stop_playback()
            return
        self._playback = {"cameras": self.export_cameras(), "start": time.monotonic(), "fps": self.state.export.fps,
                          "index": -1}
        self.panel.preview_path.text = "Stop preview (C)"

    def _step_playback(self, now: float) -> None:
        pb = self._playback
        i = int((now - pb["start"]) * pb["fps"])
        if i >= len(pb["cameras"]):
            self._stop_playback()
            return
        if i != pb["index"]:
            pb["index"] = i
            self._request_render(preview=True, camera=pb["cameras"][i])

    def _stop_playback(self) -> None:
        if self._playback is not None:
            self._playback = None
            self.panel.preview_path.text = "Preview (C)"
            self._view_changed()

    @ui_callback
    def _on_load_path(self) -> None:
        self._file_dialog(gui.FileDialog.OPEN, "Load camera path", JSON_FILTERS, self.load_camera_path)

    def load_camera_path(self, path: str) -> None:
        """Read a camera-path JSON on the worker and use it for the preview and export."""
        self.worker.submit("load camera path", lambda: load_camera_path(path),
                           on_done=lambda cp: self._post(lambda: self._on_path_loaded(path, cp)),
                           on_error=lambda name, e: self._post(lambda: self._on_task_failed(name, e)))

    def _on_path_loaded(self, path: str, cp: CameraPath) -> None:
        self.loaded_path = cp
        p = self.panel
        if p.trajectory.number_of_items == len(p.trajectory_names):
            p.trajectory.add_item(LOADED_PATH)
        p.trajectory.selected_index = len(p.trajectory_names)
        fps = float(cp.fps) if cp.fps is not None else self.state.export.fps
        self.state = replace(self.state, use_loaded_path=True, export=replace(self.state.export, fps=min(fps, 240.0)))
        p.fps.double_value = self.state.export.fps
        self._set_status(f"Camera path {os.path.basename(path)}: {len(cp.cameras)} frames")

    @ui_callback
    def _on_save_path(self) -> None:
        self._file_dialog(gui.FileDialog.SAVE, "Save camera path", JSON_FILTERS, self.save_camera_path)

    def save_camera_path(self, path: str) -> None:
        """Write the export's cameras as camera-path JSON (on the worker)."""
        cams = self.export_cameras()
        fps, size = self.state.export.fps, frame_size(self.info.size, self.state.export.size)
        self.worker.submit("save camera path", lambda: save_camera_path(path, cams, fps=fps, image_size=size),
                           on_done=lambda out: self._post(lambda: self._set_status(f"Saved {out}")),
                           on_error=lambda name, e: self._post(lambda: self._on_task_failed(name, e)))

    # -- export, screenshot ---------------------------------------------------------------
    @ui_callback
    def _on_export_params(self, *_args: Any) -> None:
        p = self.panel
        fmt = P.EXPORT_FORMATS[max(0, p.format.selected_index)][0]
        try:
            e = ExportSettings(format=fmt, size=int(p.size.int_value), frames=int(p.frames.int_value),
                               fps=float(p.fps.double_value))
        except InputError as err:
            self.show_error("export settings", err)
            return
        self.state = replace(self.state, export=e)

    @ui_callback
    def _on_export(self) -> None:
        if self.info is None or self._export_cancel is not None:
            return
        fmt = self.state.export.format
        self._file_dialog(gui.FileDialog.SAVE, f"Export ({fmt.upper()})", (), self.start_export)

    def start_export(self, path: str) -> str:
        """Export the camera path to ``path`` on the worker, with progress and Cancel; returns the destination."""
        if self.info is None:
            raise InputError("photo", "open a photo first")
        if self._export_cancel is not None:
            raise InputError("export", "an export is already running")
        e = self.state.export
        dest = export_destination(path, e.format)
        job = ExportJob(dest, self.export_cameras(), frame_size(self.info.size, e.size), e.fps,
                        self.state.stylized and self.stylize_available)
        cancel = self._export_cancel = threading.Event()

        def progress(done: int, total: Optional[int]) -> None:
            if cancel.is_set():
                raise ExportCancelled(f"{dest}: export cancelled")
            self._post(lambda: self._set_busy(f"Exporting {done}/{total} frames ...", done / max(1, total or 1)))

        self.panel.cancel.enabled = True
        self.panel.export.enabled = False
        self._set_busy(f"Exporting {len(job.cameras)} frames to {dest} ...", 0.0)
        self.worker.submit("export", lambda: self.session.export(job, progress, self.worker.serve_pending_render),
                           on_done=lambda out: self._post(lambda: self._on_export_done(str(out), None)),
                           on_error=lambda name, err: self._post(lambda: self._on_export_done(dest, err)))
        return dest

    def _on_export_done(self, dest: str, error: Optional[BaseException]) -> None:
        self._export_cancel = None
        self.panel.cancel.enabled = False
        self.panel.export.enabled = True
        if error is None:
            self.stats["last_export"] = dest
            self._set_busy(f"Exported {dest}", 1.0)
        elif isinstance(error, ExportCancelled):
            self._set_busy("Export cancelled; nothing was written", None)
        else:
            self._set_busy(None, None)
            self.show_error("export", error)

    @property
    def exporting(self) -> bool:
        return self._export_cancel is not None

    @ui_callback
    def _on_cancel(self) -> None:
        if self._export_cancel is not None:
            self._export_cancel.set()
            self._set_status("Cancelling the export ...")

    @ui_callback
    def _on_escape(self) -> None:
        if self.panel.help.visible:
            self._on_help()
        else:
            self._on_cancel()

    @ui_callback
    def _on_screenshot(self) -> None:
        if self.info is None:
            return
        self._file_dialog(gui.FileDialog.SAVE, "Save screenshot (PNG)", ((".png", "PNG"),), self.save_screenshot)

    def save_screenshot(self, path: str) -> None:
        """Save the view at full resolution: the frame on screen once it is final, else a fresh render."""
        if self.info is None:
            raise InputError("photo", "open a photo first")
        path = path if path.lower().endswith((".png", ".jpg", ".jpeg", ".webp")) else path + ".png"
        if self.scheduler.settled and self._shown is not None and not self._shown.preview:
            image = self._shown.image
            job = lambda: save_image(path, image)  # noqa: E731
        else:
            cam = view_camera(self.state, self.info.scene, self.info.fov_y_deg)
            size, stylized, session = self._display_hw, self.state.stylized and self.stylize_available, self.session
            job = lambda: save_image(path, session.render(cam, size[0], size[1], preview=False, stylized=stylized))  # noqa: E731
        self.worker.submit("screenshot", job, on_done=lambda _: self._post(lambda: self._set_status(f"Saved {path}")),
                           on_error=lambda name, e: self._post(lambda: self._on_task_failed(name, e)))
