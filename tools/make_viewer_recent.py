"""Remake ``docs/viewer_recent.png``: the viewer's File > Recent photos menu over the stylized sample.

The viewer runs on a private Xvfb with an empty settings folder; its test script opens rocket, then
astronaut, then the bundled sample (coffee), so the menu lists the three; this script then opens the File
menu and points at "Recent photos" with real XTest events, and the viewer grabs its window.

    .venv/bin/python tools/make_viewer_recent.py [--out docs/viewer_recent.png]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

from stylize3d_app.viewer import run_viewer_process  # noqa: E402
from stylize3d_app.viewer.xserver import start_xvfb, xtest_click, xtest_libs  # noqa: E402

SAMPLES = ROOT / "assets" / "samples"
FILE_MENU = (22, 12)
"""The File menu's title, in window pixels."""
RECENT_PHOTOS = (55, 136)
"""Its "Recent photos" entry."""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "docs" / "viewer_recent.png"))
    args = ap.parse_args()
    libs, server = xtest_libs(), start_xvfb((1280, 800))
    if libs is None or server is None:
        print("needs Xvfb and libXtst", file=sys.stderr)
        return 1
    lx = libs[0]
    xproc, display = server
    with tempfile.TemporaryDirectory() as tmp:
        os.environ["STYLIZE3D_CONFIG_DIR"] = str(Path(tmp) / "settings")  # no recent files of the user's
        script, report = Path(tmp) / "steps.json", Path(tmp) / "report.json"
        script.write_text(json.dumps([
            {"op": "open_photo", "path": str(SAMPLES / "rocket.jpg")}, {"op": "wait_idle", "timeout": 300},
            {"op": "open_photo", "path": str(SAMPLES / "astronaut.jpg")}, {"op": "wait_idle", "timeout": 300},
            {"op": "load_sample"}, {"op": "wait_idle", "timeout": 300},
            {"op": "grab_window", "path": str(Path(tmp) / "marker.png")},
            {"op": "sleep", "seconds": 4.0},  # the menu is opened now
            {"op": "grab_window", "path": str(Path(args.out).resolve())},
            {"op": "quit"},
        ]))
        argv = ["--size", "1280x800", "--test-script", str(script), "--test-report", str(report)]
        proc = multiprocessing.get_context("spawn").Process(target=run_viewer_process, args=(argv, display))
        proc.start()
        try:
            box, t_end = None, time.monotonic() + 900
            while box is None and time.monotonic() < t_end and proc.is_alive():
                try:
                    steps = json.loads(report.read_text())["steps"]
                    box = next((s["result"]["box"] for s in steps if s["op"] == "grab_window"), None)
                except (OSError, ValueError, KeyError, TypeError):
                    pass
                time.sleep(0.1)
            if box is None:
                print("the viewer did not open the photos", file=sys.stderr)
                return 1
            dpy = lx.XOpenDisplay(display.encode())
            xtest_click(libs, dpy, box[0] + FILE_MENU[0], box[1] + FILE_MENU[1])  # opens the File menu
            xtest_click(libs, dpy, box[0] + RECENT_PHOTOS[0], box[1] + RECENT_PHOTOS[1], press=False)  # hover
            lx.XCloseDisplay(dpy)
            proc.join(120)
        finally:
            if proc.is_alive():
                proc.terminate()
            xproc.terminate()
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
