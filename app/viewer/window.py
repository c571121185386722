"""The viewer window: an Open3D ``gui.Window`` showing the rendered view as an image, with a side panel.

Our renderer is the point rasterizer (+ the model's decoder), not Open3D's 3D
scene renderer, so the view is a ``gui.ImageWidget`` updated with each rendered
frame, and its mouse events drive the camera (:mod:`stylize3d_app.viewer.orbit`).

Threads:

* the GUI **main thread** runs this class: widgets, ``_on_*`` callbacks, the
  tick timer (rest detection, camera-path preview);
* the **compute worker** (:class:`~stylize3d_app.viewer.worker.ComputeWorker`) runs the
  :class:`~stylize3d_app.viewer.session.ViewerSession`: loading, encoding, styles,
  renders, export. Its results come back through :meth:`ViewerWindow.post`
  (``gui.Application.instance.post_to_main_thread``).

Composition: this class owns the widgets, the live view (mouse, keys, frame
scheduling) and closing; what the panel's buttons do is in three controllers
(:mod:`stylize3d_app.viewer.actions`): ``photos``, ``paths`` and ``exports``. All app
state is one :class:`~stylize3d_app.viewer.state.ViewState` in ``self.state``.

Closing: a close request first stops the worker (and the test-script thread),
then a helper thread waits for them and posts the real ``window.close()``; so no
thread posts to a destroyed window and nothing closes from a tick callback
(which crashes Open3D).
"""

from __future__ import annotations

import os
import sys
import threading
import time
import traceback
from collections import deque
from dataclasses import dataclass, replace
from typing import Any, Callable, Dict, List, Optional, Tuple

import numpy as np
import open3d as o3d
import open3d.visualization.gui as gui

from stylize3d_core.defaults import DEFAULT_STRENGTH
from stylize3d_core.errors import InputError
from stylize3d_core.models.decoder_onnx import onnx_threads
from stylize3d_core.pipeline import PhotoSpec
from stylize3d_core.render.plain import frame_size
from stylize3d_core.threads import torch_threads

from . import panel as P
from .actions import CameraPathController, ExportController, PhotoController, ui_callback
from .applications import ApplicationsController, build_applications_menu
from .backend import widget_image
from .orbit import HOME, OrbitLimits, apply_drag, apply_wheel, orbit
from .session import NO_MODEL, ViewerSession, ViewFrame, colour_jump, shown_as
from .render_state import RenderPhase, RenderStateMachine, refine_levels
from .state import (
    PREVIEW_SAMPLES, VIEWER_MAX_SIZE, PreviewSettings, ViewState, choose_preview_long_side, clamp_state_pose,
    full_frame_size, resolve_open_path, resolve_typed_path, shows_stylized, view_camera, view_fov, wheel_ticks,
)
from .settings import MAX_RECENT, ViewerSettings, load_settings, save_settings
from .worker import ComputeWorker, RenderResult

DOUBLE_CLICK_S = 0.35
CLOSE_GRACE_S = 0.25
"""Open3D turns the Esc key into a close request *before* it delivers the key event, so a close request
waits this long for an Esc key-down that follows it: if one comes, it was Esc (cancel / hide), not a close."""
NUDGE_PX = 25
"""An arrow key turns the view as far as a drag of this many pixels (1 degree in the default range)."""
MIN_WINDOW = (640, 480)
"""Smallest window (width, height): below it the panel and the view do not fit."""


@dataclass(frozen=True)
class ViewerOptions:
    """Start-up options (from the command line). See ``stylize3d_app.viewer.entrypoint`` for each flag.

    Attributes:
        spec: the photo to open (``spec.photo``, or None) and how it becomes a 3D photo.
        style: style image to apply, or None.
        model: model checkpoint, or None for the shipped one (if present).
        use_model: False shows the plain 3D photo even when a model is available.
        strength: style strength in [0, 1].
        width, height: window size in pixels.
        invert_wheel: wheel up moves backwards (default False: wheel up moves forwards, as in common
            3D viewers).
        full_threads: torch threads of the view's full-quality frames (None: the worker's own count).
        decoder_threads: ONNX Runtime threads of the decoder in the view's full-quality frames (None: the
            frame's torch count; :func:`~stylize3d_core.models.decoder_onnx.onnx_threads`).
    """

    spec: PhotoSpec = PhotoSpec(max_size=VIEWER_MAX_SIZE)
    style: Optional[str] = None
    model: Optional[str] = None
    use_model: bool = True
    strength: float = DEFAULT_STRENGTH
    width: int = 1280
    height: int = 800
    invert_wheel: bool = False
    full_threads: Optional[int] = None
    decoder_threads: Optional[int] = None


class ViewerWindow:
    """The viewer's window, widgets and view callbacks, composed with its controllers (see the module docstring).

    ``photos`` (:class:`~stylize3d_app.viewer.actions.PhotoController`), ``paths``
    (:class:`~stylize3d_app.viewer.actions.CameraPathController`) and ``exports``
    (:class:`~stylize3d_app.viewer.actions.ExportController`) do the rest; all app state is
    ``state`` (:class:`~stylize3d_app.viewer.state.ViewState`).

    Thread use: GUI main thread only, except :meth:`post` and :meth:`call_on_main`
    (any thread) and the worker callbacks they wrap.
    """

    def __init__(self, options: ViewerOptions) -> None:
        self.app = gui.Application.instance
        self._main_ident = threading.get_ident()
        self.options = options
        self.state = ViewState(spec=replace(options.spec, photo=None), model=options.model,
                               strength=options.strength)
        self.limits = OrbitLimits()  # replaced by each photo's own (photo_changed)
        self.preview = PreviewSettings()
        self.scheduler = RenderStateMachine(self.preview.rest_delay_s, levels=refine_levels(None))
        self.session = ViewerSession(options.model, use_model=options.use_model)
        self.worker = ComputeWorker(on_error=lambda name, e: self._post(lambda: self.show_error(name, e)))
        self.photos = PhotoController(self)
        self.paths = CameraPathController(self)
        self.exports = ExportController(self, self.paths)
        self.applications = ApplicationsController(self)  # the Applications menu (app/viewer/applications.py)
        self.errors: List[str] = []
        self.stats: Dict[str, Any] = {"preview_seconds": [], "full_seconds": [], "full_latency": [], "preview_shown": [],
                                      "preview_latency": [], "post_delay": [], "mouse_down": [],
                                      "drag_moves": [], "drag_clamped": [], "full_shown": [], "level_seconds": [], "level_shown": [],
                                      "colour_jump": [], "preview_sides": [], "level_sizes": [], "full_sizes": [],
                                      "interrupted": [], "drag_ticks": [], "frame_log": [], "mouse_cb": [],
                                      "tick_gap_frame": [], "tick_gap": [], "threads": {}}
        self.script_thread: Optional[threading.Thread] = None
        self._preview_side = self.preview.preview_long_side
        self._last_level: Optional[Tuple[float, float]] = None  # (scale, seconds) of the last first level
        self._last_full_s: Optional[float] = None  # seconds of the last full-size frame
        self._preview_times: deque = deque(maxlen=PREVIEW_SAMPLES)  # (long side, seconds) of the last previews
        self._display_hw: Tuple[int, int] = (0, 0)
        self._shown_generation = 0
        self._shown: Optional[ViewFrame] = None
        self._requested_at: Dict[int, float] = {}
        self._frame_lock = threading.Lock()
        self._pending_frame: Optional[Tuple[RenderResult, int, float]] = None  # the newest frame not yet shown
        self._coalesced = 0  # frames replaced in that slot before the GUI thread took them
        self._last_tick: Optional[float] = None
        self._frame_mark: Optional[float] = None  # perf_counter when the last frame went to the widget
        self._label_at = -1.0  # monotonic time of the last statistics-label update
        self._first_preview = True  # no preview of the current movement on screen yet (view_changed)
        self._drag: Optional[List[Any]] = None  # [mode, last x, last y]
        self._last_click = (-1.0, 0, 0)
        self._ctrl_down = False
        self._closing = False
        self._shutdown_done = False
        self._close_pending: Optional[float] = None  # monotonic time of a close request waiting for CLOSE_GRACE_S
        self._dialog_open = False
        self._status_before_error: Optional[str] = None
        loaded = load_settings()  # recent files and the last folder, from the last runs
        self.settings: ViewerSettings = loaded.settings
        folder = self.settings.last_folder
        self.last_folder: Optional[str] = folder if folder and os.path.isdir(folder) else None
        self._build()
        if loaded.warning:
            print(f"stylize3d-viewer: {loaded.warning}", file=sys.stderr)
            self.set_status(loaded.warning)
        self.worker.start()
        self.stats["threads"] = {"main": threading.get_native_id(), "worker": self.worker.thread.native_id}
        if options.style:
            self.photos.open_style(options.style)
        if options.spec.photo:
            self.photos.open_photo(options.spec.photo)

    # -- construction -------------------------------------------------------------
    def _build(self) -> None:
        self.app.menubar = P.build_menubar(self.settings.recent_photos, self.settings.recent_styles,
                                           extra=self._extra_menus())
        w = self.window = self.app.create_window("stylize3d viewer", self.options.width, self.options.height)
        self.em = em = w.theme.font_size
        self.image = gui.ImageWidget(widget_image(np.full((8, 12, 3), 32, np.uint8)))
        self.image.set_on_mouse(self._on_mouse)
        self.image.set_on_key(self._on_view_key)
        self.panel = p = P.Panel(em, self.state)
        ph, cp, ex = self.photos, self.paths, self.exports
        for child in (self.image, p.root, p.status_box, p.help):
            w.add_child(child)
        w.set_on_layout(self._on_layout)
        w.set_on_key(self._on_window_key)
        w.set_on_tick_event(self._on_tick)
        w.set_on_close(self._on_close)
        p.open_photo.set_on_clicked(ph.on_open_photo)
        p.sample.set_on_clicked(ph.on_sample)
        p.open_style.set_on_clicked(ph.on_open_style)
        p.recent_photos.set_on_selection_changed(ph.on_recent_photo)
        p.open_style2.set_on_clicked(ph.on_open_style2)
        p.mix.set_on_value_changed(ph.on_mix)
        p.compare.set_on_checked(self._on_compare)
        p.split.set_on_value_changed(self._on_split)
        ph.build_strip()
        ph.show_depth_model()
        p.depth.set_on_selection_changed(ph.on_depth_choice)
        p.depth_file.set_on_clicked(ph.on_open_depth)
        p.depth_download.set_on_clicked(ph.on_download_depth_model)
        p.refine.set_on_selection_changed(ph.on_refine_choice)
        p.stylized.set_on_clicked(self._on_stylized)
        p.strength.set_on_value_changed(self._on_strength)
        p.fov.set_on_value_changed(self._on_fov)
        p.reset.set_on_clicked(self._on_reset_view)
        p.trajectory.set_on_selection_changed(cp.on_trajectory)
        for n in (p.amp_x, p.amp_y, p.forward):
            n.set_on_value_changed(cp.on_trajectory_params)
        p.preview_path.set_on_clicked(cp.toggle_preview)
        p.load_path.set_on_clicked(cp.on_load_path)
        p.save_path.set_on_clicked(cp.on_save_path)
        p.format.set_on_selection_changed(ex.on_export_params)
        for n in (p.size, p.frames, p.fps):
            n.set_on_value_changed(ex.on_export_params)
        p.add_key.set_on_clicked(cp.add_keyframe)
        p.use_keys.set_on_checked(cp.on_use_keys)
        p.key_list.set_on_selection_changed(cp.on_key_selected)
        p.key_up.set_on_clicked(lambda: cp.on_key_move(-1))
        p.key_down.set_on_clicked(lambda: cp.on_key_move(1))
        p.key_delete.set_on_clicked(cp.on_key_delete)
        p.key_fov.set_on_value_changed(cp.on_key_fov)
        p.key_seconds.set_on_value_changed(cp.on_key_seconds)
        p.key_loop.set_on_checked(cp.on_key_loop)
        p.key_preview.set_on_clicked(cp.on_preview_full)
        p.key_load.set_on_clicked(cp.on_load_keys)
        p.key_save.set_on_clicked(cp.on_save_keys)
        p.export.set_on_clicked(ex.on_export)
        p.screenshot.set_on_clicked(ex.on_screenshot)
        p.cancel.set_on_clicked(ex.on_cancel)
        p.set_enabled(False)
        cp.refresh()
        menu = {
            P.MENU_OPEN: ph.on_open_photo, P.MENU_STYLE: ph.on_open_style, P.MENU_DEPTH: ph.on_open_depth,
            P.MENU_SAMPLE: ph.on_sample, P.MENU_LOAD_PATH: cp.on_load_path, P.MENU_SAVE_PATH: cp.on_save_path,
            P.MENU_EXPORT: ex.on_export, P.MENU_SCREENSHOT: ex.on_screenshot, P.MENU_QUIT: self._on_quit,
            P.MENU_STYLIZED: self._on_stylized_menu, P.MENU_RESET: self._on_reset_view,
            P.MENU_PREVIEW: cp.toggle_preview, P.MENU_HELP: self._on_help, P.MENU_ABOUT: self._on_about,
        }
        menu.update(self.applications.menu_callbacks())
        for i in range(MAX_RECENT):  # (the entries that exist; the bar is rebuilt as the lists change)
            menu[P.MENU_RECENT_PHOTO + i] = lambda i=i: self.open_recent(self.settings.recent_photos, i, ph.open_photo)
            menu[P.MENU_RECENT_STYLE + i] = lambda i=i: self.open_recent(self.settings.recent_styles, i, ph.open_style)
        for item, cb in menu.items():
            w.set_on_menu_item_activated(item, cb)

    @ui_callback
    def _on_layout(self, ctx: gui.LayoutContext) -> None:
        size = self.window.size
        if size.width < MIN_WINDOW[0] or size.height < MIN_WINDOW[1]:  # Open3D has no minimum size: grow back
            self.window.size = gui.Size(max(size.width, MIN_WINDOW[0]), max(size.height, MIN_WINDOW[1]))
        r = self.window.content_rect
        em, p = self.em, self.panel
        pw = int(P.Panel.WIDTH_EM * em)
        sh = int(P.Panel.STATUS_EM * em)
        self.image.frame = gui.Rect(r.x, r.y, max(1, r.width - pw), r.height)
        p.root.frame = gui.Rect(r.get_right() - pw, r.y, pw, max(1, r.height - sh))
        p.status_box.frame = gui.Rect(r.get_right() - pw, r.get_bottom() - sh, pw, sh)
        hw, hh = int(min(30 * em, r.width - pw)), int(min(33 * em, r.height))
        p.help.frame = gui.Rect(r.x + (r.width - pw - hw) // 2, r.y + (r.height - hh) // 2, hw, hh)
        self._update_display_size()

    def _update_display_size(self) -> None:
        info = self.state.photo_info
        if info is None:
            return
        f = self.image.frame
        hw = full_frame_size(info.size, (f.height, f.width), self.preview.full_long_side)
        if hw != self._display_hw:
            self._display_hw = hw
            self.view_changed()

    def photo_changed(self) -> None:
        """A new photo is open (``state.photo_info``): take its camera limits (what it shows cleanly,
        ``Photo3D.camera_range``), size the view for it and request its first frame."""
        info = self.state.photo_info
        if info is not None:
            self.limits = OrbitLimits.from_range(info.camera_range)  # speeds relative to its range
            self.state = clamp_state_pose(self.state, info.scene, self.limits)
        self._display_hw = (0, 0)
        self._update_display_size()

    @property
    def full_render_budget_s(self) -> float:
        """What a full-quality frame (or the first level of one) may take: the budget from rest to a sharp
        frame (``PreviewSettings.full_budget_s``) less the rest delay that comes before it and the preview
        it may have to wait for (the median of the recent previews' times)."""
        return max(0.05, self.release_budget_s - self.preview.rest_delay_s)

    @property
    def release_budget_s(self) -> float:
        """The same after a mouse release, which is a rest at once (no rest delay before the full frame)."""
        waits = [sec for _, sec in self._preview_times]
        preview_s = float(np.median(waits)) if waits else 0.0
        return max(0.05, self.preview.full_budget_s - preview_s)

    @property
    def display_hw(self) -> Tuple[int, int]:
        """(H, W) of the full-resolution frame the view shows."""
        return self._display_hw

    def final_frame(self) -> Optional[ViewFrame]:
        """The frame on screen if it is the full frame of the current view, else None."""
        if self.scheduler.settled and self._shown is not None and not self._shown.preview:
            return self._shown
        return None

    # -- threads ------------------------------------------------------------------
    def post(self, fn: Callable[[], None]) -> None:
        """Any thread: run ``fn`` on the main thread without waiting (see :meth:`_post`)."""
        self._post(fn)

    def _post(self, fn: Callable[[], None]) -> None:
        """Run ``fn`` on the main thread (at once if already there); dropped once closing has begun."""
        if self._closing:
            return
        if threading.get_ident() == self._main_ident:
            fn()
            return

        def guarded() -> None:
            if self._closing:
                return
            try:
                fn()
            except Exception as e:  # reported to the user; the session stays usable
                traceback.print_exc()
                self.show_error("update", e)

        self.app.post_to_main_thread(self.window, guarded)

    def call_on_main(self, fn: Callable[[], Any], timeout: float = 60.0) -> Any:
        """From another thread: run ``fn`` on the main thread, wait, return its result (or raise its error)."""
        done = threading.Event()
        box: Dict[str, Any] = {}

        def run() -> None:
            try:
                box["value"] = fn()
            except Exception as e:  # handed back to the calling thread
                box["error"] = e
            finally:
                done.set()

        self._post(run)
        t_end = time.monotonic() + timeout
        while not done.wait(0.05):
            if self._closing:
                raise RuntimeError("the window is closing")
            if time.monotonic() > t_end:
                raise TimeoutError(f"the main thread did not answer within {timeout:g} s")
        if "error" in box:
            raise box["error"]
        return box.get("value")

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

    # -- view changes and rendering -----------------------------------------------------
    def view_changed(self) -> None:
        """The view changed: ask for a preview now (interrupting a full render in progress); the tick asks
        for the full frame once it rests (:class:`~stylize3d_app.viewer.render_state.RenderStateMachine`). The first
        preview after a rest is the smallest (``min_preview_long_side``), and so is every one requested
        before a preview of this movement is on screen (a newer request replaces a waiting one): it is what
        a new drag waits for."""
        if self.scheduler.phase is not RenderPhase.MOVING:
            self._first_preview = True
        change = self.scheduler.changed(time.monotonic())
        if change.interrupt:
            self.worker.interrupt_render()
        self.request_render(preview=True, side=self.preview.min_preview_long_side if self._first_preview else None)

    def request_render(self, preview: bool, camera=None, side: Optional[int] = None) -> None:
        """Ask the worker for a frame of the view (or of ``camera``): a preview (of long side ``side``, else
        the adaptive size) or the full frame.

        The view's full frame carries a cancel event: any newer request stops it between stages (a
        full-quality frame of a ``camera`` -- the keyframe preview -- does not). Frames are rendered at
        their own size; the image widget scales them to the view."""
        info = self.state.photo_info
        if info is None or self._display_hw == (0, 0):
            return
        cam = camera if camera is not None else view_camera(self.state, info.scene, info.fov_y_deg)
        display = self._display_hw
        scale = 1.0 if preview or camera is not None else self.scheduler.full_scale
        if preview:
            size = frame_size(info.size, min(side or self._preview_side, max(display)))
        elif scale < 1.0:  # a progressive level: the full quality at a fraction of the size
            size = frame_size(info.size, max(32, int(round(scale * max(display)))))
        else:
            size = display
        stylized = shows_stylized(self.state)
        split = self.state.split if self.state.compare else None
        version = self.scheduler.version if camera is None else -1  # a path preview's frame never settles the view
        session = self.session
        cancel = None if preview or camera is not None else threading.Event()
        stop = None if cancel is None else cancel.is_set
        threads = None if preview else self.options.full_threads
        decoder_threads = None if preview else self.options.decoder_threads
        requested = time.perf_counter()

        def render() -> Tuple[ViewFrame, o3d.geometry.Image, Dict[str, float]]:  # (on the worker)
            started = time.perf_counter()
            times: Dict[str, float] = {"requested": requested, "wait": started - requested}
            with torch_threads(threads), onnx_threads(decoder_threads):
                frame = session.render_view(cam, size, None, preview=preview, stylized=stylized, should_stop=stop,
                                            split=split, calibrate=scale >= 1.0, timings=times)
            t = time.perf_counter()
            image = widget_image(frame.image)  # the GUI thread only hands it to the widget
            times["image"] = time.perf_counter() - t
            return frame, image, times

        def interrupted() -> None:
            self._post(lambda: self.scheduler.full_interrupted(version))

        gen = self.worker.request_render(
            render, lambda res: self._deliver(res, version, scale), preview=preview,
            on_error=lambda name, e: self._post(lambda: self._on_render_failed(name, e, version, preview)),
            cancel=cancel, on_interrupted=None if cancel is None else interrupted)
        self._requested_at[gen] = requested
        if not preview and camera is None:
            self.scheduler.full_requested()

    def _deliver(self, res: RenderResult, version: int, scale: float) -> None:
        """Worker thread: a finished frame goes into the one-frame slot; the GUI thread is woken only when the
        slot was empty (a frame that arrives while the last one waits for the GUI thread replaces it: one
        hand-over and one redraw per GUI turn, never a queue of stale frames)."""
        with self._frame_lock:
            waiting = self._pending_frame is not None
            if waiting:
                self._coalesced += 1
            self._pending_frame = (res, version, scale)
        if not waiting:
            self._post(self._show_pending)

    def _show_pending(self) -> None:
        """GUI thread: show the frame waiting in the slot, if any (posted by :meth:`_deliver`; a mouse drag
        calls it too)."""
        with self._frame_lock:
            pending, self._pending_frame = self._pending_frame, None
        if pending is not None:
            self._on_frame(*pending)

    def _on_frame(self, res: RenderResult, version: int, scale: float = 1.0) -> None:
        if res.generation <= self._shown_generation:
            return
        self._shown_generation = res.generation
        t_main = time.perf_counter()
        frame, image, times = res.value  # (ViewFrame, its Open3D image made on the worker, stage seconds)
        self.image.update_image(image)
        self.window.post_redraw()
        t_update = time.perf_counter()
        self._frame_mark = t_update
        if not res.preview and self._shown is not None and self._shown.preview:  # what the user sees change
            self.stats["colour_jump"].append([scale, *colour_jump(shown_as(self._shown.image, frame.image.shape),
                                                                  frame.image)])
        self._shown = frame
        next_level = self.scheduler.shown(version, res.preview, scale)
        self.paths.frame_shown()
        if next_level:  # a progressive level is on screen: the next (finer) one
            self.request_render(preview=False)
        now = time.perf_counter()
        latency = now - self._requested_at.pop(res.generation, now)
        for g in [g for g in self._requested_at if g < res.generation]:
            del self._requested_at[g]
        st = self.stats
        st["post_delay"].append(now - res.finished)
        kind = 0 if res.preview else (1 if scale < 1.0 else 2)
        st["frame_log"].append([kind, max(frame.rendered_size), times["requested"], times["wait"], times["render"],
                                times["split"], times["convert"], times["resize"], times["image"], t_main - res.finished,
                                t_update - t_main, self._coalesced])
        if res.preview:
            self._first_preview = False
            st["preview_latency"].append(latency)
            st["preview_seconds"].append(res.seconds)
            st["preview_shown"].append(time.monotonic())
            st["preview_sides"].append(max(frame.rendered_size))
            self._preview_times.append((max(frame.rendered_size), res.seconds))
            self._preview_side = choose_preview_long_side(self._preview_times, self._preview_side, self.preview)
        elif scale < 1.0:
            self._last_level = (scale, res.seconds)
            st["level_seconds"].append(res.seconds)
            st["level_shown"].append(time.monotonic())
            st["level_sizes"].append(list(frame.rendered_size))
        else:
            st["full_seconds"].append(res.seconds)
            st["full_shown"].append(time.monotonic())
            st["full_sizes"].append(list(frame.rendered_size))
            st["full_latency"].append(latency)
            self._last_full_s = res.seconds
            self.scheduler.levels = refine_levels(res.seconds, self.full_render_budget_s, self._last_level)  # next rest
        st["interrupted"] = [self.worker.interrupted]
        for value in st.values():
            if isinstance(value, list):
                del value[:-2000]
        if not res.preview or time.monotonic() - self._label_at > 0.5:  # text changes cost a relayout: ~2 Hz
            self._label_at = time.monotonic()
            self._update_fps_label()

    def _update_fps_label(self) -> None:
        st = self.stats
        text = ""
        if st["preview_seconds"]:
            ms = 1000.0 * float(np.median(st["preview_seconds"][-10:]))
            text = f"preview {self._preview_side}px {ms:.0f}ms"
        if st["level_seconds"] and st["level_sizes"] and self.scheduler.levels != (1.0,):
            text += f"; {max(st['level_sizes'][-1])}px {st['level_seconds'][-1]:.2f}s"
        if st["full_seconds"]:
            text += f"; full {st['full_seconds'][-1]:.1f}s"
        self.panel.set_line(self.panel.fps_label, text)

    def _on_render_failed(self, name: str, e: BaseException, version: int, preview: bool) -> None:
        self.paths.frame_shown()
        if not preview:
            self.scheduler.full_failed(version)
        self.show_error(name, e)

    @ui_callback
    def _on_tick(self) -> bool:
        if self._closing:
            return False
        now = time.monotonic()
        if self._drag is not None:  # the GUI loop's rate while dragging (the bench reports it)
            self.stats["drag_ticks"].append(now)
            t = time.perf_counter()  # the GUI loop's turn after a frame (its redraw) and without one
            if self._frame_mark is not None:
                self.stats["tick_gap_frame"].append(t - self._frame_mark)
            elif self._last_tick is not None:
                self.stats["tick_gap"].append(t - self._last_tick)
        self._frame_mark = None
        if self._close_pending is not None and now - self._close_pending >= CLOSE_GRACE_S:
            self._close_pending = None  # no Esc followed: the user closed the window
            self.quit()
        if self.state.playback is not None:
            self.paths.step(now)
        elif self.state.photo_info is not None and self.scheduler.full_due(now, holding=self._drag is not None):
            self.request_render(preview=False)
        self._last_tick = time.perf_counter()
        return False

    # -- camera control ---------------------------------------------------------------
    @ui_callback
    def _on_mouse(self, e: gui.MouseEvent) -> int:
        t0 = time.perf_counter()
        try:
            return self._mouse(e)
        finally:
            if self._drag is not None:
                self.stats["mouse_cb"].append(time.perf_counter() - t0)

    def _mouse(self, e: gui.MouseEvent) -> int:
        T = gui.MouseEvent.Type
        if self.state.photo_info is None:
            return gui.Widget.EventCallbackResult.IGNORED
        if e.type == T.BUTTON_DOWN:
            now = time.monotonic()
            t0, x0, y0 = self._last_click
            if e.is_button_down(gui.MouseButton.LEFT) and now - t0 < DOUBLE_CLICK_S and abs(e.x - x0) + abs(e.y - y0) < 6:
                self._last_click = (-1.0, 0, 0)
                self.reset_view()
                return gui.Widget.EventCallbackResult.CONSUMED
            self._last_click = (now, e.x, e.y)
            self.stats["mouse_down"].append(now)
            if self.scheduler.rendering_full:  # a drag is about to start: free the worker for its first preview
                self.worker.interrupt_render()  # (a click without a drag renders the full frame again)
            pan = (e.is_button_down(gui.MouseButton.RIGHT) or e.is_button_down(gui.MouseButton.MIDDLE)
                   or e.is_modifier_down(gui.KeyModifier.SHIFT))
            self._drag = ["pan" if pan else "orbit", e.x, e.y]
            return gui.Widget.EventCallbackResult.CONSUMED
        if e.type == T.DRAG and self._drag is not None:
            mode, x0, y0 = self._drag
            self._drag[1:] = [e.x, e.y]
            self.stats["drag_moves"].append(time.monotonic())
            self.drag(mode, e.x - x0, e.y - y0)
            # Open3D handles every queued mouse event (each one redraws the window) before it runs posted
            # functions: on a loaded machine a drag's events keep it busy and the posted frames waited until
            # the mouse stopped (a second drag showed 1 frame in 1.7 s). The drag takes the newest frame itself.
            self._show_pending()
            return gui.Widget.EventCallbackResult.CONSUMED
        if e.type == T.BUTTON_UP:
            self._drag = None
            if self.scheduler.phase is RenderPhase.MOVING and self.state.playback is None:
                if self._last_full_s is not None:  # levels for the release's budget: no rest delay comes first
                    self.scheduler.retarget(refine_levels(self._last_full_s, self.release_budget_s, self._last_level))
                self.request_render(preview=False)  # the release is the rest: the full-quality frame now (it
            return gui.Widget.EventCallbackResult.CONSUMED  # replaces a waiting preview of the same pose)
        if e.type == T.WHEEL:
            self.wheel(wheel_ticks(e.wheel_dy, self.options.invert_wheel))
            return gui.Widget.EventCallbackResult.CONSUMED
        return gui.Widget.EventCallbackResult.IGNORED

    def drag(self, mode: str, dx: float, dy: float) -> None:
        """Apply a mouse drag of (dx, dy) view pixels ("orbit" or "pan"); the test hooks call this too."""
        if self.state.photo_info is None or (dx == 0 and dy == 0):
            return
        self.paths.stop()
        view_h = max(1, self.image.frame.height)
        info = self.state.photo_info
        pose = apply_drag(self.state.pose, mode, dx, dy, view_h, view_fov(self.state, info.fov_y_deg),
                          info.scene, self.limits)
        if pose != self.state.pose:
            self.state = replace(self.state, pose=pose)
            self.view_changed()
        else:  # at the range's limit: nothing new to show (the bench reports how often)
            self.stats["drag_clamped"].append(time.monotonic())

    def wheel(self, ticks: float) -> None:
        """Move forwards by ``ticks`` wheel steps (negative: backwards)."""
        if self.state.photo_info is None:
            return
        pose = apply_wheel(self.state.pose, ticks, self.state.photo_info.scene, self.limits)
        if pose != self.state.pose:
            self.state = replace(self.state, pose=pose)
            self.view_changed()

    def reset_view(self) -> None:
        """Back to the photo's own camera and FOV."""
        self.paths.stop()
        self.state = replace(self.state, pose=HOME, view_fov=None)
        if self.state.photo_info is not None:
            self.panel.fov.double_value = self.state.photo_info.fov_y_deg
            self.panel.fov_label.text = f"Field of view: {self.state.photo_info.fov_y_deg:.1f} degrees"
        self.view_changed()

    @ui_callback
    def _on_reset_view(self) -> None:
        self.reset_view()

    @ui_callback
    def _on_fov(self, value: float) -> None:
        self.state = replace(self.state, view_fov=float(value))
        self.panel.fov_label.text = f"Field of view: {float(value):.1f} degrees"
        self.view_changed()

    @ui_callback
    def _on_window_key(self, e: gui.KeyEvent) -> bool:
        """Window-wide keys, from launch (no click in the view needed): Esc, F1, Ctrl+Q, and the letter
        shortcuts while no dialog is open (a dialog's text field takes letters). The panel has only number
        fields, which ignore letters."""
        K = gui.KeyName
        if e.key in (K.LEFT_CONTROL, K.RIGHT_CONTROL):
            self._ctrl_down = e.type == gui.KeyEvent.Type.DOWN
            return False
        if e.key == K.ESCAPE:  # never reaches Open3D's default, which closes the window
            self._close_pending = None  # the close request Open3D made of this key (it makes one on down and up)
            if e.type == gui.KeyEvent.Type.DOWN:
                self._on_escape()
            return True
        if e.type != gui.KeyEvent.Type.DOWN:
            return False
        if e.key == K.F1:
            self._on_help()
            return True
        if e.key == K.Q and self._ctrl_down:
            self.quit()
            return True
        if self._dialog_open:
            return False
        action = self._letter_actions().get(e.key)
        if action is None:
            return False
        action()
        return True

    def _letter_actions(self) -> Dict[Any, Callable[[], None]]:
        K = gui.KeyName
        ph, cp, ex = self.photos, self.paths, self.exports
        return {
            K.O: ph.on_open_photo, K.S: ph.on_open_style, K.D: ph.on_open_depth, K.M: ph.load_sample,
            K.T: self._on_stylized_menu, K.R: self.reset_view, K.C: cp.toggle_preview, K.E: ex.on_export,
            K.P: ex.on_screenshot, K.H: self._on_help, K.K: cp.add_keyframe,
            K.LEFT_BRACKET: lambda: self.set_strength(self.state.strength - 0.1),
            K.RIGHT_BRACKET: lambda: self.set_strength(self.state.strength + 0.1),
        }

    @ui_callback
    def _on_view_key(self, e: gui.KeyEvent) -> int:
        """Keys that number fields also use (arrows, + / -, PgUp / PgDn) act only while the view has the
        keyboard focus (after a click in it); letters are window-wide (:meth:`_on_window_key`)."""
        ignored, consumed = gui.Widget.EventCallbackResult.IGNORED, gui.Widget.EventCallbackResult.CONSUMED
        K = gui.KeyName
        if e.type != gui.KeyEvent.Type.DOWN:
            return ignored
        actions = {
            K.LEFT: lambda: self._nudge(-1, 0), K.RIGHT: lambda: self._nudge(1, 0),
            K.UP: lambda: self._nudge(0, 1), K.DOWN: lambda: self._nudge(0, -1),
            K.PLUS: lambda: self.wheel(1), K.EQUALS: lambda: self.wheel(1), K.MINUS: lambda: self.wheel(-1),
            K.PAGE_UP: lambda: self.wheel(1), K.PAGE_DOWN: lambda: self.wheel(-1),
        }
        action = actions.get(e.key) or self._letter_actions().get(e.key)
        if action is None:
            return ignored
        action()
        return consumed

    def _nudge(self, yaw: float, pitch: float) -> None:
        if self.state.photo_info is None:
            return
        scene = self.state.photo_info.scene
        step = NUDGE_PX * self.limits.deg_per_pixel  # an arrow key turns as far as a short drag
        self.state = replace(self.state, pose=orbit(self.state.pose, step * yaw, step * pitch, scene, self.limits))
        self.view_changed()

    # -- look: stylized / original, strength ----------------------------------------------------
    @ui_callback
    def _on_stylized(self, is_on: bool) -> None:
        self.set_stylized(bool(is_on))

    @ui_callback
    def _on_stylized_menu(self) -> None:
        self.set_stylized(not self.state.stylized)

    def set_stylized(self, on: bool) -> None:
        """Show the stylized view (True) or the original 3D photo."""
        self.state = replace(self.state, stylized=on)
        self.panel.stylized.is_on = on
        if self.app.menubar is not None:
            self.app.menubar.set_checked(P.MENU_STYLIZED, on)
        if on and not self.state.stylize_available and self.session.checkpoint_path() is None:
            self.set_status(NO_MODEL)
        self.view_changed()

    @ui_callback
    def _on_compare(self, checked: bool) -> None:
        self.set_compare(bool(checked), self.state.split)

    @ui_callback
    def _on_split(self, value: float) -> None:
        self.set_compare(True, float(value))

    def set_compare(self, on: bool, split: float) -> None:
        """Before / after: the original 3D photo left of ``split`` (a fraction of the width), stylized right."""
        self.state = replace(self.state, compare=on, split=float(min(1.0, max(0.0, split))))
        self.panel.compare.checked = on
        if abs(self.panel.split.double_value - self.state.split) > 1e-9:
            self.panel.split.double_value = self.state.split
        self.view_changed()

    @ui_callback
    def _on_strength(self, value: float) -> None:
        self.set_strength(value)

    def set_strength(self, value: float) -> None:
        """Style strength in [0, 1] (a re-blend on the worker, then a new frame)."""
        a = self.set_blend("strength", self.panel.strength, value, self.session.set_strength)
        self.panel.strength_label.text = f"Style strength: {a:.2f}"

    def set_blend(self, field: str, slider: gui.Slider, value: float, apply: Callable[[float], Any]) -> float:
        """Set ``state.<field>`` (strength, mix) to ``value`` clamped to [0, 1], show it on ``slider``,
        run ``apply(value)`` on the worker (a cheap re-blend; a newer one replaces a waiting one) and ask
        for a new frame. Returns the value."""
        a = float(min(1.0, max(0.0, value)))
        self.state = replace(self.state, **{field: a})
        if abs(slider.double_value - a) > 1e-9:
            slider.double_value = a
        self.worker.submit(field, lambda: apply(a), key=field)
        self.view_changed()
        return a

    # -- help, about, quit ---------------------------------------------------------------
    @ui_callback
    def _on_help(self) -> None:
        self.panel.help.visible = not self.panel.help.visible
        self.window.post_redraw()

    @ui_callback
    def _on_about(self) -> None:
        self.show_message(
            "About stylize3d", "Stylized 3D photos from one photo and one style image "
            "(3D Photo Stylization, Mu et al., CVPR 2022). Drag to look around; export videos from the File menu.")

    @ui_callback
    def _on_escape(self) -> None:
        """Esc cancels or hides, never quits: the open dialog, else the help, else the drag or the path
        preview. A running export goes on (its Cancel button stops it)."""
        if self._dialog_open:
            self.close_dialog()
        elif self.panel.help.visible:
            self._on_help()
        elif self._drag is not None:
            self._drag = None
        elif self.state.playback is not None:
            self.paths.stop()
        elif self.exports.exporting:
            self.set_status("The export goes on; press Cancel to stop it")

    @ui_callback
    def _on_quit(self) -> None:
        self.quit()

    def quit(self) -> None:
        """Quit (window close, Ctrl+Q, File > Quit): at once, or after asking when an export is running."""
        if self._closing:
            return
        if not self.exports.exporting:
            self.request_close()
            return
        if self._dialog_open:
            self.close_dialog()
        self.show_message(
            "Quit during an export?",
            "An export is running. Quitting now cancels it and writes nothing.",
            [("Keep exporting", None), ("Cancel the export and quit", self.request_close)])

    def is_settled(self) -> bool:
        """True when the full frame of the current view is on screen and no work is left (test hooks)."""
        return (self.state.photo_info is not None and self.scheduler.settled and self.worker.is_idle()
                and not self.exports.exporting and self.state.playback is None)

    # -- closing ---------------------------------------------------------------------------
    def _on_close(self) -> bool:
        """A close request (the window's close button, or Esc: Open3D makes one of that key's down and up,
        just before the key event). It is decided on the tick, :data:`CLOSE_GRACE_S` later, once it is
        known whether an Esc key event followed."""
        if self._shutdown_done:
            return True
        if not self._closing and self._close_pending is None:
            self._close_pending = time.monotonic()
        return False

    def request_close(self) -> None:
        """Stop the worker and the script thread, then close the window (see the module docstring)."""
        if self._closing:
            return
        self._closing = True
        self.exports.cancel()
        self.worker.stop(timeout=0)
        waiting = [t for t in (self.worker.thread, self.script_thread) if t is not None]

        def finish() -> None:
            for t in waiting:
                if t is not threading.current_thread() and t.ident is not None:
                    t.join()
            self.app.post_to_main_thread(self.window, self._finish_close)

        threading.Thread(target=finish, name="stylize3d-close", daemon=True).start()

    def _finish_close(self) -> None:
        self._shutdown_done = True
        self.window.close()
