"""Test hooks: run a JSON script of viewer actions, step by step, and write a report.

``stylize3d-viewer --test-script steps.json --test-report report.json`` reads a
list of steps such as::

    [{"op": "load_sample"},
     {"op": "wait_idle", "timeout": 120},
     {"op": "screenshot", "path": "before.png"},
     {"op": "grab_window", "path": "window.png"},
     {"op": "orbit", "dx": 150, "dy": 40, "steps": 30, "interval": 0.03},
     {"op": "wait_idle"},
     {"op": "quit"}]

and runs them on its own thread: each step acts on the window through
``post_to_main_thread`` (:meth:`ViewerWindow.call_on_main`) exactly as the
widgets' callbacks do, then waits. The report (rewritten after every step)
lists each step's outcome, the error dialogs shown and the frame statistics.
A failing step ends the script and closes the window with exit status 1.

Ops: ``open_photo`` (path, depth), ``open_style`` (path), ``load_sample``,
``wait_idle`` (timeout), ``sleep`` (seconds), ``orbit`` (dx, dy, steps,
interval, mode "orbit"/"pan"), ``wheel`` (ticks), ``reset_view``, ``preview_path``,
``set_strength`` (value), ``set_stylized`` (value), ``set_export`` (format,
size, frames, fps), ``export`` (path, wait, timeout), ``wait_export``, ``cancel_export``, ``ping``,
``screenshot`` (path), ``grab_window`` (path: the X screen cropped to the
window, needs Pillow with XCB), ``save_camera_path`` / ``load_camera_path``
(path), ``help`` (visible), ``expect_error`` (contains), ``state`` (records the
view state), ``status`` (exporting, dialog open, closing, render phase),
``resize`` (width, height), ``add_keyframe``, ``edit_keyframe`` (index, fov,
seconds, move, delete, loop), ``save_keyframes`` / ``load_keyframes`` (path),
``preview_keys``, ``open_section`` (name), ``save_as`` (what, text: types a
path into a Save dialog), ``style_strip`` (index), ``mix`` (path, value),
``compare`` (split, on), ``app_menu`` (item, fields, ok, save_as, grab: an Applications menu item
and its dialogs), ``app_call`` (method, its arguments), ``quit``.
"""

from __future__ import annotations

import json
import os
import threading
import time
import traceback
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional

from stylize3d_core.errors import InputError

from . import panel as P
from .state import VideoExport, shows_stylized, user_choices
from .window import ViewerWindow


def read_script(path: str) -> List[Dict[str, Any]]:
    """The steps of a test script (a JSON list of objects with an "op")."""
    try:
        steps = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError) as e:
        raise InputError(path, f"cannot read the test script: {e}") from e
    if not isinstance(steps, list) or not all(isinstance(s, dict) and "op" in s for s in steps):
        raise InputError(path, "a test script is a JSON list of objects, each with an \"op\"")
    return steps


class ScriptRunner:
    """Runs test-script steps against a :class:`ViewerWindow`.

    Thread use: its own thread; it touches the window only through
    :meth:`ViewerWindow.call_on_main` (post_to_main_thread).
    """

    def __init__(self, window: ViewerWindow, steps: List[Dict[str, Any]], report: str) -> None:
        self.window = window
        self.steps = steps
        self.report_path = report
        self.results: List[Dict[str, Any]] = []
        self.ok = True
        self.thread = threading.Thread(target=self._run, name="stylize3d-test-script", daemon=True)

    def start(self) -> None:
        self.window.script_thread = self.thread
        self.thread.start()

    # -- plumbing ----------------------------------------------------------------------
    def main(self, fn: Callable[[], Any], timeout: float = 60.0) -> Any:
        return self.window.call_on_main(fn, timeout)

    def _write_report(self) -> None:
        w = self.window
        stats = self.main(lambda: json.loads(json.dumps(w.stats, default=str))) if not w._closing else {}
        doc = {"ok": self.ok, "steps": self.results, "errors": list(w.errors), "stats": stats}
        tmp = self.report_path + ".tmp"
        Path(tmp).write_text(json.dumps(doc, indent=1, default=str), encoding="utf-8")
        os.replace(tmp, self.report_path)

    def _run(self) -> None:
        for step in self.steps:
            op = step["op"]
            t0 = time.perf_counter()
            entry: Dict[str, Any] = {"op": op}
            try:
                if op == "quit":
                    entry.update(ok=True, seconds=0.0)
                    self.results.append(entry)
                    self._write_report()
                    # posted, not waited for: a wait that ends while the close has begun (a loaded machine)
                    # raised "the window is closing" here and made a passing script exit with 1
                    self.window.post(self.window.request_close)
                    return
                handler = getattr(self, "op_" + op, None)
                if handler is None:
                    raise InputError("test script", f"unknown op {op!r}")
                entry["result"] = handler(**{k: v for k, v in step.items() if k != "op"})
                entry["ok"] = True
            except Exception as e:  # recorded in the report; the script stops and the app exits with 1
                entry.update(ok=False, error=f"{type(e).__name__}: {e}", trace=traceback.format_exc())
                self.ok = False
            entry["seconds"] = round(time.perf_counter() - t0, 3)
            self.results.append(entry)
            if self.window._closing:
                return
            self._write_report()
            if not self.ok:
                self.main(self.window.request_close)
                return
        self._write_report()

    # -- ops ------------------------------------------------------------------------------
    def op_open_photo(self, path: str, depth: str = None) -> None:
        self.main(lambda: self.window.photos.open_photo(path, depth))

    def op_open_style(self, path: str) -> None:
        self.main(lambda: self.window.photos.open_style(path))

    def op_load_sample(self) -> None:
        self.main(self.window.photos.load_sample)

    def op_sleep(self, seconds: float) -> None:
        time.sleep(float(seconds))

    def op_wait_idle(self, timeout: float = 120.0) -> Dict[str, Any]:
        """Wait until the full frame of the current view is on screen and the worker is idle.

        Polls by reading the window's flags from this thread (no post, so no
        redraw per poll that would compete with the render being waited for),
        then confirms once on the main thread.
        """
        t_end = time.monotonic() + float(timeout)
        while time.monotonic() < t_end:
            if self.window.is_settled() and self.main(self.window.is_settled):
                out = {"shown": self.main(self._shown_info), **self.main(self._rest_timings)}
                time.sleep(0.3)  # let Open3D draw the new image before anyone looks at the screen
                return out
            time.sleep(0.05)
        raise TimeoutError(f"the view did not settle within {timeout:g} s")

    def _rest_timings(self) -> Dict[str, Any]:
        """Seconds from the end of the last ``orbit`` step to the first full-quality frame shown after it
        (the first level of a progressive full frame, or the full one) and to the full-size frame."""
        end = getattr(self, "_orbit_end", None)
        if end is None:
            return {}
        st = self.window.stats
        half = [t - end for t in st["level_shown"] if t >= end]
        full = [t - end for t in st["full_shown"] if t >= end]
        out = {"rest_to_full_s": round(full[0], 3) if full else None}
        out["rest_to_sharp_s"] = round(min(half[:1] + full[:1]), 3) if half or full else None
        return out

    def _shown_info(self) -> Dict[str, Any]:
        f = self.window._shown
        return {} if f is None else {"stylized": f.stylized, "preview": f.preview, "size": list(f.rendered_size)}

    def op_orbit(self, dx: float = 0.0, dy: float = 0.0, steps: int = 20, interval: float = 0.02,
                 mode: str = "orbit") -> Dict[str, Any]:
        """Drag by (dx, dy) pixels as ``steps`` mouse moves ``interval`` s apart; report the preview rate.

        The moves are posted without waiting for each other, like a real mouse,
        so frames that cannot keep up are dropped, not queued.
        """
        w = self.window
        n0 = self.main(lambda: len(w.stats["preview_shown"]))
        t0 = time.monotonic()
        for i in range(int(steps)):
            w.post(lambda: w.drag(mode, dx / steps, dy / steps))
            time.sleep(max(0.0, t0 + (i + 1) * float(interval) - time.monotonic()))
        self.main(lambda: None)  # every move has been applied
        seconds = time.monotonic() - t0
        self._orbit_end = time.monotonic()
        shown = self.main(lambda: [t for t in w.stats["preview_shown"] if t0 <= t <= t0 + seconds])
        return {"pose": asdict(self.main(lambda: w.state.pose)), "drag_seconds": round(seconds, 3),
                "preview_frames": len(shown), "preview_fps": round(len(shown) / max(seconds, 1e-6), 2),
                "preview_long_side": self.main(lambda: w._preview_side), "frames_before": n0}

    def op_wheel(self, ticks: float) -> Dict[str, Any]:
        self.main(lambda: self.window.wheel(float(ticks)))
        return {"pose": asdict(self.main(lambda: self.window.state.pose))}

    def op_reset_view(self) -> None:
        self.main(self.window.reset_view)

    def op_set_strength(self, value: float) -> None:
        self.main(lambda: self.window.set_strength(float(value)))

    def op_set_stylized(self, value: bool) -> None:
        self.main(lambda: self.window.set_stylized(bool(value)))

    def op_set_refine_depth(self, value: Optional[str] = None) -> None:
        """Pick the depth-edge alignment in the panel's picker, as a user would."""
        index = [v for v, _ in P.REFINE_CHOICES].index(value)

        def pick() -> None:
            self.window.panel.refine.selected_index = index
            self.window.photos.on_refine_choice(P.REFINE_CHOICES[index][1], index)

        self.main(pick)

    def op_set_export(self, **fields: Any) -> Dict[str, Any]:
        def apply() -> Dict[str, Any]:
            w = self.window
            e = VideoExport(**{**asdict(w.state.export), **fields})
            w.state = replace(w.state, export=e)
            return asdict(e)

        return self.main(apply)

    @staticmethod
    def _wait_while(busy: Callable[[], bool], timeout: float, what: str, poll: float = 0.05) -> None:
        """Poll ``busy()`` from this thread until it is false; raise TimeoutError after ``timeout`` s."""
        t_end = time.monotonic() + float(timeout)
        while busy():
            if time.monotonic() > t_end:
                raise TimeoutError(f"{what} within {timeout:g} s")
            time.sleep(poll)

    def op_export(self, path: str, wait: bool = True, timeout: float = 300.0) -> Dict[str, Any]:
        dest = self.main(lambda: self.window.exports.start_export(path))
        if wait:
            self._wait_while(lambda: self.window.exports.exporting, timeout, "the export did not finish", 0.1)
        return {"destination": dest, "status": self.main(lambda: self.window.panel.status_text)}

    def op_preview_path(self, timeout: float = 120.0) -> Dict[str, Any]:
        """Play the camera path in the view (as the Preview button does) and wait for its end."""
        w = self.window
        n0 = self.main(lambda: len(w.stats["preview_shown"]))
        self.main(w.paths.toggle_preview)
        self._wait_while(lambda: w.paths.playing, timeout, "the camera-path preview did not end")
        return {"frames_shown": self.main(lambda: len(w.stats["preview_shown"])) - n0}

    def op_wait_export(self, timeout: float = 300.0) -> Dict[str, Any]:
        """Wait until the running export (if any) ends."""
        self._wait_while(lambda: self.window.exports.exporting, timeout, "the export did not finish", 0.1)
        return {"status": self.main(lambda: self.window.panel.status_text)}

    def op_ping(self, count: int = 20, interval: float = 0.05) -> Dict[str, Any]:
        """Round trips to the GUI thread (does the window answer while the worker is busy?)."""
        times = []
        for _ in range(int(count)):
            t0 = time.perf_counter()
            self.main(lambda: None)
            times.append(time.perf_counter() - t0)
            time.sleep(float(interval))
        busy = not self.main(self.window.worker.is_idle)
        return {"max_s": round(max(times), 4), "median_s": round(sorted(times)[len(times) // 2], 4),
                "worker_busy": busy}

    def op_cancel_export(self) -> None:
        self.main(self.window.exports.on_cancel)

    def op_screenshot(self, path: str, timeout: float = 60.0) -> str:
        self.main(lambda: self.window.exports.save_screenshot(path))
        self._wait_while(lambda: not (self.window.worker.is_idle() and os.path.exists(path)), timeout,
                         f"{path} was not written")
        return path

    def op_grab_window(self, path: str) -> Dict[str, Any]:
        """Save the window as the X server shows it (menus, panel and view)."""
        from PIL import ImageGrab

        self.main(self.window.window.post_redraw)
        time.sleep(0.5)
        r = self.main(lambda: self.window.window.os_frame)
        shot = ImageGrab.grab(xdisplay=os.environ.get("DISPLAY"))
        box = (max(0, r.x), max(0, r.y), min(shot.width, r.x + r.width), min(shot.height, r.y + r.height))
        shot.crop(box).save(path)
        return {"path": path, "box": list(box), "em": self.window.em}

    def op_save_camera_path(self, path: str) -> None:
        self.main(lambda: self.window.paths.save_camera_path(path))
        self.op_wait_worker()

    def op_load_camera_path(self, path: str) -> None:
        self.main(lambda: self.window.paths.load_camera_path(path))
        self.op_wait_worker()

    def op_wait_worker(self, timeout: float = 60.0) -> None:
        self._wait_while(lambda: not self.window.worker.is_idle(), timeout, "the worker did not finish")
        time.sleep(0.1)  # its result reaches the main thread through one more post

    def op_help(self, visible: bool = True) -> None:
        def show() -> None:
            if self.window.panel.help.visible != bool(visible):
                self.window._on_help()

        self.main(show)

    def op_expect_error(self, contains: str, timeout: float = 30.0) -> str:
        """Wait for an error dialog whose text contains ``contains``; close it."""
        t_end = time.monotonic() + float(timeout)
        while time.monotonic() < t_end:
            found = [e for e in self.window.errors if contains in e]
            if found:
                self.main(self.window.close_dialog)
                return found[-1]
            time.sleep(0.05)
        raise AssertionError(f"no error dialog containing {contains!r}; errors so far: {self.window.errors}")

    def op_status(self) -> Dict[str, Any]:
        """What the window is doing: exporting, a dialog open, closing, the status line, render counters."""
        w = self.window

        def status() -> Dict[str, Any]:
            return {"exporting": w.exports.exporting, "dialog_open": w.dialog_open, "closing": w._closing,
                    "status": w.panel.status_text, "phase": w.scheduler.phase.value,
                    "interrupted": w.worker.interrupted, "help_visible": w.panel.help.visible}

        return self.main(status)

    def op_save_as(self, what: str, text: str) -> Dict[str, Any]:
        """Open a Save dialog ("screenshot", "camera_path", "export") as its shortcut does, type ``text``
        in its path field and press Save."""
        w = self.window
        opener = {"screenshot": w.exports.on_screenshot, "camera_path": w.paths.on_save_path,
                  "export": w.exports.on_export}[what]
        self.main(opener)

        def type_and_save() -> bool:
            w.path_edit.text_value = text
            w._path_ok()
            return w.dialog_open

        still_open = self.main(type_and_save)
        self.op_wait_worker()
        return {"dialog_open": still_open, "status": self.main(lambda: w.panel.status_text)}

    def op_app_menu(self, item: Any, fields: Optional[Dict[str, Any]] = None, ok: bool = False,
                    save_as: Optional[str] = None, grab: Optional[str] = None, wait: bool = True,
                    timeout: float = 300.0) -> Dict[str, Any]:
        """Activate an Applications menu item (``item``: a ``MENU_*`` name or id of app/viewer/applications.py)
        as the menu does; set the fields of the dialog it opens (name -> a slider's or number's value, a
        combo's index, a checkbox's state), save the window to ``grab`` (PNG), press the dialog's OK with
        ``ok``, type ``save_as`` into the Save dialog that follows and press Save; then wait for the worker
        and any export."""
        import open3d.visualization.gui as gui

        from . import applications as A

        w = self.window
        item_id = getattr(A, item) if isinstance(item, str) else int(item)
        self.main(w.applications.menu_callbacks()[item_id])

        def fill() -> None:
            for name, value in (fields or {}).items():
                widget = w.applications.dialog_fields[name]
                if isinstance(widget, (gui.Slider, gui.NumberEdit)):
                    widget.double_value = float(value)
                elif isinstance(widget, gui.Combobox):
                    widget.selected_index = int(value)
                else:
                    widget.checked = bool(value)

        self.main(fill)
        if grab:
            time.sleep(0.3)
            self.op_grab_window(grab)
        if ok:
            self.main(lambda: w.applications.dialog_ok())
        if save_as is not None:
            def type_and_save() -> None:
                w.path_edit.text_value = save_as
                w._path_ok()

            self.main(type_and_save)
        if wait:
            self.op_wait_worker(timeout)
            self._wait_while(lambda: w.exports.exporting, timeout, "the export did not finish", 0.1)
            self.op_wait_worker(timeout)
        return {"dialog_open": self.main(lambda: w.dialog_open), "status": self.main(lambda: w.panel.status_text)}

    def op_app_call(self, method: str, wait: bool = True, **kwargs: Any) -> Dict[str, Any]:
        """Call ``window.applications.<method>(**kwargs)`` on the main thread (e.g. ``open_views`` with a
        path, ``dialog_ok``), then wait for the worker (with ``wait``)."""
        w = self.window
        self.main(lambda: getattr(w.applications, method)(**kwargs))
        if wait:
            self.op_wait_worker()
        return {"dialog_open": self.main(lambda: w.dialog_open), "status": self.main(lambda: w.panel.status_text)}

    def op_open_dialog(self, what: str = "photo", text: Optional[str] = None, close: bool = False) -> None:
        """Open an Open dialog ("photo", "style") as its shortcut does and leave it open (for a screenshot),
        with ``text`` typed in its path field; ``close`` closes the dialog that is open instead."""
        w = self.window
        if close:
            self.main(w.close_dialog)
            return
        self.main({"photo": w.photos.on_open_photo, "style": w.photos.on_open_style}[what])
        if text is not None:
            self.main(lambda: setattr(w.path_edit, "text_value", text))
        time.sleep(0.5)
        self.main(w.window.post_redraw)
        time.sleep(0.3)

    def op_open_as(self, what: str, text: str) -> Dict[str, Any]:
        """Open an Open dialog ("photo", "style", "camera_path") as its shortcut does, type ``text`` in its
        path field and press Open; reports whether a dialog is still open (the error's) and the errors."""
        w = self.window
        opener = {"photo": w.photos.on_open_photo, "style": w.photos.on_open_style,
                  "camera_path": w.paths.on_load_path}[what]
        self.main(opener)

        def type_and_open() -> Dict[str, Any]:
            w.path_edit.text_value = text
            w._path_ok()
            return {"dialog_open": w.dialog_open, "errors": list(w.errors)}

        out = self.main(type_and_open)
        self.op_wait_worker()
        return out

    def op_recent(self, kind: str = "photo", index: int = 0) -> Dict[str, Any]:
        """Choose entry ``index`` of File > Recent photos / styles (as the menu item does)."""
        w = self.window
        base = P.MENU_RECENT_PHOTO if kind == "photo" else P.MENU_RECENT_STYLE

        def choose() -> None:
            paths = w.settings.recent_photos if kind == "photo" else w.settings.recent_styles
            w.open_recent(paths, int(index), w.photos.open_photo if kind == "photo" else w.photos.open_style)

        self.main(choose)
        self.op_wait_worker()
        return {"menu_id": base + int(index), **self.op_settings()}

    def op_timings(self) -> Dict[str, Any]:
        """Medians (ms) of the window's render timings so far: preview render, hand-over to the main thread
        (``post_delay``), request to display (``preview_latency``), the first level and the full-size full frames;
        and how many full renders were interrupted."""
        def med(values) -> Optional[float]:
            return None if not values else round(1000.0 * sorted(values)[len(values) // 2], 1)

        def timings() -> Dict[str, Any]:
            st = self.window.stats
            return {name: med(st[name]) for name in ("preview_seconds", "post_delay", "preview_latency",
                                                      "level_seconds", "full_seconds")} | {
                "previews": len(st["preview_seconds"]), "interrupted": self.window.worker.interrupted}

        return self.main(timings)

    def op_settings(self) -> Dict[str, Any]:
        """The remembered settings (recent photos and styles, last folder) and the settings file's path."""
        from .settings import settings_path

        st = self.main(lambda: self.window.settings)
        return {"recent_photos": list(st.recent_photos), "recent_styles": list(st.recent_styles),
                "last_folder": st.last_folder, "settings_file": str(settings_path())}

    def op_style_strip(self, index: int = 0) -> Dict[str, Any]:
        """Click thumbnail ``index`` of the style strip (applies that style)."""
        w = self.window
        path = self.main(lambda: w.photos._strip[int(index)])
        self.main(lambda: w.photos.open_style(path))
        self.op_wait_worker()
        return {"style": path, "strip": self.main(lambda: list(w.photos._strip))}

    def op_mix(self, path: str, value: float) -> None:
        """Choose a second style and mix it in by ``value``."""
        self.main(lambda: self.window.photos.open_second_style(path))
        self.main(lambda: self.window.photos.set_mix(float(value)))

    def op_compare(self, split: float = 0.5, on: bool = True) -> None:
        """The before / after split at ``split`` of the width (or off)."""
        self.main(lambda: self.window.set_compare(bool(on), float(split)))

    def op_add_keyframe(self) -> Dict[str, Any]:
        """Add the current view as a keyframe (the K key / Add keyframe button)."""
        w = self.window
        self.main(w.paths.add_keyframe)
        return self.main(lambda: {"keyframes": len(w.state.keyframes.keyframes), "labels": list(
            __import__("stylize3d_app.viewer.keyframe_edit", fromlist=["x"]).keyframe_labels(w.state.keyframes))})

    def op_edit_keyframe(self, index: int = 0, fov: float = None, seconds: float = None, move: int = 0,
                         delete: bool = False, loop: bool = None) -> Dict[str, Any]:
        """Select keyframe ``index`` in the editor's list, then change it as its widgets do."""
        w, cp = self.window, self.window.paths

        def edit() -> Dict[str, Any]:
            cp._selected = int(index)
            if fov is not None:
                cp.on_key_fov(float(fov))
            if seconds is not None:
                cp.on_key_seconds(float(seconds))
            if move:
                cp.on_key_move(int(move))
            if delete:
                cp.on_key_delete()
            if loop is not None:
                cp.on_key_loop(bool(loop))
            kp = w.state.keyframes
            return {"keyframes": 0 if kp is None else len(kp.keyframes),
                    "durations_s": [] if kp is None else list(kp.durations_s),
                    "loop": bool(kp is not None and kp.loop), "use_keyframes": w.state.use_keyframes}

        return self.main(edit)

    def op_save_keyframes(self, path: str) -> None:
        self.main(lambda: self.window.paths.save_keyframes(path))
        self.op_wait_worker()

    def op_load_keyframes(self, path: str) -> None:
        self.main(lambda: self.window.paths.load_keyframes(path))
        self.op_wait_worker()

    def op_open_section(self, name: str = "keys", only: bool = False) -> None:
        """Open a collapsed panel section (for screenshots): "photo", "view", "export", "path" or "keys";
        ``only`` collapses the others (so the section is in sight without scrolling)."""
        p = self.window.panel
        sections = {"photo": p.photo_section, "view": p.view_section, "export": p.export_section,
                    "path": p.path_section, "keys": p.keys_section}

        def open_it() -> None:
            for key, section in sections.items():
                if key == name or only:
                    section.set_is_open(key == name)
            self.window.window.set_needs_layout()

        self.main(open_it)

    def op_preview_keys(self, timeout: float = 300.0) -> Dict[str, Any]:
        """Play the keyframe path at full quality (the editor's Preview button) and wait for its end."""
        w = self.window
        n0 = self.main(lambda: len(w.stats["full_seconds"]))
        self.main(w.paths.on_preview_full)
        self._wait_while(lambda: w.paths.playing, timeout, "the keyframe preview did not end")
        return {"full_frames_shown": self.main(lambda: len(w.stats["full_seconds"])) - n0}

    def op_resize(self, width: int, height: int) -> Dict[str, Any]:
        """Ask for a window size (as a user dragging its border would), then report the size it has."""
        self.main(lambda: setattr(self.window.window, "size", __import__("open3d").visualization.gui.Size(
            int(width), int(height))))
        time.sleep(1.0)
        self.main(self.window.window.post_redraw)
        time.sleep(0.5)
        r = self.main(lambda: self.window.window.size)
        return {"width": r.width, "height": r.height}

    def op_state(self) -> Dict[str, Any]:
        """The user's choices in the view state (what was loaded or is playing is left out), and whether
        a photo is open."""

        def state() -> Dict[str, Any]:
            s = self.window.state
            doc = json.loads(json.dumps(asdict(user_choices(s)), default=str))
            for name in ("photo_info", "loaded_path", "playback", "keyframes"):
                del doc[name]
            return {**doc, "photo_loaded": s.photo_info is not None, "stylized_shown": shows_stylized(s),
                    "limits": asdict(self.window.limits)}

        return self.main(state)
