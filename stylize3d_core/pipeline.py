"""High-level jobs: photo (+ depth) -> 3D photo -> frames along a camera path -> video.

The command line and the viewer are thin layers over these functions; every
setting is a documented dataclass field.
"""

from __future__ import annotations

import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Dict, NamedTuple, Optional, Tuple

import numpy as np

from .defaults import DEFAULT_STRENGTH
from .errors import InputError
from .depth.refine import REFINE_METHODS
from .depth.types import DepthMap
from .geometry.camera import DEFAULT_FOV_Y_DEG, MAX_FOV_DEG, MIN_FOV_DEG, Cameras, check_fov
from .geometry.trajectories import TrajectoryName, TrajectorySettings, make_trajectory
from .export.camera_paths import read_camera_path, write_camera_path
from .export.frames import output_kind, write_frames
from .export.layered import LayerSettings
from .export.settings import PAGE_KINDS, POINT_KINDS, ExportSettings
from .io.camera_path import MAX_FRAMES, CameraPath, save_camera_path
from .io.images import load_image
from .io.ply import write_ply
from .io.video import MAX_GIF_FPS, Progress
from .options import check_options, documented, option
from .points.sampling import start_fps_process
from .render.plain import PlainRenderer, PlainRenderSettings, frame_size
from .resources import DEFAULT_MODEL_NAME, default_model, resolve_model
from .scene.ldi import LDISettings
from .scene.photo3d import Photo3D, Photo3DSettings

Log = Callable[[str], None]

DEFAULT_MODEL = default_model()
"""The shipped trained lite checkpoint's path in this install (``stylize3d_core.resources``; its
provenance is ``model/README.md`` beside it)."""


def _quiet(_: str) -> None:
    return None


@documented
@dataclass(frozen=True)
class PhotoSpec:
    """How a photo becomes a 3D photo: the one record :func:`load_photo3d` takes.

    :class:`RenderJob` and the viewer's state hold one; both command lines derive
    their photo options from these fields (``app/options.py``), so a new option
    is written here once (its help is its documentation), validated here once.
    """

    photo: Optional[str] = option(None, help="the photo: JPEG, PNG, WebP or TIFF.", metavar="PHOTO")
    depth: str = option(
        "auto", metavar="SPEC",
        help="where depth comes from: auto (phone depth, else depth-anything where its weights are cached, else the "
             "built-in prior), prior, depth-anything, phone, a depth file "
             "(PNG16/NPY/PFM/TIFF/EXR; append :disparity for disparity), onnx:MODEL.onnx, stereo:RIGHT_IMAGE, "
             "stereo:sbs (see stylize3d_core/depth/sources.py).")
    refine_depth: Optional[str] = option(
        None, choices=REFINE_METHODS, metavar="METHOD", default_text="no refinement",
        help="align the depth's edges with the photo's first: bilateral_median (sharpens, as 3DPhoto), "
             "joint_bilateral or guided (smooth); see depth/refine.py.")
    max_size: int = option(1024, low=32, high=8192, help="shrink the photo so its long side is at most this, "
                                                         "in pixels, before anything else.")
    fov: Optional[float] = option(None, low=MIN_FOV_DEG, high=MAX_FOV_DEG, default_text="from EXIF, else 60",
                                  help="vertical field of view of the photo in degrees.")
    relief: float = option(1.0, low=0.25, high=4.0,
                           help="exaggerate (> 1) or flatten (< 1) the 3D relief: each depth d becomes "
                                "d ** relief before the scene is normalised, so the nearest surface stays put, "
                                "the photo's own view is unchanged and farther things move away (or closer); "
                                "1 keeps the depth as estimated.")
    stereo_card: bool = option(False, help="the photo is a scanned stereo card (two prints side by side on a "
                                           "mount): split, align and match it for depth, browse its left print "
                                           "(the same as --depth stereo:card).")
    ldi: LDISettings = option(default_factory=LDISettings, cli=False,
                              help="layered-depth-image settings (tearing, hidden layer, border).")

    def __post_init__(self) -> None:
        check_options(self)
        if self.stereo_card and self.depth not in ("auto", "stereo:card"):
            raise InputError("stereo_card", f"a stereo card gives its own depth; drop --depth {self.depth}")


EXPORT_POINTS_PER_PIXEL = 7.0
"""The export default of ``StylizeSettings.final_points_per_pixel`` (``RenderJob.points_per_pixel``), picked
from ``stylize3d bench speed``: the fastest point budget whose frames stay within the 40 dB final-frame
target of every point (at 512 px from a 1 MP photo, about 10 points land on each pixel)."""


@documented
@dataclass(frozen=True)
class RenderJob:
    """Render a 3D photo along a camera path into a video (:func:`run_render`).

    Every value is checked when the job is made; the output paths (extension,
    folder) are checked by :func:`check_outputs` before anything is computed.
    """

    spec: PhotoSpec = option(default_factory=PhotoSpec, help="the photo and how it becomes a 3D photo.")
    output: str = option("out.mp4", flags=("-o", "--output"),
                         help="the video: .mp4, .gif, or a folder (ending in /) for PNG frames.")
    trajectory: TrajectoryName = option("circle", help="camera path shape (see geometry/trajectories.py).")
    frames: int = option(90, low=1, high=10_000_000,
                         help="number of frames (90: 3 s at 30 fps, as the paper's code); at most max_frames.")
    fps: float = option(30.0, low=1.0, high=240.0, help=f"frames per second of the video (a GIF: at most "
                                                       f"{MAX_GIF_FPS:g}).")
    size: int = option(512, low=16, high=4096, help="long side of the output frames in pixels (the photo's aspect).")
    supersample: int = option(1, choices=(1, 2),
                              help="1 = sharp and fast, 2 = rasterize at twice the size (smoother when the "
                                   "camera moves away).")
    points_per_pixel: float = option(EXPORT_POINTS_PER_PIXEL, low=0.5, high=100.0,
                                     help="stylized frames keep about this many points per output pixel where more "
                                          "would land on each (a random subset; faster, within 40 dB PSNR of every "
                                          "point at the default: stylize3d bench targets); 100 keeps nearly all.")
    camera_path: Optional[str] = option(None, metavar="JSON",
                                        help="follow the cameras of this camera-path JSON instead of "
                                             "trajectory/frames.")
    save_camera_path: Optional[str] = option(None, metavar="JSON", help="also write the cameras used (JSON).")
    save_ply: Optional[str] = option(None, metavar="FILE", help="also write the coloured point cloud (PLY).")
    style: Optional[str] = option(None, metavar="IMAGE", default_text="none: the plain 3D photo",
                                  help="style image (a painting, a texture).")
    strength: float = option(DEFAULT_STRENGTH, low=0.0, high=1.0, help="style strength from 0 (photo) to 1.")
    max_frames: int = option(MAX_FRAMES, low=1, high=10_000_000, metavar="N",
                             help="most frames a render may have, from frames or a camera path (a guard "
                                  "against runaway inputs: 10,000 frames are 5.5 min of video at 30 fps and "
                                  "tens of minutes of rendering on a laptop CPU); raise it for longer videos.")
    model: str = option(DEFAULT_MODEL_NAME, metavar="MODEL",
                        help="the stylization model used with style: a shipped model's name (lite) or a "
                             "checkpoint you trained (.safetensors).")
    views: Optional[str] = option(None, metavar="JSON",
                                  help="multi-view input: merge the photos of this views file (images, depth files, "
                                       "poses; see stylize3d_core/multiview.py) into one 3D photo in the frame of "
                                       "PHOTO, one of them.")
    exports: ExportSettings = option(default_factory=ExportSettings,
                                     help="point files, stereo and loops (stylize3d_core/export/).")
    layers: LayerSettings = option(default_factory=LayerSettings,
                                   help="a foreground kept unstylized (stylize3d_core/export/layered.py).")

    def __post_init__(self) -> None:
        check_options(self)
        if self.camera_path is None and self.frames > self.max_frames:
            raise InputError("frames", f"{self.frames:,} frames are more than max_frames={self.max_frames:,}; "
                                       "raise max_frames (--max-frames) for a longer video")
        if self.exports.export not in POINT_KINDS + PAGE_KINDS and self.camera_path is None \
                and output_kind(self.output) == "gif" and self.fps > MAX_GIF_FPS:
            raise InputError("fps", f"a GIF plays at most {MAX_GIF_FPS:g} fps, got {self.fps!r}")
        if self.views is not None and (self.layers.active or self.spec.stereo_card):
            raise InputError("views", "multi-view input takes no --mask, --mask-rect or --stereo-card")
        if self.layers.active and self.style is None:
            raise InputError("mask", "layered stylization needs a style (--style): without one nothing is stylized")


def _check_destination(path: str, what: str, suffixes: Tuple[str, ...]) -> None:
    p = Path(path)
    if suffixes and p.suffix.lower() not in suffixes:
        raise InputError(path, f"{what} must end in {' or '.join(suffixes)}")
    folder = p.parent if str(p.parent) else Path(".")
    if not folder.is_dir():
        raise InputError(path, f"folder {folder} does not exist")
    if p.is_dir():
        raise InputError(path, f"is a folder; {what} must be a file")


def check_outputs(job: RenderJob) -> None:
    """Check every output path of ``job`` (extension, existing folder, no clashes) before anything is written."""
    out = Path(job.output)
    kind = "ply" if job.exports.export in POINT_KINDS else "html" if job.exports.export in PAGE_KINDS \
        else output_kind(job.output)  # InputError: unknown suffix
    if kind == "html":
        _check_destination(job.output, "--export html's web page", (".html", ".htm"))
    elif kind == "ply":
        _check_destination(job.output, f"--export {job.exports.export}'s point file", (".ply",))
    elif kind == "png":
        parent = out.parent if str(out.parent) else Path(".")
        if not parent.is_dir():
            raise InputError(job.output, f"folder {parent} does not exist")
        if out.exists() and not out.is_dir():
            raise InputError(job.output, "exists and is not a folder; PNG frames need a folder")
    else:
        _check_destination(job.output, "the video", ())
    if job.save_ply is not None:
        _check_destination(job.save_ply, "a point cloud file", (".ply",))
    if job.save_camera_path is not None:
        _check_destination(job.save_camera_path, "a camera-path file", (".json",))
    if job.exports.save_trajectory is not None:
        _check_destination(job.exports.save_trajectory, "an Open3D trajectory file", (".json",))
    inputs = [p for p in (job.spec.photo, job.camera_path, job.style, job.layers.mask_file, job.views)
              if p is not None]
    outputs = [p for p in (job.output, job.save_ply, job.save_camera_path, job.exports.save_trajectory)
               if p is not None]
    seen: Dict[Path, str] = {}
    for p in outputs:
        key = Path(p).resolve()
        if key in seen:
            raise InputError(p, f"is also the output {seen[key]}; give each output its own path")
        seen[key] = p
    for p in inputs:
        if Path(p).resolve() in seen:
            raise InputError(p, "is both an input and an output; writing it would destroy the input")


class RenderResult(NamedTuple):
    """What :func:`run_render` produced."""

    output: Path
    n_frames: int
    frame_size: Tuple[int, int]  # (H, W)
    n_points: int
    timings: Dict[str, float]  # seconds per stage


def _with_relief(depth_map: DepthMap, relief: float) -> DepthMap:
    """``depth_map`` with every depth raised to ``relief`` (only ratios are kept: the result is relative)."""
    d = depth_map.depth.astype(np.float64)
    scaled = np.exp(relief * (np.log(d) - np.log(np.median(d))))  # about 1 at the median: no overflow
    return DepthMap(scaled.astype(np.float32), depth_map.valid, "relative", f"{depth_map.source}, relief {relief:g}")


def load_photo3d(spec: PhotoSpec, *, log: Log = _quiet) -> Photo3D:
    """Read the photo ``spec`` names, get its depth from the source ``spec.depth`` names (edges
    aligned with the photo's by ``spec.refine_depth``, if given), and build the 3D photo."""
    return _load_photo3d(spec, log)[0]


def _load_photo3d(spec: PhotoSpec, log: Log) -> Tuple[Photo3D, Tuple[int, int]]:
    """:func:`load_photo3d`, and the photo file's (H, W) before shrinking (``LoadedImage.original_size``)."""
    from .depth.refine import RefineSettings  # the depth package is heavier (onnxruntime)
    from .depth.sources import parse_depth_spec

    if not isinstance(spec, PhotoSpec):
        raise InputError("spec", f"expected a PhotoSpec, got {type(spec).__name__}")
    if spec.photo is None:
        raise InputError("photo", "no photo given")
    photo, depth, max_size, fov = spec.photo, spec.depth, spec.max_size, spec.fov
    if spec.stereo_card:
        depth = "stereo:card"
    refine = None if spec.refine_depth is None else RefineSettings(method=spec.refine_depth)
    start_fps_process()  # its imports run beside the depth and LDI stages, ready for the model's geometry
    t0 = time.perf_counter()
    image = load_image(photo, max_size=max_size)
    source = parse_depth_spec(depth, refine=refine)
    t1 = time.perf_counter()
    found = source.estimate(image)  # reads phone depth from the bytes load_image kept; no second read
    rgb, depth_map = found.rgb, found.depth_map  # rgb: the left half of a side-by-side stereo card, else the photo
    if spec.relief != 1.0:
        depth_map = _with_relief(depth_map, spec.relief)
    t2 = time.perf_counter()
    if fov is None:
        fov = image.fov_y_deg() or DEFAULT_FOV_Y_DEG
    p3d = Photo3D.build(rgb, depth_map, Photo3DSettings(fov_y_deg=check_fov(fov), ldi=spec.ldi))
    p3d.timings.update({"load": t1 - t0, "depth": t2 - t1})
    h, w = rgb.shape[:2]
    log(
        f"photo {photo}: {w}x{h}, fov {fov:.1f} deg, depth from {depth_map.source}, "
        f"{len(p3d.points):,} points ({'with' if p3d.ldi.inpainted else 'no'} hidden layer)"
    )
    return p3d, image.original_size


def warm_up(wait: bool = False) -> float:
    """Pay the once-per-process costs of the first photo ahead of it: import the depth sources (OpenCV's
    contrib modules, onnxruntime's loader, onnx for the decoder's graph), start the farthest-point-sampling worker process and load the
    k-NN grid's, the colour transfer's, the encoder's and the rasterizer's compiled kernels (Numba). Each would otherwise run beside, and slow,
    the first photo's depth, LDI and geometry: the viewer calls this at start, while its window opens.
    ``wait``: return when all of it is done (the benchmarks time a photo after it). Returns the seconds
    it took."""
    from .points.sampling import wait_for_fps_process
    from .render.rasterize import wait_warm, warm_up_async

    t0 = time.perf_counter()
    start_fps_process()
    warm_up_async()
    if wait:
        _import_and_load()
        wait_warm()
        wait_for_fps_process()
    else:
        threading.Thread(target=_import_and_load, name="stylize3d-warm-up", daemon=True).start()
    return time.perf_counter() - t0


def _import_and_load() -> None:
    try:
        from .depth import sources  # noqa: F401 (imported lazily by load_photo3d)
        from .models import decoder_onnx
        from .models.colour_transfer import warm_up as load_colour_map
        from .models.encoder import warm_up as load_neighbour_max
        from .points.neighbours import warm_up as load_grid_search

        load_grid_search()  # the k-NN grid's Numba kernels
        load_colour_map()  # the colour transfer's
        load_neighbour_max()  # the encoder's
        decoder_onnx.available()  # imports onnx and onnxruntime (~0.8 s cold): the decoder's first frame
    except Exception:  # noqa: BLE001 (a failed warm-up is only a slower first photo; the photo's own load reports)
        pass


def prefetch_style(style_rgb: np.ndarray, encoder=None) -> Future:
    """Start the style CNN on ``style_rgb`` (h, w, 3) in a worker thread while the caller builds the 3D photo.

    The two stages are independent and torch releases the GIL in its kernels, so the CNN runs on the core
    that the photo's depth and LDI (mostly single-threaded numpy and OpenCV) leave idle. The future's result
    is the :class:`~stylize3d_core.models.style_features.StyleEncoder` (``encoder``, or a new one) whose
    feature cache (:func:`~stylize3d_core.stylize.style_feature_cache`) holds the features: pass it as
    ``Stylized3DPhoto(..., style_encoder=)`` and ``set_style(style_rgb)`` skips the CNN. The cache key
    includes the autocast state, which is per thread: under a caller's autocast the features are simply
    computed again. ``result()`` re-raises the worker's error.
    """
    from .render.rasterize import warm_up_async

    warm_up_async()  # the rasterizer's compiled kernels load meanwhile too
    pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="style-cnn")
    try:
        return pool.submit(_style_features, style_rgb, encoder)
    finally:
        pool.shutdown(wait=False)  # the thread ends after its one task


def _style_features(style_rgb: np.ndarray, encoder):
    import torch

    from .models.style_features import StyleEncoder
    from .stylize import style_feature_cache, style_tensor

    encoder = StyleEncoder() if encoder is None else encoder
    with torch.inference_mode():
        style_feature_cache(encoder).features(style_tensor(style_rgb))
    return encoder


def job_cameras(job: RenderJob, fov_y_deg: float, loaded: Optional[CameraPath] = None) -> Tuple[Cameras, float]:
    """The cameras and fps a job renders: its camera path (``loaded``, else read from its file), else its
    trajectory."""
    if job.camera_path is not None:
        path = loaded if loaded is not None else read_camera_path(job.camera_path)
        return path.cameras, float(path.fps or job.fps)
    settings = TrajectorySettings(name=job.trajectory, n_frames=job.frames, fov_y_deg=fov_y_deg)
    return make_trajectory(settings), float(job.fps)


def _check_style_inputs(job: RenderJob):
    """Fail fast, before the photo is processed: the style image, the strength and the model
    (a shipped model's name or a checkpoint path, resolved to the checkpoint's path)."""
    from .stylize import StylizeSettings

    settings = StylizeSettings(strength=job.strength, supersample=job.supersample,
                               final_points_per_pixel=job.points_per_pixel)
    style = load_image(job.style, max_size=1024).rgb
    return settings, style, resolve_model(job.model)


def _stylized(p3d: Photo3D, job: RenderJob, settings, style, model: str, timings: Dict[str, float], log: Log,
              prefetch: Optional[Future] = None):
    from .stylize import Stylized3DPhoto

    t0 = time.perf_counter()
    encoder = None if prefetch is None else prefetch.result()  # the style CNN ran while the photo loaded
    stylized = Stylized3DPhoto(p3d, model, settings, style_encoder=encoder)  # given the path, errors name it
    stylized.set_style(style)
    timings["model"] = time.perf_counter() - t0
    log(f"style {job.style} at strength {job.strength:g} with {model}")
    return stylized


def run_render(job: RenderJob, *, progress: Optional[Progress] = None, log: Log = _quiet) -> RenderResult:
    """Run a :class:`RenderJob`: check its outputs and inputs, build the 3D photo, render every frame,
    write the video (and the point cloud and camera path it asks for)."""
    check_outputs(job)
    style_inputs = _check_style_inputs(job) if job.style is not None else None
    loaded_path = (read_camera_path(job.camera_path, max_frames=job.max_frames)
                   if job.camera_path is not None else None)
    if loaded_path is not None and loaded_path.fps is not None \
            and job.exports.export not in POINT_KINDS + PAGE_KINDS and output_kind(job.output) == "gif" \
            and loaded_path.fps > MAX_GIF_FPS:
        raise InputError(job.camera_path, f"its {loaded_path.fps:g} fps is too fast for a GIF "
                                          f"(at most {MAX_GIF_FPS:g})")
    prefetch = prefetch_style(style_inputs[1]) if style_inputs is not None else None
    file_size = None  # the photo file's (H, W), for a layered job's mask (never multi-view)
    if job.views is None:
        p3d, file_size = _load_photo3d(job.spec, log)
    else:
        from .multiview import load_merged

        settings = Photo3DSettings(ldi=job.spec.ldi)
        p3d = load_merged(job.views, job.spec.photo, settings, max_size=job.spec.max_size, log=log).photo
    timings = dict(p3d.timings)
    cameras, fps = job_cameras(job, p3d.fov_y_deg, loaded_path)
    H, W = frame_size(p3d.size, job.size)
    if job.save_ply is not None:
        pts = p3d.points
        write_ply(job.save_ply, pts.xyz, pts.rgb, labels=pts.label)
        log(f"wrote {job.save_ply}")
    if job.save_camera_path is not None:
        save_camera_path(job.save_camera_path, cameras, fps=fps, image_size=(H, W))
        log(f"wrote {job.save_camera_path}")
    if job.exports.save_trajectory is not None:
        write_camera_path(job.exports.save_trajectory, cameras, fmt="open3d", fps=fps, image_size=(H, W))
        log(f"wrote {job.exports.save_trajectory} (Open3D PinholeCameraTrajectory)")
    renderer = _renderer(p3d, job, style_inputs, timings, log, file_size, prefetch)
    t0 = time.perf_counter()
    if job.exports.export in POINT_KINDS:
        from .export.run import export_points

        out = export_points(job.output, job.exports, p3d, renderer, stylized=job.style is not None)
        timings["bake+write"] = time.perf_counter() - t0
        log(f"wrote {out}: {len(p3d.points):,} points ({job.exports.export})")
        return RenderResult(Path(out), 0, (H, W), len(p3d.points), timings)
    if job.exports.export in PAGE_KINDS:
        from .export.run import export_page

        out = export_page(job.output, job.exports, p3d, renderer, job.style is not None, cameras, fps,
                          title=Path(job.spec.photo).stem)
        timings["bake+write"] = time.perf_counter() - t0
        log(f"wrote {out}: {Path(out).stat().st_size / 2 ** 20:.1f} MB web page")
        return RenderResult(Path(out), 0, (H, W), len(p3d.points), timings)
    from .export.run import export_frames

    frames, n_frames = export_frames(job.exports, p3d, renderer, cameras, H, W)
    out = write_frames(job.output, frames, fps=fps, n_frames=n_frames, progress=progress)
    timings["render+encode"] = time.perf_counter() - t0
    log(f"wrote {out}: {n_frames} frames ({job.exports.export}) from {W}x{H} views")
    return RenderResult(Path(out), n_frames, (H, W), len(p3d.points), timings)


def _renderer(p3d: Photo3D, job: RenderJob, style_inputs, timings: Dict[str, float], log: Log,
              file_size: Optional[Tuple[int, int]], prefetch: Optional[Future] = None):
    """What renders the job's views: the plain renderer, the stylized photo, or its layered composition."""
    if job.style is None:
        return PlainRenderer(p3d.points, PlainRenderSettings(supersample=job.supersample))
    if not job.layers.active:
        return _stylized(p3d, job, *style_inputs, timings, log, prefetch)
    from .export.layered import LayeredRenderer, photo_mask
    from .scene.masks import point_mask

    mask = photo_mask(job.layers, p3d, file_size)  # before the model loads: a bad mask fails fast
    kept = "unstylized" if job.layers.foreground_strength is None else \
        f"at strength {job.layers.foreground_strength:g}"
    log(f"foreground mask: {mask.mean():.0%} of the photo kept {kept}")
    stylized = _stylized(p3d, job, *style_inputs, timings, log, prefetch)
    return LayeredRenderer(p3d, point_mask(p3d.ldi, mask), stylized,
                           foreground_strength=job.layers.foreground_strength,
                           settings=PlainRenderSettings(supersample=job.supersample))
