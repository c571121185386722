"""The base of the window's controllers (:mod:`.photo_controller`, :mod:`.path_controller`,
:mod:`.export_controller`, :mod:`.applications`): :class:`Controller`, the :func:`ui_callback` wrapper of
every GUI callback, the modal forms of their dialogs (:meth:`Controller._dialog`) and the file
dialogs' filters.

A controller keeps no app state of its own: everything lives in the window's
:class:`~stylize3d_app.viewer.state.ViewState`, which it replaces. It sees the window only as a
:class:`~stylize3d_app.viewer.host.ViewerHost`. Its methods run on the GUI main thread; the work they
start runs on the compute worker, whose results come back through ``window.post``
(``post_to_main_thread``). Errors become dialogs; what was loaded stays loaded.
"""

from __future__ import annotations

import functools
import traceback
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import open3d.visualization.gui as gui

from .host import ViewerHost

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
        self.dialog_fields: Dict[str, Any] = {}  # test hooks: the last form's widgets by name (_dialog)
        self.dialog_ok: Optional[Callable[[], None]] = None  # and its OK button's action

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

    # -- modal forms ------------------------------------------------------------------------
    def _dialog(self, title: str, lines: Sequence[str], fields: List[Tuple[str, str, gui.Widget]],
                ok: Tuple[str, Callable[[], None]]) -> None:
        """A modal dialog: ``title``, text ``lines``, labelled ``fields`` (name, label, widget), Cancel and
        ``ok`` (label, action; the dialog closes first, the action's errors become a dialog)."""
        w = self.window
        em = w.em
        dlg = gui.Dialog(title)
        box = gui.Vert(0.4 * em, gui.Margins(int(em), int(em), int(em), int(em)))
        box.add_child(gui.Label(title))
        for line in lines:
            box.add_child(gui.Label(line))
        grid = gui.VGrid(2, 0.4 * em)
        for _name, label, widget in fields:
            grid.add_child(gui.Label(label))
            grid.add_child(widget)
        if fields:
            box.add_child(grid)
        label, action = ok

        def run_ok() -> None:
            w.close_dialog()
            try:
                action()
            except Exception as e:  # reported to the user; the session stays usable
                self.show_error(title.lower(), e)

        row = gui.Horiz(0.5 * em)
        row.add_stretch()
        for text, cb in (("Cancel", w.close_dialog), (label, run_ok)):
            b = gui.Button(text)
            b.set_on_clicked(cb)
            row.add_child(b)
        box.add_child(row)
        dlg.add_child(box)
        self.dialog_fields = {name: widget for name, _label, widget in fields}
        self.dialog_ok = run_ok
        w.show_dialog(dlg)

    @staticmethod
    def _slider(value: float, lo: float = 0.0, hi: float = 1.0) -> gui.Slider:
        s = gui.Slider(gui.Slider.DOUBLE)
        s.set_limits(lo, hi)
        s.double_value = float(value)
        return s

    @staticmethod
    def _number(value: float, lo: float, hi: float) -> gui.NumberEdit:
        n = gui.NumberEdit(gui.NumberEdit.DOUBLE)
        n.set_limits(lo, hi)
        n.decimal_precision = 4
        n.double_value = float(value)
        return n
