"""What the user changes about the window's view: the camera (mouse drags, the wheel, arrow and
letter keys, the field of view, reset) and the look (stylized or original, before / after, style
strength).

:class:`ViewControls` is a mixin of :class:`~stylize3d_app.viewer.window.ViewerWindow`: its methods run
on the GUI main thread and use the window's ``state``, ``panel``, ``image``, ``limits``, ``scheduler``,
``worker``, ``session``, ``stats``, its controllers and its frame requests (:mod:`.window_frames`).
Every change replaces ``state`` and calls ``view_changed``.
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Any, Callable, Dict

import open3d.visualization.gui as gui

from . import panel as P
from .controller import ui_callback
from .orbit import HOME, apply_drag, apply_wheel, orbit
from .render_state import RenderPhase, refine_levels
from .session import NO_MODEL
from .state import view_fov, wheel_ticks

DOUBLE_CLICK_S = 0.35
NUDGE_PX = 25
"""An arrow key turns the view as far as a drag of this many pixels (1 degree in the default range)."""


class ViewControls:
    """The camera and look controls of :class:`~stylize3d_app.viewer.window.ViewerWindow` (a mixin; see the
    module docstring)."""

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
