"""Viewer rendering speed without a window: preview fps while orbiting, and full-frame latency.

Measures exactly what the viewer's compute worker does for each frame
(``ViewerSession.render_view``: rasterize (+ decode through the model), then
convert and resize for display), on the bundled sample at the viewer's default
photo size, along an orbit drag of ``--frames`` camera positions:

* **preview** at each ``--preview-sizes`` long side (``render(preview=True)``,
  a point subset), reported as ms per frame and frames per second;
* **adaptive preview**: the size the viewer's adaptation settles on for a
  100 ms budget, and the fps there;
* **full frame** at the viewer's full size (``--full-size``, 768 for the
  default 1280x800 window): latency from request to display-ready image.

Both paths are measured: the plain 3D photo, and the stylized one through a
model checkpoint (``--model``; default: the trained one if present, else an
untrained lite model written to a temporary file, which costs the same time).
The machine is shared, so the load average is printed with the figures.

Run: ``python benchmarks/bench_viewer.py [--threads 1] [--frames 40]``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path
from typing import List

import torch

from app.viewer.orbit import OrbitPose, pose_camera
from app.viewer.session import DEFAULT_MODEL, SAMPLE_PHOTO, SAMPLE_STYLE, ViewerSession
from app.viewer.state import PreviewSettings, adapt_preview_long_side
from stylize3d_core.pipeline import PhotoSpec
from stylize3d_core.render.plain import frame_size


def orbit_cameras(session: ViewerSession, n: int):
    """``n`` cameras along a left-right drag with a little pitch, inside the viewer's limits."""
    info = session.info
    cams = []
    for i in range(n):
        t = i / max(1, n - 1)
        pose = OrbitPose(yaw_deg=-8.0 + 16.0 * t, pitch_deg=3.0 * (t - 0.5))
        cams.append(pose_camera(pose, info.scene, info.fov_y_deg))
    return cams


def time_frames(session: ViewerSession, cams, size, display, preview: bool, stylized: bool) -> List[float]:
    times = []
    session.render_view(cams[0], size, display, preview=preview, stylized=stylized)  # warm-up
    for cam in cams:
        t0 = time.perf_counter()
        session.render_view(cam, size, display, preview=preview, stylized=stylized)
        times.append(time.perf_counter() - t0)
    return times


def report(label: str, times: List[float]) -> None:
    med = statistics.median(times)
    p90 = sorted(times)[int(0.9 * (len(times) - 1))]
    print(f"  {label:40s} {1000 * med:7.1f} ms median  {1000 * p90:7.1f} ms p90  {1 / med:6.1f} fps")


def adaptive(session: ViewerSession, cams, display, stylized: bool) -> None:
    settings = PreviewSettings()
    side = settings.preview_long_side
    times = []
    for cam in cams:
        size = frame_size(session.info.size, side)
        t0 = time.perf_counter()
        session.render_view(cam, size, display, preview=True, stylized=stylized)
        dt = time.perf_counter() - t0
        times.append(dt)
        side = adapt_preview_long_side(side, dt, settings)
    tail = times[len(times) // 2:]
    report(f"adaptive preview (settles at {side} px)", tail)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=1, help="torch threads (the viewer's default is 1)")
    parser.add_argument("--frames", type=int, default=40, help="camera positions along the orbit")
    parser.add_argument("--max-size", type=int, default=640, help="photo long side (viewer default 640)")
    parser.add_argument("--preview-sizes", default="128,192,256,320")
    parser.add_argument("--full-size", type=int, default=768, help="full-frame long side (viewer default cap 768)")
    parser.add_argument("--model", default=None, help="checkpoint for the stylized path")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)

    with tempfile.TemporaryDirectory() as tmp:
        model = args.model or (str(DEFAULT_MODEL) if DEFAULT_MODEL.is_file() else None)
        untrained = model is None
        if untrained:
            from stylize3d_core.models.checkpoint import save_checkpoint
            from stylize3d_core.models.stylize3d import ModelConfig, Stylize3DModel

            torch.manual_seed(0)
            model = str(Path(tmp) / "untrained_lite.safetensors")
            save_checkpoint(model, Stylize3DModel(ModelConfig.lite()), 1, {"note": "benchmark only"})
        s = ViewerSession(model)
        t0 = time.perf_counter()
        info = s.load_photo(PhotoSpec(str(SAMPLE_PHOTO), "auto", max_size=args.max_size))
        t_load = time.perf_counter() - t0
        t0 = time.perf_counter()
        s.prepare_stylized()
        t_encode = time.perf_counter() - t0
        t0 = time.perf_counter()
        s.load_style(str(SAMPLE_STYLE))
        t_style = time.perf_counter() - t0
        t0 = time.perf_counter()
        s.set_strength(0.6)
        t_strength = time.perf_counter() - t0

        cams = orbit_cameras(s, args.frames)
        display = frame_size(info.size, args.full_size)
        h, w = info.size
        print(f"sample {SAMPLE_PHOTO.name}: {w}x{h}, {info.n_points:,} points; torch threads {args.threads}; "
              f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
        print(f"model: {Path(model).name}{' (untrained lite: same cost as the trained one)' if untrained else ''}")
        print(f"  build 3D photo {t_load:.2f} s, encode {t_encode:.2f} s, new style {t_style:.2f} s, "
              f"new strength {t_strength:.3f} s")
        for stylized in (False, True):
            print("stylized view" if stylized else "plain 3D photo (no trained model)")
            for side in (int(v) for v in args.preview_sizes.split(",")):
                size = frame_size(info.size, side)
                report(f"preview {size[1]}x{size[0]}", time_frames(s, cams, size, display, True, stylized))
            adaptive(s, cams, display, stylized)
            report(f"full frame {display[1]}x{display[0]}",
                   time_frames(s, cams[:: max(1, len(cams) // 5)], display, display, False, stylized))
        print(f"load average after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
