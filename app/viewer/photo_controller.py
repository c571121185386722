"""The viewer's :class:`PhotoController`: open photos and styles, the depth source and its edge
alignment, the sample, and encoding the photo for the model; the recent photos, the style strip
(bundled and recently used styles), a second style and its mix.

A controller of the window (:mod:`.controller`): main thread only; the loading, building and
encoding run on the compute worker.
"""

from __future__ import annotations

import os
import threading
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Optional

import open3d.visualization.gui as gui

from stylize3d_core.depth import depth_anything

from . import panel as P
from .controller import DEPTH_FILTERS, IMAGE_FILTERS, Controller, ui_callback
from .host import ViewerHost
from .orbit import HOME
from .session import NO_MODEL, SAMPLE_PHOTO, SAMPLE_STYLE, StylizeInfo
from .state import PhotoInfo, fov_range, trajectory_limits

if TYPE_CHECKING:
    from stylize3d_core.pipeline import PhotoSpec


def style_thumbnail(path: str, px: int = P.THUMB_PX):
    """A (px, px, 3) uint8 centre crop of an image file, for the style strip; None if it cannot be read."""
    import cv2
    import numpy as np

    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:
        return None
    h, w = bgr.shape[:2]
    side = min(h, w)
    crop = bgr[(h - side) // 2:(h - side) // 2 + side, (w - side) // 2:(w - side) // 2 + side]
    return np.ascontiguousarray(cv2.resize(crop, (px, px), interpolation=cv2.INTER_AREA)[:, :, ::-1])


BUNDLED_STYLES = tuple(sorted(str(p) for p in Path(str(SAMPLE_STYLE)).parent.glob("*.jpg")))
"""The style images shipped in ``assets/styles`` (the style strip shows them first)."""
MAX_STRIP = 12


class PhotoController(Controller):
    """Photos, styles, the depth source and its edge alignment, the sample, encoding for the model; recent
    photos, the style strip (bundled and recently used styles), a second style and its mix."""

    def __init__(self, window: ViewerHost) -> None:
        super().__init__(window)
        self._strip: list = []
        self._download: Optional[threading.Thread] = None  # the Depth Anything download, while it runs

    def build_strip(self) -> None:
        """Thumbnails of the bundled styles and the recently used ones (main thread, at start); the recent
        photos in the panel's picker."""
        for path in BUNDLED_STYLES + tuple(p for p in self.window.settings.recent_styles if os.path.isfile(p)):
            self._add_to_strip(path)
        self.show_recent()

    @property
    def recent_photos(self) -> tuple:
        """The recent photos, most recent first (kept in the settings file)."""
        return self.window.settings.recent_photos

    def show_recent(self) -> None:
        """List the recent photos in the panel's picker."""
        combo = self.window.panel.recent_photos
        combo.clear_items()
        combo.add_item(P.RECENT_PHOTOS)
        for path in self.recent_photos:
            combo.add_item(os.path.basename(path))
        combo.selected_index = 0

    def _add_to_strip(self, path: str) -> None:
        if path in self._strip or len(self._strip) >= MAX_STRIP:
            return
        thumb = style_thumbnail(path)
        if thumb is None:
            return
        self._strip.append(path)
        self.window.panel.add_style_thumbnail(thumb, os.path.basename(path), lambda: self.open_style(path))
        self.window.window.set_needs_layout()

    def open_photo(self, path: str, depth: Optional[str] = None) -> None:
        """Build the 3D photo of ``path`` on the worker with the state's photo spec (and ``depth``, if
        given); the current photo stays until the new one is built."""
        w = self.window
        spec = replace(w.state.spec, photo=str(path), depth=w.state.spec.depth if depth is None else depth)
        self.load(spec)

    def load(self, spec: "PhotoSpec") -> None:
        """Build the 3D photo ``spec`` describes on the worker; on success it becomes the state's spec."""
        w = self.window
        w.set_busy(f"Building the 3D photo of {os.path.basename(str(spec.photo))} ...", 0.1)
        session = w.session
        self.submit("open photo", lambda: session.load_photo(spec), lambda info: self._loaded(info, spec), key="photo")

    def _loaded(self, info: PhotoInfo, spec: "PhotoSpec") -> None:
        w = self.window
        w.remember(w.settings.with_photo(str(spec.photo)))
        w.state = replace(w.state, spec=spec, photo_info=info, stylize_available=False, pose=HOME, view_fov=None)
        p = w.panel
        h, wd = info.size
        p.photo_label.text = f"{os.path.basename(info.path)}  {wd}x{h}, {info.n_points:,} points"
        lo, hi = fov_range(info.fov_y_deg)
        p.fov.set_limits(lo, hi)
        p.fov.double_value = info.fov_y_deg
        p.fov_label.text = f"Field of view: {info.fov_y_deg:.1f} degrees"
        self.window.paths.set_limits(trajectory_limits(info.camera_range, info.scene))
        p.set_enabled(True)
        narrow = "" if info.range_scale >= 0.995 else f"; camera range {100 * info.range_scale:.0f} %"
        w.set_busy(f"3D photo ready in {info.seconds:.1f} s (depth: {info.depth_source}{narrow})", 0.5)
        w.photo_changed()  # requests the first (plain) frame
        p.model_label.text = "encoding the point cloud for the model ..."
        w.worker.submit("encode photo", w.session.prepare_stylized,
                        on_done=lambda r: w.post(lambda: self._stylize_ready(r)),
                        on_error=lambda name, e: w.post(lambda: self._stylize_failed(name, e)))

    def _set_stylize_available(self, available: bool, message: str) -> None:
        w = self.window
        w.state = replace(w.state, stylize_available=available)
        w.panel.set_line(w.panel.model_label, message)
        w.panel.stylized.enabled = available

    def _stylize_ready(self, r: StylizeInfo) -> None:
        self._set_stylize_available(r.available, r.message)
        self.window.set_busy(f"Ready (model set up in {r.seconds:.1f} s)" if r.available else "Ready", None)
        self.window.view_changed()  # requested before the task below: the first stylized frame does not wait
        if r.available:
            w = self.window
            self.submit("prepare model", w.session.prepare_model_features, lambda _r: None, key="prepare model")

    def _stylize_failed(self, name: str, e: BaseException) -> None:
        self._set_stylize_available(False, NO_MODEL)
        self.task_failed(name, e)

    def open_style(self, path: str) -> None:
        """Read a style image on the worker and apply it (the encoded point cloud is re-used)."""
        w = self.window
        w.set_busy(f"Applying style {os.path.basename(path)} ...", 0.3)
        session = w.session
        self.submit("open style", lambda: session.load_style(path), lambda _hw: self._style_loaded(path), key="style")

    def _style_loaded(self, path: str) -> None:
        w = self.window
        w.state = replace(w.state, style=path)
        self._add_to_strip(str(path))
        if os.path.abspath(str(path)) not in BUNDLED_STYLES:  # (the strip always shows the bundled ones)
            w.remember(w.settings.with_style(str(path)))
        w.panel.style_label.text = os.path.basename(path)
        if w.state.stylize_available:
            w.set_busy("Style applied", None)
        elif w.session.checkpoint_path() is not None:  # the model is still loading or encoding: no NO_MODEL flash
            w.set_busy("Style chosen (shown once the model is ready)", None)
        else:
            w.set_busy(f"Style chosen ({NO_MODEL})", None)
        w.view_changed()

    @ui_callback
    def on_recent_photo(self, _text: str, index: int) -> None:
        if index >= 1:
            self.window.open_recent(self.recent_photos, index - 1, self.open_photo)

    def open_second_style(self, path: Optional[str]) -> None:
        """Read a second style image on the worker to mix with the first (None removes it)."""
        w = self.window
        session = w.session
        self.submit("open second style", lambda: session.load_second_style(path),
                    lambda _hw: self._style2_loaded(path), key="style2")

    def _style2_loaded(self, path: Optional[str]) -> None:
        w = self.window
        w.state = replace(w.state, style2=path)
        w.panel.style2_label.text = "no second style" if path is None else os.path.basename(path)
        w.set_status("Second style chosen: move Mix to blend" if path else "Second style removed")
        w.view_changed()

    def set_mix(self, value: float) -> None:
        """Mix of the two styles in [0, 1] (a re-blend on the worker, then a new frame)."""
        w = self.window
        w.set_blend("mix", w.panel.mix, value, w.session.set_mix)

    @ui_callback
    def on_open_style2(self) -> None:
        self.window.file_dialog(gui.FileDialog.OPEN, "Second style image", IMAGE_FILTERS, self.open_second_style)

    @ui_callback
    def on_mix(self, value: float) -> None:
        self.set_mix(value)

    def load_sample(self) -> None:
        """Open the bundled sample photo and style."""
        self.open_style(str(SAMPLE_STYLE))
        self.open_photo(str(SAMPLE_PHOTO))

    def change_spec(self, status: str, **changes: Any) -> None:
        """Change options of the photo spec (e.g. ``depth="prior"``) and rebuild the open photo with them;
        with no photo open, keep them for the next one and show ``status``."""
        w = self.window
        spec = replace(w.state.spec, **changes)  # InputError for a bad value: nothing changes
        if spec.photo is None:
            w.state = replace(w.state, spec=spec)
            w.set_status(status)
        else:
            self.load(spec)

    def set_refine_depth(self, method: Optional[str]) -> None:
        """Choose the depth-edge alignment (None: none) and rebuild the open photo with it."""
        self.change_spec(f"Depth edges: {method or 'as estimated'}", refine_depth=method)

    def set_depth(self, source: str) -> None:
        """Choose the depth source (a spec such as "prior" or a depth file) and rebuild the open photo with it.
        Depth Anything without its weights is not chosen: the status line points at the Download button."""
        if source == depth_anything.SPEC and depth_anything.cached_folder() is None:
            self.show_depth_model()
            self.show_depth_choice()
            self.window.set_status("Depth Anything's weights are not downloaded: click "
                                   f"\"{P.DOWNLOAD_LABEL}\" under Depth (once, needs the network)"
                                   if depth_anything.installed() else
                                   f"Depth Anything needs the depth extra: {depth_anything.EXTRA_HINT}")
            return
        self.change_spec(f"Depth source: {source}", depth=source)

    def show_depth_choice(self) -> None:
        """Show the state's depth source in the picker (a depth file shows as the picker's first entry)."""
        specs = [spec for spec, _ in P.DEPTH_CHOICES]
        depth = self.window.state.spec.depth
        self.window.panel.depth.selected_index = specs.index(depth) if depth in specs else 0

    def show_depth_model(self, downloading: bool = False) -> None:
        """The Download button: offered while the depth extra is installed and the weights are not cached."""
        button = self.window.panel.depth_download
        cached = depth_anything.cached_folder() is not None
        button.text = ("Downloading Depth Anything ..." if downloading else
                       "Depth Anything downloaded" if cached else P.DOWNLOAD_LABEL)
        button.enabled = not downloading and not cached and depth_anything.installed()

    def download_depth_model(self) -> None:
        """Download Depth Anything's pinned weights on a thread of their own, the progress in the status line;
        once they are in the cache, choose it as the depth source (the open photo is rebuilt with it)."""
        w = self.window
        if depth_anything.cached_folder() is not None:
            self.show_depth_model()
            self.set_depth(depth_anything.SPEC)
            return
        if self._download is not None and self._download.is_alive():
            return
        self.show_depth_model(downloading=True)
        w.set_busy("Downloading Depth Anything V2 Small (about 99 MB) ...", 0.0)
        shown = [-1]

        def progress(fraction: float) -> None:  # on the download thread: post only whole-percent changes
            percent = int(100 * fraction)
            if percent != shown[0]:
                shown[0] = percent
                w.post(lambda: w.set_busy(f"Downloading Depth Anything V2 Small ... {percent} %", fraction))

        def failed(name: str, e: BaseException) -> None:
            self.show_depth_model()
            self.task_failed(name, e)

        def run() -> None:
            try:
                depth_anything.download(progress=progress)
            except BaseException as e:  # noqa: BLE001 (InputError and anything else): a dialog, not a dead thread
                w.post(lambda e=e: failed("download Depth Anything", e))
            else:
                w.post(self._depth_model_downloaded)

        # its own thread, not the compute worker's: the view keeps rendering through a long download
        self._download = threading.Thread(target=run, name="download Depth Anything", daemon=True)
        self._download.start()

    def _depth_model_downloaded(self) -> None:
        self.show_depth_model()
        self.window.set_busy("Depth Anything downloaded: it is the depth source now", None)
        self.set_depth(depth_anything.SPEC)
        self.window.panel.depth.selected_index = [spec for spec, _ in P.DEPTH_CHOICES].index(depth_anything.SPEC)

    # -- widget callbacks --------------------------------------------------------------
    @ui_callback
    def on_open_photo(self) -> None:
        self.window.file_dialog(gui.FileDialog.OPEN, "Open photo", IMAGE_FILTERS, self.open_photo,
                                recent=self.recent_photos)

    @ui_callback
    def on_open_style(self) -> None:
        self.window.file_dialog(gui.FileDialog.OPEN, "Open style image", IMAGE_FILTERS, self.open_style,
                                recent=self.window.settings.recent_styles)

    @ui_callback
    def on_sample(self) -> None:
        self.load_sample()

    @ui_callback
    def on_depth_choice(self, text: str, index: int) -> None:
        self.set_depth(P.DEPTH_CHOICES[index][0])

    @ui_callback
    def on_open_depth(self) -> None:
        self.window.file_dialog(gui.FileDialog.OPEN, "Open depth or disparity file", DEPTH_FILTERS, self.set_depth)

    @ui_callback
    def on_download_depth_model(self) -> None:
        self.download_depth_model()

    @ui_callback
    def on_refine_choice(self, text: str, index: int) -> None:
        self.set_refine_depth(P.REFINE_CHOICES[index][0])
