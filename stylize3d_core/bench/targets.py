"""``bench targets``: the product's speed, error and memory targets on the 1 MP case, each measured figure
beside its target.

Each photo size runs in a fresh process (``python -m stylize3d_core.bench.targets``), so its peak
resident memory is its own. The 1 MP process (the sample photo resized to 1 MP) measures, with the model and the
style CNN loaded beforehand (not counted):

* first frame: photo file + style image -> the first stylized 512-pixel frame in a process that has
  paid its once-per-process costs, as the viewer has when a photo is opened (timed apart:
  ``pipeline.warm_up``, which the viewer runs at start: the depth modules' imports, the FPS worker
  process, the Numba kernels of the k-NN grid and the rasterizer): read, prior depth, LDI, points, with
  the style CNN in a worker thread meanwhile (``pipeline.prefetch_style``, as ``stylize3d render``
  does), then geometry, encoding, AdaAttN, upsampling, rasterization, decode; in seconds of wall
  time and of the process's CPU time (all threads; steadier on a shared machine);
* the viewer's preview (256 pixels on the long side, ``preview=True``: a point subset of
  ``StylizeSettings.preview_points_per_pixel``) and a full 512-pixel frame: the median over
  cameras of the circle after one warm-up each;
* the error of the preview against the full-quality float32 frame of the same camera and size,
  and of the export default (``RenderJob``'s settings) against the full-quality float32 frame;
* a full frame with the export default (``RenderJob``'s settings: ``points_per_pixel``) and the 90-frame
  512-pixel MP4 of the circle trajectory with it (rendering and encoding, ``write_video``).

A second process lifts a 4 MP photo and renders one 512-pixel stylized frame: its peak memory.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import List, Optional

from ..eval.metrics import psnr
from .report import Log, progress, quiet, write_table


@dataclass(frozen=True)
class TargetsPreset:
    megapixels: float  # the photo of the timed targets
    big_megapixels: float  # the photo of the peak-memory target
    frame: int  # long side of full frames and of the video
    preview: int  # long side of previews
    video_frames: int
    renders: int  # cameras timed for the preview and the full frame


FULL = TargetsPreset(megapixels=1.0, big_megapixels=4.0, frame=512, preview=256, video_frames=90, renders=7)
QUICK = TargetsPreset(megapixels=0.01, big_megapixels=0.02, frame=64, preview=32, video_frames=6, renders=2)


def measure(megapixels: float, frame: int, preview: int, video_frames: int, renders: int,
            photo: Optional[str] = None, model: Optional[str] = None) -> dict:
    """Run in a fresh process: the figures of one photo size (``video_frames`` 0: first frame and memory only).

    ``model``: a checkpoint name or path (default the shipped lite model)."""
    import numpy as np
    import torch

    from ..eval.timing import peak_rss_gib
    from ..geometry.trajectories import circle
    from ..io.images import load_image
    from ..io.video import write_video
    from ..models.checkpoint import load_checkpoint
    from ..models.style_features import StyleEncoder
    from ..pipeline import PhotoSpec, RenderJob, load_photo3d, prefetch_style, warm_up
    from ..render.plain import frame_size
    from ..resources import resolve_model, style_image
    from ..stylize import Stylized3DPhoto, StylizeSettings
    from .photos import photo_at_megapixels

    ck = load_checkpoint(resolve_model(model or "lite"))
    encoder = StyleEncoder()
    style_path = str(style_image())
    out: dict = {"threads": torch.get_num_threads()}
    out["warm_up_s"] = warm_up(wait=True)  # once per process, as the viewer does at start (not counted)
    with tempfile.TemporaryDirectory() as tmp:
        path = photo_at_megapixels(megapixels, Path(tmp), photo)
        t0, c0 = time.perf_counter(), time.process_time()
        style = load_image(style_path, max_size=512).rgb
        prefetch = prefetch_style(style, encoder)  # the style CNN runs while the photo's depth and LDI are built
        p3d = load_photo3d(PhotoSpec(photo=str(path), depth="prior", max_size=8192))
        st = Stylized3DPhoto(p3d, ck, style_encoder=prefetch.result())
        st.set_style(style)
        H, W = frame_size(p3d.size, frame)
        cams = circle(max(video_frames, 90), fov_y_deg=p3d.fov_y_deg)
        st.render(cams[0], H, W)
        out["first_frame_s"] = time.perf_counter() - t0
        out["first_frame_cpu_s"] = time.process_time() - c0  # all threads: steadier than wall time under load
        out.update({"photo": list(p3d.size), "points": st.num_points, "frame": [H, W],
                    "stages": {**{k: float(v) for k, v in p3d.timings.items()}, **st.timings}})
        if not video_frames:  # the memory job: the learned parts made too (a view with uncovered pixels needs them)
            st.prepare()
        if video_frames:
            # a style change: another style image -> the first stylized full frame (style features, AdaAttN,
            # the style prior's painting where the model has one, upsampling, one frame); median of three
            from ..resources import style_names

            others = [n for n in style_names() if Path(n).name != Path(style_path).name][:3]
            restyle = []
            for name in others:
                other = load_image(str(style_image(name)), max_size=512).rgb
                s0 = time.perf_counter()
                st.set_style(other)
                st.render(cams[0], H, W)
                restyle.append(time.perf_counter() - s0)
            st.set_style(style)
            out["restyle_s"] = float(np.median(restyle)) if restyle else math.nan
            Hp, Wp = frame_size(p3d.size, preview)
            every_point = st.settings  # the preview and full frames' settings
            prev, full, prev_db = [], [], []
            st.render(cams[1], Hp, Wp, preview=True)  # warm-up at each size
            st.render(cams[1], H, W)
            for k in range(renders):
                c = cams[(7 * k + 3) % len(cams)]
                s0 = time.perf_counter()
                p = st.render(c, Hp, Wp, preview=True)
                prev.append(time.perf_counter() - s0)
                s0 = time.perf_counter()
                st.render(c, H, W)
                full.append(time.perf_counter() - s0)
                if k < 3:  # against the full-quality float32 frame (the default may decode in bfloat16)
                    default, st.settings = st.settings, replace(st.settings, bfloat16=False)
                    prev_db.append(psnr(p, st.render(c, Hp, Wp)))
                    st.settings = default
            out.update({"preview": [Hp, Wp], "preview_ms": 1000 * float(np.median(prev)),
                        "full_ms": 1000 * float(np.median(full)), "preview_psnr_db": float(np.mean(prev_db))})
            # the export default (RenderJob's settings) against the full-quality float32 frame
            job = RenderJob()
            export = StylizeSettings(strength=st.settings.strength, supersample=job.supersample,
                                     final_points_per_pixel=job.points_per_pixel)
            reference = StylizeSettings(strength=st.settings.strength, supersample=1, bfloat16=False)
            final_db = []
            for k in range(2):
                c = cams[(11 * k + 5) % len(cams)]
                st.settings = reference
                ref = st.render(c, H, W)
                st.settings = export
                final_db.append(min(psnr(st.render(c, H, W), ref), 1e9))
            out["export_psnr_db"] = float(np.mean(final_db)) if max(final_db) < 1e9 else math.inf
            out["export_settings"] = repr(export)
            out["bfloat16"] = export.decode_bfloat16
            full_export = []
            for k in range(renders):
                c = cams[(7 * k + 3) % len(cams)]
                s0 = time.perf_counter()
                st.render(c, H, W)
                full_export.append(time.perf_counter() - s0)
            out["full_export_ms"] = 1000 * float(np.median(full_export))
            t0 = time.perf_counter()  # the video with the export default (st.settings is export now)
            write_video(Path(tmp) / "video.mp4", st.frames(cams[:video_frames], H, W), fps=30,
                        n_frames=video_frames)
            out["video_s"] = time.perf_counter() - t0
            # which measured views needed the learned parts (an uncovered pixel), found after the timing
            measured = [cams[(7 * k + 3) % len(cams)] for k in range(renders)]
            st.settings = every_point
            out["learned_views"] = {
                "previews": sum(st.needs_learned_parts(c, Hp, Wp, preview=True) for c in measured),
                "full frames": sum(st.needs_learned_parts(c, H, W) for c in measured)}
            st.settings = export
            out["learned_views"].update({
                "export frames": sum(st.needs_learned_parts(c, H, W) for c in measured),
                "video frames": sum(st.needs_learned_parts(cams[k], H, W) for k in range(video_frames))})
            out["measured_views"] = {"previews": renders, "full frames": renders, "export frames": renders,
                                     "video frames": video_frames}
    out["peak_rss_gib"] = peak_rss_gib()
    return out


def _child(args: List[str]) -> dict:
    root = Path(__file__).resolve().parents[2]
    done = subprocess.run([sys.executable, "-m", "stylize3d_core.bench.targets"] + args, capture_output=True,
                          text=True, cwd=root)
    if done.returncode != 0:
        from ..errors import Stylize3DError

        raise Stylize3DError(f"bench targets: the measuring process failed:\n{done.stderr.strip()[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def run_targets(out: Path, quick: bool = False, show_progress: bool = False, log: Log = quiet,
                photo: Optional[str] = None) -> List[dict]:
    p = QUICK if quick else FULL
    jobs = [[str(p.megapixels), str(p.frame), str(p.preview), str(p.video_frames), str(p.renders)],
            [str(p.big_megapixels), str(p.frame), str(p.preview), "0", "0"]]
    results = [_child(j + ([str(photo)] if photo else [])) for j in progress(jobs, len(jobs), "targets", show_progress)]
    one, big = results
    h, w = one["photo"]
    H, W = one["frame"]
    Hp, Wp = one["preview"]
    bh, bw = big["photo"]
    mp = f"{w}x{h} photo ({h * w / 1e6:.2f} MP, {one['points']:,} points)"
    fps = 1000.0 / one["preview_ms"]

    def row(what: str, target: str, measured: float, unit: str, met: bool) -> dict:
        return {"what": what, "target": target, "measured": measured, "unit": unit, "met": met}

    rows = [
        row(f"stylized preview while orbiting, {Wp}x{Hp}", ">= 30 fps", fps, "fps", fps >= 30),
        row(f"stylized full frame {W}x{H}, {mp}: every point", "<= 150 ms", one["full_ms"], "ms",
            one["full_ms"] <= 150),
        row(f"the same with the export default ({p.frame}-px frames: RenderJob.points_per_pixel)", "<= 150 ms",
            one["full_export_ms"], "ms", one["full_export_ms"] <= 150),
        row(f"stylized {p.video_frames}-frame {W}x{H} MP4 (export default)", "<= 15 s", one["video_s"], "s",
            one["video_s"] <= 15),
        row("style change -> first stylized frame", "<= 1.5 s", one["restyle_s"], "s", one["restyle_s"] <= 1.5),
        row("photo + style -> first stylized frame", "<= 3 s", one["first_frame_s"], "s", one["first_frame_s"] <= 3),
        row("error of the export default vs full-quality float32 (final frames; inf: identical)", ">= 40 dB",
            one["export_psnr_db"], "dB PSNR", one["export_psnr_db"] >= 40),
        row(f"error of the preview ({Wp}x{Hp}) vs full-quality float32 at its size", ">= 30 dB",
            one["preview_psnr_db"], "dB PSNR", one["preview_psnr_db"] >= 30),
        row(f"peak memory at {bh * bw / 1e6:.2g} MP ({bw}x{bh}, {big['points']:,} points; one {W}-px frame)",
            "<= 6 GiB", big["peak_rss_gib"], "GiB", big["peak_rss_gib"] <= 6),
    ]
    stages = ", ".join(f"{k} {v:.2f}" for k, v in one["stages"].items())
    write_table(Path(out), "targets", "Targets", rows, notes=[
        f"{mp}; torch threads {one['threads']}; fresh process per photo size, model and style CNN loaded first "
        "(not counted)" + (" (--quick preset: tiny sizes, the targets do not apply)" if quick else ""),
        f"preview and full frame: median over {p.renders} cameras of the circle after one warm-up; the preview "
        "renders a point subset (StylizeSettings.preview_points_per_pixel)",
        f"first frame {one['first_frame_s']:.2f} s wall, {one['first_frame_cpu_s']:.2f} s CPU (all threads); "
        f"its stages (s): {stages}; not counted, like the model's loading, once per process (the viewer pays "
        f"them at start): pipeline.warm_up (depth modules, FPS worker process, Numba kernels) "
        f"{one['warm_up_s']:.2f} s",
        f"export default: {one['export_settings']}; peak memory at 1 MP {one['peak_rss_gib']:.2f} GiB; "
        f"at {bh * bw / 1e6:.2g} MP with the learned parts made (Stylized3DPhoto.prepare)",
        "measured views with an uncovered pixel, which run the learned parts (geometry, encoder, stylizer, "
        "U-Net; Stylized3DPhoto.needs_learned_parts); the others are the rasterized prior colours: "
        + ", ".join(f"{kind} {n} of {one['measured_views'][kind]}" for kind, n in one["learned_views"].items())
        + " (`bench floor` times the whole U-Net)",
        "decoder in bfloat16 (StylizeSettings.bfloat16 None: this CPU computes bfloat16 natively): "
        f"{'yes' if one.get('bfloat16') else 'no'}; the references of the error rows are float32"])
    log("targets: " + "; ".join(f"{r['what'].split(',')[0]} {r['measured']:.3g} {r['unit']}" for r in rows))
    return rows


if __name__ == "__main__":
    from ..memory import keep_freed_memory

    keep_freed_memory()  # as the viewer and the command line do in their processes
    a = sys.argv[1:]
    print(json.dumps(measure(float(a[0]), int(a[1]), int(a[2]), int(a[3]), int(a[4]), (a[5:6] or [""])[0] or None,
                             (a[6:7] or [""])[0] or None)))
