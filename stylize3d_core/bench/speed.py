"""``bench speed`` and ``bench skips``: time per frame and to the first frame against the error of each knob.

The reference is the full-quality float32 render: every point, supersample 1,
the preset's frame size, torch's default threads, the decoder's channels-last
layout. Each variant changes one knob (point budget, render resolution, supersampling, bfloat16 decoding (``StylizeSettings.bfloat16``; the
reference is float32) or a bfloat16 autocast of the style CNN, the decoder's memory layout, the
rasterizer's tensor path instead of its compiled one, threads) and is compared with the reference on the same
cameras: PSNR and the EfficientNet perceptual distance
(``eval.consistency.masked_feature_distance`` with a full mask: unit-normalised
EfficientNet-Lite0 features, stages 1..3; 0 = identical).

The full preset is the targets' case: the sample photo resized to 1 MP, frames
512 pixels on the long side, 3 cameras, median of 3 runs after one warm-up. The
scene (photo, geometry, content features, style) is built once and shared by
every variant. Variants that are an order of magnitude slower (``slow``:
bfloat16 without hardware support) are timed once, without a warm-up.

Time to first frame: a new style (style CNN + AdaAttN; the style-feature cache
is cleared first) and the first full frame (upsampling, rasterization,
decode); the photo's geometry and encoding are not in it.

:func:`choose` picks, from the rows, the fastest settings within an error
target (previews >= 30 dB, final frames >= 40 dB PSNR against the reference).

``skips``: what the caches save, measured (see ``stylize.py`` and ``scene/ldi/``).
"""

from __future__ import annotations

import contextlib
import math
import statistics
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import List, Optional, Sequence, Tuple

import numpy as np
import torch

from ..eval.timing import median_time
from ..models.decoder import native_bfloat16
from ..threads import torch_threads
from ..eval.metrics import psnr
from .report import Log, pareto_front, progress, quiet, scatter_plot, write_table


@dataclass(frozen=True)
class SpeedPreset:
    photo_size: int  # long side of the photo, pixels (when megapixels is None)
    frame_size: int  # long side of the frames
    cameras: int
    repeats: int
    warmup: int
    style_size: int
    megapixels: Optional[float] = None  # the photo resized to this many pixels (millions)


QUICK = SpeedPreset(photo_size=64, frame_size=48, cameras=1, repeats=1, warmup=0, style_size=64)
FULL = SpeedPreset(photo_size=4096, frame_size=512, cameras=3, repeats=3, warmup=1, style_size=256, megapixels=1.0)

PREVIEW_PSNR_DB = 30.0
"""Error target of previews against the full-quality float32 frame (the issue's targets)."""
FINAL_PSNR_DB = 40.0
"""Error target of final (exported) frames."""


@dataclass(frozen=True)
class Variant:
    name: str
    knob: str
    preview_points_per_pixel: Optional[float] = None  # a preview (point subset) with this budget
    scale: float = 1.0  # render at this fraction of the frame size, upscaled (bilinear) for the comparison
    supersample: int = 1
    bf16_decoder: bool = False
    bf16_style: bool = False
    channels_first: bool = False  # the decoder in NCHW (the reference is channels-last, DecoderConfig's default)
    threads: Optional[int] = None
    slow: bool = False  # timed once without a warm-up (bfloat16 emulated in software is ~10x slower)
    final_points_per_pixel: Optional[float] = None  # StylizeSettings.final_points_per_pixel of full frames
    tensor_rasterizer: bool = False  # the rasterizer's tensor path instead of its compiled one (rasterize_fast)
    runtime: str = "auto"  # StylizeSettings.decoder_runtime (the reference: ONNX Runtime where it imports)

    @property
    def setting(self) -> bool:
        """A setting a user can pick (``StylizeSettings``); the thread count, the rasterizer's path and the
        style CNN's bfloat16 are measured beside them, not offered (:func:`choose` leaves them out)."""
        return self.threads is None and not self.tensor_rasterizer and not self.bf16_style

    @property
    def final(self) -> bool:
        """Applies to final frames (exports): every knob but the render scale (a point budget is
        ``StylizeSettings.final_points_per_pixel``, the same prefix of the point order as a preview's)."""
        return self.scale == 1.0


def variants(quick: bool) -> List[Variant]:
    out = [Variant("reference (float32, all points)", "reference")]
    out += [Variant(f"preview {p:g} pts/px", "point budget", preview_points_per_pixel=p)
            for p in ((1.0,) if quick else (1.0, 2.0, 3.0, 6.0))]
    out += [Variant(f"render at {s:g}x, upscaled", "resolution", scale=s) for s in ((0.5,) if quick else (0.5, 0.75))]
    out += [Variant("supersample 2", "supersampling", supersample=2)]
    if quick:
        out += [Variant("bfloat16 decoder + style CNN", "bfloat16", bf16_decoder=True, bf16_style=True)]
    else:
        out += [Variant("bfloat16 decoder", "bfloat16", bf16_decoder=True, slow=not native_bfloat16()),
                Variant("bfloat16 style CNN", "bfloat16", bf16_style=True)]
    out += [Variant("torch decoder (channels-last), not ONNX Runtime", "decoder runtime", runtime="torch")]
    out += [Variant("channels-first (NCHW) torch decoder", "channels-last", channels_first=True, runtime="torch")]
    out += [Variant("rasterizer's tensor path (not compiled)", "rasterizer", tensor_rasterizer=True)]
    out += [Variant("1 thread", "threads", threads=1)]
    return out


def _bf16(on: bool):
    return torch.autocast("cpu", dtype=torch.bfloat16) if on else contextlib.nullcontext()


class PerceptualDistance:
    """``eval.consistency.masked_feature_distance`` of two whole images (mask everywhere)."""

    def __init__(self, stages: Sequence[int] = (1, 2, 3)) -> None:
        from ..eval.consistency import feature_extractor

        self.stages = tuple(stages)
        self.extractor = feature_extractor(self.stages)

    def features(self, rgb: np.ndarray):
        with torch.inference_mode():
            return self.extractor(torch.from_numpy(np.ascontiguousarray(rgb)).permute(2, 0, 1)[None].float())

    def __call__(self, a: np.ndarray, b: np.ndarray, b_feats=None) -> float:
        from ..eval.consistency import masked_feature_distance

        fb = b_feats if b_feats is not None else self.features(b)
        mask = torch.ones(a.shape[:2], dtype=torch.bool)
        return masked_feature_distance(self.features(a), fb, mask, self.stages)


def _resize(rgb: np.ndarray, h: int, w: int) -> np.ndarray:
    import cv2

    if rgb.shape[:2] == (h, w):
        return rgb
    return np.clip(cv2.resize(rgb, (w, h), interpolation=cv2.INTER_LINEAR), 0, 1)


@dataclass
class SpeedScene:
    """The photo, style, model and cameras a speed run uses (built once)."""

    photo3d: object
    style: np.ndarray
    checkpoint: object
    style_encoder: object
    cameras: object
    frame: Tuple[int, int]
    instance: Optional[object] = None

    @contextlib.contextmanager
    def stylized(self, supersample: int = 1, per_pixel: float = 3.0,
                 final_per_pixel: Optional[float] = None, bfloat16: bool = False, runtime: str = "auto",
                 rasterizer: str = "auto"):
        """The one ``Stylized3DPhoto`` of the scene, with these settings while the context lasts (its
        settings are read at render time, so the cached geometry and features are shared by every variant)."""
        from ..stylize import Stylized3DPhoto

        if self.instance is None:
            self.instance = Stylized3DPhoto(self.photo3d, self.checkpoint, style_encoder=self.style_encoder)
            self.instance.set_style(self.style)
        s = self.instance
        before = s.settings
        s.settings = replace(before, supersample=supersample, preview_points_per_pixel=per_pixel,
                             final_points_per_pixel=final_per_pixel, bfloat16=bfloat16, decoder_runtime=runtime,
                             rasterizer=rasterizer)
        try:
            yield s
        finally:
            s.settings = before


def speed_scene(preset: SpeedPreset, photo: Optional[str] = None, style: Optional[str] = None) -> SpeedScene:
    from ..geometry.trajectories import TrajectorySettings, make_trajectory
    from ..io.images import load_image
    from ..models.checkpoint import load_checkpoint
    from ..models.style_features import StyleEncoder
    from ..pipeline import PhotoSpec, load_photo3d
    from ..render.plain import frame_size
    from ..resources import resolve_model, sample_photo, style_image

    if preset.megapixels is not None:
        import tempfile

        from .photos import photo_at_megapixels

        with tempfile.TemporaryDirectory() as tmp:
            path = photo_at_megapixels(preset.megapixels, Path(tmp), photo)
            p3d = load_photo3d(PhotoSpec(photo=str(path), depth="prior", max_size=preset.photo_size))
    else:
        p3d = load_photo3d(PhotoSpec(photo=str(photo or sample_photo()), depth="prior", max_size=preset.photo_size))
    style_rgb = load_image(str(style or style_image()), max_size=preset.style_size).rgb
    traj = make_trajectory(TrajectorySettings(n_frames=max(8, preset.cameras * 2), fov_y_deg=p3d.fov_y_deg))
    cams = traj[:: max(1, len(traj) // preset.cameras)][: preset.cameras]
    return SpeedScene(p3d, style_rgb, load_checkpoint(resolve_model("lite")), StyleEncoder(), cams,
                      frame_size(p3d.size, preset.frame_size))


class VariantRun:
    """One variant's settings applied to the scene's shared ``Stylized3DPhoto`` (``with run:``), its two timed
    calls (:meth:`first`, :meth:`frames`) and the frames of its last call."""

    def __init__(self, scene: SpeedScene, v: Variant) -> None:
        H, W = scene.frame
        self.scene, self.v = scene, v
        self.hw = (max(1, round(H * v.scale)), max(1, round(W * v.scale)))
        self.preview = v.preview_points_per_pixel is not None
        self.cameras = [scene.cameras[i] for i in range(len(scene.cameras))]
        self.last: List[np.ndarray] = []
        self._stack: Optional[contextlib.ExitStack] = None

    def __enter__(self) -> "VariantRun":
        v = self.v
        self._stack = contextlib.ExitStack()
        self.s = self._stack.enter_context(self.scene.stylized(v.supersample, v.preview_points_per_pixel or 3.0,
                                                               v.final_points_per_pixel,
                                                               v.bf16_decoder, v.runtime,
                                                               "tensor" if v.tensor_rasterizer else "auto"))
        self._stack.enter_context(torch_threads(v.threads))  # restored when the stack closes
        self._config = self.s.model.decoder.config
        if v.channels_first:
            self.s.model.decoder.config = replace(self._config, channels_last=False)
            self.s.model.decoder.to(memory_format=torch.contiguous_format)
        return self

    def __exit__(self, *exc) -> None:
        decoder, config = self.s.model.decoder, self._config
        if self.v.channels_first:
            decoder.config = config
            decoder.to(memory_format=torch.channels_last if config.channels_last else torch.contiguous_format)
        if self.v.bf16_style:
            with torch.inference_mode():
                self.s.set_style(self.scene.style)  # leave float32 features for the next variant
        self._stack.close()

    def first(self) -> None:
        """A new style (the style CNN runs: its cache is cleared) and the first frame."""
        from ..stylize import style_feature_cache

        style_feature_cache(self.scene.style_encoder).clear()
        with _bf16(self.v.bf16_style):
            self.s.set_style(self.scene.style)
        self.s.render(self.cameras[0], *self.hw, preview=self.preview)

    def frames(self) -> None:
        self.last = [self.s.render(c, *self.hw, preview=self.preview) for c in self.cameras]

    def output(self) -> List[np.ndarray]:
        """The last frames at the reference's size (bilinear upscaling of a smaller render)."""
        H, W = self.scene.frame
        return [_resize(f, H, W) for f in self.last]


def measure_variants(scene: SpeedScene, vs: Sequence[Variant], repeats: int, warmup: int = 1,
                     show_progress: bool = False, per_round: bool = False) -> List[tuple]:
    """(frames, seconds per frame, seconds to the first frame) of each variant, timed in interleaved rounds:
    every round times each variant once, so a change of load on a shared machine hits them all alike.
    ``slow`` variants are timed in the first round only, without a warm-up. ``per_round``: each tuple
    also holds the list of seconds per frame of every round."""
    runs = [VariantRun(scene, v) for v in vs]
    first_t: List[List[float]] = [[] for _ in vs]
    frame_t: List[List[float]] = [[] for _ in vs]
    steps = [(k, i) for k in range(-1, repeats) for i in range(len(vs))]
    steps = [(k, i) for k, i in steps if not (vs[i].slow and k != 0)]  # slow: one timed round, no warm-up
    for k, i in progress(steps, len(steps), "speed", show_progress):
        with runs[i] as run:
            if k < 0:  # warm-up round (allocator, thread pool, lazy upsampling): frames always, first if asked
                if warmup:
                    run.first()
                run.frames()
                continue
            t0 = time.perf_counter()
            run.first()
            t1 = time.perf_counter()
            run.frames()
            t2 = time.perf_counter()
        first_t[i].append(t1 - t0)
        frame_t[i].append((t2 - t1) / len(run.cameras))
    return [(run.output(), statistics.median(ft), statistics.median(tt)) + ((ft,) if per_round else ())
            for run, ft, tt in zip(runs, frame_t, first_t)]


@dataclass(frozen=True)
class Choice:
    use: str  # "viewer preview", "viewer final frame", "export default"
    variant: str
    ms_per_frame: float
    psnr_db: float
    target_db: float


TIE = 1.15
"""Times within this factor of the fastest count as a tie (noise on a shared machine): the lower error wins."""


def choose(rows: Sequence[dict]) -> List[Choice]:
    """The fastest row within each use's error target: previews any knob at >= 30 dB; final frames and the
    export default a knob that applies to final frames (every knob but the render scale) at >= 40 dB.
    Rows within :data:`TIE` of the fastest count as equally fast and the one with the higher PSNR is
    chosen. Only rows that are settings (``Variant.setting``: not the thread count, the rasterizer's path or
    the style CNN's bfloat16) are chosen from; the others still show on the plot."""
    picks = []
    settable = [r for r in rows if r["setting"]]
    for use, target, final in (("viewer preview", PREVIEW_PSNR_DB, False), ("viewer final frame", FINAL_PSNR_DB, True),
                               ("export default", FINAL_PSNR_DB, True)):
        ok = [r for r in settable if _db(r["psnr_db"]) >= target and (r["knob"] != "resolution" or not final)]
        fastest = min(r["ms_per_frame"] for r in ok)  # the reference (inf dB) is always there
        best = max((r for r in ok if r["ms_per_frame"] <= TIE * fastest), key=lambda r: _db(r["psnr_db"]))
        picks.append(Choice(use, best["variant"], best["ms_per_frame"], _db(best["psnr_db"]), target))
    return picks


def _db(v) -> float:
    """A PSNR from a row or its JSON ("inf" for identical frames)."""
    return float(v)


def speed_plot(out: Path, rows: Sequence[dict]) -> Path:
    """``speed.png``: PSNR against ms per frame (log), the Pareto front in red (rows of ``speed.json`` will do)."""
    pts = [(float(r["ms_per_frame"]), min(_db(r["psnr_db"]), PSNR_CAP)) for r in rows]
    return scatter_plot(Path(out) / "speed.png", pts, [r["variant"] for r in rows], "ms per frame (log)",
                        "PSNR dB vs reference", "speed vs quality (red: Pareto front)", front=pareto_front(pts),
                        log_x=True)


def write_choices(out: Path, rows: Sequence[dict], frame: Tuple[int, int]) -> List[Choice]:
    """``speed_choices.md/json``: :func:`choose` of ``rows`` (those of ``speed.json`` will do)."""
    H, W = frame
    picks = choose(rows)
    write_table(Path(out), "speed_choices", "Settings chosen from the speed sweep", [
        {"use": c.use, "variant": c.variant, "ms_per_frame": c.ms_per_frame, "psnr_db": c.psnr_db,
         "target_db": c.target_db} for c in picks], notes=[
        f"the fastest row of speed.md at or above the target PSNR (frames {W}x{H}), times within {TIE:g}x of the "
        "fastest counting as a tie won by the higher PSNR; final frames and the export default from every knob but "
        "the render scale (a point budget: StylizeSettings.final_points_per_pixel); thread counts and the style "
        "CNN's bfloat16 are not offered as settings (the decoder's is: StylizeSettings.bfloat16)"])
    return picks


PSNR_CAP = 60.0
"""Identical frames (infinite PSNR) are plotted at this PSNR."""


def run_speed(out: Path, quick: bool = False, show_progress: bool = False, log: Log = quiet,
              photo: Optional[str] = None, style: Optional[str] = None) -> List[dict]:
    preset = QUICK if quick else FULL
    scene = speed_scene(preset, photo, style)
    dist = PerceptualDistance()
    vs = variants(quick)
    reference: List[np.ndarray] = []
    ref_feats = []
    rows = []
    for v, (frames, per_frame, ttff) in zip(vs, measure_variants(scene, vs, preset.repeats, preset.warmup,
                                                                  show_progress)):
        if not reference:
            reference, ref_feats = frames, [dist.features(f) for f in frames]
        p = float(np.mean([min(psnr(f, r), 1e9) for f, r in zip(frames, reference)]))
        d = float(np.mean([dist(f, r, fr) for f, r, fr in zip(frames, reference, ref_feats)]))
        rows.append({"variant": v.name, "knob": v.knob, "ms_per_frame": 1000 * per_frame,
                     "first_frame_s": ttff, "psnr_db": p if p < 1e9 else math.inf, "perceptual": d,
                     "finite": bool(all(np.isfinite(f).all() for f in frames)), "final": v.final, "setting": v.setting,
                     "timed_runs": 1 if v.slow else preset.repeats})
    ref_ms = rows[0]["ms_per_frame"]
    for r in rows:
        r["speedup"] = ref_ms / r["ms_per_frame"] if r["ms_per_frame"] > 0 else math.inf
    H, W = scene.frame
    pts = [(r["ms_per_frame"], min(r["psnr_db"], PSNR_CAP)) for r in rows]
    front = pareto_front(pts)
    for i, r in enumerate(rows):
        r["pareto"] = i in front
    out = Path(out)
    cols = ["variant", "knob", "ms_per_frame", "first_frame_s", "speedup", "psnr_db", "perceptual", "pareto", "finite",
            "timed_runs"]
    picks = write_choices(out, rows, (H, W))
    write_table(out, "speed", "Speed against quality", rows, cols, notes=[
        f"photo {scene.photo3d.size[1]}x{scene.photo3d.size[0]} ({len(scene.photo3d.points):,} points), "
        f"frames {W}x{H}, {len(scene.cameras)} cameras of the circle trajectory, median of {preset.repeats} "
        "run(s), the variants interleaved (each round times every variant once), after one warm-up round "
        f"({'with' if preset.warmup else 'without'} the first frame); timed_runs 1: timed in the first round "
        "only, no warm-up (too slow to repeat)" + (" (--quick preset)" if quick else ""),
        "error against the reference (full-quality float32 render): PSNR in dB (inf = identical) and the "
        "EfficientNet perceptual distance (0 = identical)",
        "first_frame_s: a new style (style CNN + AdaAttN) and the first frame; pareto: not beaten on both "
        f"ms per frame and PSNR (PSNR capped at {PSNR_CAP:g} dB)"])
    speed_plot(out, rows)
    log(f"speed: {len(rows)} variants, frames {W}x{H}; " + "; ".join(f"{c.use}: {c.variant}" for c in picks))
    return rows


# ---------------------------------------------------------------------------- skips


def run_skips(out: Path, quick: bool = False, show_progress: bool = False, log: Log = quiet,
              photo: Optional[str] = None, style: Optional[str] = None) -> List[dict]:
    """What the caches skip, measured: each row is a change, the time with and without the skip, the difference."""
    preset = QUICK if quick else FULL
    scene = speed_scene(preset, photo, style)
    cam = scene.cameras[len(scene.cameras) - 1]
    with scene.stylized() as s:
        return _skips(out, scene, s, preset, cam, log)


def _skips(out: Path, scene: SpeedScene, s, preset: SpeedPreset, cam, log: Log) -> List[dict]:
    from ..depth.types import DepthMap
    from ..scene.photo3d import Photo3D
    from ..stylize import Stylized3DPhoto, style_feature_cache

    H, W = scene.frame
    rows = []
    r = preset.repeats

    # 1. camera or strength change: no re-encoding (cached geometry + content features)
    s.set_strength(0.5)
    cached = s.render(cam, H, W)

    def strength_change() -> None:
        s.set_strength(0.5)
        s.render(cam, H, W)

    rebuilt_frame: List[np.ndarray] = []

    def rebuilt() -> None:
        fresh = Stylized3DPhoto(scene.photo3d, scene.checkpoint, s.settings, style_encoder=scene.style_encoder)
        style_feature_cache(scene.style_encoder).clear()
        fresh.set_style(scene.style)
        fresh.set_strength(0.5)
        rebuilt_frame[:] = [fresh.render(cam, H, W)]

    wu = preset.warmup
    t_skip = median_time(strength_change, r, warmup=wu)
    t_full = median_time(rebuilt, 1)  # seconds of geometry and encoding: once is enough against a frame
    diff = float(np.abs(rebuilt_frame[0] - cached).max())
    rows.append({"change": "strength only", "skip": "no re-encoding, no style CNN (stylize.py caches)",
                 "holds": True, "with_skip_s": t_skip, "without_s": t_full, "speedup": t_full / t_skip,
                 "max_abs_diff": diff})
    t_cam = median_time(lambda: s.render(cam, H, W), r, warmup=wu)
    rows.append({"change": "camera only", "skip": "no re-encoding, no upsampling (dense features cached)",
                 "holds": True, "with_skip_s": t_cam, "without_s": t_full, "speedup": t_full / t_cam,
                 "max_abs_diff": diff})
    s.set_strength(0.8)

    # 2. photo change: the style CNN's features are kept (stylize.StyleFeatureCache, shared through the encoder)
    cache = style_feature_cache(scene.style_encoder)

    def restyle(cold: bool):
        def run() -> None:
            if cold:
                cache.clear()
            s.set_style(scene.style)
        return run

    t_cold = median_time(restyle(True), r, warmup=wu)
    t_warm = median_time(restyle(False), r, warmup=1)
    cache.clear()
    s.set_style(scene.style)
    cold_frame = s.render(cam, H, W)
    s.set_style(scene.style)  # from the cache
    rows.append({"change": "photo only", "skip": "style CNN features kept across photos (stylize.StyleFeatureCache)",
                 "holds": cache.hits > 0, "with_skip_s": t_warm, "without_s": t_cold, "speedup": t_cold / t_warm,
                 "max_abs_diff": float(np.abs(s.render(cam, H, W) - cold_frame).max())})

    # 3. many points to a pixel: a preview keeps about preview_points_per_pixel per pixel (a prefix of the
    #    stratified order) instead of every point
    hp, wp = max(1, H // 2), max(1, W // 2)
    t_all = median_time(lambda: s.render(cam, hp, wp), r, warmup=wu)
    t_sub = median_time(lambda: s.render(cam, hp, wp, preview=True), r, warmup=wu)

    sub_db = psnr(s.render(cam, hp, wp, preview=True), s.render(cam, hp, wp))
    rows.append({"change": f"{len(scene.photo3d.points) / (hp * wp):.0f} points per pixel ({wp}x{hp} preview)",
                 "skip": f"a {s.settings.preview_points_per_pixel:g} points-per-pixel subset (stylize.py previews)",
                 "holds": True, "with_skip_s": t_sub, "without_s": t_all, "speedup": t_all / t_sub,
                 "max_abs_diff": float(np.abs(s.render(cam, hp, wp, preview=True) - s.render(cam, hp, wp)).max()),
                 "psnr_db": sub_db})

    # 4. points outside the view: the rasterizer culls them before any per-point work (render/rasterize.py);
    #    a camera zoomed 3x sees about 1/9 of the points
    from ..geometry.camera import Cameras

    zoomed = Cameras.create(cam.cam_to_world, np.asarray(cam.fov_y_deg) / 3.0)
    t_zoom = median_time(lambda: s.render(zoomed, H, W), r, warmup=wu)
    t_view = median_time(lambda: s.render(cam, H, W), r, warmup=wu)
    rows.append({"change": "a view 3x zoomed in (most points outside the frustum)",
                 "skip": "frustum culling in the rasterizer (every point is still projected)",
                 "holds": True, "with_skip_s": t_zoom, "without_s": t_view, "speedup": t_view / t_zoom,
                 "max_abs_diff": math.nan})

    # 3. no depth edge: the LDI's hidden-layer inpainting is skipped
    rgb = scene.photo3d.rgb
    flat = DepthMap(np.full(rgb.shape[:2], 2.0, np.float32), np.ones(rgb.shape[:2], bool), "relative", "flat")
    t_flat = median_time(lambda: Photo3D.build(rgb, flat), r, warmup=wu)
    t_edges = median_time(lambda: Photo3D.build(rgb, scene.photo3d.depth), r, warmup=wu)
    flat3d = Photo3D.build(rgb, flat)
    rows.append({"change": "photo without depth edges", "skip": "no LDI inpainting (scene/ldi/)",
                 "holds": not flat3d.ldi.inpainted, "with_skip_s": t_flat, "without_s": t_edges,
                 "speedup": t_edges / t_flat, "max_abs_diff": math.nan})
    cols = ["change", "skip", "holds", "with_skip_s", "without_s", "speedup", "max_abs_diff", "psnr_db"]
    write_table(Path(out), "skips", "Skipped work, measured", rows, cols, notes=[
        f"frames {W}x{H}; photo {rgb.shape[1]}x{rgb.shape[0]}; median of {r} run(s) (the rebuild: one run)",
        "without_s for strength / camera: a new Stylized3DPhoto (geometry, encoding, style CNN, AdaAttN) and one frame; "
        "max_abs_diff: the cached frame against the rebuilt one",
        "photo only: set_style with the style CNN's features cached (a new photo, the same style) against a cleared "
        "cache; max_abs_diff: the frames",
        "points per pixel: the preview's point subset against every point at the same size; max_abs_diff and psnr_db: "
        "that preview against the all-points frame (the difference is reported, not zero)",
        "zoomed view: the same frame size with a third of the FOV: without_s is the normal view; the decoder's "
        "cost is the same, so the difference is the rasterization of the culled points",
        "no depth edges: a flat depth map (no hidden layer) against the photo's own depth; the two clouds "
        "differ, so the time difference is what the skipped step costs on this photo"])
    log("skips: " + ", ".join(f"{x['change']} {x['speedup']:.1f}x" for x in rows))
    return rows
