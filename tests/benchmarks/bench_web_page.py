"""The web-page export (``--export html``): file size, seconds to the first frame in headless Chromium and
frames per second while orbiting at 1280x720 (software WebGL), for the bundled samples and a 1 MP photo.

Each page opens in a fresh browser, as a receiver opens it. The orbit rate is the median of three
one-second sweeps taken after the page has rested for two seconds (for about a second after the first frame
the browser is still settling the page's decoded data and runs slower).

    python tests/benchmarks/bench_web_page.py [--out DIR] [--style STYLE]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from stylize3d_core.bench.photos import photo_at_megapixels
from stylize3d_core.eval.browser import PageBrowser
from stylize3d_core.resources import sample_names, sample_photo, style_image


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None, help="folder for the pages (default: a temporary one)")
    ap.add_argument("--style", default=str(style_image()), help="style image (default the sample style)")
    args = ap.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="bench_web_"))
    out.mkdir(parents=True, exist_ok=True)
    photos = [(Path(name).stem, sample_photo(name)) for name in sample_names()]
    photos.append(("1 MP", photo_at_megapixels(1.0, out, str(sample_photo()))))
    print(f"{'photo':12} {'MB':>6} {'first frame s':>14} {'orbit fps':>10}")
    for name, path in photos:
        page = out / f"{name.replace(' ', '_')}.html"
        subprocess.run([sys.executable, "-m", "stylize3d", "render", str(path), "--style", args.style,
                        "--export", "html", "-o", str(page), "-q"], check=True)
        with PageBrowser((1280, 720)) as browser:
            seconds = browser.open(page)
            time.sleep(2.0)
            fps = statistics.median(browser.orbit_fps(1.0) for _ in range(3))
        print(f"{name:12} {page.stat().st_size / 2 ** 20:6.2f} {seconds:14.2f} {fps:10.1f}")


if __name__ == "__main__":
    main()
