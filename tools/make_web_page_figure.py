"""Remake ``docs/apps_web_page.png``: the web-page export of the bundled sample in headless Chromium at the
photo's camera, the desktop render of the same camera, and the page after a drag, side by side.

    .venv/bin/python tools/make_web_page_figure.py [--style vangogh_starry_night.jpg] [--out docs/apps_web_page.png]

The page is written as ``stylize3d render --export html`` writes it (``export.run.export_page``: the shipped
model's colours baked on the points); Chromium is driven by ``stylize3d_core/eval/browser.py`` (needs
``chromium`` and ``chromium-driver``, which ``setup.sh`` installs). Prints the PSNR between the page's
home view and the desktop render.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]

from stylize3d_core.eval.browser import PageBrowser  # noqa: E402
from stylize3d_core.eval.metrics import psnr  # noqa: E402
from stylize3d_core.export.run import export_page  # noqa: E402
from stylize3d_core.export.settings import ExportSettings  # noqa: E402
from stylize3d_core.geometry.camera import Cameras  # noqa: E402
from stylize3d_core.geometry.trajectories import circle  # noqa: E402
from stylize3d_core.io.images import load_image, save_image  # noqa: E402
from stylize3d_core.models.checkpoint import load_checkpoint  # noqa: E402
from stylize3d_core.pipeline import PhotoSpec, load_photo3d  # noqa: E402
from stylize3d_core.resources import resolve_model, sample_photo, style_image  # noqa: E402
from stylize3d_core.stylize import Stylized3DPhoto  # noqa: E402

SCALE = 1.28
"""The viewport's size over the photo's (768 x 512 for the 600 x 400 sample)."""


def _titled(image: np.ndarray, title: str, band: int = 40) -> np.ndarray:
    """(H + band, W, 3) uint8: ``title`` in black on a white band above ``image``."""
    top = np.full((band, image.shape[1], 3), 255, np.uint8)
    cv2.putText(top, title, (10, band - 12), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (0, 0, 0), 2, cv2.LINE_AA)
    return np.concatenate([top, image], axis=0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--style", default="vangogh_starry_night.jpg", help="a shipped style's file name or a path")
    ap.add_argument("--out", default=str(ROOT / "docs/apps_web_page.png"))
    args = ap.parse_args()
    style = Path(args.style) if Path(args.style).is_file() else style_image(args.style)
    photo = load_photo3d(PhotoSpec(str(sample_photo())))
    stylized = Stylized3DPhoto(photo, load_checkpoint(resolve_model("lite")))
    stylized.set_style(load_image(str(style), max_size=512).rgb)
    h, w = (int(round(s * SCALE)) // 2 * 2 for s in photo.size)
    with tempfile.TemporaryDirectory() as tmp:
        page = export_page(str(Path(tmp) / "page.html"), ExportSettings(export="html"), photo, stylized, True,
                           circle(90, fov_y_deg=photo.fov_y_deg), 30.0, title="3D photo")
        with PageBrowser((w, h)) as browser:
            browser.open(page)
            home = browser.canvas()
            browser.drag(160, 40)
            moved = browser.screenshot()  # with the page's buttons
    desktop = np.rint(np.clip(stylized.render(Cameras.identity(photo.fov_y_deg), h, w), 0, 1) * 255).astype(np.uint8)
    print(f"page home view against the desktop render: {psnr(home, desktop, peak=255.0):.1f} dB PSNR ({w}x{h})")
    gap = np.full((h + 40, 12, 3), 255, np.uint8)
    sheet = np.concatenate([_titled(home, "web page in Chromium, home view"), gap,
                            _titled(desktop, "desktop render, same camera"), gap,
                            _titled(moved, "web page after a drag")], axis=1)
    save_image(args.out, sheet.astype(np.float32) / 255.0)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
