"""The window's frames: asking the compute worker for the view's frames and showing them as they come.

A change of the view asks for a preview at once and, once the view rests, for the full-quality frame
(progressive levels first; :class:`~stylize3d_app.viewer.render_state.RenderStateMachine` decides). The
worker renders each frame and makes its widget image; a finished frame goes into a one-frame slot
that the GUI main thread empties (:meth:`FrameDelivery._deliver`), so a slow GUI turn never queues
stale frames. Each frame shown adds to ``stats`` (what a test script reports).

:class:`FrameDelivery` is a mixin of :class:`~stylize3d_app.viewer.window.ViewerWindow`: main thread
only, except :meth:`FrameDelivery._deliver` (the worker) and the render function it hands the worker.
"""

from __future__ import annotations

import threading
import time
from typing import Dict, Optional, Tuple

import numpy as np
import open3d as o3d

from stylize3d_core.models.decoder_onnx import onnx_threads
from stylize3d_core.render.plain import frame_size
from stylize3d_core.threads import torch_threads

from .backend import widget_image
from .render_state import RenderPhase, refine_levels
from .session import ViewFrame, colour_jump, shown_as
from .state import choose_preview_long_side, shows_stylized, view_camera
from .worker import RenderResult


class FrameDelivery:
    """Frame requests, budgets and delivery of :class:`~stylize3d_app.viewer.window.ViewerWindow` (a mixin;
    see the module docstring)."""

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
