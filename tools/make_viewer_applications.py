"""Remake docs/viewer_applications.png: the viewer's Applications menu, four window grabs tiled 2 x 2.

    xvfb-run -a -s "-screen 0 1280x800x24" .venv/bin/python tools/make_viewer_applications.py [--out docs/viewer_applications.png]

Runs the viewer with a test script (``app/viewer/script.py``) on the astronaut sample with Renoir's
*The Bridge at Chatou* (``renoir_bridge_at_chatou.jpg``) and the shipped model, in an empty settings folder:
the GrabCut dialog, the layered view it gives from a camera moved to the side, the side-by-side export
dialog, and the centre-view choice for a views file (the procedural views of ``tools/make_application_samples.py``).
Needs an X display (``$DISPLAY``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]

from stylize3d_core.io.images import load_image, save_image  # noqa: E402
from stylize3d_core.resources import sample_photo, style_image  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "docs/viewer_applications.png"))
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        subprocess.run([sys.executable, str(ROOT / "tools/make_application_samples.py"), "--out", str(t / "samples")],
                       check=True, stdout=subprocess.DEVNULL)
        grabs = [str(t / f"grab{i}.png") for i in range(4)]
        steps = [
            {"op": "open_photo", "path": str(sample_photo("astronaut.jpg"))},
            {"op": "open_style", "path": str(style_image("renoir_bridge_at_chatou.jpg"))},
            {"op": "wait_idle", "timeout": 240},
            {"op": "app_menu", "item": "MENU_GRABCUT", "ok": True, "grab": grabs[0],
             "fields": {"left": 0.117, "top": 0.04, "right": 0.76, "bottom": 1.0, "strength": 0.0}},
            {"op": "wait_idle", "timeout": 240},
            {"op": "orbit", "dx": 60, "dy": 0, "steps": 20, "interval": 0.02},
            {"op": "wait_idle", "timeout": 240},
            {"op": "grab_window", "path": grabs[1]},
            {"op": "app_menu", "item": "MENU_SBS", "grab": grabs[2], "wait": False,
             "fields": {"layout": 0, "eye_distance": 0.01}},
            {"op": "app_call", "method": "open_views", "path": str(t / "samples/views/views.json")},
            {"op": "sleep", "seconds": 1.0},
            {"op": "grab_window", "path": grabs[3]},
            {"op": "quit"},
        ]
        (t / "steps.json").write_text(json.dumps(steps))
        env = {**os.environ, "STYLIZE3D_CONFIG_DIR": str(t / "config")}
        subprocess.run([sys.executable, "-m", "stylize3d_app.viewer", "--test-script", str(t / "steps.json"),
                        "--test-report", str(t / "report.json")], cwd=ROOT, env=env, check=True)
        tiles = [load_image(g, max_size=4096).rgb for g in grabs]  # the window grabs, at their own size
        h, w = (min(tile.shape[i] for tile in tiles) for i in (0, 1))
        half = [cv2.resize(np.ascontiguousarray(tile[:h, :w]), (w // 2, h // 2), interpolation=cv2.INTER_AREA)
                for tile in tiles]
        sheet = np.concatenate([np.concatenate(half[:2], axis=1), np.concatenate(half[2:], axis=1)], axis=0)
        save_image(args.out, sheet)
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
