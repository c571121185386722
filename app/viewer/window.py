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

Composition: this class owns the widgets, their layout, the threads' hand-over, the
tick and closing; three mixins add the live view: the camera and look controls
(mouse, keys, strength; :mod:`.window_view`), the frames' requests and delivery
(:mod:`.window_frames`) and the dialogs, status line and recent files
(:mod:`.window_dialogs`). What the panel's buttons do is in the controllers
(:mod:`stylize3d_app.viewer.actions`): ``photos``, ``paths`` and ``exports``, and
``applications`` (:mod:`.applications`). All app state is one
:class:`~stylize3d_app.viewer.state.ViewState` in ``self.state``.

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
import open3d.visualization.gui as gui

from stylize3d_core.defaults import DEFAULT_STRENGTH
from stylize3d_core.pipeline import PhotoSpec

from . import panel as P
from .actions import CameraPathController, ExportController, PhotoController, ui_callback
from .applications import ApplicationsController
from .backend import widget_image
from .orbit import OrbitLimits
from .session import ViewerSession, ViewFrame
from .render_state import RenderStateMachine, refine_levels
from .state import (
    PREVIEW_SAMPLES, VIEWER_MAX_SIZE, PreviewSettings, ViewState, clamp_state_pose, full_frame_size,
)
from .settings import MAX_RECENT, ViewerSettings, load_settings
from .window_dialogs import WindowDialogs
from .window_frames import FrameDelivery
from .window_view import ViewControls
from .worker import ComputeWorker, RenderResult

CLOSE_GRACE_S = 0.25
"""Open3D turns the Esc key into a close request *before* it delivers the key event, so a close request
waits this long for an Esc key-down that follows it: if one comes, it was Esc (cancel / hide), not a close."""
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


class ViewerWindow(ViewControls, FrameDelivery, WindowDialogs):
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

    # -- the tick: rest detection, the path preview, a close request ---------------------
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
