"""The viewer's compute side: the loaded 3D photo, its renderers, the model and the style.

:class:`ViewerSession` has no widgets and knows nothing of Open3D's GUI; the
window runs its methods as :class:`~stylize3d_app.viewer.worker.ComputeWorker` tasks and
renders. It keeps everything that does not depend on the camera:

* the 3D photo and its :class:`~stylize3d_core.render.plain.PlainRenderer`
  (previews rasterize a random subset of the points, see ``render/plain.py``);
* when a model checkpoint is available, a :class:`~stylize3d_core.stylize.Stylized3DPhoto`
  holding the encoded point cloud: a new style re-uses it (no re-encoding), a
  new strength only re-blends.

Without a checkpoint (none given, the shipped lite model missing from the install,
or ``use_model=False``) the session renders the plain 3D photo and says so
(:data:`NO_MODEL`).

Everything that fails keeps what was there before: a photo that cannot be read
leaves the current photo loaded, a style that cannot be read the current style.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Dict, NamedTuple, Optional, Tuple

import cv2
import numpy as np

from stylize3d_core import resources
from stylize3d_core.defaults import DEFAULT_STRENGTH
from stylize3d_core.errors import InputError, RenderInterrupted
from stylize3d_core.geometry.camera import Cameras
from stylize3d_core.io.images import load_image, to_uint8
from stylize3d_core.io.video import Progress, write_video
from stylize3d_core.pipeline import EXPORT_POINTS_PER_PIXEL, PhotoSpec, load_photo3d
from stylize3d_core.render.plain import PlainRenderer, PlainRenderSettings, frame_size
from stylize3d_core.scene.photo3d import Photo3D

from .layers import ViewerLayers
from .orbit import OrbitScene
from .state import PhotoInfo

DEFAULT_MODEL = resources.shipped_location(resources.MODELS[resources.DEFAULT_MODEL_NAME])
"""The shipped trained checkpoint (found by ``stylize3d_core.resources``; may be missing from an install)."""
SAMPLE_PHOTO = resources.shipped_location(f"samples/{resources.SAMPLE_PHOTO_NAME}")
SAMPLE_STYLE = resources.shipped_location(f"styles/{resources.SAMPLE_STYLE_NAME}")
NO_MODEL = "no trained model: showing the plain 3D photo"
STYLE_MAX_SIZE = 512
"""Style images are read with their long side shrunk to this (the style encoder's own cap)."""


class StylizeInfo(NamedTuple):
    """Outcome of :meth:`ViewerSession.prepare_stylized`: whether stylized views are available, and why not."""

    available: bool
    message: str
    seconds: float


class ViewFrame(NamedTuple):
    """A rendered view ready for display.

    Attributes:
        image: (Hd, Wd, 3) uint8: the rendered size, or the display size it was resized to
            (:meth:`ViewerSession.render_view`'s ``display_hw``).
        rendered_size: (H, W) it was rendered at.
        stylized: True if it came through the model.
        preview: True for a reduced-resolution preview.
    """

    image: np.ndarray
    rendered_size: Tuple[int, int]
    stylized: bool
    preview: bool


@dataclass(frozen=True)
class ExportJob:
    """One export: where, which cameras, frame size (H, W), fps, stylized or original."""

    path: str
    cameras: Cameras
    size: Tuple[int, int]
    fps: float
    stylized: bool


def display_image(rgb: np.ndarray, display_hw: Tuple[int, int]) -> np.ndarray:
    """(H, W, 3) float RGB -> (Hd, Wd, 3) uint8, resized (bilinear) to ``display_hw``; NaN/inf become 0."""
    a = np.nan_to_num(np.asarray(rgb, dtype=np.float32), nan=0.0, posinf=1.0, neginf=0.0)
    u8 = to_uint8(a)  # (H, W, 3)
    hd, wd = int(display_hw[0]), int(display_hw[1])
    if u8.shape[:2] != (hd, wd):
        u8 = cv2.resize(u8, (wd, hd), interpolation=cv2.INTER_LINEAR)
    return np.ascontiguousarray(u8)


def colour_jump(before: np.ndarray, after: np.ndarray) -> Tuple[float, float]:
    """How much the view changes from ``before`` to ``after`` (two (H, W, 3) uint8 frames of one size):
    the mean absolute difference of their per-channel mean colours, and the mean absolute pixel
    difference, both in 8-bit levels."""
    if before.shape != after.shape:
        raise InputError("colour jump", f"image shapes differ: {before.shape} and {after.shape}")
    a, b = before.astype(np.float32), after.astype(np.float32)
    return float(np.abs(a.mean((0, 1)) - b.mean((0, 1))).mean()), float(np.abs(a - b).mean())


def shown_as(image: np.ndarray, shape: Tuple[int, ...]) -> np.ndarray:
    """``image`` (H, W, 3) uint8 scaled (bilinear) to ``shape``'s (H, W), as the view shows a smaller frame
    in the place of a larger one (for comparing a preview with the full frame that replaces it)."""
    h, w = int(shape[0]), int(shape[1])
    if image.shape[:2] == (h, w):
        return image
    return cv2.resize(image, (w, h), interpolation=cv2.INTER_LINEAR)


def split_view(before: np.ndarray, after: np.ndarray, fraction: float) -> np.ndarray:
    """Before / after comparison of two (H, W, 3) images: ``before`` left of ``fraction`` of the width,
    ``after`` right of it, and a 1-pixel light line at the split (none at 0 or 1)."""
    if before.shape != after.shape:
        raise InputError("split view", f"image shapes differ: {before.shape} and {after.shape}")
    f = float(min(1.0, max(0.0, fraction)))
    w = before.shape[1]
    col = int(round(f * w))
    out = np.array(after, copy=True)
    out[:, :col] = before[:, :col]
    if 0 < col < w:
        out[:, col] = 0.9
    return out


class ViewerSession:
    """The loaded 3D photo, renderers, model and style (see the module docstring).

    Thread use: not thread-safe; every method runs on the compute worker's thread.
    """

    def __init__(self, model: Optional[str] = None, plain_settings: PlainRenderSettings = PlainRenderSettings(), *,
                 use_model: bool = True) -> None:
        self.plain_settings = plain_settings
        self.use_model = use_model
        self.model_path: Optional[Path] = Path(model) if model is not None else None
        self._checkpoint = None
        self._style_encoder = None
        self.photo: Optional[Photo3D] = None
        self.info: Optional[PhotoInfo] = None
        self._plain: Optional[PlainRenderer] = None
        self._stylized = None  # Stylized3DPhoto
        self.style_path: Optional[str] = None
        self._style_rgb: Optional[np.ndarray] = None
        self.strength = DEFAULT_STRENGTH
        self.colour_gain: Optional[np.ndarray] = None  # (3,) per-channel gain of stylized previews
        self._preview_hw: Optional[Tuple[int, int]] = None  # size of the last stylized preview
        self.style2_path: Optional[str] = None
        self._style2_rgb: Optional[np.ndarray] = None
        self.mix = 0.0
        self.layers: Optional[ViewerLayers] = None  # a foreground kept unstylized (layered stylization)

    # -- model --------------------------------------------------------------------
    def checkpoint_path(self) -> Optional[Path]:
        """The checkpoint to use: the one given, else the default if it exists, else None (or if not ``use_model``)."""
        if not self.use_model:
            return None
        if self.model_path is not None:
            return self.model_path
        return DEFAULT_MODEL if DEFAULT_MODEL.is_file() else None

    def _load_checkpoint(self):
        if self._checkpoint is None:
            path = self.checkpoint_path()
            if path is None:
                return None
            from stylize3d_core.models.checkpoint import load_checkpoint

            self._checkpoint = load_checkpoint(path)  # InputError naming the file if unreadable
        return self._checkpoint

    @property
    def can_stylize(self) -> bool:
        """True when the current photo is encoded for the model."""
        return self._stylized is not None

    # -- photo --------------------------------------------------------------------
    def load_photo(self, spec: PhotoSpec) -> PhotoInfo:
        """Build the 3D photo ``spec`` describes; on any error the current photo stays loaded."""
        t0 = time.perf_counter()
        return self.set_photo(load_photo3d(spec), str(spec.photo), t0)

    def set_photo(self, photo: Photo3D, name: str, t0: Optional[float] = None) -> PhotoInfo:
        """Make ``photo`` (built elsewhere: a merged multi-view photo) the current photo; ``name`` is its
        file, ``t0`` when building began (``time.perf_counter``). A foreground mask (``layers``) is kept
        for a rebuild of the same photo at the same size (carried by the new LDI), else dropped."""
        t0 = time.perf_counter() if t0 is None else t0
        ldi = photo.ldi
        scene = OrbitScene.from_depths(ldi.depth[ldi.photo_region])
        plain = PlainRenderer(photo.points, self.plain_settings)
        layers = None if self.layers is None else self.layers.rebase(photo, name)
        # Nothing failed: replace the old photo (and drop its encoding).
        self.photo, self._plain, self._stylized, self.layers = photo, plain, None, layers
        self.colour_gain = None
        self.info = PhotoInfo(name, tuple(photo.size), plain.num_points, float(photo.fov_y_deg),
                              photo.depth.source, scene, time.perf_counter() - t0, photo.camera_range,
                              float(ldi.range_scale))
        return self.info

    def prepare_stylized(self) -> StylizeInfo:
        """Encode the current photo for the model (seconds), re-applying the style and strength."""
        t0 = time.perf_counter()
        if self.photo is None:
            raise InputError("photo", "open a photo first")
        ck = self._load_checkpoint()
        if ck is None:
            return StylizeInfo(False, NO_MODEL, 0.0)
        from stylize3d_core.models.style_features import StyleEncoder
        from stylize3d_core.stylize import Stylized3DPhoto, StylizeSettings

        if self._style_encoder is None:
            self._style_encoder = StyleEncoder()
        # full frames and exports keep the export default's point budget (chosen by `bench speed` within the
        # 40 dB final-frame target of every point); previews their own smaller one
        settings = StylizeSettings(strength=self.strength, final_points_per_pixel=EXPORT_POINTS_PER_PIXEL)
        s = Stylized3DPhoto(self.photo, ck, settings, style_encoder=self._style_encoder)
        if self._style_rgb is not None:
            s.set_style(self._style_rgb)
        if self._style2_rgb is not None:
            s.set_second_style(self._style2_rgb)
        s.set_mix(self.mix)
        self._stylized = s
        stage = "" if ck.stage == 2 else f" (stage {ck.stage}: no style training)"
        return StylizeInfo(True, f"model {self.checkpoint_path().name}{stage}", time.perf_counter() - t0)

    def prepare_model_features(self) -> None:
        """Make the model's learned inputs for the current photo and styles now (seconds at 1 MP; see
        ``Stylized3DPhoto.prepare``), so that no later view waits for them. The viewer runs it as a task
        once the first stylized frame is on screen: views whose every pixel the points cover never need
        them, and the first frame does not wait for them."""
        if self._stylized is not None:
            self._stylized.prepare()

    # -- style and strength ----------------------------------------------------------
    def load_style(self, path: str) -> Tuple[int, int]:
        """Read a style image and apply it (re-using the encoded point cloud); returns its (h, w)."""
        rgb = load_image(str(path), max_size=STYLE_MAX_SIZE).rgb  # (h, w, 3) float32
        if self._stylized is not None:
            self._stylized.set_style(rgb)
        self._style_rgb, self.style_path = rgb, str(path)
        return rgb.shape[:2]

    def load_second_style(self, path: Optional[str]) -> Optional[Tuple[int, int]]:
        """Read a second style image to mix with the first (None removes it); returns its (h, w)."""
        if path is None:
            if self._stylized is not None:
                self._stylized.set_second_style(None)
            self._style2_rgb, self.style2_path = None, None
            return None
        rgb = load_image(str(path), max_size=STYLE_MAX_SIZE).rgb
        if self._stylized is not None:
            self._stylized.set_second_style(rgb)
        self._style2_rgb, self.style2_path = rgb, str(path)
        return rgb.shape[:2]

    def set_mix(self, mix: float) -> float:
        """Mix of the two styles in [0, 1] (cheap: re-blends the two styles' cached features)."""
        if self._stylized is not None:
            self._stylized.set_mix(mix)
        self.mix = float(mix)
        return self.mix

    def set_strength(self, strength: float) -> float:
        """Style strength in [0, 1] (cheap: re-blends the cached features)."""
        if self._stylized is not None:
            self._stylized.set_strength(strength)
        self.strength = float(strength)
        return self.strength

    # -- rendering ----------------------------------------------------------------
    def render(self, camera: Cameras, height: int, width: int, *, preview: bool, stylized: bool,
               should_stop: Optional[Callable[[], bool]] = None) -> np.ndarray:
        """One view (H, W, 3) float32 in [0, 1]: through the model when ``stylized`` and available.

        ``should_stop`` is checked between stages and between chunks of points
        while rasterizing; once it returns True the render raises
        :class:`~stylize3d_core.errors.RenderInterrupted`.
        """
        if self.photo is None:
            raise InputError("photo", "open a photo first")
        if stylized and self._stylized is not None and self.layers is not None:
            return self.layers.renderer(self._stylized, self.strength).render(camera, height, width, preview=preview,
                                                                              should_stop=should_stop)
        if stylized and self._stylized is not None:
            return self._stylized.render(camera, height, width, preview=preview, should_stop=should_stop)
        if should_stop is not None and should_stop():
            raise RenderInterrupted("render stopped before rasterizing")
        return self._plain.render(camera, height, width, preview=preview, should_stop=should_stop)

    def render_view(self, camera: Cameras, size: Tuple[int, int], display_hw: Optional[Tuple[int, int]] = None, *,
                    preview: bool, stylized: bool, should_stop: Optional[Callable[[], bool]] = None,
                    split: Optional[float] = None, calibrate: bool = True,
                    timings: Optional[Dict[str, float]] = None) -> ViewFrame:
        """Render at ``size`` (H, W) and convert to 8 bits for display (``should_stop``: see :meth:`render`);
        resized (bilinear) to ``display_hw`` when given, else kept at ``size`` (the window's image widget
        scales it to the view smoothly on the GPU: no full-view upscale in Python).

        ``split`` in [0, 1] (stylized views only): a before / after comparison, the original 3D photo
        left of that fraction of the width and the stylized view right of it (see :func:`split_view`).
        A stylized full frame re-matches the previews' colours to itself (:meth:`calibrate_previews`)
        unless ``calibrate`` is False (an intermediate level of a progressive frame: the final one will).
        The original 3D photo's full frames are rendered at most at the photo's own size and scaled up
        (:meth:`render_original`). ``timings``, when given, receives the seconds of each stage
        (``render``, ``split``, ``convert``, ``resize``)."""
        t0 = time.perf_counter()
        styled = stylized and self.can_stylize
        if styled:
            rgb = self.render(camera, size[0], size[1], preview=preview, stylized=True, should_stop=should_stop)
            if preview:
                self._preview_hw = (int(size[0]), int(size[1]))
                if self.colour_gain is not None:
                    rgb = np.clip(rgb * self.colour_gain, 0.0, 1.0)
            elif calibrate:
                self.calibrate_previews(camera, rgb)
        else:
            rgb = self.render_original(camera, size, preview=preview, should_stop=should_stop)
        t1 = time.perf_counter()
        if split is not None and styled:
            rgb = split_view(self.render_original(camera, size, preview=preview), rgb, split)
        t2 = time.perf_counter()
        u8 = to_uint8(np.nan_to_num(np.asarray(rgb, dtype=np.float32), nan=0.0, posinf=1.0, neginf=0.0))
        t3 = time.perf_counter()
        if display_hw is not None and u8.shape[:2] != tuple(display_hw):
            u8 = cv2.resize(u8, (int(display_hw[1]), int(display_hw[0])), interpolation=cv2.INTER_LINEAR)
        u8 = np.ascontiguousarray(u8)
        if timings is not None:
            timings.update(render=t1 - t0, split=t2 - t1, convert=t3 - t2, resize=time.perf_counter() - t3)
        return ViewFrame(u8, tuple(size), styled, preview)

    def render_original(self, camera: Cameras, size: Tuple[int, int], *, preview: bool,
                        should_stop: Optional[Callable[[], bool]] = None) -> np.ndarray:
        """The original (plain) 3D photo for the view, (H, W, 3) float32: a full frame larger than the photo
        is rendered at the photo's size and scaled up (bilinear), since past one point per pixel the
        splats' seams show as a faint dot grid that the scaling does not have."""
        h, w = int(size[0]), int(size[1])
        cap = max(self.photo.size) if self.photo is not None else max(h, w)
        if preview or max(h, w) <= cap:
            return self.render(camera, h, w, preview=preview, stylized=False, should_stop=should_stop)
        small = frame_size(tuple(self.photo.size), int(cap), even=False)
        rgb = self.render(camera, small[0], small[1], preview=False, stylized=False, should_stop=should_stop)
        return cv2.resize(np.ascontiguousarray(rgb, dtype=np.float32), (w, h), interpolation=cv2.INTER_LINEAR)

    def calibrate_previews(self, camera: Cameras, full: np.ndarray) -> Optional[np.ndarray]:
        """Match the colours of stylized previews to the full frame ``full`` of ``camera``: the decoder
        paints a small preview of fewer points a little differently (greener, at 96 px), so each release
        would visibly jump. Renders one preview of the same camera at the last preview size and keeps the
        per-channel gain (mean of the full frame / mean of the preview, within [0.8, 1.25]) that later
        previews are multiplied by. Returns the gain (None before any preview)."""
        if self._preview_hw is None or self._stylized is None:
            return None
        h, w = self._preview_hw
        small = self.render(camera, h, w, preview=True, stylized=True)
        m_full = full.reshape(-1, 3).mean(0)
        m_prev = small.reshape(-1, 3).mean(0)
        self.colour_gain = np.clip(m_full / np.maximum(m_prev, 1e-3), 0.8, 1.25).astype(np.float32)
        return self.colour_gain

    def export(self, job: ExportJob, progress: Optional[Progress] = None,
               between_frames: Optional[Callable[[], object]] = None) -> Path:
        """Write ``job`` (atomic; see ``stylize3d_core.io.video``); ``between_frames`` runs before each frame."""
        H, W = job.size

        def frames():
            for i in range(len(job.cameras)):
                if between_frames is not None:
                    between_frames()
                yield self.render(job.cameras[i], H, W, preview=False, stylized=job.stylized)

        return write_video(job.path, frames(), fps=job.fps, n_frames=len(job.cameras), progress=progress)
