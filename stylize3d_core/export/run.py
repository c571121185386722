"""The export steps of a render job (``pipeline.run_render``): point files, or the frames to write."""

from __future__ import annotations

from pathlib import Path
from typing import Iterator, Tuple

import numpy as np

from ..errors import InputError
from ..geometry.camera import Cameras
from ..io.ply import write_ply
from ..scene.photo3d import Photo3D
from .bake import bake_cameras, bake_colours
from .layered import ViewRenderer
from .loop import boomerang, boomerang_length
from .settings import POINT_KINDS, STEREO_KINDS, ExportSettings
from .splat import point_footprints, write_splat_ply
from .stereo import check_eye_distance, stereo_frames
from .web_page import orbit_centre, write_page


def check_point_output(path: str, settings: ExportSettings) -> None:
    """A point export (ply, splat) writes a ``.ply`` file."""
    if settings.export in POINT_KINDS and Path(path).suffix.lower() != ".ply":
        raise InputError(path, f"--export {settings.export} writes a point file: the output must end in .ply")


def point_colours(photo: Photo3D, renderer: ViewRenderer, stylized: bool) -> np.ndarray:
    """(N, 3) colours of the photo's points: their own, or baked from the renderer's views when it stylizes."""
    if not stylized:
        return photo.points.rgb
    h, w = photo.size
    baked = bake_colours(photo.points.xyz, renderer.render, bake_cameras(photo.fov_y_deg), (h, w))
    return baked.rgb


def export_points(path: str, settings: ExportSettings, photo: Photo3D, renderer: ViewRenderer,
                  stylized: bool) -> Path:
    """Write the photo's points to ``path`` as a PLY (``export`` "ply") or a Gaussian splat file ("splat")."""
    check_point_output(path, settings)
    rgb = point_colours(photo, renderer, stylized)
    pts = photo.points
    if settings.export == "ply":
        return write_ply(path, pts.xyz, rgb, labels=pts.label)
    if settings.export == "splat":
        footprint = point_footprints(pts.xyz, photo.fov_y_deg, photo.size[0])
        return write_splat_ply(path, pts.xyz, rgb, footprint, scale_factor=settings.splat_scale)
    raise InputError("export", f"{settings.export!r} is not a point export ({', '.join(POINT_KINDS)})")


def export_page(path: str, settings: ExportSettings, photo: Photo3D, renderer: ViewRenderer, stylized: bool,
                cameras: Cameras, fps: float, title: str = "3D photo") -> Path:
    """Write the photo as one web page (``export`` "html", :mod:`.web_page`): the points with the colours
    :func:`point_colours` gives them, orbiting within ``photo.camera_range`` about the desktop viewer's centre,
    the ``cameras`` played at ``fps``."""
    if Path(path).suffix.lower() not in (".html", ".htm"):
        raise InputError(path, "--export html writes a web page: the output must end in .html or .htm")
    rgb = point_colours(photo, renderer, stylized)
    pts = photo.points
    scene = orbit_centre(photo.ldi.depth[photo.ldi.photo_region])  # the desktop viewer's (session.py)
    return write_page(path, pts.xyz, rgb, photo.size, photo.fov_y_deg, photo.camera_range, scene,
                      trajectory=cameras, fps=fps, max_points=settings.max_points,
                      max_bytes=int(settings.html_max_mb * 2 ** 20), title=title)


def export_frames(settings: ExportSettings, photo: Photo3D, renderer: ViewRenderer, cameras: Cameras,
                  height: int, width: int) -> Tuple[Iterator[np.ndarray], int]:
    """The frames of a video export (mono, side by side or anaglyph; a boomerang with ``loop``) and their count.
    The eye distance is checked against the scene before any frame is rendered."""
    if settings.export in STEREO_KINDS:
        check_eye_distance(settings.eye_distance, photo.points.xyz, cameras, (height, width))
        frames = stereo_frames(renderer.render, cameras, height, width, settings.eye_distance,
                               settings.export, settings.stereo_layout)
    elif settings.export == "video":
        frames = (renderer.render(cameras[i], height, width) for i in range(len(cameras)))
    else:
        raise InputError("export", f"{settings.export!r} does not write a video")
    n = len(cameras)
    if settings.loop:
        return boomerang(frames), boomerang_length(n)
    return frames, n
