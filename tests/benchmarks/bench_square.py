"""The model issue's own speed targets: a 512x512 stylized frame and a 256x256 preview of a 1 MP photo.

Builds the sample photo resized to 1 MP (``bench.photos.photo_at_megapixels``), its 3D photo (built-in
depth prior) and the shipped model (or ``--model``) with the bundled style, then renders, over
``--rounds`` rounds, 7 cameras of the circle trajectory each: the full frame of every point at
``--full`` px square and the preview (``preview=True``: a point subset, ``StylizeSettings``' preview
defaults) at ``--preview`` px square. Prints the median per round and over all rounds, and the preview's
PSNR against the full-quality float32 frame of the same camera and size (the preview target's measure).
Targets (issue 11): 512x512 <= 0.5 s, 256x256 <= 60 ms, on this machine's 2 cores.

    .venv/bin/python tests/benchmarks/bench_square.py [--threads 2] [--rounds 3] [--model M]
        [--preview-points-per-pixel P] [--preview-border-margin M]

Pause any background training while it runs (``kill -STOP``): the figures are wall times.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default="lite", help="checkpoint name or path (default the shipped model)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--full", type=int, default=512, help="side of the full frames (default 512)")
    ap.add_argument("--preview", type=int, default=256, help="side of the previews (default 256)")
    ap.add_argument("--megapixels", type=float, default=1.0)
    ap.add_argument("--preview-points-per-pixel", type=float, default=None)
    ap.add_argument("--preview-border-margin", type=int, default=None)
    args = ap.parse_args()

    import torch

    torch.set_num_threads(args.threads)
    from stylize3d_core.bench.photos import photo_at_megapixels
    from stylize3d_core.bench.speed import psnr
    from stylize3d_core.geometry.trajectories import circle
    from stylize3d_core.io.images import load_image
    from stylize3d_core.models.checkpoint import load_checkpoint
    from stylize3d_core.models.style_features import StyleEncoder
    from stylize3d_core.pipeline import PhotoSpec, load_photo3d, warm_up
    from stylize3d_core.resources import resolve_model, style_image
    from stylize3d_core.stylize import Stylized3DPhoto

    warm_up(wait=True)
    ck = load_checkpoint(resolve_model(args.model))
    with tempfile.TemporaryDirectory() as tmp:
        path = photo_at_megapixels(args.megapixels, Path(tmp), None)
        p3d = load_photo3d(PhotoSpec(photo=str(path), depth="prior", max_size=8192))
    st = Stylized3DPhoto(p3d, ck, style_encoder=StyleEncoder())
    st.set_style(load_image(str(style_image()), max_size=512).rgb)
    over = {}
    if args.preview_points_per_pixel is not None:
        over["preview_points_per_pixel"] = args.preview_points_per_pixel
    if args.preview_border_margin is not None:
        over["preview_border_margin"] = args.preview_border_margin
    st.settings = replace(st.settings, **over)
    cams = circle(90, fov_y_deg=p3d.fov_y_deg)
    views = [cams[(7 * k + 3) % len(cams)] for k in range(7)]
    F, P = args.full, args.preview
    default = st.settings
    st.settings = replace(default, bfloat16=False)
    refs = [st.render(c, P, P) for c in views]  # full-quality float32 at the preview's size
    st.settings = default
    st.render(cams[1], F, F)
    st.render(cams[1], P, P, preview=True)
    full, prev, db = [], [], []
    print(f"{p3d.size[1]}x{p3d.size[0]} photo, {st.num_points:,} points, torch {args.threads} threads, "
          f"preview settings: {st.settings.preview_points_per_pixel:g} points per pixel, border margin "
          f"{st.settings.preview_border_margin}")
    for r in range(args.rounds):
        f_r, p_r = [], []
        for k, c in enumerate(views):
            t = time.perf_counter()
            st.render(c, F, F)
            f_r.append(time.perf_counter() - t)
            t = time.perf_counter()
            out = st.render(c, P, P, preview=True)
            p_r.append(time.perf_counter() - t)
            if r == 0:
                db.append(psnr(out, refs[k]))
        full += f_r
        prev += p_r
        print(f"round {r + 1}: {F}x{F} every point {1000 * np.median(f_r):.0f} ms, {P}x{P} preview "
              f"{1000 * np.median(p_r):.1f} ms", flush=True)
    print(f"median of {len(full)}: {F}x{F} {1000 * np.median(full):.0f} ms (target 500), {P}x{P} preview "
          f"{1000 * np.median(prev):.1f} ms (target 60); preview vs full quality {np.mean(db):.2f} dB "
          f"(least {np.min(db):.2f}; target 30)")


if __name__ == "__main__":
    main()
