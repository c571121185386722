"""Error of split-resolution decoding against full-size decoding, over photos x styles x cameras.

For each shipped sample photo (1024 px long side) and style, renders frames of the circle path at its
default amplitude and at twice it (more disocclusion, so more holes for the U-Net to fill), and reports
per variant the PSNR (median and worst) and the EfficientNet perceptual distance against the
full-quality float32 render of the same size (every point, decode_scale 1): final frames at 512 px,
previews at 256 px against the full-quality 256 px frame.

    .venv/bin/python benchmarks/bench_split_error.py [--frames 3] [--size 512] [--model CKPT]
"""

from __future__ import annotations

import argparse
import statistics
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from stylize3d_core.bench.speed import PerceptualDistance, psnr  # noqa: E402
from stylize3d_core.geometry.trajectories import DEFAULT_XY, circle  # noqa: E402
from stylize3d_core.io.images import load_image  # noqa: E402
from stylize3d_core.models.checkpoint import load_checkpoint  # noqa: E402
from stylize3d_core.pipeline import PhotoSpec, load_photo3d  # noqa: E402
from stylize3d_core.render.plain import frame_size  # noqa: E402
from stylize3d_core.resources import resolve_model, sample_names, sample_photo, style_image  # noqa: E402
from stylize3d_core.stylize import Stylized3DPhoto, StylizeSettings  # noqa: E402

STYLES = ("painting_style03_coffee.jpg", "texture_voronoi_seed7.jpg")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=3, help="cameras per path")
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--preview-size", type=int, default=256)
    ap.add_argument("--photos", nargs="*", default=None, help="sample names (default: all)")
    ap.add_argument("--model", default=None, help="checkpoint (default: the shipped model)")
    args = ap.parse_args()
    torch.set_num_threads(1)
    ck_path = ROOT / "assets" / "model" / "stylize3d_lite.safetensors"
    ck = load_checkpoint(args.model or (str(ck_path) if ck_path.exists() else resolve_model("lite")))
    dist = PerceptualDistance()
    base = StylizeSettings()
    variants = [  # name, settings, preview
        ("final: decode 1/2", replace(base, decode_scale=2), False),
        ("final: decode 1/4", replace(base, decode_scale=4), False),
        ("preview 3 pts/px, decode 1", base, True),
        ("preview 3 pts/px, decode 1/2", replace(base, preview_decode_scale=2), True),
        ("preview 4 pts/px, decode 1/2", replace(base, preview_points_per_pixel=4.0, preview_decode_scale=2), True),
        ("preview 6 pts/px, decode 1/2", replace(base, preview_points_per_pixel=6.0, preview_decode_scale=2), True),
    ]
    res = {name: [] for name, _, _ in variants}
    for photo in args.photos or sample_names():
        p3d = load_photo3d(PhotoSpec(str(sample_photo(photo)), "prior", max_size=1024))
        st = Stylized3DPhoto(p3d, ck, base)
        big, small = frame_size(p3d.size, args.size), frame_size(p3d.size, args.preview_size)
        paths = {"circle": circle(args.frames + 1, fov_y_deg=p3d.fov_y_deg)[:args.frames],
                 "circle x2": circle(args.frames + 1, x=2 * DEFAULT_XY, y=2 * DEFAULT_XY,
                                     fov_y_deg=p3d.fov_y_deg)[:args.frames]}
        for style in STYLES:
            st.settings = base
            st.set_style(load_image(str(style_image(style)), max_size=512).rgb)
            for path, cams in paths.items():
                for i in range(len(cams)):
                    st.settings = base
                    refs = {size: st.render(cams[i], *size) for size in (big, small)}
                    feats = {size: dist.features(r) for size, r in refs.items()}
                    for name, s, preview in variants:
                        st.settings = s
                        size = small if preview else big
                        out = st.render(cams[i], *size, preview=preview)
                        assert np.isfinite(out).all()
                        p = min(psnr(out, refs[size]), 200.0)
                        res[name].append((p, dist(out, refs[size], feats[size]), photo, style, path))
        print(f"done {photo} ({st.num_points:,} points)", flush=True)
    print(f"\n{'variant':32s} {'median dB':>9s} {'worst dB':>9s} {'perceptual':>10s}  worst case")
    for name, rows in res.items():
        worst = min(rows, key=lambda r: r[0])
        print(f"{name:32s} {statistics.median(r[0] for r in rows):9.2f} {worst[0]:9.2f} "
              f"{statistics.median(r[1] for r in rows):10.5f}  {worst[2]} / {worst[3]} / {worst[4]}")
    print(f"({len(next(iter(res.values())))} frames per variant; PSNR capped at 200 dB; perceptual: median)")


if __name__ == "__main__":
    main()
