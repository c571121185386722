"""Stand-ins for the viewer window's surface that the controllers use (no GUI): a worker that runs each
task at once and a window with a real session and the real camera-path, export and Applications
controllers. Used by tests/app/test_viewer_applications.py and tests/scene/test_person_mask.py."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any, List

import stylize3d_app.viewer.applications as A
from stylize3d_app.viewer.actions import CameraPathController, ExportController
from stylize3d_app.viewer.session import SAMPLE_PHOTO, SAMPLE_STYLE, ViewerSession
from stylize3d_app.viewer.state import VideoExport as ViewerExport, ViewState
from stylize3d_core.pipeline import PhotoSpec

MAX_SIZE = 96
"""The photos' long side in these tests (small: fast)."""


class SyncWorker:
    """Runs each task at once (the window's worker runs them on its thread, in order)."""

    def __init__(self) -> None:
        self.names: List[str] = []

    def submit(self, name, fn, on_done=None, on_error=None, key=None):
        self.names.append(name)
        try:
            r = fn()
        except Exception as e:  # handed to on_error, as the worker does
            if on_error is None:
                raise
            on_error(name, e)
            return
        if on_done is not None:
            on_done(r)

    @staticmethod
    def serve_pending_render() -> bool:
        return False


class StandInWindow:
    """The window's surface the controllers use, with a real session and the real path/export controllers."""

    def __init__(self, session: ViewerSession) -> None:
        self.session = session
        info = session.info
        self.state = ViewState(spec=PhotoSpec(str(SAMPLE_PHOTO), "prior", max_size=MAX_SIZE), photo_info=info,
                               stylize_available=session.can_stylize, style=str(SAMPLE_STYLE),
                               export=ViewerExport(format="gif", size=64, frames=4, fps=10))
        self.worker = SyncWorker()
        self.errors: List[str] = []
        self.status = ""
        self.views_changed = 0
        self.loaded: List[Any] = []
        self.stats: dict = {}
        flag = lambda: SimpleNamespace(enabled=False)  # noqa: E731
        self.panel = SimpleNamespace(cancel=flag(), export=flag())
        self.paths = CameraPathController(self)
        self.exports = ExportController(self, self.paths)
        self.photos = SimpleNamespace(load=lambda spec: self.loaded.append(spec),
                                      _loaded=lambda info, spec: self.loaded.append((info, spec)))
        self.applications = A.ApplicationsController(self)

    def post(self, fn):
        fn()

    def set_status(self, text):
        self.status = text

    def set_busy(self, text, fraction=None):
        if text is not None:
            self.status = text

    def show_error(self, what, error):
        self.errors.append(f"{what}: {error}")

    def view_changed(self):
        self.views_changed += 1
