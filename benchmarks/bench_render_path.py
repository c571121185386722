"""Stylized render path: full-size decoding against split-resolution decoding, timed interleaved.

Prints, per variant, the median wall-clock ms per frame and the median CPU ms (process time: with
``--threads 1`` the work done, which a shared machine's load inflates far less than wall time) over the rounds (each round renders every variant once,
so load changes on a shared machine hit all of them alike), the ratio to the first variant measured
round by round, and the PSNR / max error against the full-quality float32 render (every point,
decode_scale 1) of the same camera.

    .venv/bin/python benchmarks/bench_render_path.py [--photo P] [--style S] [--rounds 5] [--size 512]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from stylize3d_core.bench.speed import psnr  # noqa: E402
from stylize3d_core.geometry.trajectories import circle  # noqa: E402
from stylize3d_core.io.images import load_image  # noqa: E402
from stylize3d_core.models.checkpoint import load_checkpoint  # noqa: E402
from stylize3d_core.pipeline import PhotoSpec, load_photo3d  # noqa: E402
from stylize3d_core.render.plain import frame_size  # noqa: E402
from stylize3d_core.resources import resolve_model, sample_photo, style_image  # noqa: E402
from stylize3d_core.stylize import Stylized3DPhoto, StylizeSettings  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--photo", default=None)
    ap.add_argument("--style", default=None)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--preview-size", type=int, default=256)
    ap.add_argument("--max-size", type=int, default=1024, help="photo long side (1024: ~0.4 M points)")
    ap.add_argument("--threads", type=int, default=None, help="torch threads (default: torch's)")
    args = ap.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    photo = args.photo or str(sample_photo("coffee.jpg"))
    style = args.style or str(style_image("painting_style03_coffee.jpg"))
    p3d = load_photo3d(PhotoSpec(photo, "prior", max_size=args.max_size))
    ck = ROOT / "assets" / "model" / "stylize3d_lite.safetensors"  # this checkout's model
    st = Stylized3DPhoto(p3d, load_checkpoint(str(ck) if ck.exists() else resolve_model("lite")), StylizeSettings())
    st.set_style(load_image(style, max_size=512).rgb)
    H, W = frame_size(p3d.size, args.size)
    h, w = frame_size(p3d.size, args.preview_size)
    cams = circle(12, fov_y_deg=p3d.fov_y_deg)
    base = st.settings
    variants = [  # name, settings, preview, size
        ("full: all points, decode 1", base, False, (H, W)),
        ("full: 6 pts/px, decode 1", replace(base, final_points_per_pixel=6.0), False, (H, W)),
        ("full: all points, decode 1/2", replace(base, decode_scale=2), False, (H, W)),
        ("full: 6 pts/px, decode 1/2", replace(base, final_points_per_pixel=6.0, decode_scale=2), False, (H, W)),
        ("preview 3 pts/px, decode 1", base, True, (h, w)),
        ("preview 3 pts/px, decode 1/2", replace(base, preview_decode_scale=2), True, (h, w)),
        ("preview 4 pts/px, decode 1/2", replace(base, preview_points_per_pixel=4.0, preview_decode_scale=2), True,
         (h, w)),
        ("preview 6 pts/px, decode 1/2", replace(base, preview_points_per_pixel=6.0, preview_decode_scale=2), True,
         (h, w)),
    ]
    print(f"photo {photo} {p3d.size[1]}x{p3d.size[0]}, {st.num_points:,} points; frames {W}x{H}, previews {w}x{h}; "
          f"torch threads {torch.get_num_threads()}")
    refs = {}
    st.settings = base
    for size in {(H, W), (h, w)}:
        refs[size] = [st.render(cams[i], *size) for i in range(len(cams))]
    times = [[] for _ in variants]
    errs = [[] for _ in variants]
    cpu = [[] for _ in variants]
    for k in range(args.rounds + 1):
        cam = k % len(cams)
        for i, (name, s, preview, size) in enumerate(variants):
            st.settings = s
            t0, c0 = time.perf_counter(), time.process_time()
            out = st.render(cams[cam], *size, preview=preview)
            dt, dc = time.perf_counter() - t0, time.process_time() - c0
            assert np.isfinite(out).all()
            if k:
                times[i].append(dt)
                cpu[i].append(dc)
                errs[i].append((psnr(out, refs[size][cam]), float(np.abs(out - refs[size][cam]).max())))
    st.settings = base
    print(f"{'variant':34s} {'median ms':>9s} {'ratio':>6s} {'CPU ms':>7s} {'ratio':>6s} {'PSNR dB':>8s} {'max err':>8s}")
    for i, (name, *_rest) in enumerate(variants):
        ratio = statistics.median(t / t0 for t, t0 in zip(times[i], times[0]))
        cratio = statistics.median(t / t0 for t, t0 in zip(cpu[i], cpu[0]))
        p = statistics.median(e[0] for e in errs[i])
        print(f"{name:34s} {1000 * statistics.median(times[i]):9.1f} {ratio:6.2f} "
              f"{1000 * statistics.median(cpu[i]):7.1f} {cratio:6.2f} {p:8.2f} "
              f"{max(e[1] for e in errs[i]):8.3f}")


if __name__ == "__main__":
    main()
