"""The model's positions-only preprocessing of a point cloud, shared by inference and training.

:func:`prepare_geometry` is the one recipe: it turns a cloud (world points of
a photo's camera, its FOV and image size) into a :class:`SceneGeometry`::

    xyz (N, 3) world  --ndc_params / to_ndc-->  NDC (N, 3)
      --encoder subset (<= max_points, a seeded random subset)-->  N_e points
      --build_hierarchy (FPS levels, ball queries; radii x radius_scale)-->  PointHierarchy
      --idw_neighbours (k-NN IDW from the coarsest level to all N points)-->  IDWWeights

:class:`~stylize3d_core.stylize.Stylized3DPhoto` calls it for a photo;
:func:`stylize3d_core.train.data.make_sample` calls it for a training sample
and caches the result, so the trainer encodes exactly what inference would.

All its settings live in one :class:`NeighbourhoodConfig` (the encoder's
layer widths are a separate :class:`~stylize3d_core.models.encoder.EncoderConfig`).

**Radii follow the cloud's density.** The published radii suit ~512 points
across (``reference_points_across``); :func:`radius_scale` scales them for any
other density, so every ball spans about as many points as in the paper.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, Callable, Mapping, NamedTuple, Optional, Tuple

import torch

from ..checks import check_finite, check_shape
from ..errors import InputError
from ..geometry.ndc import NDCParams, ndc_params, to_ndc
from ..points import IDWWeights, KNNIndex, KNNResult, ball_from_knn, farthest_point_sample, idw_from_knn

REFERENCE_POINTS_ACROSS = 512
"""Points across the long side of the clouds the published encoder radii were set for (512 x 512 photos)."""


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


@dataclass(frozen=True)
class NeighbourhoodConfig:
    """Every setting of :func:`prepare_geometry` (defaults: the public code's config "r3").

    Attributes:
        k: the most neighbours per ball query (public code: 16).
        stem_radius: ball radius among all encoded points (level 0), NDC units, before
            density scaling (public code: 0.015).
        stage_radii: per down-sampling stage, the radius of the ball of each sampled
            centre among the previous level, then of the ball within the new level
            (public code: ((0.015, 0.025), (0.025, 0.05))).
        downsample: per stage, the FPS factor: a level of n points keeps
            ``max(1, n // factor)`` (public code: (4, 4)). Its length is the number of stages.
        fps_start: seed of the first FPS pick at every level, clamped to the level's
            size (see :func:`stylize3d_core.points.farthest_point_sample`); default 0.
        reference_points_across: points across the long side of a cloud for which
            the radii are used unscaled (see :func:`radius_scale`); default 512.
        upsample_k: neighbours of the IDW upsampling from the coarsest level to every
            point (the paper: 3-NN).
        max_points: clouds with more points are encoded from a seeded random subset
            of this size, to bound the encoder's cost (default 300k).
    """

    k: int = 16
    stem_radius: float = 0.015
    stage_radii: Tuple[Tuple[float, float], ...] = ((0.015, 0.025), (0.025, 0.05))
    downsample: Tuple[int, ...] = (4, 4)
    fps_start: int = 0
    reference_points_across: int = REFERENCE_POINTS_ACROSS
    upsample_k: int = 3
    max_points: int = 300_000

    def __post_init__(self) -> None:
        name = "NeighbourhoodConfig"
        for field, low in (("k", 1), ("fps_start", 0), ("reference_points_across", 1), ("upsample_k", 1),
                           ("max_points", 16)):
            value = getattr(self, field)
            if not _is_int(value) or value < low:
                raise InputError(f"{name}.{field}", f"must be an integer >= {low}, got {value!r}")
        if len(self.stage_radii) != len(self.downsample):
            raise InputError(name, f"stage_radii and downsample need one entry per stage; got "
                                   f"{len(self.stage_radii)} and {len(self.downsample)}")
        if not all(_is_int(f) and f >= 1 for f in self.downsample):
            raise InputError(f"{name}.downsample", f"must all be integers >= 1, got {self.downsample}")
        if any(len(pair) != 2 for pair in self.stage_radii):
            raise InputError(f"{name}.stage_radii", f"need two radii per stage, got {self.stage_radii}")
        radii = [self.stem_radius] + [r for pair in self.stage_radii for r in pair]
        if not all(isinstance(r, (int, float)) and 0 < r < float("inf") for r in radii):
            raise InputError(f"{name}.stage_radii", f"radii must be positive and finite, got stem "
                                                    f"{self.stem_radius!r}, stages {self.stage_radii!r}")

    @property
    def num_stages(self) -> int:
        """Down-sampling stages (levels - 1); the encoder needs as many."""
        return len(self.downsample)

    def to_dict(self) -> dict:
        """The fields by name, JSON-ready (tuples become lists)."""
        return json.loads(json.dumps(dataclasses.asdict(self)))

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], source: Any = "neighbourhood config") -> "NeighbourhoodConfig":
        """Inverse of :meth:`to_dict`; unknown or ill-typed fields raise InputError naming ``source``."""
        if not isinstance(d, Mapping):
            raise InputError(source, f"the neighbourhood configuration is not a mapping ({type(d).__name__})")
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise InputError(source, f"unknown neighbourhood settings {unknown}")
        kwargs = dict(d)
        if "stage_radii" in kwargs:
            kwargs["stage_radii"] = tuple(tuple(pair) for pair in kwargs["stage_radii"])
        if "downsample" in kwargs:
            kwargs["downsample"] = tuple(kwargs["downsample"])
        try:
            return cls(**kwargs)
        except TypeError as e:
            raise InputError(source, f"malformed neighbourhood configuration ({e})") from None

    @property
    def key(self) -> str:
        """A short hash of the named fields (:meth:`to_dict` as sorted JSON); equal configs, equal keys."""
        return hashlib.sha256(json.dumps(self.to_dict(), sort_keys=True).encode()).hexdigest()[:16]

    def radii(self, scale: float = 1.0) -> Tuple[float, Tuple[Tuple[float, float], ...]]:
        """(stem radius, stage radii), each multiplied by ``scale`` (> 0, finite)."""
        if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not 0 < scale < float("inf"):
            raise InputError("radius scale", f"must be a positive finite number, got {scale!r}")
        return self.stem_radius * scale, tuple((a * scale, b * scale) for a, b in self.stage_radii)


def radius_scale(image_size: Tuple[int, int], n_encoded: int, n_total: int,
                 reference_points_across: int = REFERENCE_POINTS_ACROSS) -> float:
    """Factor for the ball radii so every ball spans as many points as in the paper.

    The radii are in NDC, where the photo spans [-1, 1]: a photo whose long side
    is ``L`` pixels has points ``2 / L`` apart, thinned by ``sqrt(n_encoded /
    n_total)`` when the encoder sees a subset. The factor is
    ``reference_points_across / (L * sqrt(n_encoded / n_total))``: 1 at 512 px,
    4 for a 128 px training crop.
    """
    long_side = max(image_size) * (n_encoded / max(n_total, 1)) ** 0.5
    return reference_points_across / max(long_side, 1.0)


class PointHierarchy(NamedTuple):
    """Sampled levels and neighbourhoods of one point cloud (from :func:`build_hierarchy`).

    Level 0 is the input cloud (N_0 = N points); stage s maps level s to level s + 1.
    Only positions went into it: reuse it for any features of the same cloud.
    """

    xyz: Tuple[torch.Tensor, ...]  # per level l: (N_l, 3) float32 NDC positions
    stem_neighbours: torch.Tensor  # (N_0, k) long, ball of each point among level 0
    sample_idx: Tuple[torch.Tensor, ...]  # per stage s: (N_{s+1},) long FPS indices into level s
    down_neighbours: Tuple[torch.Tensor, ...]  # per stage s: (N_{s+1}, k) long, into level s
    same_neighbours: Tuple[torch.Tensor, ...]  # per stage s: (N_{s+1}, k) long, into level s + 1
    neighbourhood: NeighbourhoodConfig  # the (unscaled) settings it was built with
    scale: float  # the factor its ball radii were multiplied by

    @property
    def num_points(self) -> Tuple[int, ...]:
        """Number of points at each level, N_0 first."""
        return tuple(x.shape[0] for x in self.xyz)

    @property
    def num_stages(self) -> int:
        """Down-sampling stages (len(xyz) - 1)."""
        return len(self.sample_idx)


def build_hierarchy(
    xyz_ndc: torch.Tensor, config: NeighbourhoodConfig = NeighbourhoodConfig(), scale: float = 1.0
) -> PointHierarchy:
    """FPS levels and ball-query neighbourhoods of a point cloud for the encoder.

    Args:
        xyz_ndc: (N, 3) point positions in NDC, N >= 1. Not modified.
        config: radii, k, down-sampling factors, FPS start.
        scale: factor applied to every radius (see :func:`radius_scale`).

    Returns:
        :class:`PointHierarchy`; a level of n points has ``max(1, n // factor)``
        points at the next level, so any N >= 1 works.
    """
    return _build_hierarchy(xyz_ndc, config, scale)[0]


def _fps_level(prev: torch.Tensor, factor: int, fps_start: int) -> torch.Tensor:
    """FPS indices of the next level of ``prev`` (n, 3): ``max(1, n // factor)`` of them."""
    m = max(1, prev.shape[0] // factor)
    return farthest_point_sample(prev, m, start=min(fps_start, prev.shape[0] - 1))  # (m,)


def _build_hierarchy(
    xyz_ndc: torch.Tensor, config: NeighbourhoodConfig, scale: float,
    while_waiting: Optional[Callable[[], None]] = None,
) -> Tuple[PointHierarchy, KNNIndex]:
    """:func:`build_hierarchy`, plus the k-d tree of its coarsest level (for the upsampling search).

    Every ball query is a k-NN search plus a radius mask (:func:`~stylize3d_core.points.ball_from_knn`),
    and each level's centres are some of the previous level's points, so one k-NN search of
    each level among itself gives both its own balls (the stem's, or the stage's ``same``
    balls) and, by rows, the next stage's ``down`` balls: three searches instead of five for
    the default two stages, the same indices. The FPS of the next level runs in a worker thread while the level's k-NN
    search runs (large levels in fpsample's worker process, so the two really overlap; see
    :mod:`stylize3d_core.points.sampling`).
    """
    if not isinstance(config, NeighbourhoodConfig):
        raise InputError("config", f"expected a NeighbourhoodConfig, got {type(config).__name__}")
    stem_radius, stage_radii = config.radii(scale)
    check_shape(xyz_ndc, "xyz_ndc", (None, 3))
    if xyz_ndc.shape[0] == 0:
        raise InputError("xyz_ndc", "the point cloud is empty")
    if not torch.is_floating_point(xyz_ndc):
        raise InputError("xyz_ndc", f"expected a floating-point tensor, got {xyz_ndc.dtype}")
    check_finite(xyz_ndc, "xyz_ndc")
    k = config.k
    with torch.no_grad(), ThreadPoolExecutor(max_workers=1) as pool:
        xyz = xyz_ndc.detach().to(device="cpu", dtype=torch.float32).clone()  # (N, 3)
        levels = [xyz]
        samples, down, same = [], [], []
        radius = stem_radius  # of the balls of the current level among itself
        stem = None
        for s in range(config.num_stages + 1):
            cur = levels[-1]  # (n, 3)
            fps = pool.submit(_fps_level, cur, config.downsample[s], config.fps_start) if s < config.num_stages else None
            index = KNNIndex(cur)
            self_knn = index.self_knn(k)  # (n, k) of the level among itself
            balls = ball_from_knn(self_knn, radius, index.num_points).idx  # (n, k)
            if s == 0:
                stem = balls
            else:
                same.append(balls)
            if fps is None:
                break
            if while_waiting is not None and not fps.done():  # the FPS worker's wait: the caller's own work
                while_waiting()
                while_waiting = None
            idx = fps.result()  # (m,)
            r_down, radius = stage_radii[s]
            rows = KNNResult(self_knn.idx.index_select(0, idx), self_knn.sq_dist.index_select(0, idx))  # (m, k)
            samples.append(idx)
            down.append(ball_from_knn(rows, r_down, index.num_points).idx)  # (m, k) into cur
            levels.append(cur.index_select(0, idx))  # (m, 3)
    hierarchy = PointHierarchy(tuple(levels), stem, tuple(samples), tuple(down), tuple(same), config, float(scale))
    return hierarchy, index


class SceneGeometry(NamedTuple):
    """Everything about a point cloud's positions the model needs (from :func:`prepare_geometry`).

    Attributes:
        xyz: (N, 3) float32 world points (scene units).
        rgb: (N, 3) float32 colours in [0, 1].
        ndc: NDC parameters of the cloud in the photo's camera.
        encoder_idx: (N_e,) long indices of the points the encoder sees (all when N <= max_points).
        hierarchy: FPS / ball-query levels of the encoder's points (in NDC).
        upsample: IDW weights from the encoder's coarsest level to all N points.
    """

    xyz: torch.Tensor
    rgb: torch.Tensor
    ndc: NDCParams
    encoder_idx: torch.Tensor
    hierarchy: PointHierarchy
    upsample: IDWWeights

    @property
    def neighbourhood(self) -> NeighbourhoodConfig:
        """The settings it was prepared with."""
        return self.hierarchy.neighbourhood


def encoder_subset(n: int, max_points: int, seed: int = 0) -> torch.Tensor:
    """Sorted (min(n, max_points),) long indices of the points the encoder sees: all, or a seeded random subset."""
    if n <= max_points:
        return torch.arange(n)
    g = torch.Generator().manual_seed(int(seed))
    keep = torch.zeros(n, dtype=torch.bool)
    keep[torch.randperm(n, generator=g)[:max_points]] = True
    return keep.nonzero().squeeze(1)  # ascending: the sorted subset, without a sort


def prepare_geometry(
    xyz: torch.Tensor, rgb: torch.Tensor, fov_y_deg: float, image_size: Tuple[int, int],
    config: NeighbourhoodConfig = NeighbourhoodConfig(), seed: int = 0,
    while_waiting: Optional[Callable[[], None]] = None,
) -> SceneGeometry:
    """Positions-only preprocessing of a cloud: NDC, encoder subset, hierarchy, upsampling weights.

    Args:
        xyz: (N, 3) world points (= the photo's camera frame), z > 0.
        rgb: (N, 3) colours in [0, 1].
        fov_y_deg: vertical FOV of the photo's camera.
        image_size: (H, W) of the photo (sets the NDC aspect and the radius scale).
        config: the neighbourhood settings (a model's ``config.neighbourhood``).
        seed: seed of the encoder subset (reproducible features).
        while_waiting: work of the caller's that does not need the geometry, called (once, on this
            thread) where it would otherwise wait for the first farthest-point sampling, which runs in
            fpsample's worker process while this thread's k-NN search is done: one core is idle there
            (~0.15 s at 1 MP). Not called where no such wait comes (small clouds, FPS already done).
    """
    if not isinstance(config, NeighbourhoodConfig):
        raise InputError("config", f"expected a NeighbourhoodConfig, got {type(config).__name__}")
    check_shape(xyz, "xyz", (None, 3))
    check_shape(rgb, "rgb", (xyz.shape[0], 3))
    if len(image_size) != 2 or min(image_size) < 1:
        raise InputError("image_size", f"expected (H, W) >= 1, got {tuple(image_size)!r}")
    with torch.no_grad():
        xyz = xyz.detach().float()
        params = ndc_params(xyz[:, 2], fov_y_deg, image_size[1] / image_size[0])
        ndc = to_ndc(xyz, params)  # (N, 3)
        n = xyz.shape[0]
        idx = encoder_subset(n, config.max_points, seed)
        scale = radius_scale(image_size, idx.numel(), n, config.reference_points_across)
        hierarchy, coarsest = _build_hierarchy(ndc.index_select(0, idx), config, scale, while_waiting)
        up = idw_from_knn(coarsest.knn(ndc, config.upsample_k), coarsest.num_points)  # = idw_neighbours(ndc, ...)
    return SceneGeometry(xyz, rgb.detach().float(), params, idx, hierarchy, up)


__all__ = [
    "REFERENCE_POINTS_ACROSS", "NeighbourhoodConfig", "radius_scale", "PointHierarchy", "build_hierarchy",
    "SceneGeometry", "encoder_subset", "prepare_geometry",
]
