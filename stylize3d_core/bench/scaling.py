"""``bench scaling``: time and peak memory against the photo's size (0.25-4 MP) and the frame size (256²-1024²).

Each photo size runs in a fresh process (``python -m stylize3d_core.bench.scaling``)
so its peak resident memory (``eval.timing.peak_rss_gib``) is its own: the
sample photo is resized to the target pixel count, given the built-in prior's
depth, lifted to 3D (``load_photo3d``), encoded (``Stylized3DPhoto``) and
rendered at each square frame size (plain and stylized).
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable, List, Optional, Sequence

from .report import write_table

Log = Callable[[str], None]

FULL_MEGAPIXELS = (0.25, 0.5, 1.0, 2.0, 4.0)
FULL_FRAMES = (256, 512, 1024)
QUICK_MEGAPIXELS = (0.005, 0.02)
QUICK_FRAMES = (48, 96)


def _quiet(_: str) -> None:
    return None


def measure(megapixels: float, frames: Sequence[int], photo: Optional[str] = None) -> List[dict]:
    """Run in a fresh process: one photo size, every frame size; rows with seconds and peak memory."""
    import cv2
    import numpy as np

    from ..eval.timing import median_time, peak_rss_gib
    from ..io.images import load_image, save_image
    from ..models.checkpoint import load_checkpoint
    from ..pipeline import PhotoSpec, load_photo3d
    from ..render.plain import PlainRenderer
    from ..resources import resolve_model, sample_photo, style_image
    from ..stylize import Stylized3DPhoto
    from ..geometry.camera import Cameras

    rgb = load_image(str(photo or sample_photo()), max_size=8192).rgb
    h, w = rgb.shape[:2]
    scale = math.sqrt(megapixels * 1e6 / (h * w))
    size = (max(16, round(w * scale)), max(16, round(h * scale)))
    big = cv2.resize(rgb, size, interpolation=cv2.INTER_CUBIC if scale > 1 else cv2.INTER_AREA)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "photo.png"
        save_image(path, np.clip(big, 0, 1))
        t0 = time.perf_counter()
        p3d = load_photo3d(PhotoSpec(photo=str(path), depth="prior", max_size=8192))
        t_photo = time.perf_counter() - t0
    t0 = time.perf_counter()
    s = Stylized3DPhoto(p3d, load_checkpoint(resolve_model("lite")))
    s.set_style(load_image(str(style_image()), max_size=256).rgb)
    t_model = time.perf_counter() - t0
    plain = PlainRenderer(p3d.points)
    cam = Cameras.create(np.array([[1, 0, 0, 0.02], [0, 1, 0, 0], [0, 0, 1, 0.02], [0, 0, 0, 1.0]]), p3d.fov_y_deg)
    rows = []
    for f in frames:
        t_plain = median_time(lambda: plain.render(cam, f, f), 1, warmup=1)
        t_styl = median_time(lambda: s.render(cam, f, f), 1, warmup=1)
        rows.append({"photo_mp": round(h * w * scale * scale / 1e6, 3), "photo": f"{size[0]}x{size[1]}",
                     "points": len(p3d.points), "frame": f"{f}x{f}", "photo3d_s": t_photo,
                     "model_s": t_model, "plain_ms": 1000 * t_plain, "stylized_ms": 1000 * t_styl,
                     "peak_rss_gib": peak_rss_gib()})
    return rows


def run_scaling(out: Path, quick: bool = False, show_progress: bool = False, log: Log = _quiet,
                photo: Optional[str] = None) -> List[dict]:
    from .suites import progress

    mps, frames = (QUICK_MEGAPIXELS, QUICK_FRAMES) if quick else (FULL_MEGAPIXELS, FULL_FRAMES)
    rows: List[dict] = []
    root = Path(__file__).resolve().parents[2]
    for mp in progress(list(mps), len(mps), "scaling", show_progress):
        cmd = [sys.executable, "-m", "stylize3d_core.bench.scaling", str(mp), ",".join(map(str, frames))]
        if photo:
            cmd.append(str(photo))
        done = subprocess.run(cmd, capture_output=True, text=True, cwd=root)
        if done.returncode != 0:
            rows.append({"photo_mp": mp, "photo": "failed", "points": 0, "frame": "-", "photo3d_s": math.nan,
                         "model_s": math.nan, "plain_ms": math.nan, "stylized_ms": math.nan,
                         "peak_rss_gib": math.nan, "error": done.stderr.strip().splitlines()[-1:]})
            continue
        rows.extend(json.loads(done.stdout.strip().splitlines()[-1]))
    cols = ["photo_mp", "photo", "points", "frame", "photo3d_s", "model_s", "plain_ms", "stylized_ms",
            "peak_rss_gib"]
    write_table(Path(out), "scaling", "Scaling with photo and frame size", rows, cols, notes=[
        "each photo size in a fresh process (peak_rss_gib is that process's peak, all frame sizes included); "
        "photo3d_s: read + prior depth + LDI + points; model_s: geometry + encoding + style; one timed render "
        "after one warm-up per frame size" + (" (--quick preset)" if quick else "")])
    log(f"scaling: {len(rows)} rows")
    return rows


if __name__ == "__main__":
    args = sys.argv[1:]
    result = measure(float(args[0]), [int(x) for x in args[1].split(",")], args[2] if len(args) > 2 else None)
    print(json.dumps(result))
