"""Remake ``docs/viewer_after.png``: the viewer's window with the bundled sample in a public-domain painting.

    xvfb-run -a -s "-screen 0 1280x800x24" .venv/bin/python tools/make_viewer_screenshot.py \
        [--style vangogh_starry_night.jpg] [--out docs/viewer_after.png]

Runs the viewer with a test script (``app/viewer/script.py``) in an empty settings folder: the bundled sample
photo, the style (a shipped style's file name or a path), the camera moved a little to the side with real
drag steps so the view shows the photo in 3D, then a grab of the window once the full frame is shown. Needs
an X display (``$DISPLAY``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

from stylize3d_core.resources import sample_photo, style_image  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--style", default="vangogh_starry_night.jpg",
                    help="a shipped style's file name or a path (default: %(default)s)")
    ap.add_argument("--out", default=str(ROOT / "docs/viewer_after.png"))
    args = ap.parse_args()
    style = Path(args.style) if Path(args.style).is_file() else style_image(args.style)
    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        steps = [
            {"op": "open_photo", "path": str(sample_photo())},
            {"op": "open_style", "path": str(style)},
            {"op": "wait_idle", "timeout": 240},
            {"op": "orbit", "dx": 40, "dy": 12, "steps": 16, "interval": 0.03},
            {"op": "wait_idle", "timeout": 240},
            {"op": "sleep", "seconds": 0.5},
            {"op": "grab_window", "path": str(Path(args.out).resolve())},
            {"op": "quit"},
        ]
        (t / "steps.json").write_text(json.dumps(steps))
        env = {**os.environ, "STYLIZE3D_CONFIG_DIR": str(t / "config")}
        subprocess.run([sys.executable, "-m", "stylize3d_app.viewer", "--test-script", str(t / "steps.json"),
                        "--test-report", str(t / "report.json")], cwd=ROOT, env=env, check=True)
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
