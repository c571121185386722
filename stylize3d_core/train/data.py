"""Training samples for the stylization model (training from 2D images only).

A :class:`TrainSample` holds everything one training example needs: the source
image, its LDI point cloud (world = source camera frame, scene units), the
model's :class:`~stylize3d_core.models.scene_geometry.SceneGeometry` of it (made
by :func:`~stylize3d_core.models.scene_geometry.prepare_geometry`, the function
inference uses, with the config's :class:`NeighbourhoodConfig`), ``V`` target
cameras and their target images with masks. Two kinds:

* ``"ldi"`` -- a *pseudo* novel view, as in the paper: a random crop / scale /
  flip / colour jitter of a real photo (:mod:`.photos`), depth from the
  built-in prior (:func:`stylize3d_core.depth.prior.estimate_prior`) or a random
  procedural depth map (:func:`.procedural.random_depth`), then
  :func:`build_ldi` + :func:`ldi_to_points`; targets are the LDI's points
  rasterized from the target cameras (the same z-buffered splatting the model
  renders with) with holes filled by push-pull. ``masks`` is
  False at those holes.
* ``"procedural"`` -- a *true* novel view: a random textured scene
  (:mod:`.procedural`) is ray-cast for the source view (colour + depth -> LDI ->
  points) and for every target camera, so targets include what the source view
  could not see. It measures real view-synthesis accuracy (held-out PSNR).

``seen`` marks target pixels whose surface the source photo saw (``"ldi"``: a
rasterized point of the photo itself, not the hidden layer or the border;
``"procedural"``: the surface point is visible from the source camera), so
accuracy can be reported separately on disoccluded regions.

Target cameras follow the public code (:class:`ViewSampling`): translation x, y
in [-0.05, 0.05], z in [-0.05, 0.15] scene units, FOV x [0.95, 1.05], no rotation.

Colours (source image, point colours, targets) are quantised to multiples of
1/255, so a sample stores exactly in 8 bits (see :mod:`.cache`). Every sample is
a deterministic function of ``(config, seed, index)``: its random generator is
``numpy.random.default_rng([seed, index])``.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from typing import Dict, NamedTuple, Optional, Tuple

import numpy as np
import torch

from ..checks import check_choice, check_range
from ..depth.prior import estimate_prior
from ..errors import InputError
from ..geometry.camera import Cameras
from ..io.images import to_uint8
from ..models.scene_geometry import NeighbourhoodConfig, SceneGeometry, prepare_geometry
from ..render.holes import fill_holes
from ..render.rasterize import RasterSettings
from ..render.rasterizer import PointRasterizer
from ..scene.ldi import ORIGINAL, LDISettings, build_ldi
from ..scene.pointcloud import PointCloud, PointTensors, ldi_to_points
from .photos import EVAL_PHOTOS, TRAIN_PHOTOS, PhotoAugment, augmented_photo
from .procedural import random_depth, random_scene, ray_cast, visible_from
from .textures import random_texture

KINDS = ("ldi", "procedural")
"""Sample kinds: pseudo views rendered from a photo's LDI, and true views of procedural scenes."""


def _check_interval(value: Tuple[float, float], name: str, low: float, high: float) -> None:
    if len(value) != 2:
        raise InputError(name, f"expected (low, high), got {value!r}")
    a = check_range(value[0], name, low, high)
    b = check_range(value[1], name, low, high)
    if a > b:
        raise InputError(name, f"low must be <= high, got {value!r}")


@dataclass(frozen=True)
class ViewSampling:
    """How target cameras are drawn around the source camera (defaults: the public code)."""

    num_views: int = 2
    """Target views per sample (public code: 2)."""
    x: Tuple[float, float] = (-0.05, 0.05)
    """Range of the sideways translation, scene units (near surface at 1/3)."""
    y: Tuple[float, float] = (-0.05, 0.05)
    """Range of the vertical translation (+y is down)."""
    z: Tuple[float, float] = (-0.05, 0.15)
    """Range of the forward translation (+z moves into the scene)."""
    fov_scale: Tuple[float, float] = (0.95, 1.05)
    """Range of the factor applied to the source FOV."""

    def __post_init__(self) -> None:
        if isinstance(self.num_views, bool) or not isinstance(self.num_views, int) or not 1 <= self.num_views <= 1024:
            raise InputError("num_views", f"must be an integer in [1, 1024], got {self.num_views!r}")
        for name in ("x", "y", "z"):
            _check_interval(getattr(self, name), name, -1.0, 1.0)
        _check_interval(self.fov_scale, "fov_scale", 0.1, 10.0)


def sample_target_cameras(
    rng: np.random.Generator, fov_y_deg: float, sampling: ViewSampling = ViewSampling()
) -> Cameras:
    """``sampling.num_views`` target cameras: translated source cameras (no rotation) with jittered FOV.

    Args:
        rng: random generator (the cameras are a function of its state).
        fov_y_deg: the source camera's vertical FOV in degrees.
    Returns:
        :class:`Cameras` of V cameras; ``cam_to_world`` is identity but for the translation.
    """
    v = sampling.num_views
    t = np.stack([rng.uniform(*sampling.x, v), rng.uniform(*sampling.y, v), rng.uniform(*sampling.z, v)], axis=1)
    fov = fov_y_deg * rng.uniform(*sampling.fov_scale, v)
    c2w = np.tile(np.eye(4), (v, 1, 1))  # (V, 4, 4)
    c2w[:, :3, 3] = t
    return Cameras.create(c2w, fov)


@dataclass(frozen=True)
class DataConfig:
    """How training samples are made. Its ``repr`` identifies a dataset (see :mod:`.cache`)."""

    image_size: Tuple[int, int] = (128, 128)
    """(H, W) of source and target images; small so a CPU training step is cheap."""
    views: ViewSampling = field(default_factory=ViewSampling)
    """Target camera distribution."""
    procedural_fraction: float = 0.25
    """Probability that a sample is a procedural scene (true novel views) rather than a photo's LDI."""
    prior_fraction: float = 0.5
    """Probability that an ``"ldi"`` sample takes its depth from the built-in prior (else a random depth map)."""
    fov_range: Tuple[float, float] = (50.0, 70.0)
    """Range of the source camera's vertical FOV in degrees."""
    photos: Tuple[str, ...] = TRAIN_PHOTOS
    """Photos (names in :data:`.photos.PHOTO_LICENCES`, or file paths) for ``"ldi"`` samples and scene textures."""
    augment: PhotoAugment = field(default_factory=PhotoAugment)
    """Crop / flip / colour jitter of the photos."""
    ldi: LDISettings = field(default_factory=lambda: LDISettings(subpixel_silhouettes=False))
    """How the LDI is built: the product's defaults but for ``subpixel_silhouettes`` (off): the samples'
    points stay on the photo's pixel grid, as the stage-2 teacher needs (it bakes colours per canvas pixel,
    ``train/teacher.py``), and the model draws every point opaque anyway (its rasterizer does not blend
    coverage), so the silhouettes' shares would not reach it."""
    neighbourhood: NeighbourhoodConfig = field(default_factory=NeighbourhoodConfig)
    """The geometry precomputed for the model (the paper's by default); it must equal the
    trained model's ``config.neighbourhood``."""
    target_supersample: int = 1
    """Supersampling of the ``"ldi"`` target rasterization (1 or 2). 1: at 2x, a surface
    magnified by forward motion (z up to +0.15 at the near depth 1/3, ~1.8x) spreads its
    points wider than the 2 x 2 sub-pixel splat and the hidden layer shows through."""
    depth_tolerance: float = 0.02
    """Relative depth band of the front surface when rasterizing ``"ldi"`` targets."""
    scene_samples: int = 3
    """Anti-aliasing rays per pixel along each axis for procedural scenes (9 per pixel)."""
    scene_textures: int = 6
    """Textures drawn per procedural scene."""
    texture_size: int = 128
    """Side of each procedural-scene texture in pixels."""
    photo_texture_fraction: float = 0.4
    """Probability that a scene texture is a photo crop rather than a procedural texture."""

    def __post_init__(self) -> None:
        if not isinstance(self.neighbourhood, NeighbourhoodConfig):
            got = type(self.neighbourhood).__name__
            raise InputError("neighbourhood", f"expected a NeighbourhoodConfig, got {got}")
        if len(self.image_size) != 2 or not all(isinstance(s, int) and 32 <= s <= 1024 for s in self.image_size):
            raise InputError("image_size", f"expected (H, W) integers in [32, 1024], got {self.image_size!r}")
        check_range(self.procedural_fraction, "procedural_fraction", 0.0, 1.0)
        check_range(self.prior_fraction, "prior_fraction", 0.0, 1.0)
        check_range(self.photo_texture_fraction, "photo_texture_fraction", 0.0, 1.0)
        _check_interval(self.fov_range, "fov_range", 10.0, 120.0)
        if len(self.photos) == 0 or not all(isinstance(p, str) for p in self.photos):
            raise InputError("photos", f"expected a non-empty tuple of names or paths, got {self.photos!r}")
        if self.target_supersample not in (1, 2):
            raise InputError("target_supersample", f"must be 1 or 2, got {self.target_supersample!r}")
        check_range(self.depth_tolerance, "depth_tolerance", 0.0, 1.0)
        for name, low, high in (("scene_samples", 1, 8), ("scene_textures", 1, 64), ("texture_size", 16, 1024)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
                raise InputError(name, f"must be an integer in [{low}, {high}], got {value!r}")


def held_out_config(config: DataConfig) -> DataConfig:
    """The same settings on the held-out photos (:data:`.photos.EVAL_PHOTOS`); use it with another seed."""
    overlap = set(config.photos) & set(EVAL_PHOTOS)
    if overlap:
        raise InputError("photos", f"the training photos include held-out ones: {sorted(overlap)}")
    return dataclasses.replace(config, photos=EVAL_PHOTOS)


class TrainSample(NamedTuple):
    """One training example (all torch tensors; V target views of size (H, W); N points).

    Attributes:
        kind: ``"ldi"`` (pseudo views) or ``"procedural"`` (true views).
        image: (H, W, 3) float32 source image in [0, 1].
        points: the LDI point cloud: ``xyz`` (N, 3) float32 world (= source
            camera frame, scene units), ``rgb`` (N, 3) float32, ``label`` (N,) uint8.
        geometry: ``prepare_geometry(points.xyz, points.rgb, fov_y_deg, image_size,
            config.neighbourhood)``: NDC parameters, encoder subset, FPS / ball-query
            hierarchy and upsampling weights, exactly as inference prepares them.
        fov_y_deg: the source camera's vertical FOV (its pose is the identity).
        cameras: the V target cameras.
        targets: (V, 3, H, W) float32 target images in [0, 1].
        masks: (V, H, W) bool, True where the target is trustworthy (not a filled hole).
        seen: (V, H, W) bool, True where the target shows a surface the source photo saw.
        source: where it came from (photo, crop, depth source; or the scene).
        seed, index: the sample is ``make_sample(index, config, seed)``.
        timings: seconds per generation step (not part of the sample's identity).
    """

    kind: str
    image: torch.Tensor
    points: PointTensors
    geometry: SceneGeometry
    fov_y_deg: float
    cameras: Cameras
    targets: torch.Tensor
    masks: torch.Tensor
    seen: torch.Tensor
    source: str
    seed: int
    index: int
    timings: Dict[str, float]

    @property
    def num_points(self) -> int:
        """N, the number of points."""
        return int(self.points.xyz.shape[0])

    @property
    def image_size(self) -> Tuple[int, int]:
        """(H, W) of the source and target images."""
        return int(self.image.shape[0]), int(self.image.shape[1])


def from_u8(x: torch.Tensor) -> torch.Tensor:
    """uint8 colours -> float32 multiples of 1/255 (the one place this division happens)."""
    return x.to(torch.float32) / 255.0


def _quantised(x: np.ndarray) -> torch.Tensor:
    return from_u8(torch.from_numpy(to_uint8(x)))


def _render_ldi_targets(
    points: PointCloud, cameras: Cameras, size: Tuple[int, int], config: DataConfig
) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rasterize the LDI points from each camera: targets (V, 3, H, W), masks and seen (V, H, W)."""
    h, w = size
    xyz = torch.from_numpy(points.xyz)
    original = torch.from_numpy(points.label == ORIGINAL).to(torch.float32)[:, None]  # (N, 1)
    features = torch.cat([torch.from_numpy(points.rgb), original], dim=1)  # (N, 4)
    raster = PointRasterizer(RasterSettings(height=h, width=w, depth_tolerance=config.depth_tolerance,
                                            supersample=config.target_supersample))
    targets, masks, seen = [], [], []
    with torch.inference_mode():
        for v in range(len(cameras)):
            frags = raster(xyz, features, cameras[v])
            rgb = fill_holes(frags.image[:3], frags.hole)  # (3, H, W)
            targets.append(torch.nan_to_num(rgb, nan=0.0, posinf=1.0, neginf=0.0).clamp(0.0, 1.0).numpy())
            masks.append((~frags.hole).numpy())
            seen.append(((~frags.hole) & (frags.image[3] > 0.5)).numpy())
    return np.stack(targets), np.stack(masks), np.stack(seen)


def _photo_and_depth(rng: np.random.Generator, config: DataConfig, timings: Dict[str, float]):
    """An augmented photo (H, W, 3) quantised, its depth (H, W) and a description."""
    size = config.image_size
    name = str(config.photos[int(rng.integers(0, len(config.photos)))])
    image, where = augmented_photo(name, rng, size, config.augment)
    image = _quantised(image).numpy()
    t0 = time.perf_counter()
    if rng.random() < config.prior_fraction:
        depth, how = estimate_prior(image).depth, "prior depth"
    else:
        depth, how = random_depth(rng, size, image), "random depth"
    timings["depth"] = time.perf_counter() - t0
    return image, depth, f"{where}, {how}"


def _scene_textures(rng: np.random.Generator, config: DataConfig):
    side = (config.texture_size, config.texture_size)
    out = []
    for _ in range(config.scene_textures):
        if rng.random() < config.photo_texture_fraction:
            name = str(config.photos[int(rng.integers(0, len(config.photos)))])
            out.append(augmented_photo(name, rng, side, config.augment)[0])
        else:
            out.append(random_texture(rng, side)[1])
    return out


def make_sample(
    index: int, config: DataConfig = DataConfig(), seed: int = 0, kind: Optional[str] = None
) -> TrainSample:
    """Generate training sample ``index`` of the dataset ``(config, seed)`` (see the module docstring).

    Args:
        index: sample number, >= 0.
        config: the data settings.
        seed: the dataset's seed.
        kind: force ``"ldi"`` or ``"procedural"``; None draws it with
            ``config.procedural_fraction`` (the draw is made either way, so the
            rest of the sample does not depend on this argument).
    """
    if not isinstance(config, DataConfig):
        raise InputError("config", f"expected a DataConfig, got {type(config).__name__}")
    for name, value in (("index", index), ("seed", seed)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
            raise InputError(name, f"must be an integer >= 0, got {value!r}")
    rng = np.random.default_rng([int(seed), int(index)])
    drawn = "procedural" if rng.random() < config.procedural_fraction else "ldi"
    kind = drawn if kind is None else check_choice(kind, "kind", KINDS)
    h, w = config.image_size
    fov = float(rng.uniform(*config.fov_range))
    timings: Dict[str, float] = {}
    t_start = time.perf_counter()

    if kind == "ldi":
        image, depth, source = _photo_and_depth(rng, config, timings)
    else:
        t0 = time.perf_counter()
        scene = random_scene(rng, _scene_textures(rng, config), fov, w / h)
        cast = ray_cast(scene, Cameras.identity(fov), h, w, config.scene_samples)
        if not cast.hit.all():
            raise RuntimeError("procedural scene: a source ray missed every quad (the back wall should catch all)")
        image, depth, source = _quantised(cast.rgb).numpy(), cast.depth, f"procedural scene of {len(scene.half)} quads"
        timings["scene"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    ldi = build_ldi(image, depth, config.ldi)
    cloud = ldi_to_points(ldi, fov)
    timings["ldi"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    cameras = sample_target_cameras(rng, fov, config.views)
    if kind == "ldi":
        targets, masks, seen = _render_ldi_targets(cloud, cameras, (h, w), config)
    else:
        scaled = scene.scaled(ldi.depth_scale)  # scene units, as the LDI's points
        views = [ray_cast(scaled, cameras[v], h, w, config.scene_samples) for v in range(len(cameras))]
        targets = np.stack([r.rgb.transpose(2, 0, 1) for r in views])
        masks = np.stack([r.hit for r in views])
        seen = np.stack([r.hit & visible_from(scaled, r.points.reshape(-1, 3), Cameras.identity(fov), h, w)
                         .reshape(h, w) for r in views])
    timings["targets"] = time.perf_counter() - t0

    points = PointTensors(torch.from_numpy(cloud.xyz.copy()), _quantised(cloud.rgb),
                          torch.from_numpy(cloud.label.copy()))
    t0 = time.perf_counter()
    # seed 0, as Stylized3DPhoto's default: a cloud over max_points is subset as inference would
    geometry = prepare_geometry(points.xyz, points.rgb, fov, (h, w), config.neighbourhood, seed=0)
    timings["geometry"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_start
    return TrainSample(
        kind=kind,
        image=torch.from_numpy(image.copy()),
        points=points,
        geometry=geometry,
        fov_y_deg=fov,
        cameras=cameras,
        targets=_quantised(targets),
        masks=torch.from_numpy(np.ascontiguousarray(masks)),
        seen=torch.from_numpy(np.ascontiguousarray(seen)),
        source=source,
        seed=int(seed),
        index=int(index),
        timings=timings,
    )
