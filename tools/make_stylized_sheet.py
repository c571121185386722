"""Render a contact sheet of stylized 3D photos: per row a style, per column a camera of the circle path.

    .venv/bin/python tools/make_stylized_sheet.py [--photo P] [--model M] [--out docs/stylized_sheet.png]

The first row is the plain 3D photo; the left column shows the style images.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]

from stylize3d_core.geometry.trajectories import circle  # noqa: E402
from stylize3d_core.io.images import load_image, save_image  # noqa: E402
from stylize3d_core.pipeline import DEFAULT_MODEL, PhotoSpec, load_photo3d  # noqa: E402
from stylize3d_core.render.plain import PlainRenderer, frame_size  # noqa: E402
from stylize3d_core.stylize import Stylized3DPhoto, StylizeSettings  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--photo", default=str(ROOT / "assets/samples/coffee.jpg"))
    ap.add_argument("--model", default=DEFAULT_MODEL)
    ap.add_argument("--styles", nargs="*", default=sorted(str(p) for p in (ROOT / "assets/styles").glob("*.jpg")))
    ap.add_argument("--strength", type=float, default=1.0)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--out", default=str(ROOT / "docs/stylized_sheet.png"))
    args = ap.parse_args()

    p3d = load_photo3d(PhotoSpec(args.photo))
    H, W = frame_size(p3d.size, args.size)
    cams = circle(90, fov_y_deg=p3d.fov_y_deg)
    picks = (0, 22, 45, 67)
    stylized = Stylized3DPhoto(p3d, args.model, StylizeSettings(strength=args.strength))
    blank = np.ones((H, H, 3), np.float32)
    rows = [np.concatenate([blank] + [PlainRenderer(p3d.points).render(cams[i], H, W) for i in picks], 1)]
    for style_path in args.styles:
        style = load_image(style_path).rgb
        stylized.set_style(style)
        thumb = cv2.resize(style, (H, H), interpolation=cv2.INTER_AREA)
        rows.append(np.concatenate([thumb] + [stylized.render(cams[i], H, W) for i in picks], 1))
    save_image(args.out, np.concatenate(rows, 0))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
