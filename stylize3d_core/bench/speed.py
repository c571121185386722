"""``bench speed`` and ``bench skips``: time per frame and to the first frame against the error of each knob.

The reference is the full-quality float32 render: every point, supersample 1,
the preset's frame size, torch's default threads. Each variant changes one knob
(point budget, render resolution, supersampling, bfloat16 autocast of the
decoder / the style CNN, channels-last decoder weights, threads) and is
compared with the reference on the same cameras: PSNR and the EfficientNet
perceptual distance (``eval.consistency.masked_feature_distance`` with a full
mask: unit-normalised EfficientNet-Lite0 features, stages 1..3; 0 = identical).

Time to first frame: a new style (style CNN + AdaAttN) and the first full frame
(upsampling, rasterization, decode); the photo's geometry and encoding are not in it.

``skips``: what the caches save, measured (see ``stylize.py`` and ``scene/ldi.py``).
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, List, Optional, Sequence, Tuple

import numpy as np
import torch

from ..eval.timing import median_time
from .report import pareto_front, scatter_plot, write_table

Log = Callable[[str], None]


def _quiet(_: str) -> None:
    return None


@dataclass(frozen=True)
class SpeedPreset:
    photo_size: int  # long side of the photo, pixels
    frame_size: int  # long side of the frames
    cameras: int
    repeats: int
    warmup: int
    style_size: int


QUICK = SpeedPreset(photo_size=64, frame_size=48, cameras=1, repeats=1, warmup=0, style_size=64)
FULL = SpeedPreset(photo_size=512, frame_size=384, cameras=4, repeats=3, warmup=1, style_size=256)


@dataclass(frozen=True)
class Variant:
    name: str
    knob: str
    preview_points_per_pixel: Optional[float] = None  # a preview (point subset) with this budget
    scale: float = 1.0  # render at this fraction of the frame size, upscaled (bilinear) for the comparison
    supersample: int = 1
    bf16_decoder: bool = False
    bf16_style: bool = False
    channels_last: bool = False
    threads: Optional[int] = None


def variants(quick: bool) -> List[Variant]:
    out = [Variant("reference (float32, all points)", "reference")]
    out += [Variant(f"preview {p:g} pts/px", "point budget", preview_points_per_pixel=p)
            for p in ((1.0,) if quick else (0.5, 1.0, 2.0, 3.0, 6.0))]
    out += [Variant(f"render at {s:g}x, upscaled", "resolution", scale=s) for s in ((0.5,) if quick else (0.5, 0.75))]
    out += [Variant("supersample 2", "supersampling", supersample=2)]
    if not quick:
        out += [Variant("bfloat16 decoder", "bfloat16", bf16_decoder=True),
                Variant("bfloat16 style CNN", "bfloat16", bf16_style=True)]
    out += [Variant("bfloat16 decoder + style CNN", "bfloat16", bf16_decoder=True, bf16_style=True),
            Variant("channels-last decoder", "channels-last", channels_last=True)]
    out += [Variant(f"{t} thread{'s' if t > 1 else ''}", "threads", threads=t) for t in ((1,) if quick else (1, 2, 4))]
    return out


def _bf16(on: bool):
    return torch.autocast("cpu", dtype=torch.bfloat16) if on else contextlib.nullcontext()


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return math.inf if mse == 0 else 10.0 * math.log10(1.0 / mse)


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
    def stylized(self, supersample: int = 1, per_pixel: float = 3.0):
        """The one ``Stylized3DPhoto`` of the scene, with these settings while the context lasts (its
        settings are read at render time, so the cached geometry and features are shared by every variant)."""
        from ..stylize import Stylized3DPhoto

        if self.instance is None:
            self.instance = Stylized3DPhoto(self.photo3d, self.checkpoint, style_encoder=self.style_encoder)
            self.instance.set_style(self.style)
        s = self.instance
        before = s.settings
        s.settings = replace(before, supersample=supersample, preview_points_per_pixel=per_pixel)
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

    p3d = load_photo3d(PhotoSpec(photo=str(photo or sample_photo()), depth="prior", max_size=preset.photo_size))
    style_rgb = load_image(str(style or style_image()), max_size=preset.style_size).rgb
    traj = make_trajectory(TrajectorySettings(n_frames=max(8, preset.cameras * 2), fov_y_deg=p3d.fov_y_deg))
    cams = traj[:: max(1, len(traj) // preset.cameras)][: preset.cameras]
    return SpeedScene(p3d, style_rgb, load_checkpoint(resolve_model("lite")), StyleEncoder(), cams,
                      frame_size(p3d.size, preset.frame_size))


def measure_variant(scene: SpeedScene, v: Variant, repeats: int, warmup: int = 1) -> Tuple[List[np.ndarray], float, float]:
    """(frames, seconds per frame, seconds to the first frame) of one variant."""
    H, W = scene.frame
    h, w = max(1, round(H * v.scale)), max(1, round(W * v.scale))
    preview = v.preview_points_per_pixel is not None
    with scene.stylized(v.supersample, v.preview_points_per_pixel or 3.0) as s:
        return _measure(scene, s, v, (h, w), preview, repeats, warmup)


def _measure(scene: SpeedScene, s, v: Variant, hw: Tuple[int, int], preview: bool, repeats: int,
             warmup: int) -> Tuple[List[np.ndarray], float, float]:
    H, W = scene.frame
    h, w = hw
    threads = torch.get_num_threads()
    decoder = s.model.decoder
    try:
        if v.threads is not None:
            torch.set_num_threads(v.threads)
        if v.channels_last:
            decoder.to(memory_format=torch.channels_last)

        def first() -> None:
            with _bf16(v.bf16_style):
                s.set_style(scene.style)
            with _bf16(v.bf16_decoder):
                s.render(scene.cameras[0], h, w, preview=preview)

        def frames() -> List[np.ndarray]:
            with _bf16(v.bf16_decoder):
                return [s.render(scene.cameras[i], h, w, preview=preview) for i in range(len(scene.cameras))]

        ttff = median_time(first, repeats, warmup=warmup)
        # frames are cheap: always warm up once (allocator, thread pool), even in --quick
        per_frame = median_time(frames, repeats, warmup=max(1, warmup)) / len(scene.cameras)
        out = [_resize(f, H, W) for f in frames()]
    finally:
        torch.set_num_threads(threads)
        if v.channels_last:
            decoder.to(memory_format=torch.contiguous_format)
        with torch.inference_mode():
            s.set_style(scene.style)  # leave float32 features for the next variant
    return out, per_frame, ttff


PSNR_CAP = 60.0
"""Identical frames (infinite PSNR) are plotted at this PSNR."""


def run_speed(out: Path, quick: bool = False, show_progress: bool = False, log: Log = _quiet,
              photo: Optional[str] = None, style: Optional[str] = None) -> List[dict]:
    from .suites import progress

    preset = QUICK if quick else FULL
    scene = speed_scene(preset, photo, style)
    dist = PerceptualDistance()
    vs = variants(quick)
    reference: List[np.ndarray] = []
    ref_feats = []
    rows = []
    for v in progress(vs, len(vs), "speed", show_progress):
        frames, per_frame, ttff = measure_variant(scene, v, preset.repeats, preset.warmup)
        if not reference:
            reference, ref_feats = frames, [dist.features(f) for f in frames]
        p = float(np.mean([min(psnr(f, r), 1e9) for f, r in zip(frames, reference)]))
        d = float(np.mean([dist(f, r, fr) for f, r, fr in zip(frames, reference, ref_feats)]))
        rows.append({"variant": v.name, "knob": v.knob, "ms_per_frame": 1000 * per_frame,
                     "first_frame_s": ttff, "psnr_db": p if p < 1e9 else math.inf, "perceptual": d,
                     "finite": bool(all(np.isfinite(f).all() for f in frames))})
    ref_ms = rows[0]["ms_per_frame"]
    for r in rows:
        r["speedup"] = ref_ms / r["ms_per_frame"] if r["ms_per_frame"] > 0 else math.inf
    H, W = scene.frame
    pts = [(r["ms_per_frame"], min(r["psnr_db"], PSNR_CAP)) for r in rows]
    front = pareto_front(pts)
    for i, r in enumerate(rows):
        r["pareto"] = i in front
    out = Path(out)
    cols = ["variant", "knob", "ms_per_frame", "first_frame_s", "speedup", "psnr_db", "perceptual", "pareto", "finite"]
    write_table(out, "speed", "Speed against quality", rows, cols, notes=[
        f"photo {scene.photo3d.size[1]}x{scene.photo3d.size[0]} ({len(scene.photo3d.points):,} points), "
        f"frames {W}x{H}, {len(scene.cameras)} cameras of the circle trajectory, median of {preset.repeats} "
        f"run(s) after {max(1, preset.warmup)} warm-up(s) ({preset.warmup} for the first frame)" + (" (--quick preset)" if quick else ""),
        "error against the reference (full-quality float32 render): PSNR in dB (inf = identical) and the "
        "EfficientNet perceptual distance (0 = identical)",
        "first_frame_s: a new style (style CNN + AdaAttN) and the first frame; pareto: not beaten on both "
        f"ms per frame and PSNR (PSNR capped at {PSNR_CAP:g} dB)"])
    scatter_plot(out / "speed.png", pts, [r["variant"] for r in rows], "ms per frame", "PSNR dB vs reference",
                 "speed vs quality (red: Pareto front)", front=front)
    log(f"speed: {len(rows)} variants, frames {W}x{H}")
    return rows


# ---------------------------------------------------------------------------- skips


def run_skips(out: Path, quick: bool = False, show_progress: bool = False, log: Log = _quiet,
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
    from ..stylize import Stylized3DPhoto

    H, W = scene.frame
    rows = []
    r = preset.repeats

    # 1. camera or strength change: no re-encoding (cached geometry + content features)
    s.set_strength(0.5)
    cached = s.render(cam, H, W)

    def strength_change() -> None:
        s.set_strength(0.5)
        s.render(cam, H, W)

    def rebuilt() -> np.ndarray:
        fresh = Stylized3DPhoto(scene.photo3d, scene.checkpoint, style_encoder=scene.style_encoder)
        fresh.set_style(scene.style)
        fresh.set_strength(0.5)
        return fresh.render(cam, H, W)

    wu = preset.warmup
    t_skip = median_time(strength_change, r, warmup=wu)
    t_full = median_time(rebuilt, r)
    diff = float(np.abs(rebuilt() - cached).max())
    rows.append({"change": "strength only", "skip": "no re-encoding, no style CNN (stylize.py caches)",
                 "holds": True, "with_skip_s": t_skip, "without_s": t_full, "speedup": t_full / t_skip,
                 "max_abs_diff": diff})
    t_cam = median_time(lambda: s.render(cam, H, W), r, warmup=wu)
    rows.append({"change": "camera only", "skip": "no re-encoding, no upsampling (dense features cached)",
                 "holds": True, "with_skip_s": t_cam, "without_s": t_full, "speedup": t_full / t_cam,
                 "max_abs_diff": diff})
    s.set_strength(0.8)

    # 2. photo change: are the style features kept? Stylized3DPhoto is one instance per photo, so set_style runs
    #    the style CNN again; measure what keeping its maps would save
    with torch.inference_mode():
        t_cnn = median_time(lambda: scene.style_encoder(_style_tensor(scene.style)), r, warmup=wu)
    t_set = median_time(lambda: s.set_style(scene.style), r, warmup=wu)
    rows.append({"change": "photo only", "skip": "style CNN features kept across photos", "holds": False,
                 "with_skip_s": t_set - t_cnn, "without_s": t_set, "speedup": t_set / max(t_set - t_cnn, 1e-9),
                 "max_abs_diff": 0.0})

    # 3. no depth edge: the LDI's hidden-layer inpainting is skipped
    rgb = scene.photo3d.rgb
    flat = DepthMap(np.full(rgb.shape[:2], 2.0, np.float32), np.ones(rgb.shape[:2], bool), "relative", "flat")
    t_flat = median_time(lambda: Photo3D.build(rgb, flat), r, warmup=wu)
    t_edges = median_time(lambda: Photo3D.build(rgb, scene.photo3d.depth), r, warmup=wu)
    flat3d = Photo3D.build(rgb, flat)
    rows.append({"change": "photo without depth edges", "skip": "no LDI inpainting (scene/ldi.py)",
                 "holds": not flat3d.ldi.inpainted, "with_skip_s": t_flat, "without_s": t_edges,
                 "speedup": t_edges / t_flat, "max_abs_diff": 0.0})
    write_table(Path(out), "skips", "Skipped work, measured", rows, notes=[
        f"frames {W}x{H}; photo {rgb.shape[1]}x{rgb.shape[0]}; median of {r} run(s)",
        "without_s for strength / camera: a new Stylized3DPhoto (geometry, encoding, style) and one frame; "
        "max_abs_diff: the cached frame against the rebuilt one",
        "photo only: the style CNN's share of set_style, which a new photo repeats (not cached across instances)",
        "no depth edges: a flat depth map (no hidden layer) against the photo's own depth; the two clouds "
        "differ, so the time difference is what the skipped step costs on this photo"])
    log("skips: " + ", ".join(f"{x['change']} {x['speedup']:.1f}x" for x in rows))
    return rows


def _style_tensor(rgb: np.ndarray) -> torch.Tensor:
    from ..stylize import style_tensor

    return style_tensor(rgb)
