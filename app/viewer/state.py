"""The viewer's state and scheduling rules: plain data and pure functions, no widgets, no threads.

:class:`ViewState` is an immutable snapshot of the whole app state: everything
the user chose (the photo's :class:`~stylize3d_core.pipeline.PhotoSpec`, style,
strength, camera pose, trajectory, export settings), what was loaded (the 3D
photo's :class:`PhotoInfo`, whether the model is ready, a camera path) and the
camera-path :class:`Playback`; the window replaces it with
:func:`dataclasses.replace` on every change and hands snapshots to the compute
worker, so no state is shared between threads. :func:`shows_stylized` is the
one rule for whether the view goes through the model.

When a frame is needed (a preview at once after every change, the full frame
once the view rests) is :mod:`stylize3d_app.viewer.render_state`'s state machine.
:func:`choose_preview_long_side` keeps previews within their time budget
(~24 fps) by choosing the preview size from the measured render times.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Dict, List, Literal, NamedTuple, Optional, Sequence, Tuple, get_args

import numpy as np

from stylize3d_core.checks import check_choice, check_range
from stylize3d_core.defaults import DEFAULT_STRENGTH
from stylize3d_core.errors import InputError
from stylize3d_core.geometry.camera import Cameras, check_fov
from stylize3d_core.geometry.camera_range import CameraRange
from stylize3d_core.geometry.keyframes import KeyframePath, interpolate_keyframes
from stylize3d_core.io.camera_path import CameraPath
from stylize3d_core.geometry.trajectories import (
    DEFAULT_XY, DEFAULT_Z, TrajectoryName, TrajectorySettings, make_trajectory,
)
from stylize3d_core.io.video import MAX_GIF_FPS
from stylize3d_core.options import option_info
from stylize3d_core.pipeline import PhotoSpec, RenderJob
from stylize3d_core.render.plain import frame_size

from .orbit import HOME, OrbitLimits, OrbitPose, OrbitScene, clamp_pose, pose_camera, relative_to
from .render_state import REST_DELAY_S

ExportFormat = Literal["mp4", "gif", "png"]
EXPORT_SUFFIX = {"mp4": ".mp4", "gif": ".gif", "png": ""}
"""File suffix per export format ("png" writes a folder of frames)."""

VIEWER_MAX_SIZE = 640
"""The viewer's default long side of the photo (smaller than the command line's, for interactive speed)."""
LOADED_PATH = "camera path file"
"""Trajectory-picker entry for a camera path loaded from JSON."""


_JOB = {f.name: f for f in fields(RenderJob)}


def _job_range(name: str):
    """(low, high) of the ``RenderJob`` option ``name``: the viewer's export accepts what the library does."""
    info = option_info(_JOB[name])
    return info.low, info.high


@dataclass(frozen=True)
class VideoExport:
    """What the panel's Export button writes (the library's ``RenderJob`` writes it).

    Attributes:
        format: "mp4" (default, H.264), "gif", or "png" (a folder of frames).
        size: long side of the frames in pixels (the photo's aspect); ``RenderJob.size``'s default and range.
        frames: number of frames of the trajectory; ``RenderJob.frames``'s default, at most
            ``RenderJob.max_frames``'s default.
        fps: frames per second; ``RenderJob.fps``'s default and range (a GIF: at most ``MAX_GIF_FPS``).
    """

    format: ExportFormat = "mp4"
    size: int = _JOB["size"].default
    frames: int = _JOB["frames"].default
    fps: float = _JOB["fps"].default

    def __post_init__(self) -> None:
        check_choice(self.format, "export format", get_args(ExportFormat))
        for name, low, high in (("size", *_job_range("size")), ("frames", 1, _JOB["max_frames"].default)):
            value = getattr(self, name)
            if isinstance(value, bool) or int(value) != value or not low <= value <= high:
                raise InputError(f"export {name}", f"must be an integer from {low:g} to {high:g}, got {value!r}")
        low, high = _job_range("fps")
        check_range(self.fps, "export fps", low, MAX_GIF_FPS if self.format == "gif" else high)


@dataclass(frozen=True)
class PreviewSettings:
    """Frame sizes and timing of the live view.

    Attributes:
        preview_long_side: long side of the first preview, pixels (later ones follow the measured
            render time, :func:`choose_preview_long_side`). Default 128.
        min_preview_long_side: smallest preview the adaptation may choose, and the size of the first
            preview after a rest (what a new drag waits for). Default 48: small enough that a new drag's first
            stylized preview comes within a frame or two on a loaded 2-core machine.
        max_preview_long_side: largest preview the adaptation may choose. Default 384.
        full_long_side: cap on the full-resolution frame's long side (it fits the view). Default 768.
        target_preview_s: time budget of rendering one preview frame. Default 0.035: with the
            hand-over to the GUI thread, a frame every ~1/24 s while dragging (>= 24 fps where the
            display keeps up).
        rest_delay_s: the camera must rest this long before the full frame is rendered. Default
            :data:`~stylize3d_app.viewer.render_state.REST_DELAY_S`.
        full_budget_s: seconds from the rest to a sharp frame: a full frame slower than this (less the
            rest delay) is rendered progressively, a smaller level first, as large as fits
            (:func:`~stylize3d_app.viewer.render_state.refine_levels`). Default 0.5.
    """

    preview_long_side: int = 128
    min_preview_long_side: int = 48
    max_preview_long_side: int = 384
    full_long_side: int = 768
    target_preview_s: float = 0.035
    rest_delay_s: float = REST_DELAY_S
    full_budget_s: float = 0.5

    def __post_init__(self) -> None:
        lo, hi = self.min_preview_long_side, self.max_preview_long_side
        if not 16 <= lo <= self.preview_long_side <= hi <= 4096:
            raise InputError("preview sizes", f"need 16 <= min {lo} <= preview {self.preview_long_side} <= max {hi}")
        check_range(self.full_long_side, "full_long_side", 16, 4096)
        check_range(self.target_preview_s, "target_preview_s", 0.005, 10.0)
        check_range(self.rest_delay_s, "rest_delay_s", 0.0, 10.0)
        check_range(self.full_budget_s, "full_budget_s", 0.0, 60.0)


class PhotoInfo(NamedTuple):
    """What :meth:`~stylize3d_app.viewer.session.ViewerSession.load_photo` built (the open 3D photo)."""

    path: str
    size: Tuple[int, int]  # (H, W) of the photo
    n_points: int
    fov_y_deg: float
    depth_source: str
    scene: OrbitScene
    seconds: float
    camera_range: CameraRange = CameraRange()
    """The part of the viewer's camera range this photo shows cleanly (``Photo3D.camera_range``): the
    orbit limits (:meth:`~stylize3d_app.viewer.orbit.OrbitLimits.from_range`) and the trajectory limits
    (:func:`trajectory_limits`) come from it."""
    range_scale: float = 1.0
    """That part as a fraction of the full range (``LDI.range_scale``; 1: all of it)."""


@dataclass(frozen=True)
class Playback:
    """The camera-path preview playing in the view.

    Attributes:
        cameras: the cameras it plays, one per frame.
        start: ``time.monotonic()`` when it started.
        fps: frames per second.
        index: the camera last requested (-1: none yet).
        full: render each frame at full quality (the keyframe editor's preview) instead of as a preview.
    """

    cameras: Cameras
    start: float
    fps: float
    index: int = -1
    full: bool = False

    def __post_init__(self) -> None:
        check_range(self.fps, "playback fps", 1e-3, 1000.0)


def playback_frame(playback: Playback, now: float) -> Optional[int]:
    """The camera the preview shows at ``now``, or None once it has played to the end."""
    i = max(0, int((now - playback.start) * playback.fps))
    return i if i < len(playback.cameras) else None


@dataclass(frozen=True)
class ViewState:
    """The viewer's whole state; an immutable snapshot (replace it, never mutate it).

    What the user chose:

    Attributes:
        spec: the photo and how it becomes a 3D photo (``stylize3d_core.pipeline.PhotoSpec``);
            ``spec.photo`` is the open photo (None before one is built). Default max size 640.
        style: path of the style image, or None.
        model: checkpoint path, or None for the default ``assets/model/stylize3d_lite.safetensors``.
        strength: style strength in [0, 1]. Default :data:`~stylize3d_core.defaults.DEFAULT_STRENGTH` (1).
        style2: path of a second style image to mix with the first, or None.
        mix: mix of the two styles in [0, 1] (0: the first only). Default 0.
        compare: show a before / after split of the view (original left, stylized right).
        split: where the before / after split is, as a fraction of the width. Default 0.5.
        stylized: show the stylized view (True, default) or the original 3D photo.
        view_fov: vertical FOV of the view in degrees; None = the photo's FOV.
        pose: the camera relative to the input view.
        trajectory: the camera-path shape and its parameters (frames come from ``export``).
        use_loaded_path: follow the camera path loaded from JSON instead of ``trajectory``.
        keyframes: the keyframe editor's path, or None (no keyframe yet).
        use_keyframes: follow the keyframe path (at ``export.fps``) instead of the trajectory or the
            loaded path.
        export: export settings.

    What was loaded and what is playing:

    Attributes:
        photo_info: the open 3D photo (size, FOV, scene depths), or None.
        stylize_available: the open photo is encoded for the model (see :func:`shows_stylized`).
        loaded_path: the camera path loaded from JSON, or None.
        playback: the camera-path preview playing in the view, or None.
    """

    spec: PhotoSpec = PhotoSpec(max_size=VIEWER_MAX_SIZE)
    style: Optional[str] = None
    model: Optional[str] = None
    strength: float = DEFAULT_STRENGTH
    style2: Optional[str] = None
    mix: float = 0.0
    compare: bool = False
    split: float = 0.5
    stylized: bool = True
    view_fov: Optional[float] = None
    pose: OrbitPose = HOME
    trajectory: TrajectorySettings = field(default_factory=TrajectorySettings)
    use_loaded_path: bool = False
    keyframes: Optional[KeyframePath] = None
    use_keyframes: bool = False
    export: VideoExport = field(default_factory=VideoExport)
    photo_info: Optional[PhotoInfo] = None
    stylize_available: bool = False
    loaded_path: Optional[CameraPath] = None
    playback: Optional[Playback] = None

    def __post_init__(self) -> None:
        if not isinstance(self.spec, PhotoSpec):
            raise InputError("spec", f"expected a PhotoSpec, got {type(self.spec).__name__}")
        check_range(self.strength, "strength", 0.0, 1.0)
        check_range(self.mix, "style mix", 0.0, 1.0)
        check_range(self.split, "split", 0.0, 1.0)
        if self.view_fov is not None:
            check_fov(self.view_fov, "view fov")
        check_choice(self.trajectory.name, "trajectory", get_args(TrajectoryName))


def shows_stylized(state: ViewState) -> bool:
    """Whether the view (and what is exported or saved from it) goes through the model:
    the user asked for the stylized view and the open photo is encoded for it."""
    return bool(state.stylized and state.stylize_available and state.photo_info is not None)


def user_choices(state: ViewState) -> ViewState:
    """``state`` without what was loaded or is playing (for reports: no arrays, no cameras)."""
    return replace(state, photo_info=None, loaded_path=None, playback=None, keyframes=None)


def view_fov(state: ViewState, photo_fov_deg: float) -> float:
    """The view's vertical FOV: the user's choice, else the photo's."""
    return float(photo_fov_deg if state.view_fov is None else state.view_fov)


def view_camera(state: ViewState, scene: OrbitScene, photo_fov_deg: float) -> Cameras:
    """The camera (a batch of one) the live view shows."""
    return pose_camera(state.pose, scene, view_fov(state, photo_fov_deg))


def fov_range(photo_fov_deg: float) -> Tuple[float, float]:
    """Range offered by the FOV slider: half to 1.5x the photo's FOV, within [10, 120] degrees."""
    f = check_fov(photo_fov_deg)
    return max(10.0, min(0.5 * f, 120.0)), max(10.0, min(1.5 * f, 120.0))


def trajectory_cameras(state: ViewState, scene: OrbitScene, photo_fov_deg: float,
                       loaded: Optional[Cameras] = None) -> Cameras:
    """The cameras "Export" renders.

    The keyframe path sampled at ``state.export.fps``, when ``state.use_keyframes``;
    the loaded camera path as it is, when ``state.use_loaded_path``; else the
    trajectory with ``state.export.frames`` frames and the view's FOV, started
    from the current view (each trajectory pose is composed with the orbit pose,
    so the video moves around what the user is looking at).
    """
    if state.use_keyframes:
        if state.keyframes is None:
            raise InputError("keyframes", "add a keyframe first (Add keyframe, K)")
        return interpolate_keyframes(state.keyframes, state.export.fps)
    if state.use_loaded_path:
        if loaded is None:
            raise InputError("camera path", "no camera path is loaded")
        return loaded
    settings = replace(state.trajectory, n_frames=state.export.frames, fov_y_deg=view_fov(state, photo_fov_deg))
    return relative_to(state.pose, scene, make_trajectory(settings))


def full_frame_size(photo_hw: Tuple[int, int], view_hw: Tuple[int, int], cap: int) -> Tuple[int, int]:
    """(H, W) of the full-resolution frame: the photo's aspect, fitting ``view_hw``, long side <= ``cap``."""
    h, w = photo_hw
    vh, vw = max(1, view_hw[0]), max(1, view_hw[1])
    fit = min(vh / h, vw / w)  # scale at which the photo fills the view
    long_side = int(min(cap, max(32, math.floor(fit * max(h, w)))))
    return frame_size(photo_hw, long_side)


def screenshot_size(photo_hw: Tuple[int, int], view_hw: Tuple[int, int], long_side: int = 0) -> Tuple[int, int]:
    """(H, W) of a screenshot: ``long_side`` (the photo's aspect) if > 0, else the view's size on screen
    (the photo fitted into ``view_hw``, no cap)."""
    if long_side and long_side > 0:
        return frame_size(photo_hw, int(min(8192, max(16, long_side))))
    return full_frame_size(photo_hw, view_hw, 8192)


PREVIEW_SAMPLES = 12
"""How many recent previews :func:`choose_preview_long_side` fits its cost model to."""


def preview_cost_model(samples: Sequence[Tuple[int, float]]) -> Optional[Tuple[float, float]]:
    """``(a, b)`` of ``seconds ~ a + b * side**2`` fitted to recent previews ``(long side, seconds)``.

    A preview's time is a fixed part (display conversion, the decoder's and rasterizer's per-call overhead)
    plus a part that grows with the pixel count (rasterization and the U-Net decoder, per pixel). The
    median time of each size seen is used (robust to a spike of machine load); with two sizes or more
    the line is fitted by least squares, with one the fixed part is taken as zero (all time per pixel:
    the cautious reading, it never overestimates how large a preview may be). None without a usable
    sample.
    """
    by_side: Dict[int, List[float]] = {}
    for side, seconds in samples:
        if side > 0 and math.isfinite(seconds) and seconds > 0:
            by_side.setdefault(int(side), []).append(float(seconds))
    if not by_side:
        return None
    x = np.array([float(side) ** 2 for side in by_side], np.float64)
    y = np.array([float(np.median(v)) for v in by_side.values()], np.float64)
    if len(x) >= 2 and np.ptp(x) > 0.1 * x.max():
        b, a = np.polyfit(x, y, 1)
        if b > 0 and a >= 0:
            return float(a), float(b)
    i = int(np.argmax(x))  # one size (or an unusable fit): all per pixel, from the largest size seen
    return 0.0, float(y[i] / x[i])


def choose_preview_long_side(samples: Sequence[Tuple[int, float]], current: int,
                             settings: PreviewSettings = PreviewSettings()) -> int:
    """The next preview's long side, from the measured times ``samples`` (``(long side, seconds)`` of the
    last previews, oldest first; :data:`PREVIEW_SAMPLES` of them are used) so that a preview fits
    ``settings.target_preview_s`` (~24 fps while dragging).

    The side that fits the budget under :func:`preview_cost_model` is approached in damped steps (at
    most x1.25 up, /1.5 down per frame: a burst of load does not collapse the size at once), kept when
    the predicted time at ``current`` is within 15 % under to 10 % over the budget (no flicker between
    sizes), rounded to a multiple of 8 inside ``[min_preview_long_side, max_preview_long_side]``. When
    the fixed part alone exceeds the budget the smallest size is chosen.
    """
    lo, hi = settings.min_preview_long_side, settings.max_preview_long_side
    cur = int(min(hi, max(lo, current)))
    model = preview_cost_model(list(samples)[-PREVIEW_SAMPLES:])
    if model is None:
        return cur
    a, b = model
    budget = settings.target_preview_s
    predicted = a + b * cur * cur
    if 0.85 * budget <= predicted <= 1.1 * budget:
        return cur
    ideal = math.sqrt((budget - a) / b) if budget > a else 0.0
    step = min(1.25 * cur, max(cur / 1.5, ideal))
    nxt = int(round(step / 8.0)) * 8
    if nxt == cur and ideal != cur:  # the rounding must not freeze the adaptation
        nxt = cur + (8 if ideal > cur else -8)
    return int(min(hi, max(lo, nxt)))


def wheel_ticks(wheel_dy: float, invert: bool = False) -> float:
    """Forward wheel steps from Open3D's ``wheel_dy`` (positive for wheel up under X11, as GLFW's scroll
    offset): wheel up moves forwards, as in common 3D viewers (Blender, MeshLab, nerfstudio); ``invert``
    swaps it."""
    ticks = float(wheel_dy)
    return -ticks if invert else ticks


def export_progress_text(done: int, total: int, elapsed_s: float) -> str:
    """"Exporting 12/90 frames, 0:04 elapsed, about 0:26 left" (no estimate before the first frame)."""
    def clock(seconds: float) -> str:
        m, sec = divmod(int(round(max(0.0, seconds))), 60)
        return f"{m}:{sec:02d}"

    text = f"Exporting {done}/{total} frames, {clock(elapsed_s)} elapsed"
    if done > 0 and total > done:
        text += f", about {clock(elapsed_s / done * (total - done))} left"
    return text


def path_source(state: ViewState) -> str:
    """What the export follows: "keyframes", "loaded" (a camera-path file) or "trajectory"."""
    if state.use_keyframes:
        return "keyframes"
    return "loaded" if state.use_loaded_path else "trajectory"


def resolve_typed_path(text: str, folder: Optional[str]) -> str:
    """The file a typed path names: ``~`` expanded; an absolute path as it is; a relative one inside
    ``folder`` (the dialog's folder; the working directory if None)."""
    t = os.path.expanduser(str(text).strip())
    if not t:
        raise InputError("file name", "type a file name or path")
    if os.path.isabs(t):
        return os.path.normpath(t) + ("/" if t.endswith("/") else "")
    base = folder or os.getcwd()
    return os.path.normpath(os.path.join(base, t)) + ("/" if t.endswith("/") else "")


def resolve_open_path(text: str, folder: Optional[str]) -> str:
    """The existing file a typed path names (as :func:`resolve_typed_path`); InputError naming the path
    when nothing is there or it is a folder."""
    path = resolve_typed_path(text, folder).rstrip("/") or "/"
    if os.path.isdir(path):
        raise InputError(path, "is a folder: type a file's name, or use Browse...")
    if not os.path.exists(path):
        raise InputError(path, "no such file")
    return path


def push_recent(recent: Tuple[str, ...], path: str, limit: int = 8) -> Tuple[str, ...]:
    """``recent`` with ``path`` first (moved there if present), at most ``limit`` entries."""
    p = str(path)
    return ((p,) + tuple(r for r in recent if r != p))[: max(1, int(limit))]


def export_destination(path: str, fmt: ExportFormat) -> str:
    """``path`` with the suffix ``fmt`` needs (MP4/GIF), or a folder path for PNG frames."""
    check_choice(fmt, "export format", get_args(ExportFormat))
    p = Path(path)
    if fmt == "png":
        return str(p.with_suffix("")) + "/" if p.suffix else (path if path.endswith("/") else path + "/")
    return str(p.with_suffix(EXPORT_SUFFIX[fmt])) if p.suffix.lower() != EXPORT_SUFFIX[fmt] else path


class TrajectoryLimits(NamedTuple):
    """Bounds of the trajectory's parameters for one photo (scene units): the sideways and vertical
    amplitude ``[0, max_xy]`` and the forward end ``[min_forward, max_forward]``."""

    max_xy: float
    min_forward: float
    max_forward: float


def trajectory_limits(rng: CameraRange, scene: OrbitScene) -> TrajectoryLimits:
    """What the trajectory's parameters may reach on a photo whose clean range is ``rng``: the range's
    pan for the amplitudes, its dolly (kept the near margin in front of the near surface) for the forward
    end; never less than the default trajectory (the layered depth image always covers that one)."""
    centre, near = scene.centre_depth, scene.near_depth
    max_forward = min(rng.max_dolly * centre, (1.0 - rng.near_margin) * near)
    return TrajectoryLimits(max(DEFAULT_XY, rng.max_pan), min(0.0, rng.min_dolly * centre),
                            max(DEFAULT_Z[1], max_forward))


def clamp_trajectory(t: TrajectorySettings, limits: TrajectoryLimits) -> TrajectorySettings:
    """``t`` with its amplitudes and forward end inside ``limits`` (ranges given as (start, end) are
    clamped end by end; a single number ``a`` means ``(-a, a)``, as in the trajectories)."""
    hi = limits.max_xy

    def amp(v):  # an amplitude in [0, hi], or a (start, end) range in [-hi, hi]
        if isinstance(v, (int, float)):
            return float(min(hi, max(0.0, v)))
        return tuple(float(min(hi, max(-hi, x))) for x in v)

    z = tuple(t.z) if isinstance(t.z, (tuple, list)) else (-float(t.z), float(t.z))  # a number a: (-a, a)
    z = tuple(float(min(limits.max_forward, max(limits.min_forward, v))) for v in z)
    return replace(t, x=amp(t.x), y=amp(t.y), z=z)


def clamp_state_pose(state: ViewState, scene: OrbitScene, limits: OrbitLimits = OrbitLimits()) -> ViewState:
    """``state`` with its pose clamped to ``limits`` for ``scene`` (after a new photo or a loaded path)."""
    return replace(state, pose=clamp_pose(state.pose, scene, limits))
