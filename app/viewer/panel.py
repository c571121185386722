"""The viewer's widgets: side panel, status area, help overlay and menus (construction only).

:class:`Panel` builds the widgets and keeps references to them; the window
(:mod:`stylize3d_app.viewer.window`) connects their callbacks. Sizes are in em units (the
theme's font size), so the layout follows the UI scale.
"""

from __future__ import annotations

import os
from typing import Callable, List, Optional, Sequence, Tuple, get_args

import open3d.visualization.gui as gui

from stylize3d_core.geometry.trajectories import TrajectoryName

from .state import VideoExport, ViewState

DEPTH_CHOICES: Tuple[Tuple[str, str], ...] = (
    ("auto", "auto (phone, Depth Anything if downloaded, else prior)"),
    ("prior", "built-in prior"),
    ("phone", "phone depth (XMP)"),
    ("stereo:sbs", "side-by-side stereo card"),
    ("depth-anything", "Depth Anything V2 (learned)"),
)
"""Depth sources offered in the picker: (spec, label). A depth file is chosen with "Depth file..."."""
DOWNLOAD_LABEL = "Download Depth Anything (99 MB)"

REFINE_CHOICES: Tuple[Tuple[Optional[str], str], ...] = (
    (None, "depth edges as estimated"),
    ("bilateral_median", "align edges to the photo (sharp)"),
    ("joint_bilateral", "align edges (smooth, joint bilateral)"),
    ("guided", "align edges (smooth, guided filter)"),
)
"""Depth-edge alignment offered in the picker: (``refine_depth`` value, label)."""

EXPORT_FORMATS: Tuple[Tuple[str, str], ...] = (("mp4", "MP4 video"), ("gif", "GIF animation"), ("png", "PNG frames"))

SHORTCUTS: Tuple[Tuple[str, str], ...] = (
    ("left-drag", "orbit about the scene centre"),
    ("right-drag / shift-drag", "pan"),
    ("wheel up / down, + / -, PgUp / PgDn", "move forwards / backwards"),
    ("double-click, R", "reset the view"),
    ("arrow keys", "orbit (an eighth of the range a step)"),
    ("O / S / D", "open photo / style / depth file"),
    ("M", "open the bundled sample"),
    ("T", "stylized / original"),
    ("[ / ]", "strength -0.1 / +0.1"),
    ("C", "preview the camera path"),
    ("K", "add the view as a keyframe"),
    ("E", "export a video"),
    ("P", "save a screenshot"),
    ("H or F1", "show / hide this help"),
    ("Esc", "close dialog / help, stop preview"),
    ("", "(Esc never quits; an export goes on)"),
    ("Ctrl+Q", "quit (asks first during an export)"),
    ("", "(arrows, + / -: click the view first)"),
)

RECENT_PHOTOS = "Recent photos..."
THUMBS_PER_ROW = 4
THUMB_PX = 44
SLIDER_TRACK = gui.Color(0.32, 0.32, 0.36, 1.0)
"""Background of the sliders: Open3D's dark theme draws their track in the panel's colour (invisible)."""

MENU_OPEN, MENU_STYLE, MENU_DEPTH, MENU_SAMPLE = 1, 2, 3, 4
MENU_LOAD_PATH, MENU_SAVE_PATH, MENU_EXPORT, MENU_SCREENSHOT, MENU_QUIT = 5, 6, 7, 8, 9
MENU_STYLIZED, MENU_RESET, MENU_PREVIEW, MENU_HELP, MENU_ABOUT = 10, 11, 12, 13, 14


MENU_RECENT_PHOTO = 100
"""Menu ids of the recent photos: ``MENU_RECENT_PHOTO + i`` for the i-th most recent."""
MENU_RECENT_STYLE = 200
"""Menu ids of the recent styles: ``MENU_RECENT_STYLE + i``."""


def recent_label(path: str, index: int) -> str:
    """A recent file's menu entry: its number and name, then its folder (shortened from the left)."""
    folder, name = os.path.split(path)
    if len(folder) > 40:
        folder = "..." + folder[-37:]
    return f"{index + 1}  {name}   ({folder})"


def build_menubar(recent_photos: Sequence[str] = (), recent_styles: Sequence[str] = (),
                  stylized: bool = True, extra: Sequence[Tuple[str, gui.Menu]] = ()) -> gui.Menu:
    """The application's menu bar (File with its recent photos and styles, View, the ``extra`` menus as
    (title, menu) pairs, Help). Open3D menus cannot change once built, so the window builds a new bar when
    the recent files change."""
    file_menu = gui.Menu()
    file_menu.add_item("Open photo...   O", MENU_OPEN)
    file_menu.add_item("Open style...   S", MENU_STYLE)
    file_menu.add_item("Open depth file...   D", MENU_DEPTH)
    file_menu.add_item("Open bundled sample   M", MENU_SAMPLE)
    for title, paths, base in (("Recent photos", recent_photos, MENU_RECENT_PHOTO),
                               ("Recent styles", recent_styles, MENU_RECENT_STYLE)):
        sub = gui.Menu()
        if paths:
            for i, path in enumerate(paths):
                sub.add_item(recent_label(path, i), base + i)
        else:
            sub.add_item("(none yet)", base + 99)
            sub.set_enabled(base + 99, False)
        file_menu.add_menu(title, sub)
    file_menu.add_separator()
    file_menu.add_item("Load camera path...", MENU_LOAD_PATH)
    file_menu.add_item("Save camera path...", MENU_SAVE_PATH)
    file_menu.add_separator()
    file_menu.add_item("Export video...   E", MENU_EXPORT)
    file_menu.add_item("Save screenshot...   P", MENU_SCREENSHOT)
    file_menu.add_separator()
    file_menu.add_item("Quit   Ctrl+Q", MENU_QUIT)
    view_menu = gui.Menu()
    view_menu.add_item("Stylized   T", MENU_STYLIZED)
    view_menu.set_checked(MENU_STYLIZED, stylized)
    view_menu.add_item("Reset view   R", MENU_RESET)
    view_menu.add_item("Preview camera path   C", MENU_PREVIEW)
    help_menu = gui.Menu()
    help_menu.add_item("Keyboard shortcuts   H", MENU_HELP)
    help_menu.add_item("About", MENU_ABOUT)
    bar = gui.Menu()
    bar.add_menu("File", file_menu)
    bar.add_menu("View", view_menu)
    for title, menu in extra:
        bar.add_menu(title, menu)
    bar.add_menu("Help", help_menu)
    return bar


def message_dialog(em: float, title: str, message: str,
                   buttons: Sequence[Tuple[str, Callable[[], None]]]) -> gui.Dialog:
    """A modal dialog: ``title``, ``message`` (wrapped by its line breaks) and a row of buttons, each
    (label, callback); the first button is the default one."""
    dlg = gui.Dialog(title)
    box = gui.Vert(0.5 * em, gui.Margins(int(em), int(em), int(em), int(em)))
    box.add_child(gui.Label(title))
    for line in message.splitlines() or [""]:
        box.add_child(gui.Label(line))
    row = gui.Horiz(0.5 * em)
    row.add_stretch()
    for label, cb in buttons:
        b = gui.Button(label)
        b.set_on_clicked(cb)
        row.add_child(b)
    box.add_child(row)
    dlg.add_child(box)
    return dlg


def _row(em: float, *widgets: gui.Widget) -> gui.Horiz:
    h = gui.Horiz(0.5 * em)
    for w in widgets:
        h.add_child(w)
    return h


def _number(kind, value: float, lo: float, hi: float, decimals: int = 3) -> gui.NumberEdit:
    n = gui.NumberEdit(kind)
    n.set_limits(lo, hi)
    if kind == gui.NumberEdit.DOUBLE:
        n.decimal_precision = decimals
        n.double_value = float(value)
    else:
        n.int_value = int(value)
    return n


LINE_CHAR_EM = 0.46
"""The width of an average character of Open3D's default font (Roboto), in em: what :func:`fit_line` assumes."""


def fit_line(text: str, width_px: float, em: float) -> str:
    """``text`` cut to what one line ``width_px`` wide holds (characters of :data:`LINE_CHAR_EM` em), with
    "..." where it was cut: a label that wrapped would push the status area's buttons out of the window."""
    n = max(8, int(width_px / (LINE_CHAR_EM * em)))
    t = " ".join(str(text).split())
    return t if len(t) <= n else t[: n - 3].rstrip() + "..."


def set_if_changed(widget, attr: str, value) -> bool:
    """Set ``widget.attr = value`` only when it differs (returns whether it was set): the status lines are
    refreshed while dragging, mostly with the same text, and a label's new text can cost the GUI thread a
    relayout; an unchanged widget is left alone."""
    if getattr(widget, attr) == value:
        return False
    setattr(widget, attr, value)
    return True


class Panel:
    """The side panel, status area and help overlay of the viewer window.

    Thread use: built and touched on the GUI main thread only.
    """

    WIDTH_EM = 21.0
    STATUS_EM = 9.0

    def __init__(self, em: float, state: ViewState) -> None:
        self.em = em
        m = gui.Margins(int(0.75 * em), int(0.5 * em), int(0.75 * em), int(0.5 * em))
        self.root = gui.ScrollableVert(0.4 * em, m)

        # Photo, depth, style.
        photo = gui.CollapsableVert("Photo and style", 0.3 * em, gui.Margins(int(0.5 * em), 0, 0, 0))
        self.open_photo = gui.Button("Open photo...")
        self.sample = gui.Button("Sample")
        self.sample.tooltip = "open the bundled sample photo and style"
        photo.add_child(_row(em, self.open_photo, self.sample))
        self.photo_label = gui.Label("no photo")
        photo.add_child(self.photo_label)
        self.recent_photos = gui.Combobox()
        self.recent_photos.add_item(RECENT_PHOTOS)
        self.recent_photos.tooltip = "photos opened recently (also in File > Recent photos)"
        photo.add_child(self.recent_photos)
        self.depth = gui.Combobox()
        for _, label in DEPTH_CHOICES:
            self.depth.add_item(label)
        self.depth_file = gui.Button("Depth file...")
        depth = gui.CollapsableVert("Depth", 0.3 * em, gui.Margins(int(0.5 * em), 0, 0, 0))
        depth.add_child(self.depth)
        depth.add_child(self.depth_file)
        self.depth_download = gui.Button(DOWNLOAD_LABEL)
        self.depth_download.tooltip = ("download Depth Anything V2 Small's weights (Apache-2.0, about 99 MB) once "
                                       "into the Hugging Face cache; needs the network")
        depth.add_child(self.depth_download)
        self.refine = gui.Combobox()
        for _, label in REFINE_CHOICES:
            self.refine.add_item(label)
        depth.add_child(self.refine)
        depth.set_is_open(False)  # rarely changed: keeps Export above the fold
        photo.add_child(depth)
        self.open_style = gui.Button("Open style...")
        photo.add_child(self.open_style)
        self.style_label = gui.Label("no style")
        photo.add_child(self.style_label)
        photo.add_child(gui.Label("Styles (click to apply)"))
        self.style_strip = gui.VGrid(THUMBS_PER_ROW, 0.25 * em)
        photo.add_child(self.style_strip)
        self.open_style2 = gui.Button("Mix with...")
        self.open_style2.tooltip = "a second style image to mix with the first"
        self.style2_label = gui.Label("no second style")
        photo.add_child(_row(em, self.open_style2, self.style2_label))
        self.mix = gui.Slider(gui.Slider.DOUBLE)
        self.mix.set_limits(0.0, 1.0)
        self.mix.double_value = state.mix
        self.mix.tooltip = "0: the first style, 1: the second"
        photo.add_child(self.mix)
        self.root.add_child(photo)
        self.photo_section = photo

        # Look: stylized / original, strength, FOV, reset.
        look = gui.CollapsableVert("View", 0.3 * em, gui.Margins(int(0.5 * em), 0, 0, 0))
        self.stylized = gui.ToggleSwitch("Stylized (T)")
        self.stylized.is_on = state.stylized
        look.add_child(self.stylized)
        self.strength_label = gui.Label(f"Style strength: {state.strength:.2f}")
        look.add_child(self.strength_label)
        self.strength = gui.Slider(gui.Slider.DOUBLE)
        self.strength.set_limits(0.0, 1.0)
        self.strength.double_value = state.strength
        look.add_child(self.strength)
        self.fov_label = gui.Label("Field of view: 60.0 degrees")  # (the slider's handle hides its own value)
        look.add_child(self.fov_label)
        self.fov = gui.Slider(gui.Slider.DOUBLE)
        self.fov.set_limits(30.0, 90.0)
        self.fov.double_value = 60.0
        look.add_child(self.fov)
        self.compare = gui.Checkbox("Before / after (original | stylized)")
        look.add_child(self.compare)
        self.split = gui.Slider(gui.Slider.DOUBLE)
        self.split.set_limits(0.0, 1.0)
        self.split.double_value = state.split
        look.add_child(self.split)
        self.reset = gui.Button("Reset view (R)")
        look.add_child(self.reset)
        for slider in (self.strength, self.fov, self.mix, self.split):  # the theme draws no track of its own
            slider.background_color = SLIDER_TRACK
        self.root.add_child(look)
        self.view_section = look

        # Export.
        export = gui.CollapsableVert("Export", 0.3 * em, gui.Margins(int(0.5 * em), 0, 0, 0))
        self.format = gui.Combobox()
        for _, label in EXPORT_FORMATS:
            self.format.add_item(label)
        export.add_child(self.format)
        e: VideoExport = state.export
        grid = gui.VGrid(2, 0.3 * em)
        self.size = _number(gui.NumberEdit.INT, e.size, 16, 4096)
        self.frames = _number(gui.NumberEdit.INT, e.frames, 1, 10000)
        self.fps = _number(gui.NumberEdit.DOUBLE, e.fps, 1.0, 240.0, decimals=1)
        self.shot_size = _number(gui.NumberEdit.INT, 0, 0, 8192)
        self.shot_size.tooltip = "long side of screenshots in pixels; 0: the view's size on screen"
        for label, w in (("size (long side)", self.size), ("frames", self.frames), ("fps", self.fps),
                         ("screenshot (0: view)", self.shot_size)):
            grid.add_child(gui.Label(label))
            grid.add_child(w)
        export.add_child(grid)
        self.export = gui.Button("Export... (E)")
        self.screenshot = gui.Button("Screenshot (P)")
        self.root.add_child(export)  # (its buttons are in the status area, always in sight)
        self.export_section = export

        # Camera path: trajectory and its parameters, preview, load / save.
        path = gui.CollapsableVert("Camera path", 0.3 * em, gui.Margins(int(0.5 * em), 0, 0, 0))
        self.trajectory = gui.Combobox()
        self.trajectory_names: List[str] = list(get_args(TrajectoryName))
        for name in self.trajectory_names:
            self.trajectory.add_item(name)
        self.trajectory.selected_index = self.trajectory_names.index(state.trajectory.name)
        path.add_child(self.trajectory)
        grid = gui.VGrid(2, 0.3 * em)
        t = state.trajectory
        self.amp_x = _number(gui.NumberEdit.DOUBLE, float(t.x) if isinstance(t.x, (int, float)) else 0.02, 0.0, 0.1)
        self.amp_y = _number(gui.NumberEdit.DOUBLE, float(t.y) if isinstance(t.y, (int, float)) else 0.02, 0.0, 0.1)
        self.forward = _number(gui.NumberEdit.DOUBLE, float(t.z[1]) if isinstance(t.z, tuple) else 0.05, -0.1, 0.15)
        for label, w in (("sideways", self.amp_x), ("vertical", self.amp_y), ("forward", self.forward)):
            grid.add_child(gui.Label(label))
            grid.add_child(w)
        path.add_child(grid)
        self.path_info = gui.Label("")
        path.add_child(self.path_info)
        self.preview_path = gui.Button("Preview (C)")
        path.add_child(self.preview_path)
        self.load_path = gui.Button("Load...")
        self.save_path = gui.Button("Save...")
        path.add_child(_row(em, self.load_path, self.save_path))
        self.root.add_child(path)
        self.path_section = path

        # Keyframe editor: keyframes from the view, their FOV and timing, loop, full-quality preview, files.
        keys = gui.CollapsableVert("Keyframes", 0.3 * em, gui.Margins(int(0.5 * em), 0, 0, 0))
        self.add_key = gui.Button("Add keyframe (K)")
        self.add_key.tooltip = "add the current view as a keyframe after the selected one"
        self.use_keys = gui.Checkbox("Export follows the keyframes")
        keys.add_child(_row(em, self.add_key))
        keys.add_child(self.use_keys)
        self.key_list = gui.ListView()
        self.key_list.set_max_visible_items(5)
        keys.add_child(self.key_list)
        self.key_up, self.key_down, self.key_delete = gui.Button("Up"), gui.Button("Down"), gui.Button("Delete")
        keys.add_child(_row(em, self.key_up, self.key_down, self.key_delete))
        grid = gui.VGrid(2, 0.3 * em)
        self.key_fov = _number(gui.NumberEdit.DOUBLE, 60.0, 1.0, 170.0, decimals=1)
        self.key_seconds = _number(gui.NumberEdit.DOUBLE, 2.0, 0.05, 600.0, decimals=2)
        for label, w in (("keyframe FOV", self.key_fov), ("seconds to next", self.key_seconds)):
            grid.add_child(gui.Label(label))
            grid.add_child(w)
        keys.add_child(grid)
        self.key_loop = gui.Checkbox("Loop back to the first")
        keys.add_child(self.key_loop)
        self.key_preview = gui.Button("Preview (full quality)")
        keys.add_child(self.key_preview)
        self.key_load, self.key_save = gui.Button("Load keys..."), gui.Button("Save keys...")
        keys.add_child(_row(em, self.key_load, self.key_save))
        keys.set_is_open(False)
        self.keys_section = keys
        self.root.add_child(keys)

        # Status area: messages, progress, Cancel (always visible, below the scrolling panel).
        self.status_box = gui.Vert(0.3 * em, m)
        self.status = gui.Label("Open a photo (O) or the bundled sample (M).")
        self.model_label = gui.Label("")
        self.fps_label = gui.Label("")
        self.progress = gui.ProgressBar()
        self.progress.value = 0.0
        self.cancel = gui.Button("Cancel")
        self.cancel.enabled = False
        self.status_text = self.status.text  # the whole message (the label shows one line of it)
        self.status_box.add_child(self.status)
        self.status_box.add_child(self.model_label)
        self.status_box.add_child(self.fps_label)
        self.status_box.add_child(self.progress)
        self.status_box.add_child(_row(em, self.export, self.screenshot, self.cancel))

        # Help overlay, drawn over the view.
        self.help = gui.Vert(0.2 * em, gui.Margins(int(em), int(em), int(em), int(em)))
        self.help.background_color = gui.Color(0.08, 0.08, 0.1, 0.88)
        self.help.add_child(gui.Label("Keyboard and mouse  (H or Esc to close)"))
        grid = gui.VGrid(2, 0.3 * em)
        for key, what in SHORTCUTS:
            grid.add_child(gui.Label(key))
            grid.add_child(gui.Label(what))
        self.help.add_child(grid)
        self.help.visible = False

    def add_style_thumbnail(self, thumb_u8, tooltip: str, on_click) -> None:
        """Add a clickable (THUMB_PX, THUMB_PX, 3) uint8 thumbnail to the style strip."""
        from .backend import widget_image

        img = gui.ImageWidget(widget_image(thumb_u8))
        img.tooltip = tooltip

        def on_mouse(e: gui.MouseEvent) -> int:
            if e.type == gui.MouseEvent.Type.BUTTON_DOWN:
                on_click()
                return gui.Widget.EventCallbackResult.CONSUMED
            return gui.Widget.EventCallbackResult.IGNORED

        img.set_on_mouse(on_mouse)
        self.style_strip.add_child(img)

    def set_line(self, label: gui.Label, text: str) -> None:
        """Show ``text`` on ``label`` of the status area as one line (:func:`fit_line`); the whole text is its
        tooltip when cut."""
        full = str(text)
        line = fit_line(full, (self.WIDTH_EM - 1.5) * self.em, self.em)
        set_if_changed(label, "text", line)
        set_if_changed(label, "tooltip", full if line != full else "")

    def set_status(self, text: str) -> None:
        """The status line: ``text`` (kept whole in :attr:`status_text`), shown as one line."""
        self.status_text = str(text)
        self.set_line(self.status, self.status_text)

    def set_enabled(self, photo_loaded: bool) -> None:
        """Enable the controls that need a photo."""
        for w in (self.stylized, self.strength, self.fov, self.reset, self.preview_path,
                  self.save_path, self.load_path, self.export, self.screenshot, self.add_key, self.key_preview,
                  self.key_load, self.key_save):
            w.enabled = photo_loaded
