"""The viewer's :class:`ExportController`: video export with progress and Cancel, and screenshots.

A controller of the window (:mod:`.controller`): main thread only; the export runs on the compute
worker (:meth:`ExportController.run_export` also runs the Applications menu's exports). The cancel event
of a running export is its one piece of state outside the window's ``ViewState``: a thread handle.
"""

from __future__ import annotations

import threading
import time
from dataclasses import replace
from typing import Any, Callable, Optional

import open3d.visualization.gui as gui

from stylize3d_core.errors import InputError
from stylize3d_core.io.images import save_image
from stylize3d_core.io.video import ExportCancelled
from stylize3d_core.render.plain import frame_size

from . import panel as P
from .controller import Controller, ui_callback
from .host import ViewerHost
from .path_controller import CameraPathController
from .session import ExportJob
from .state import VideoExport, export_destination, export_progress_text, screenshot_size, shows_stylized, view_camera


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
