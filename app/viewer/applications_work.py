"""The Applications menu's work on the compute worker (:mod:`.applications`): foreground masks as the
session's layers, merged multi-view photos, and the exports (points, web page, stereo and loop videos)
through the library's writers.

Each function takes the :class:`~stylize3d_app.viewer.session.ViewerSession` and needs no window; errors
are :class:`~stylize3d_core.errors.InputError` that name what is wrong.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Optional, Sequence, Tuple

import numpy as np

from stylize3d_core.errors import InputError
from stylize3d_core.export.frames import output_kind, write_frames
from stylize3d_core.export.run import export_frames, export_page, export_points
from stylize3d_core.export.settings import ExportSettings
from stylize3d_core.geometry.camera import Cameras
from stylize3d_core.scene.masks import check_mask, grabcut_mask, load_mask_file, person_mask
from stylize3d_core.scene.photo3d import Photo3DSettings

from .layers import ViewerLayers

if TYPE_CHECKING:
    from .session import ViewerSession

LOOP_SUFFIXES = (".mp4", ".gif", ".webp")


def _need_photo(session: "ViewerSession"):
    if session.photo is None or session.info is None:
        raise InputError("photo", "open a photo first")
    return session.photo


def photo_file_size(session: "ViewerSession", spec_depth: str) -> Tuple[int, int]:
    """(H, W) of the file a mask may also be the size of: the open photo's file (upright), or the photo as
    loaded for a stereo card (the photo is its left print) or when the file cannot be read."""
    photo = _need_photo(session)
    if str(spec_depth).startswith("stereo:card"):
        return tuple(photo.size)
    from PIL import Image

    try:
        with Image.open(session.info.path) as im:
            w, h = im.size
            orientation = im.getexif().get(274, 1)
    except (OSError, ValueError):
        return tuple(photo.size)
    return (w, h) if orientation in (5, 6, 7, 8) else (h, w)


def layers_from_file(session: "ViewerSession", mask_path: str, foreground_strength: float,
                     spec_depth: str = "auto") -> ViewerLayers:
    """Read a foreground mask file for the open photo (its size or the photo file's; anything else is an
    error naming the mask file and both sizes) and make it the session's layers."""
    photo = _need_photo(session)
    mask = load_mask_file(mask_path, tuple(photo.size), photo_file_size(session, spec_depth))
    session.layers = ViewerLayers(photo, session.info.path, mask, foreground_strength, os.path.basename(mask_path))
    return session.layers


def rect_pixels(size: Tuple[int, int], fractions: Sequence[float]) -> Tuple[int, int, int, int]:
    """(left, top, right, bottom) fractions of a photo of (H, W) = ``size`` -> (x, y, w, h) in its pixels."""
    if len(fractions) != 4 or not all(np.isfinite(float(f)) for f in fractions):
        raise InputError("GrabCut rectangle", f"expected four fractions left, top, right, bottom; got {fractions!r}")
    left, top, right, bottom = (min(1.0, max(0.0, float(f))) for f in fractions)
    if right - left < 0.02 or bottom - top < 0.02:
        raise InputError("GrabCut rectangle", f"left {left:.2f} < right {right:.2f} and top {top:.2f} < bottom "
                                              f"{bottom:.2f} are needed (the rectangle is empty)")
    h, w = size
    x0, y0 = int(round(left * w)), int(round(top * h))
    return x0, y0, max(2, int(round(right * w)) - x0), max(2, int(round(bottom * h)) - y0)


def layers_by_grabcut(session: "ViewerSession", fractions: Sequence[float], foreground_strength: float) -> ViewerLayers:
    """GrabCut inside the rectangle ``fractions`` (left, top, right, bottom) of the open photo; the result
    becomes the session's layers."""
    photo = _need_photo(session)
    rect = rect_pixels(tuple(photo.size), fractions)
    mask = grabcut_mask(photo.rgb, rect, name="GrabCut rectangle")
    session.layers = ViewerLayers(photo, session.info.path, mask, foreground_strength, "GrabCut")
    return session.layers


def layers_by_person(session: "ViewerSession", foreground_strength: float) -> ViewerLayers:
    """The people in the open photo (the automatic person segmentation) become the session's layers."""
    photo = _need_photo(session)
    mask = person_mask(photo.rgb)
    if not mask.any():
        raise InputError("person mask", "found no person in the photo; use a mask file or GrabCut")
    check_mask(mask, "person mask")
    session.layers = ViewerLayers(photo, session.info.path, mask, foreground_strength, "person segmentation")
    return session.layers


def set_foreground_strength(session: "ViewerSession", strength: float) -> Optional[ViewerLayers]:
    """The session's layers with another foreground strength (None: no mask yet)."""
    if session.layers is not None:
        session.layers = session.layers.with_strength(strength)
    return session.layers


def clear_layers(session: "ViewerSession") -> None:
    session.layers = None


def merged_photo(session: "ViewerSession", views: list, centre: int, ldi_settings) -> Any:
    """Merge ``views`` (``stylize3d_core.multiview.load_views``) in the frame of ``views[centre]`` and make
    the result the session's photo; returns its PhotoInfo."""
    import time

    from stylize3d_core.scene.multiview import merge_views

    t0 = time.perf_counter()
    merged = merge_views(views, centre, Photo3DSettings(ldi=ldi_settings))
    return session.set_photo(merged.photo, views[centre].name, t0)


class SessionRenderer:
    """The session's views as the library's exports want them (``render(camera, h, w, preview=False)``):
    stylized (and layered) or plain; ``between`` (serving the view's waiting render, checking Cancel) runs
    before each view."""

    def __init__(self, session: "ViewerSession", stylized: bool, between: Callable[[], object] = lambda: None):
        self.session, self.stylized, self.between = session, bool(stylized), between

    def render(self, camera: Cameras, height: int, width: int, *, preview: bool = False) -> np.ndarray:
        self.between()
        return self.session.render(camera, height, width, preview=preview, stylized=self.stylized)


def point_destination(path: str) -> str:
    """``path`` ending in .ply (appended when it has no suffix; another suffix is an error)."""
    p = Path(path)
    if p.suffix == "":
        return path + ".ply"
    if p.suffix.lower() != ".ply":
        raise InputError(path, "a point file must end in .ply")
    return path


def video_destination(path: str, suffixes: Sequence[str] = LOOP_SUFFIXES) -> str:
    """``path`` with a video suffix (.mp4 appended when it has none; another suffix is an error)."""
    p = Path(path)
    if p.suffix == "":
        return path + ".mp4"
    if p.suffix.lower() not in suffixes:
        raise InputError(path, f"the video must end in {', '.join(suffixes)}")
    output_kind(path)
    return path


def export_point_file(session: "ViewerSession", path: str, kind: str, stylized: bool, splat_scale: float = 0.6,
                      between: Callable[[], object] = lambda: None) -> Path:
    """Write the open photo's points to ``path`` as a baked-colour PLY (``kind`` "ply") or Gaussian splats
    ("splat"): the library's :func:`~stylize3d_core.export.run.export_points`, colours baked from the
    session's stylized (layered) views when ``stylized``."""
    photo = _need_photo(session)
    settings = ExportSettings(export=kind, splat_scale=splat_scale)
    use_model = bool(stylized and session.can_stylize)
    return export_points(point_destination(path), settings, photo, SessionRenderer(session, use_model, between),
                         stylized=use_model)


def page_destination(path: str) -> str:
    """``path`` with ``.html`` appended when it has no suffix (another suffix than .html/.htm is an error)."""
    p = Path(path)
    if p.suffix == "":
        return path + ".html"
    if p.suffix.lower() not in (".html", ".htm"):
        raise InputError(path, "a web page must end in .html or .htm")
    return path


def export_web_page(session: "ViewerSession", path: str, cameras: Cameras, fps: float, stylized: bool,
                    between: Callable[[], object] = lambda: None) -> Path:
    """Write the open photo as one self-contained web page (the library's
    :func:`~stylize3d_core.export.run.export_page`): colours baked from the session's stylized views when
    ``stylized``, orbiting within the photo's camera range, ``cameras`` played by its Play button."""
    photo = _need_photo(session)
    use_model = bool(stylized and session.can_stylize)
    title = Path(session.info.path).stem if session.info.path else "3D photo"
    return export_page(page_destination(path), ExportSettings(export="html"), photo,
                       SessionRenderer(session, use_model, between), use_model, cameras, fps, title=title)


def export_video(session: "ViewerSession", path: str, settings: ExportSettings, cameras: Cameras,
                 size: Tuple[int, int], fps: float, stylized: bool, progress=None,
                 between: Callable[[], object] = lambda: None) -> Path:
    """Write a stereo (sbs, anaglyph) or mono video along ``cameras`` at ``size`` (H, W), a boomerang with
    ``settings.loop``: the library's :func:`~stylize3d_core.export.run.export_frames` and ``write_frames``
    (the eye distance is checked against the scene first; the file is written atomically)."""
    photo = _need_photo(session)
    dest = video_destination(path)
    renderer = SessionRenderer(session, bool(stylized and session.can_stylize), between)
    frames, n = export_frames(settings, photo, renderer, cameras, size[0], size[1])
    return write_frames(dest, frames, fps=fps, n_frames=n, progress=progress)
