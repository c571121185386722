"""Viewer rendering speed without a window: preview fps while orbiting, and full-frame latency.

Measures exactly what the viewer's compute worker does for each frame
(``ViewerSession.render_view``: rasterize (+ decode through the model), then
convert and resize for display), on the bundled sample at the viewer's default
photo size, along an orbit drag of ``--frames`` camera positions:

* **preview** at each ``--preview-sizes`` long side (``render(preview=True)``,
  a point subset), reported as ms per frame and frames per second;
* **adaptive preview**: the size the viewer's adaptation settles on for a
  35 ms budget (``PreviewSettings.target_preview_s``), and the fps there;
* **full frame** at the viewer's full size (``--full-size``, 768 for the
  default 1280x800 window): latency from request to display-ready image.

* **interactive** (``--interactive``): the live view's own machinery without a
  window -- :class:`~stylize3d_app.viewer.worker.ComputeWorker`, the render state machine
  (:mod:`stylize3d_app.viewer.render_state`) and the preview-size adaptation -- driven by
  a simulated drag of mouse moves at 60 Hz on a photo of ``--megapixels`` (the
  sample upscaled; default 1 MP), once as the viewer opens it (``--max-size``,
  default 640) and once at its full size, through the stylized path. It reports the
  frames per second delivered while dragging (what the window would show, less
  its own redraw), the latency from mouse-down to the first new frame (also for
  a second drag started 0.3 s after the first, while the first rest's full frame
  renders), the time from rest to the first full-quality frame (the first
  level of a progressive full frame) and to the full-size one, and the colour
  jump between the last preview and the full frame (mean absolute per-channel
  difference of the means, in 8-bit levels, and mean absolute pixel
  difference). The current settings and the previous ones (``BASELINE``) run
  interleaved, ``--repeats`` drag pairs each, so their ratio is measured under
  the same machine load.

* **window** (``--window``): the viewer itself, in its own process on a private
  Xvfb, with the shipped model, on a photo of ``--megapixels`` (the sample
  upscaled; default 1 MP) opened as a user opens it (``--max-size``, the
  viewer's default 640, or 0 for the whole photo), driven with real XTest mouse
  events: ``--repeats`` pairs of 1.5 s drags (mouse moves of 2 px every 1/60 s:
  180 px, right then back, inside the photo's yaw range, whose limit a drag reaches
  after 200 px), the second one 0.3 s after the first, then a 3 s rest. From the window's own frame
  log it reports the frames per second shown while dragging, the latency from
  the XTest mouse-down to the first new frame on screen (first drag; second drag,
  while the first rest's full frame renders), the time from the mouse-up to the
  first full-quality frame (which size) and to the full-size frame, and the colour
  jump between the last preview shown and the full-quality frame that replaces
  it (mean absolute difference of the mean colours, and mean pixel difference, in
  8-bit levels). These are the four figures of issue 13's "Done when".

Both paths are measured: the plain 3D photo, and the stylized one through a
model checkpoint (``--model``; default: the trained one if present, else an
untrained lite model written to a temporary file, which costs the same time).
The machine is shared, so the load average is printed with the figures.

Run: ``python tests/benchmarks/bench_viewer.py [--threads 1] [--frames 40]`` or
``python tests/benchmarks/bench_viewer.py --interactive [--megapixels 1.0] [--repeats 2]`` or
``python tests/benchmarks/bench_viewer.py --window [--max-size 640] [--repeats 2] [--render-backend opengl|vulkan]
[--save-report report.json]`` (needs Xvfb and libXtst;
it measures the checkout it is in).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path
from typing import List

import torch

from stylize3d_app.viewer.backend import BACKENDS, DEFAULT_BACKEND
from stylize3d_app.viewer.orbit import OrbitPose, pose_camera
from stylize3d_app.viewer.session import DEFAULT_MODEL, SAMPLE_PHOTO, SAMPLE_STYLE, ViewerSession
from stylize3d_app.viewer.state import PreviewSettings, choose_preview_long_side
from stylize3d_core.pipeline import PhotoSpec
from stylize3d_core.render.plain import frame_size

from viewer_window import big_sample, window  # this folder's module


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
    times, samples = [], []
    for cam in cams:
        size = frame_size(session.info.size, side)
        t0 = time.perf_counter()
        session.render_view(cam, size, display, preview=True, stylized=stylized)
        dt = time.perf_counter() - t0
        times.append(dt)
        samples.append((max(size), dt))
        side = choose_preview_long_side(samples, side, settings)
    tail = times[len(times) // 2:]
    report(f"adaptive preview (settles at {side} px)", tail)


def _drag_session(model: str, megapixels: float, tmp: str, max_size: int = 0):
    """A session on the sample upscaled to ``megapixels``, loaded as the viewer loads it with ``max_size``
    (0: the whole photo)."""
    path, big_hw = big_sample(megapixels, tmp)
    s = ViewerSession(model)
    s.load_style(str(SAMPLE_STYLE))
    info = s.load_photo(PhotoSpec(path, "auto", max_size=max_size or max(big_hw)))
    s.prepare_stylized()
    return s, info


BASELINE = PreviewSettings(preview_long_side=256, min_preview_long_side=96, max_preview_long_side=320)
"""The live view's previous settings (first preview 256 px, 96-320 px, every full frame in one level),
measured interleaved with the current ones for a ratio that the machine's load cancels out of."""


def interactive(model: str, megapixels: float, full_side: int, tmp: str, max_size: int = 0,
                repeats: int = 2) -> None:
    """Simulated drags through the viewer's worker and render state machine (see the module docstring),
    with the current preview settings and progressive full frames, and with :data:`BASELINE`, interleaved."""
    import queue
    import threading
    from collections import deque

    import numpy as np

    from stylize3d_app.viewer.render_state import RenderStateMachine, refine_levels
    from stylize3d_app.viewer.session import display_image
    from stylize3d_app.viewer.state import PREVIEW_SAMPLES
    from stylize3d_app.viewer.worker import ComputeWorker

    s, info = _drag_session(model, megapixels, tmp, max_size)
    h, w = info.size
    display = frame_size(info.size, full_side)
    print(f"interactive: photo {w}x{h} ({w * h / 1e6:.2f} MP), {info.n_points:,} points, full frame "
          f"{display[1]}x{display[0]}, preview budget {1000 * PreviewSettings().target_preview_s:.0f} ms; "
          f"load average {os.getloadavg()[0]:.1f}")
    cam0 = pose_camera(OrbitPose(), info.scene, info.fov_y_deg)
    s.render_view(cam0, frame_size(info.size, 128), display, preview=True, stylized=True)
    worker = ComputeWorker()
    worker.start()
    shown: "queue.Queue" = queue.Queue()

    def run_policy(name: str, settings: PreviewSettings, progressive: bool) -> dict:
        machine = RenderStateMachine(settings.rest_delay_s, levels=refine_levels(None) if progressive else (1.0,))
        state = {"side": settings.preview_long_side, "yaw": 0.0, "times": deque(maxlen=PREVIEW_SAMPLES)}

        def request(preview: bool) -> None:
            cam = pose_camera(OrbitPose(yaw_deg=state["yaw"], pitch_deg=0.0), info.scene, info.fov_y_deg)
            scale = 1.0 if preview else machine.full_scale
            if preview:
                size = frame_size(info.size, min(state["side"], max(display)))
            else:
                size = display if scale >= 1.0 else frame_size(info.size, int(round(scale * max(display))))
            cancel = None if preview else threading.Event()
            version = machine.version

            def fn():
                return s.render_view(cam, size, None, preview=preview, stylized=True,  # as the window: own size
                                     should_stop=None if cancel is None else cancel.is_set, calibrate=scale >= 1.0)

            worker.request_render(fn, lambda r: shown.put((time.perf_counter(), version, scale, r)),
                                  preview=preview, cancel=cancel)
            if not preview:
                machine.full_requested()

        def pump(until: float, moving: bool, log: list) -> None:
            """The main loop: a mouse move every 1/60 s while ``moving``, deliveries, the tick."""
            step_at = time.perf_counter()
            while time.perf_counter() < until:
                now = time.perf_counter()
                if moving and now >= step_at:
                    state["yaw"] = (state["yaw"] + 0.15) % 8.0
                    if machine.changed(now).interrupt:
                        worker.interrupt_render()
                    request(True)
                    step_at += 1 / 60
                if machine.full_due(now, holding=moving):
                    request(False)
                try:
                    t, version, scale, r = shown.get(timeout=0.002)
                except queue.Empty:
                    continue
                if machine.shown(version, r.preview, scale):
                    request(False)
                if r.preview:
                    state["times"].append((max(r.value.rendered_size), r.seconds))
                    state["side"] = choose_preview_long_side(state["times"], state["side"], settings)
                elif scale < 1.0:
                    state["last_level"] = (scale, r.seconds)
                elif progressive:
                    machine.levels = refine_levels(r.seconds, settings.full_budget_s - settings.rest_delay_s,
                                                   state.get("last_level"))
                log.append((t, r.preview, r.value, version, scale))
                if not moving and machine.settled:
                    break

        def drag(seconds: float, rest: float) -> dict:
            log: list = []
            t0 = time.perf_counter()
            pump(t0 + seconds, True, log)
            t_rest = time.perf_counter()
            pump(t_rest + rest, False, log)
            moving = [e for e in log if e[0] <= t_rest and e[1]]
            first = min((e[0] for e in log), default=float("nan"))
            after = [e for e in log if not e[1] and e[0] > t_rest]
            fulls = [e for e in after if e[4] >= 1.0]
            out = {"fps": len(moving) / seconds, "side": state["side"], "first_ms": 1000 * (first - t0),
                   "sharp_s": after[0][0] - t_rest if after else float("nan"),
                   "full_s": fulls[0][0] - t_rest if fulls else float("nan"), "jump": float("nan")}
            if moving and fulls:
                full = fulls[0][2].image.astype(np.float32)
                # the same pose: re-render the last preview's pose as a preview for a like-for-like comparison
                cam = pose_camera(OrbitPose(yaw_deg=state["yaw"]), info.scene, info.fov_y_deg)
                ps = frame_size(info.size, state["side"])
                same = s.render_view(cam, ps, display, preview=True, stylized=True).image.astype(np.float32)
                raw = display_image(s.render(cam, *ps, preview=True, stylized=True), display).astype(np.float32)
                out["jump"] = float(np.abs(same.mean((0, 1)) - full.mean((0, 1))).mean())
                out["raw_jump"] = float(np.abs(raw.mean((0, 1)) - full.mean((0, 1))).mean())
                out["pixel_diff"] = float(np.abs(same - full).mean())
            return out

        first = drag(1.5, 0.3)  # a second drag 0.3 s after the first: its full frame is rendering
        second = drag(1.5, 12.0)
        return {"first": first, "second": second}

    policies = [("baseline (256 px first, 96-320 px, one level)", BASELINE, False),
                ("current (128 px first, 64-384 px, progressive)", PreviewSettings(), True)]
    results: dict = {name: [] for name, _, _ in policies}
    try:
        for _ in range(repeats):
            for name, settings, progressive in policies:  # interleaved: both see the same load
                results[name].append(run_policy(name, settings, progressive))
        for name, _, _ in policies:
            runs = results[name]

            def med(key: str, which: str = "second") -> float:
                vals = [r[which][key] for r in runs if np.isfinite(r[which].get(key, float("nan")))]
                return float(np.median(vals)) if vals else float("nan")

            print(f"  {name} ({len(runs)} runs, medians):")
            print(f"    drag fps {med('fps', 'first'):5.1f} (first drag), {med('fps'):5.1f} (second, 0.3 s after); "
                  f"preview ends at {med('side'):.0f} px")
            print(f"    mouse-down to first frame: {med('first_ms', 'first'):5.0f} ms (first drag), "
                  f"{med('first_ms'):5.0f} ms (second drag, while the first rest's full frame renders)")
            print(f"    rest to first full-quality frame {med('sharp_s'):5.2f} s, to the full-size frame "
                  f"{med('full_s'):5.2f} s")
            print(f"    colour jump last preview -> full frame (same pose): {med('jump'):.2f} levels mean colour "
                  f"(without colour matching {med('raw_jump'):.2f}), mean pixel difference {med('pixel_diff'):.1f}")
        print(f"  full renders interrupted: {worker.interrupted}; load average {os.getloadavg()[0]:.1f}")
    finally:
        worker.stop(timeout=10)


def main() -> None:
    import os
    import tempfile

    # the benchmark's photos (temporary files) must not land in the user's recent files
    os.environ.setdefault("STYLIZE3D_CONFIG_DIR", tempfile.mkdtemp(prefix="stylize3d_bench_config_"))
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=1, help="torch threads (the viewer's default is 1)")
    parser.add_argument("--frames", type=int, default=40, help="camera positions along the orbit")
    parser.add_argument("--max-size", type=int, default=640, help="photo long side (viewer default 640)")
    parser.add_argument("--preview-sizes", default="128,192,256,320")
    parser.add_argument("--full-size", type=int, default=768, help="full-frame long side (viewer default cap 768)")
    parser.add_argument("--model", default=None, help="checkpoint for the stylized path")
    parser.add_argument("--interactive", action="store_true", help="simulated drags through the live view's "
                        "worker and state machine (fps, latencies, colour jump)")
    parser.add_argument("--window", action="store_true", help="the viewer window on Xvfb with real XTest drags "
                        "(the four figures of issue 13)")
    parser.add_argument("--plain", action="store_true", help="--window without the model (the plain 3D photo: "
                        "what the window itself costs)")
    parser.add_argument("--save-report", default=None, metavar="JSON",
                        help="--window: write the window's report (its frame log, GUI-loop turns) and the drags here")
    parser.add_argument("--render-backend", default=None, choices=sorted(BACKENDS),
                        help=f"--window: the viewer's graphics back end (default: the viewer's, {DEFAULT_BACKEND})")
    parser.add_argument("--full-threads", type=int, default=None,
                        help="--window: the viewer's --full-threads (default: the viewer's own choice)")
    parser.add_argument("--decoder-threads", type=int, default=None,
                        help="--window: the viewer's --decoder-threads (default: the viewer's own choice)")
    parser.add_argument("--megapixels", type=float, default=1.0, help="photo size of --interactive and --window "
                        "(default 1 MP)")
    parser.add_argument("--repeats", type=int, default=2, help="drag pairs per settings in --interactive (default 2)")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    from stylize3d_core.memory import keep_freed_memory

    keep_freed_memory()  # as the viewer does (its window process does it itself)
    if args.window:
        with tempfile.TemporaryDirectory() as tmp:
            window(args.model or str(DEFAULT_MODEL), args.megapixels, tmp, args.max_size, args.repeats, args.threads,
                   args.plain, args.render_backend, args.save_report, args.full_threads, args.decoder_threads)
        return
    if args.interactive:
        model = args.model or str(DEFAULT_MODEL)
        with tempfile.TemporaryDirectory() as tmp:
            print(f"model {Path(model).name}; torch threads {args.threads}; {os.cpu_count()} CPUs")
            for max_size in (args.max_size, 0):  # as the viewer opens it (default --max-size), and whole
                interactive(model, args.megapixels, args.full_size, tmp, max_size, args.repeats)
        print(f"load average after: {os.getloadavg()[0]:.1f}")
        return

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
