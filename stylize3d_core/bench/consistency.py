"""``bench consistency``: the paper's consistency table for ours, plain, the per-frame 2D baseline and
stylize-then-bake, with the style distance and the sharpness beside each.

Consistency (``eval/consistency.py``): view ``i`` warped into view ``j`` through
the point cloud; RMSE and the masked EfficientNet feature distance over the
co-visible pixels, for short-range pairs (adjacent frames) and long-range pairs
(7 apart). Style distance (``models.losses.style_distance``): the frames'
feature statistics against the style image's (lower = closer to the style; the
plain frames are the photo's distance). Sharpness: the standard deviation of the
Laplacian of the grey frame (higher = sharper), mean over frames.

Stylize-then-bake: the stylized views of ``export.bake.bake_cameras`` baked onto
the points (``export.bake.bake_colours``), then rendered plainly: consistent by
construction, the blur of baking is what the sharpness column shows.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Dict, List, Optional

import numpy as np
import torch

from ..eval.colour_stats import sharpness  # noqa: F401 (also this module's public name)
from ..errors import InputError
from .report import Log, progress, quiet, write_table


@dataclass(frozen=True)
class ConsistencyPreset:
    photo_size: int
    frame_size: int
    trajectory_frames: int  # the circle's length (adjacent frames as far apart as in a video of this length)
    frames: int  # the first frames of it that are rendered


QUICK = ConsistencyPreset(photo_size=96, frame_size=64, trajectory_frames=90, frames=9)
FULL = ConsistencyPreset(photo_size=512, frame_size=256, trajectory_frames=90, frames=30)


SMOOTHING = 0.5
"""Weight of the previous smoothed frame in the temporally smoothed 2D baseline."""


def temporal_smoothing(frames: List[np.ndarray], keep: float) -> List[np.ndarray]:
    """An exponential moving average over frames in order: ``s_t = keep * s_(t-1) + (1 - keep) * f_t``
    (no warping: the plain temporal filter a per-frame method can add)."""
    if not 0.0 <= keep < 1.0:
        raise InputError("temporal smoothing", f"keep must be in [0, 1), got {keep!r}")
    out: List[np.ndarray] = []
    for f in frames:
        out.append(f.copy() if not out else (keep * out[-1] + (1.0 - keep) * f).astype(f.dtype))
    return out


def run_consistency(out: Path, quick: bool = False, show_progress: bool = False, log: Log = quiet,
                    photo: Optional[str] = None, style: Optional[str] = None) -> List[dict]:
    from ..eval.baseline import baseline_frames
    from ..eval.consistency import consistency_metrics, long_range_pairs, short_range_pairs
    from ..export.bake import bake_cameras, bake_colours
    from ..geometry.trajectories import TrajectorySettings, make_trajectory
    from ..io.images import load_image
    from ..models.checkpoint import load_checkpoint
    from ..models.losses import style_distance
    from ..pipeline import PhotoSpec, load_photo3d
    from ..render.plain import PlainRenderer, frame_size
    from ..resources import resolve_model, sample_photo, style_image
    from ..stylize import Stylized3DPhoto
    preset = QUICK if quick else FULL
    p3d = load_photo3d(PhotoSpec(photo=str(photo or sample_photo()), depth="prior", max_size=preset.photo_size))
    style_rgb = load_image(str(style or style_image()), max_size=256).rgb
    cams = make_trajectory(TrajectorySettings(n_frames=preset.trajectory_frames, fov_y_deg=p3d.fov_y_deg))
    cams = cams[: preset.frames]
    H, W = frame_size(p3d.size, preset.frame_size)
    ours = Stylized3DPhoto(p3d, load_checkpoint(resolve_model("lite")))
    ours.set_style(style_rgb)
    plain = PlainRenderer(p3d.points)

    def baked() -> List[np.ndarray]:
        from dataclasses import replace

        colours = bake_colours(p3d.points.xyz, ours.render, bake_cameras(p3d.fov_y_deg), (H, W)).rgb
        renderer = PlainRenderer(replace(p3d.points, rgb=colours.astype(np.float32)))
        return list(renderer.frames(cams, H, W))

    per_frame: List[np.ndarray] = []

    def baseline() -> List[np.ndarray]:
        per_frame[:] = baseline_frames(p3d, cams, H, W, style_rgb)
        return list(per_frame)

    methods: Dict[str, Callable[[], List[np.ndarray]]] = {
        "ours": lambda: list(ours.frames(cams, H, W)),
        "plain (no style)": lambda: list(plain.frames(cams, H, W)),
        "2D baseline per frame": baseline,
        f"2D baseline + temporal smoothing (EMA {SMOOTHING:g})": lambda: temporal_smoothing(per_frame, SMOOTHING),
        "stylize then bake": baked,
    }
    xyz = torch.from_numpy(p3d.points.xyz)
    style_t = torch.from_numpy(np.ascontiguousarray(style_rgb)).permute(2, 0, 1)[None]
    short, long_ = short_range_pairs(len(cams)), long_range_pairs(len(cams))
    rows = []
    for name, render in progress(list(methods.items()), len(methods), "consistency", show_progress):
        frames = render()
        s = consistency_metrics(xyz, frames, cams, short)
        lg = consistency_metrics(xyz, frames, cams, long_)
        with torch.inference_mode():
            batch = torch.from_numpy(np.stack(frames)).permute(0, 3, 1, 2).contiguous()
            sd = float(style_distance(batch, style_t).mean())
        rows.append({"method": name, "short_rmse": s.rmse, "short_feature": s.feature_distance,
                     "long_rmse": lg.rmse, "long_feature": lg.feature_distance, "style_distance": sd,
                     "sharpness": float(np.mean([sharpness(f) for f in frames]))})
    write_table(Path(out), "consistency", "Consistency (paper Sec. 4.2)", rows, notes=[
        f"photo {p3d.size[1]}x{p3d.size[0]}, frames {W}x{H}: the first {len(cams)} cameras of a "
        f"{preset.trajectory_frames}-frame circle" + (" (--quick preset)" if quick else ""),
        "short: adjacent frames; long: 7 frames apart; RMSE of colours in [0, 1] and the masked "
        "EfficientNet feature distance over co-visible pixels (lower = more consistent)",
        "style_distance: feature statistics against the style image (lower = closer); sharpness: std of "
        "the Laplacian (higher = sharper)",
        f"temporal smoothing: the per-frame 2D baseline's frames averaged over time (s_t = {SMOOTHING:g} s_t-1 + "
        f"{1 - SMOOTHING:g} f_t, no warping)"])
    log(f"consistency: {len(rows)} methods, {len(cams)} frames {W}x{H}")
    return rows
