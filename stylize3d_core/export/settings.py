"""The export options of a render job (``RenderJob.exports``; ``stylize3d render --export ...``)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, Optional

from ..errors import InputError
from ..options import check_options, documented, option

ExportKind = Literal["video", "ply", "splat", "sbs", "anaglyph", "html"]
STEREO_KINDS = ("sbs", "anaglyph")
POINT_KINDS = ("ply", "splat")
PAGE_KINDS = ("html",)
"""Exports written once from the points, not frame by frame: point files and the web page."""


@documented
@dataclass(frozen=True)
class ExportSettings:
    """What a render job writes to ``--output`` besides a plain video, and how (``stylize3d_core/export/``)."""

    export: ExportKind = option(
        "video", metavar="KIND",
        help="what --output gets: video (the default), ply (the point cloud with the colours of the rendered, "
             "stylized views baked in, for Blender and MeshLab), splat (a 3D Gaussian splat .ply for SuperSplat "
             "and gsplat viewers), sbs (side-by-side stereo video for VR), anaglyph (red-cyan stereo video), html "
             "(one self-contained web page that orbits the 3D photo in a browser, offline; the trajectory plays "
             "on its Play button).")
    stereo_layout: Literal["full", "half"] = option(
        "full", help="sbs: full (each eye at full width, frames twice as wide) or half (each eye squeezed "
                     "to half width).")
    eye_distance: float = option(
        0.01, low=1e-4, high=1.0,
        help="sbs and anaglyph: distance between the eyes in scene units (the nearest surface is about 1/3 away); "
             "at most half the distance to the nearest surface.")
    loop: bool = option(False, help="boomerang: play the frames forward, then back, so the loop has no jump "
                                    "(MP4, GIF, WebP, PNG frames).")
    splat_scale: float = option(0.6, low=0.05, high=5.0,
                                help="splat: size of each Gaussian (standard deviation) in point footprints.")
    max_points: int = option(2_000_000, low=1, high=100_000_000, metavar="N",
                             help="html: most points in the page; a photo with more is thinned on a lattice "
                                  "(every k-th pixel each way) with larger splats.")
    html_max_mb: float = option(8.0, low=0.01, high=2048.0, metavar="MB",
                                help="html: largest page written, in MiB; a larger one is an error and nothing "
                                     "is written.")
    save_trajectory: Optional[str] = option(
        None, metavar="JSON",
        help="also write the cameras used as an Open3D PinholeCameraTrajectory (JSON); --camera-path reads "
             "these as well as stylize3d camera paths.")

    def __post_init__(self) -> None:
        check_options(self)
        if self.loop and self.export in POINT_KINDS + PAGE_KINDS:
            raise InputError("loop", f"a loop is a video; --export {self.export} writes "
                                    f"{'a web page' if self.export in PAGE_KINDS else 'a point file'}")
