"""The viewer's Applications menu: the paper's applications and the exports (``docs/applications.md``).

* **Multi-view input** (paper Sec. 4.4): a views file (images, depth files and
  poses, inline or an Open3D ``PinholeCameraTrajectory``; ``stylize3d_core/multiview.py``)
  merged into one 3D photo in the frame of the view the user picks.
* **Stereo cards**: a scanned card, parallel or cross-eyed (depth ``stereo:card``
  / ``stereo:card:cross``), browsed as the photo of its left print.
* **Layered stylization** (Sec. 4.5): a foreground mask from a file, the automatic
  person segmentation (``scene.masks.person_mask``) or GrabCut in
  a rectangle (sliders as fractions of the photo), kept at its own strength (0: the
  original colours); the session renders through :class:`~stylize3d_app.viewer.layers.ViewerLayers`.
* **Exports**: baked-colour PLY, 3D Gaussian splat ``.ply``, side-by-side (full
  or half width) and red-cyan anaglyph videos with an eye distance, boomerang
  loops (MP4, GIF, WebP), one self-contained web page to orbit in a browser
  (``stylize3d_core/export/web_page.py``; it plays the export's camera path),
  camera paths as stylize3d JSON and Open3D trajectory.

:class:`ApplicationsController` is a controller like those of :mod:`stylize3d_app.viewer.actions`:
its methods run on the GUI main thread, the work (the library's functions below)
on the compute worker; exports go through
:meth:`~stylize3d_app.viewer.actions.ExportController.run_export` (progress, Cancel, atomic
writes by the library's writers). The work functions (:mod:`.applications_work`:
``layers_from_file``, ``layers_by_grabcut``, ``merged_photo``, ``export_point_file``,
``export_web_page``, ``export_video``, ...) take the session and need no window; this
module re-exports them.
"""

from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import open3d.visualization.gui as gui

from stylize3d_core.errors import InputError
from stylize3d_core.export.camera_paths import write_camera_path
from stylize3d_core.export.settings import ExportSettings
from stylize3d_core.render.plain import frame_size

from .applications_work import (  # (re-exported: scripts and tests call them as applications.<name>)
    LOOP_SUFFIXES, SessionRenderer, clear_layers, export_point_file, export_video, export_web_page,
    layers_by_grabcut, layers_by_person, layers_from_file, merged_photo, page_destination, photo_file_size,
    point_destination, rect_pixels, set_foreground_strength, video_destination,
)
from .controller import JSON_FILTERS, Controller, ui_callback
from .host import ViewerHost
from .layers import ViewerLayers
from .state import shows_stylized

(MENU_VIEWS, MENU_CARD, MENU_CARD_CROSS, MENU_MASK_FILE, MENU_GRABCUT, MENU_PERSON, MENU_FG_STRENGTH,
 MENU_MASK_CLEAR, MENU_PLY, MENU_SPLAT, MENU_SBS, MENU_ANAGLYPH, MENU_LOOP, MENU_PATH_JSON, MENU_PATH_OPEN3D,
 MENU_PATH_LOAD, MENU_HTML) = range(301, 318)
"""Menu ids of the Applications menu: clear of the recent photos' and styles' (100 + i, 200 + i, panel.py)."""

CARD_SPECS = {False: "stereo:card", True: "stereo:card:cross"}
"""Depth specs of a parallel (False) and a cross-eyed (True) stereo card."""
DEFAULT_RECT = (0.2, 0.1, 0.8, 1.0)
"""GrabCut's default rectangle (left, top, right, bottom as fractions of the photo): the centre, to the bottom."""
VIEWS_FILTERS = ((".json", "Views file or Open3D trajectory views (JSON)"), ("", "All files"))
MASK_FILTERS = ((".png .jpg .jpeg .webp .tif .tiff .bmp", "Mask images (PNG, ...)"), ("", "All files"))
CARD_FILTERS = ((".jpg .jpeg .png .webp .tif .tiff", "Scanned stereo cards"), ("", "All files"))
PLY_FILTERS = ((".ply", "PLY"), ("", "All files"))
HTML_FILTERS = ((".html .htm", "Web page (HTML)"), ("", "All files"))


def build_applications_menu() -> gui.Menu:
    """The Applications menu (its items' ids are this module's ``MENU_*``)."""
    m = gui.Menu()
    m.add_item("Open multi-view views file...", MENU_VIEWS)
    m.add_item("Open stereo card (parallel)...", MENU_CARD)
    m.add_item("Open stereo card (cross-eyed)...", MENU_CARD_CROSS)
    m.add_separator()
    m.add_item("Foreground mask from file...", MENU_MASK_FILE)
    m.add_item("Foreground by GrabCut (rectangle)...", MENU_GRABCUT)
    m.add_item("Foreground: person (automatic)", MENU_PERSON)
    m.add_item("Foreground strength...", MENU_FG_STRENGTH)
    m.add_item("Clear foreground mask", MENU_MASK_CLEAR)
    m.add_separator()
    m.add_item("Export point cloud (PLY, baked colours)...", MENU_PLY)
    m.add_item("Export Gaussian splats (.ply)...", MENU_SPLAT)
    m.add_item("Export web page (HTML, orbit in a browser)...", MENU_HTML)
    m.add_item("Export side-by-side stereo video...", MENU_SBS)
    m.add_item("Export red-cyan anaglyph video...", MENU_ANAGLYPH)
    m.add_item("Export boomerang loop (MP4, GIF, WebP)...", MENU_LOOP)
    m.add_separator()
    m.add_item("Save camera path (stylize3d JSON)...", MENU_PATH_JSON)
    m.add_item("Save camera path (Open3D trajectory)...", MENU_PATH_OPEN3D)
    m.add_item("Load camera path (stylize3d or Open3D)...", MENU_PATH_LOAD)
    return m


# -- the controller (GUI main thread) -----------------------------------------------------------
class ApplicationsController(Controller):
    """The Applications menu's actions (see the module docstring).

    Its dialogs are :meth:`~stylize3d_app.viewer.controller.Controller._dialog` forms (test hooks:
    ``dialog_fields``, ``dialog_ok``)."""

    def __init__(self, window: ViewerHost) -> None:
        super().__init__(window)
        self.foreground_strength = 0.0
        self.rect = DEFAULT_RECT
        self.eye_distance = ExportSettings().eye_distance
        self.stereo_layout = "full"
        self.stereo_loop = False
        self.mask_source: Optional[str] = None  # what the foreground came from (None: no mask)
        self._views: Optional[list] = None

    def menu_callbacks(self) -> Dict[int, Callable[[], None]]:
        """Menu id -> callback, for ``window.set_on_menu_item_activated``."""
        return {
            MENU_VIEWS: self.on_open_views, MENU_CARD: lambda: self.on_open_card(False),
            MENU_CARD_CROSS: lambda: self.on_open_card(True), MENU_MASK_FILE: self.on_mask_file,
            MENU_GRABCUT: self.on_grabcut, MENU_PERSON: self.on_person, MENU_FG_STRENGTH: self.on_foreground_strength,
            MENU_MASK_CLEAR: self.on_clear_mask, MENU_PLY: lambda: self.on_export("ply"),
            MENU_SPLAT: lambda: self.on_export("splat"), MENU_HTML: lambda: self.on_export("html"), MENU_SBS: lambda: self.on_export("sbs"),
            MENU_ANAGLYPH: lambda: self.on_export("anaglyph"), MENU_LOOP: lambda: self.on_export("loop"),
            MENU_PATH_JSON: lambda: self.on_save_path("stylize3d"), MENU_PATH_OPEN3D: lambda: self.on_save_path("open3d"),
            MENU_PATH_LOAD: self.on_load_path,
        }

    def _require_photo(self) -> bool:
        if self.window.state.photo_info is None:
            self.window.set_status("Open a photo first")
            return False
        return True

    # -- multi-view and stereo cards -------------------------------------------------------
    @ui_callback
    def on_open_views(self) -> None:
        self.window.file_dialog(gui.FileDialog.OPEN, "Open multi-view views file", VIEWS_FILTERS, self.open_views)

    def open_views(self, path: str, centre: Optional[int] = None) -> None:
        """Read the views file ``path`` on the worker; then merge it in the frame of view ``centre`` (None:
        ask, when there is more than one view)."""
        w = self.window
        from stylize3d_core.multiview import load_views

        w.set_busy(f"Reading the views of {os.path.basename(path)} ...", 0.1)
        max_size = w.state.spec.max_size
        self.submit("open views", lambda: load_views(path, max_size=max_size),
                    lambda views: self._views_read(path, views, centre), key="photo")

    def _views_read(self, path: str, views: list, centre: Optional[int]) -> None:
        self._views = views
        names = [os.path.basename(v.name) for v in views]
        if centre is not None or len(views) == 1:
            self.merge_views(0 if centre is None else centre)
            return
        combo = gui.Combobox()
        for n in names:
            combo.add_item(n)
        combo.selected_index = 0
        self.window.set_busy(f"{len(views)} views read from {os.path.basename(path)}", None)
        self._dialog("Multi-view input", [f"{len(views)} views in {os.path.basename(path)}.",
                                          "The 3D photo is built in the frame of the centre view."],
                     [("centre", "Centre view", combo)], ("Merge", lambda: self.merge_views(combo.selected_index)))

    def merge_views(self, centre: int) -> None:
        """Merge the views read last in the frame of view ``centre`` (on the worker) and open the result."""
        w = self.window
        views = self._views
        if not views:
            raise InputError("views", "open a views file first")
        if not 0 <= int(centre) < len(views):
            raise InputError("centre view", f"must be 0 to {len(views) - 1}, got {centre}")
        spec = replace(w.state.spec, photo=str(views[int(centre)].name), depth="auto", stereo_card=False)
        w.set_busy(f"Merging {len(views)} views in the frame of {os.path.basename(spec.photo)} ...", 0.2)
        session, ldi = w.session, spec.ldi
        self.submit("merge views", lambda: merged_photo(session, views, int(centre), ldi),
                    lambda info: self._photo_opened(info, spec, f"{len(views)} views merged"), key="photo")

    def _photo_opened(self, info, spec, what: str) -> None:
        self.window.photos._loaded(info, spec)  # the photo controller's own update: labels, encoding, view
        self._mask_dropped_unless_kept()
        self.window.set_status(f"{what}: {info.n_points:,} points")

    def _mask_dropped_unless_kept(self) -> None:
        if self.mask_source is not None and self.window.session.layers is None:
            self.mask_source = None

    @ui_callback
    def on_open_card(self, cross_eyed: bool = False) -> None:
        kind = "cross-eyed" if cross_eyed else "parallel"
        self.window.file_dialog(gui.FileDialog.OPEN, f"Open stereo card ({kind})", CARD_FILTERS,
                                lambda path: self.open_card(path, cross_eyed))

    def open_card(self, path: str, cross_eyed: bool = False) -> None:
        """Open a scanned stereo card (split, aligned, matched for depth; its left print is the photo)."""
        w = self.window
        w.photos.load(replace(w.state.spec, photo=str(path), depth=CARD_SPECS[bool(cross_eyed)], stereo_card=False))

    # -- layered stylization ---------------------------------------------------------------
    def _layers_done(self, layers: ViewerLayers) -> None:
        w = self.window
        self.mask_source = layers.source
        kept = "original colours" if layers.foreground_strength is None else \
            f"strength {layers.foreground_strength:.2f}"
        note = "" if w.state.stylize_available else " (once stylized)"
        w.set_busy(f"Foreground from {layers.source}: {layers.fraction:.0%}, {kept}{note}", None)
        w.view_changed()

    @ui_callback
    def on_mask_file(self) -> None:
        if self._require_photo():
            self.window.file_dialog(gui.FileDialog.OPEN, "Foreground mask (white = keep)", MASK_FILTERS,
                                    self.load_mask)

    def load_mask(self, path: str) -> None:
        """Use the mask file ``path`` as the foreground (read and checked on the worker)."""
        w = self.window
        if w.state.photo_info is None:
            raise InputError("photo", "open a photo first")
        session, fs, depth = w.session, self.foreground_strength, w.state.spec.depth
        self.submit("foreground mask", lambda: layers_from_file(session, path, fs, depth), self._layers_done,
                    key="layers")

    @ui_callback
    def on_grabcut(self) -> None:
        if not self._require_photo():
            return
        names = ("left", "top", "right", "bottom")
        fields = [(n, n.capitalize(), self._slider(v)) for n, v in zip(names, self.rect)]
        fields.append(("strength", "Foreground strength", self._slider(self.foreground_strength)))
        f = {name: widget for name, _label, widget in fields}

        def ok() -> None:
            self.grabcut([f[n].double_value for n in names], f["strength"].double_value)

        self._dialog("Foreground by GrabCut", ["The rectangle around the person or object, as fractions",
                                               "of the photo's width (left, right) and height (top, bottom).",
                                               "Strength 0 keeps the foreground's original colours."],
                     fields, ("Find foreground", ok))

    def grabcut(self, fractions: Sequence[float], foreground_strength: Optional[float] = None) -> None:
        """GrabCut in the rectangle ``fractions`` (left, top, right, bottom) on the worker; the foreground
        becomes the mask (at ``foreground_strength``, default the current one)."""
        w = self.window
        if w.state.photo_info is None:
            raise InputError("photo", "open a photo first")
        rect = tuple(float(v) for v in fractions)
        rect_pixels(w.state.photo_info.size, rect)  # a bad rectangle fails here, before the worker
        if foreground_strength is not None:
            self.foreground_strength = float(min(1.0, max(0.0, foreground_strength)))
        self.rect = rect
        w.set_busy("GrabCut: finding the foreground ...", 0.3)
        session, fs = w.session, self.foreground_strength
        self.submit("GrabCut", lambda: layers_by_grabcut(session, rect, fs), self._layers_done, key="layers")

    @ui_callback
    def on_person(self) -> None:
        if self._require_photo():
            self.person()

    def person(self) -> None:
        """Find the people in the photo on the worker; they become the foreground (at the current strength)."""
        w = self.window
        if w.state.photo_info is None:
            raise InputError("photo", "open a photo first")
        w.set_busy("Person segmentation: finding the people ...", 0.3)
        session, fs = w.session, self.foreground_strength
        self.submit("person mask", lambda: layers_by_person(session, fs), self._layers_done, key="layers")

    @ui_callback
    def on_foreground_strength(self) -> None:
        slider = self._slider(self.foreground_strength)
        self._dialog("Foreground strength", ["Style strength of the foreground: 0 keeps its original colours."],
                     [("strength", "Strength", slider)], ("Apply", lambda: self.set_foreground_strength(slider.double_value)))

    def set_foreground_strength(self, value: float) -> None:
        """The foreground's style strength in [0, 1] (0: its original colours), for this mask and the next."""
        w = self.window
        self.foreground_strength = float(min(1.0, max(0.0, value)))
        session, fs = w.session, self.foreground_strength

        def done(layers: Optional[ViewerLayers]) -> None:
            if layers is None:
                w.set_status(f"Foreground strength {fs:.2f} (used by the next mask)")
            else:
                self._layers_done(layers)

        self.submit("foreground strength", lambda: set_foreground_strength(session, fs), done, key="layers")

    @ui_callback
    def on_clear_mask(self) -> None:
        self.clear_mask()

    def clear_mask(self) -> None:
        """Drop the foreground mask: the whole photo is stylized again."""
        w = self.window
        session = w.session

        def done(_r: None) -> None:
            self.mask_source = None
            w.set_status("Foreground mask cleared: the whole photo is stylized")
            w.view_changed()

        self.submit("clear mask", lambda: clear_layers(session), done, key="layers")

    # -- exports ---------------------------------------------------------------------------
    @ui_callback
    def on_export(self, kind: str) -> None:
        """Ask for the export's options (stereo) and its file, then export on the worker."""
        w = self.window
        if not self._require_photo() or w.exports.exporting:
            return
        if kind in ("sbs", "anaglyph"):
            self._stereo_dialog(kind)
            return
        names = {"ply": "stylized_points.ply", "splat": "stylized_splats.ply", "loop": "stylized_loop.mp4",
                 "html": "stylized_3d_photo.html"}
        titles = {"ply": "Export point cloud (PLY)", "splat": "Export Gaussian splats (.ply)",
                  "loop": "Export boomerang loop (.mp4, .gif or .webp)", "html": "Export web page (.html)"}
        filters = PLY_FILTERS if kind in ("ply", "splat") else HTML_FILTERS if kind == "html" else ()
        w.file_dialog(gui.FileDialog.SAVE, titles[kind], filters, lambda path: self.start_export(kind, path),
                      names[kind])

    def _stereo_dialog(self, kind: str) -> None:
        fields: List[Tuple[str, str, gui.Widget]] = []
        layout = gui.Combobox()
        if kind == "sbs":
            for text in ("Full width (each eye full size)", "Half width (each eye squeezed)"):
                layout.add_item(text)
            layout.selected_index = 0 if self.stereo_layout == "full" else 1
            fields.append(("layout", "Layout", layout))
        eye = self._number(self.eye_distance, 1e-4, 1.0)
        loop = gui.Checkbox("forward, then back")
        loop.checked = self.stereo_loop
        fields += [("eye_distance", "Eye distance", eye), ("loop", "Boomerang loop", loop)]
        title = "Side-by-side stereo video" if kind == "sbs" else "Red-cyan anaglyph video"

        def ok() -> None:
            self.eye_distance = float(eye.double_value)
            self.stereo_loop = bool(loop.checked)
            if kind == "sbs":
                self.stereo_layout = "full" if layout.selected_index == 0 else "half"
            self.window.file_dialog(gui.FileDialog.SAVE, title + " (.mp4, .gif or .webp)", (),
                                    lambda path: self.start_export(kind, path), f"stylized_{kind}.mp4")

        self._dialog(title, ["Eye distance in scene units (the nearest surface is about 1/3 away);",
                             "at most half the distance to the nearest surface in any frame."],
                     fields, ("Choose file...", ok))

    def export_settings(self, kind: str) -> ExportSettings:
        """The library's export settings for ``kind`` (ply, splat, html, sbs, anaglyph, loop) from the dialogs'
        choices."""
        if kind == "loop":
            return ExportSettings(export="video", loop=True)
        if kind in ("sbs", "anaglyph"):
            return ExportSettings(export=kind, stereo_layout=self.stereo_layout, eye_distance=self.eye_distance,
                                  loop=self.stereo_loop)
        if kind in ("ply", "splat", "html"):
            return ExportSettings(export=kind)
        raise InputError("export", f"unknown export {kind!r}: ply, splat, html, sbs, anaglyph or loop")

    def start_export(self, kind: str, path: str) -> str:
        """Export ``kind`` to ``path`` on the worker (progress, Cancel); returns the destination."""
        w = self.window
        s = w.state
        if s.photo_info is None:
            raise InputError("photo", "open a photo first")
        settings = self.export_settings(kind)  # InputError for bad choices: nothing starts
        session, stylized = w.session, shows_stylized(s)
        if kind in ("ply", "splat"):
            dest = point_destination(path)

            def points(progress, between) -> Path:
                def step() -> None:
                    progress(0, 1)  # raises ExportCancelled once Cancel is pressed
                    between()

                return export_point_file(session, dest, kind, stylized, settings.splat_scale, step)

            what = "baked point cloud" if kind == "ply" else "Gaussian splats"
            return w.exports.run_export(dest, f"Writing the {what} to {dest} ...", 1, points)
        cams = w.paths.export_cameras()
        if kind == "html":
            dest, fps = page_destination(path), s.export.fps

            def page(progress, between) -> Path:
                def step() -> None:
                    progress(0, 1)
                    between()

                return export_web_page(session, dest, cams, fps, stylized, step)

            return w.exports.run_export(dest, f"Writing the web page to {dest} ...", 1, page)
        dest = video_destination(path)
        size, fps = frame_size(s.photo_info.size, s.export.size), s.export.fps
        n = 2 * len(cams) - 2 if settings.loop and len(cams) > 1 else len(cams)

        def video(progress, between) -> Path:
            return export_video(session, dest, settings, cams, size, fps, stylized, progress, between)

        return w.exports.run_export(dest, f"Exporting {n} {kind} frames to {dest} ...", n, video)

    # -- camera paths ------------------------------------------------------------------------
    @ui_callback
    def on_save_path(self, fmt: str) -> None:
        if not self._require_photo():
            return
        name = "camera_path.json" if fmt == "stylize3d" else "trajectory_open3d.json"
        title = "Save camera path (stylize3d JSON)" if fmt == "stylize3d" else "Save camera path (Open3D trajectory)"
        self.window.file_dialog(gui.FileDialog.SAVE, title, JSON_FILTERS, lambda p: self.save_path(p, fmt), name)

    def save_path(self, path: str, fmt: str) -> None:
        """Write the export's cameras as ``fmt`` ("stylize3d" or "open3d") JSON on the worker."""
        w = self.window
        s = w.state
        if Path(path).suffix.lower() != ".json":
            raise InputError(path, "a camera path file must end in .json")
        cams = w.paths.export_cameras()
        fps, size = s.export.fps, frame_size(s.photo_info.size, s.export.size)
        self.submit("save camera path", lambda: write_camera_path(path, cams, fmt=fmt, fps=fps, image_size=size),
                    lambda out: w.set_status(f"Saved {out} ({len(cams)} cameras, {fmt})"))

    @ui_callback
    def on_load_path(self) -> None:
        self.window.file_dialog(gui.FileDialog.OPEN, "Load camera path (stylize3d or Open3D)", JSON_FILTERS,
                                self.load_path)

    def load_path(self, path: str) -> None:
        """Read a stylize3d camera path or an Open3D trajectory on the worker and follow it."""
        self.window.paths.load_camera_path(path)  # File > Load camera path: it reads both formats

