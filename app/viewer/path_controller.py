"""The viewer's :class:`CameraPathController`: the trajectory, the camera-path preview in the view
(:class:`~stylize3d_app.viewer.state.Playback`), the keyframe editor, and loading and saving camera paths
and keyframes.

A controller of the window (:mod:`.controller`): main thread only; files are read and written on the
compute worker.
"""

from __future__ import annotations

import os
import time
from dataclasses import replace

import open3d.visualization.gui as gui

from stylize3d_core.errors import InputError
from stylize3d_core.export.camera_paths import read_camera_path
from stylize3d_core.io.camera_path import CameraPath, save_camera_path
from stylize3d_core.io.keyframes import load_keyframes, save_keyframes
from stylize3d_core.render.plain import frame_size

from . import keyframe_edit as KE
from .controller import JSON_FILTERS, Controller, ui_callback
from .state import (
    LOADED_PATH, Playback, TrajectoryLimits, clamp_trajectory, path_source, playback_frame, trajectory_cameras,
    view_camera,
)


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
