"""The window's dialogs and status line: error and message dialogs, the file dialog (a typed path,
Browse... and the recent files), the status line and progress bar, and the recent files kept in the
settings file (the menu bar lists them).

:class:`WindowDialogs` is a mixin of :class:`~stylize3d_app.viewer.window.ViewerWindow`: main thread only.
While a dialog is open the letter shortcuts are off (``_dialog_open``); an error's dialog puts "Error
(what)" in the status line until it is closed.
"""

from __future__ import annotations

import os
from typing import Callable, Optional, Tuple

import open3d.visualization.gui as gui

from stylize3d_core.errors import InputError

from . import panel as P
from .applications import build_applications_menu
from .settings import MAX_RECENT, ViewerSettings, save_settings
from .state import resolve_open_path, resolve_typed_path


class WindowDialogs:
    """Dialogs, status and recent files of :class:`~stylize3d_app.viewer.window.ViewerWindow` (a mixin; see
    the module docstring)."""

    # -- recent files (the settings file) ---------------------------------------------
    @staticmethod
    def _extra_menus():
        """The menus between View and Help: the Applications menu (``applications.py``)."""
        return (("Applications", build_applications_menu()),)

    def remember(self, settings: ViewerSettings) -> None:
        """Keep ``settings`` (recent files, last folder): write the settings file and rebuild the menu bar
        with the recent files. A settings file that cannot be written is said in the status line."""
        if settings == self.settings:
            return
        self.settings = settings
        try:
            save_settings(settings)
        except Exception as e:  # not fatal: the history is only not kept for the next run
            self.set_status(f"Recent files not saved: {e}")
        self.app.menubar = P.build_menubar(settings.recent_photos, settings.recent_styles, self.state.stylized,
                                           extra=self._extra_menus())
        self.window.set_needs_layout()
        self.photos.show_recent()

    def open_recent(self, paths: Tuple[str, ...], index: int, open_fn: Callable[[str], None]) -> None:
        """A recent file was chosen (File > Recent ...): open it, or say it is gone and forget it."""
        if not 0 <= index < len(paths):
            return
        path = paths[index]
        if not os.path.isfile(path):
            self.remember(self.settings.without(path))
            self.show_error("open recent", InputError(path, "no such file any more (removed from the recent files)"))
            return
        open_fn(path)

    # -- errors and status ------------------------------------------------------------
    def show_error(self, what: str, error: BaseException, then: Optional[Callable[[], None]] = None) -> None:
        """Show ``error`` in a dialog and keep it for the test report (main thread). The status line says
        "Error (what)" while the dialog is open and goes back to what it said when it is closed; ``then``
        runs after its OK (the path dialog comes back with what was typed)."""
        message = str(error) if isinstance(error, InputError) else f"{type(error).__name__}: {error}"
        self.errors.append(f"{what}: {message}")
        if self._status_before_error is None:
            self._status_before_error = self.panel.status_text
        self.panel.set_status(f"Error ({what})")
        self.show_message("stylize3d: " + what, message, [("OK", then)])

    def show_message(self, title: str, message: str, buttons=None) -> None:
        """A modal message with buttons ((label, callback); default a single OK that closes it)."""
        def close_then(cb: Optional[Callable[[], None]]) -> Callable[[], None]:
            def run() -> None:
                self.close_dialog()
                if cb is not None:
                    cb()
            return run

        buttons = buttons or [("OK", None)]
        self.show_dialog(P.message_dialog(self.em, title, message, [(label, close_then(cb)) for label, cb in buttons]))

    def show_dialog(self, dlg: gui.Dialog) -> None:
        """Show a modal dialog (letter shortcuts are off while one is open)."""
        self._dialog_open = True
        self.window.show_dialog(dlg)
        self.window.post_redraw()  # Open3D draws a new dialog's first frame garbled until the next redraw

    def close_dialog(self) -> None:
        """Close the open dialog; an error's status line goes back to what it said before."""
        self._dialog_open = False
        self.window.close_dialog()
        if self._status_before_error is not None:
            self.panel.set_status(self._status_before_error)
            self._status_before_error = None

    @property
    def dialog_open(self) -> bool:
        return self._dialog_open

    def set_status(self, text: str) -> None:
        """Show ``text`` in the status line."""
        self.panel.set_status(text)

    def set_busy(self, text: Optional[str], fraction: Optional[float] = None) -> None:
        """Show ``text`` (if not None) in the status line and ``fraction`` (None: none) on the progress bar."""
        if text is not None:
            self.panel.set_status(text)
        self.panel.progress.value = 0.0 if fraction is None else float(min(1.0, max(0.0, fraction)))

    def file_dialog(self, mode, title: str, filters, on_done: Callable[[str], None], default_name: str = "",
                    recent: Tuple[str, ...] = ()) -> None:
        """Choose a file; ``on_done(path)`` runs with it (its errors become a dialog). A small dialog asks
        for a typed path (absolute, ``~/...``, or relative to the folder shown: the last used one), with
        Browse... for Open3D's file browser in that folder and, when opening, the ``recent`` files to pick
        with one click. Opening checks that the file exists (a clear error names it if not)."""
        self._path_dialog(mode, title, filters, on_done, default_name, recent)

    def _run_chosen(self, title: str, on_done: Callable[[str], None], path: str) -> None:
        self.close_dialog()
        self.last_folder = os.path.dirname(path.rstrip("/")) or self.last_folder
        try:
            on_done(path)
        except Exception as e:  # reported to the user; the session stays usable
            self.show_error(title, e)

    def _browse(self, mode, title: str, filters, on_done: Callable[[str], None]) -> None:
        dlg = gui.FileDialog(mode, title, self.window.theme)
        for ext, desc in filters:
            dlg.add_filter(ext, desc)
        if self.last_folder:
            dlg.set_path(self.last_folder)
        dlg.set_on_cancel(self.close_dialog)
        dlg.set_on_done(lambda path: self._run_chosen(title, on_done, path))
        self.show_dialog(dlg)

    def _path_dialog(self, mode, title: str, filters, on_done: Callable[[str], None], default_name: str,
                     recent: Tuple[str, ...], text: Optional[str] = None) -> None:
        saving = mode == gui.FileDialog.SAVE
        folder = self.last_folder or os.getcwd()
        em = self.em
        dlg = gui.Dialog(title)
        box = gui.Vert(0.5 * em, gui.Margins(int(em), int(em), int(em), int(em)))
        box.add_child(gui.Label(title))
        box.add_child(gui.Label(f"in {folder}"))
        edit = gui.TextEdit()
        if text is None:
            text = os.path.join(folder, default_name) if default_name else folder + os.sep
        edit.text_value = text
        edit.tooltip = "an absolute path, ~/..., or a path relative to the folder above"
        box.add_child(edit)
        self.path_edit = edit  # (test hooks type into it)

        def accept() -> None:
            try:
                path = (resolve_typed_path if saving else resolve_open_path)(edit.text_value, folder)
            except InputError as e:  # say why, then ask again with what was typed
                typed = edit.text_value
                self.show_error(title, e, lambda: self._path_dialog(mode, title, filters, on_done, default_name,
                                                                      recent, typed))
                return
            self._run_chosen(title, on_done, path)

        def browse() -> None:
            self.close_dialog()
            self._browse(mode, title, filters, on_done)

        if recent and not saving:
            box.add_child(gui.Label("Recent:"))
            for i, path in enumerate(recent[:MAX_RECENT]):  # one click opens it (a missing one is forgotten)
                b = gui.Button(P.recent_label(path, i))
                b.horizontal_padding_em = 0.3
                b.set_on_clicked(lambda i=i: self.open_recent(recent, i, lambda p: self._run_chosen(title, on_done, p)))
                box.add_child(b)
        row = gui.Horiz(0.5 * em)
        for label, cb in (("Browse...", browse), ("Cancel", self.close_dialog), ("Save" if saving else "Open", accept)):
            b = gui.Button(label)
            b.set_on_clicked(cb)
            row.add_child(b)
        box.add_child(row)
        dlg.add_child(box)
        self._path_ok = accept  # (test hooks press Save / Open)
        self.show_dialog(dlg)
