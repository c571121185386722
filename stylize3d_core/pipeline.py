"""High-level jobs: photo (+ depth) -> 3D photo -> frames along a camera path -> video.

The command line and the viewer are thin layers over these functions; every
setting is a documented dataclass field.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Dict, NamedTuple, Optional, Tuple

from .errors import InputError
from .geometry.camera import DEFAULT_FOV_Y_DEG, Cameras, check_fov
from .geometry.trajectories import TrajectoryName, TrajectorySettings, make_trajectory
from .io.camera_path import load_camera_path, save_camera_path
from .io.images import load_image
from .io.ply import write_ply
from .io.video import Progress, write_video
from .render.plain import PlainRenderer, PlainRenderSettings, frame_size
from .scene.ldi import LDISettings
from .scene.photo3d import Photo3D, Photo3DSettings

Log = Callable[[str], None]

DEFAULT_MODEL = str(Path(__file__).resolve().parents[1] / "assets" / "model" / "stylize3d_lite.safetensors")
"""The trained lite checkpoint shipped with the repository (see assets/model/README.md)."""


def _quiet(_: str) -> None:
    return None


@dataclass(frozen=True)
class RenderJob:
    """Render a 3D photo along a camera path into a video.

    Attributes:
        photo: the photo (JPEG, PNG, WebP, TIFF).
        output: the video: ``.mp4``, ``.gif``, or a folder for PNG frames. Default "out.mp4".
        depth: where depth comes from (see ``stylize3d_core.depth.sources``):
            "auto" (default: depth embedded by the phone, else the built-in prior),
            "prior", a depth file, "onnx:MODEL.onnx", "stereo:RIGHT".
        refine_depth: align the depth's edges with the photo's before building the
            LDI: None (default), "bilateral_median" (3DPhoto's; sharpens edges),
            "joint_bilateral" or "guided" (smooth); see ``depth/refine.py``.
        trajectory: camera path shape (see ``geometry/trajectories.py``). Default "circle".
        frames: number of frames. Default 90 (3 s at 30 fps, as the paper's code).
        fps: frames per second of the video. Default 30.
        size: long side of the output frames in pixels (aspect of the photo). Default 512.
        max_size: long side the photo is shrunk to before anything else. Default 1024.
        fov: vertical field of view of the photo in degrees; None (default) takes
            it from the photo's EXIF focal length, else 60.
        supersample: 1 (default) or 2: rasterize at twice the size (smoother when zooming out).
        camera_path: a camera-path JSON to follow instead of ``trajectory``/``frames``.
        save_camera_path: also write the cameras used to this JSON file.
        save_ply: also write the coloured point cloud to this PLY file.
        style: a style image; None (default) renders the plain, unstylized 3D photo.
        strength: style strength in [0, 1]. Default 0.8.
        model: the model checkpoint used with ``style``. Default: the shipped lite model.
        ldi: layered-depth-image settings.
    """

    photo: str
    output: str = "out.mp4"
    depth: str = "auto"
    refine_depth: Optional[str] = None
    trajectory: TrajectoryName = "circle"
    frames: int = 90
    fps: float = 30.0
    size: int = 512
    max_size: int = 1024
    fov: Optional[float] = None
    supersample: int = 1
    camera_path: Optional[str] = None
    save_camera_path: Optional[str] = None
    save_ply: Optional[str] = None
    style: Optional[str] = None
    strength: float = 0.8
    model: str = DEFAULT_MODEL
    ldi: LDISettings = field(default_factory=LDISettings)


class RenderResult(NamedTuple):
    """What :func:`run_render` produced."""

    output: Path
    n_frames: int
    frame_size: Tuple[int, int]  # (H, W)
    n_points: int
    timings: Dict[str, float]  # seconds per stage


def load_photo3d(
    photo: str, depth: str = "auto", *, max_size: int = 1024, fov: Optional[float] = None,
    ldi: LDISettings = LDISettings(), refine_depth: Optional[str] = None, log: Log = _quiet,
) -> Photo3D:
    """Read ``photo``, get its depth from the source ``depth`` names (edges aligned with the
    photo's by the ``refine_depth`` method, if given), and build the 3D photo."""
    from .depth.refine import RefineSettings  # the depth package is heavier (onnxruntime)
    from .depth.sources import parse_depth_spec

    refine = None if refine_depth is None else RefineSettings(method=refine_depth)
    t0 = time.perf_counter()
    image = load_image(photo, max_size=max_size)
    source = parse_depth_spec(depth, refine=refine)
    t1 = time.perf_counter()
    rgb = source.photo_view(image.rgb)  # the left half of a side-by-side stereo card, else the photo
    depth_map = source.estimate(image.rgb, photo_path=photo)
    t2 = time.perf_counter()
    if fov is None:
        fov = image.fov_y_deg() or DEFAULT_FOV_Y_DEG
    p3d = Photo3D.build(rgb, depth_map, Photo3DSettings(fov_y_deg=check_fov(fov), ldi=ldi))
    p3d.timings.update({"load": t1 - t0, "depth": t2 - t1})
    h, w = rgb.shape[:2]
    log(
        f"photo {photo}: {w}x{h}, fov {fov:.1f} deg, depth from {depth_map.source}, "
        f"{len(p3d.points):,} points ({'with' if p3d.ldi.inpainted else 'no'} hidden layer)"
    )
    return p3d


def job_cameras(job: RenderJob, fov_y_deg: float) -> Tuple[Cameras, float]:
    """The cameras and fps a job renders: its camera-path file, else its trajectory."""
    if job.camera_path is not None:
        path = load_camera_path(job.camera_path)
        return path.cameras, float(path.fps or job.fps)
    settings = TrajectorySettings(name=job.trajectory, n_frames=job.frames, fov_y_deg=fov_y_deg)
    return make_trajectory(settings), float(job.fps)


def _check_style_inputs(job: RenderJob):
    """Fail fast, before the photo is processed: the style image, the strength and the model file."""
    from .stylize import StylizeSettings

    settings = StylizeSettings(strength=job.strength, supersample=job.supersample)
    style = load_image(job.style, max_size=1024).rgb
    if not Path(job.model).exists():
        raise InputError(job.model, "model checkpoint not found (train one with `stylize3d train`, or pass --model)")
    return settings, style


def _stylized(p3d: Photo3D, job: RenderJob, settings, style, timings: Dict[str, float], log: Log):
    from .stylize import Stylized3DPhoto

    t0 = time.perf_counter()
    stylized = Stylized3DPhoto(p3d, job.model, settings)  # given the path, its errors name the checkpoint
    stylized.set_style(style)
    timings["model"] = time.perf_counter() - t0
    log(f"style {job.style} at strength {job.strength:g} with {job.model}")
    return stylized


def run_render(job: RenderJob, *, progress: Optional[Progress] = None, log: Log = _quiet) -> RenderResult:
    """Run a :class:`RenderJob`: build the 3D photo, render every frame, write the video."""
    if job.supersample not in (1, 2):
        raise InputError("supersample", f"must be 1 or 2, got {job.supersample!r}")
    style_inputs = _check_style_inputs(job) if job.style is not None else None
    p3d = load_photo3d(job.photo, job.depth, max_size=job.max_size, fov=job.fov, ldi=job.ldi,
                      refine_depth=job.refine_depth, log=log)
    timings = dict(p3d.timings)
    cameras, fps = job_cameras(job, p3d.fov_y_deg)
    H, W = frame_size(p3d.size, job.size)
    if job.save_ply is not None:
        pts = p3d.points
        write_ply(job.save_ply, pts.xyz, pts.rgb, labels=pts.label)
        log(f"wrote {job.save_ply}")
    if job.save_camera_path is not None:
        save_camera_path(job.save_camera_path, cameras, fps=fps, image_size=(H, W))
        log(f"wrote {job.save_camera_path}")
    if job.style is None:
        frames = PlainRenderer(p3d.points, PlainRenderSettings(supersample=job.supersample)).frames(cameras, H, W)
    else:
        frames = _stylized(p3d, job, *style_inputs, timings, log).frames(cameras, H, W)
    t0 = time.perf_counter()
    out = write_video(job.output, frames, fps=fps, n_frames=len(cameras), progress=progress)
    timings["render+encode"] = time.perf_counter() - t0
    log(f"wrote {out}: {len(cameras)} frames of {W}x{H}")
    return RenderResult(Path(out), len(cameras), (H, W), len(p3d.points), timings)
