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
from typing import List, Optional, Sequence

from .report import Log, progress, quiet, write_table


FULL_MEGAPIXELS = (0.25, 0.5, 1.0, 2.0, 4.0)
FULL_FRAMES = (256, 512, 1024)
QUICK_MEGAPIXELS = (0.005, 0.02)
QUICK_FRAMES = (48, 96)


def measure(megapixels: float, frames: Sequence[int], photo: Optional[str] = None, repeats: int = 1) -> List[dict]:
    """Run in a fresh process: one photo size, every frame size; rows with seconds (median of ``repeats``
    after one warm-up) and peak memory."""
    import numpy as np

    from ..eval.timing import median_time, peak_rss_gib
    from ..models.checkpoint import load_checkpoint
    from ..pipeline import PhotoSpec, load_photo3d
    from ..render.plain import PlainRenderer
    from ..resources import resolve_model, style_image
    from ..io.images import load_image
    from ..stylize import Stylized3DPhoto
    from ..geometry.camera import Cameras
    from .photos import photo_at_megapixels

    import open3d.core  # noqa: F401 (the geometry's k-NN; imported before the clock starts, once per process)

    with tempfile.TemporaryDirectory() as tmp:
        path = photo_at_megapixels(megapixels, Path(tmp), photo)
        t0 = time.perf_counter()
        p3d = load_photo3d(PhotoSpec(photo=str(path), depth="prior", max_size=8192))
        t_photo = time.perf_counter() - t0
    t0 = time.perf_counter()
    s = Stylized3DPhoto(p3d, load_checkpoint(resolve_model("lite")))
    s.set_style(load_image(str(style_image()), max_size=256).rgb)
    t_model = time.perf_counter() - t0
    plain = PlainRenderer(p3d.points)
    cam = Cameras.create(np.array([[1, 0, 0, 0.02], [0, 1, 0, 0], [0, 0, 1, 0.02], [0, 0, 0, 1.0]]), p3d.fov_y_deg)
    h, w = p3d.size
    rows = []
    for f in frames:
        t_plain = median_time(lambda: plain.render(cam, f, f), repeats, warmup=1)
        t_styl = median_time(lambda: s.render(cam, f, f), repeats, warmup=1)
        rows.append({"photo_mp": round(h * w / 1e6, 3), "photo": f"{w}x{h}",
                     "points": len(p3d.points), "frame": f"{f}x{f}", "photo3d_s": t_photo,
                     "model_s": t_model, "geometry_s": s.timings["geometry"], "encode_s": s.timings["encode"],
                     "plain_ms": 1000 * t_plain, "stylized_ms": 1000 * t_styl,
                     "stylized_ns_per_point": 1e9 * t_styl / len(p3d.points), "peak_rss_gib": peak_rss_gib()})
    return rows


def run_scaling(out: Path, quick: bool = False, show_progress: bool = False, log: Log = quiet,
                photo: Optional[str] = None) -> List[dict]:
    mps, frames = (QUICK_MEGAPIXELS, QUICK_FRAMES) if quick else (FULL_MEGAPIXELS, FULL_FRAMES)
    rows: List[dict] = []
    root = Path(__file__).resolve().parents[2]
    for mp in progress(list(mps), len(mps), "scaling", show_progress):
        cmd = [sys.executable, "-m", "stylize3d_core.bench.scaling", str(mp), ",".join(map(str, frames)),
               "1" if quick else "3"] + ([str(photo)] if photo else [])
        done = subprocess.run(cmd, capture_output=True, text=True, cwd=root)
        if done.returncode != 0:
            rows.append({"photo_mp": mp, "photo": "failed", "points": 0, "frame": "-", "photo3d_s": math.nan,
                         "model_s": math.nan, "geometry_s": math.nan, "encode_s": math.nan, "plain_ms": math.nan,
                         "stylized_ms": math.nan, "stylized_ns_per_point": math.nan, "peak_rss_gib": math.nan,
                         "error": done.stderr.strip().splitlines()[-1:]})
        else:
            rows.extend(json.loads(done.stdout.strip().splitlines()[-1]))
        _write(Path(out), rows, quick)  # after every photo size: a long run stopped early keeps what it measured
    log(f"scaling: {len(rows)} rows")
    return rows


def _write(out: Path, rows: List[dict], quick: bool) -> None:
    cols = ["photo_mp", "photo", "points", "frame", "photo3d_s", "model_s", "geometry_s", "encode_s", "plain_ms",
            "stylized_ms", "stylized_ns_per_point", "peak_rss_gib"]
    growth = growth_notes(rows)
    ok = [r for r in rows if r["photo"] != "failed"]
    out.mkdir(parents=True, exist_ok=True)
    if ok:
        from .report import scatter_plot

        pts = [(r["points"] / 1e6, r["stylized_ms"]) for r in ok]
        scatter_plot(out / "scaling.png", pts, [f"{r['photo_mp']:g} MP {r['frame']}" for r in ok],
                     "points (millions)", "stylized ms per frame", "scaling: time per frame vs points")
        last = {r["photo_mp"]: r for r in ok}.values()  # a process's peak: after its largest frame
        scatter_plot(out / "scaling_memory.png", [(r["points"] / 1e6, r["peak_rss_gib"]) for r in last],
                     [f"{r['photo_mp']:g} MP" for r in last], "points (millions)", "peak GiB",
                     "scaling: peak memory vs points")
    failed = [f"{r['photo_mp']:g} MP failed: {' '.join(r.get('error') or [])}" for r in rows if r["photo"] == "failed"]
    write_table(out, "scaling", "Scaling with photo and frame size", rows, cols, notes=failed + growth + [
        "each photo size in a fresh process (peak_rss_gib is that process's peak, all frame sizes included); "
        "photo3d_s: read + prior depth + LDI + points; model_s: geometry + encoding + style (open3d.core "
        "imported before); "
        f"{'one timed render' if quick else 'median of 3 renders'} after one warm-up per frame size"
        + (" (--quick preset)" if quick else "")])


def growth_notes(rows: Sequence[dict]) -> List[str]:
    """For each frame size, how the frame time and the peak memory grow against the points
    (``x`` times the points, ``y`` times the time: linear when ``y`` is about ``x``)."""
    notes = []
    ok = [r for r in rows if r["photo"] != "failed"]
    for frame in dict.fromkeys(r["frame"] for r in ok):
        rs = sorted((r for r in ok if r["frame"] == frame), key=lambda r: r["points"])
        if len(rs) < 2:
            continue
        a, b = rs[0], rs[-1]
        notes.append(f"{frame}: {b['points'] / a['points']:.1f}x the points -> {b['plain_ms'] / a['plain_ms']:.1f}x "
                     f"plain time, {b['stylized_ms'] / a['stylized_ms']:.1f}x stylized time")
    if len(ok) >= 2:
        a, b = min(ok, key=lambda r: r["points"]), max(ok, key=lambda r: r["points"])
        notes.append(f"{b['points'] / a['points']:.1f}x the points -> {b['model_s'] / a['model_s']:.1f}x model "
                     f"(geometry + encoding + style) time, {b['peak_rss_gib'] / a['peak_rss_gib']:.1f}x peak memory")
    return notes


if __name__ == "__main__":
    args = sys.argv[1:]
    result = measure(float(args[0]), [int(x) for x in args[1].split(",")], args[3] if len(args) > 3 else None,
                     repeats=int(args[2]))
    print(json.dumps(result))
