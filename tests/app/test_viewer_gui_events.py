"""The viewer window under Xvfb with real input: XTest mouse drags, key presses and wheel turns, and a
window manager's close request (``WM_DELETE_WINDOW``), sent while the viewer runs its test script.

Each test is skipped where Xvfb or libXtst is missing; the scripted sessions are in
``test_viewer_gui.py``, the shared runner in ``viewer_gui_helpers.py``.
"""

from __future__ import annotations

import ctypes
import time
from pathlib import Path
from typing import Any, Dict

import numpy as np
import pytest

from viewer_gui_helpers import display  # noqa: F401 (the module's Xvfb, a fixture)
from viewer_gui_helpers import check_ran, pixels, run_viewer, step, wait_for_step
from viewer_gui_helpers import xtest_or_skip

pytestmark = [pytest.mark.gui, pytest.mark.slow]  # each test starts Open3D in a subprocess: 8-30 s


def test_real_mouse_drag_and_key_press(display, tmp_path):
    lx, lt = xtest_or_skip()
    steps = [
        {"op": "load_sample"},
        {"op": "wait_idle", "timeout": 120},
        {"op": "screenshot", "path": str(tmp_path / "before.png")},
        {"op": "grab_window", "path": str(tmp_path / "window.png")},
        {"op": "sleep", "seconds": 4.0},  # the test drags the mouse now
        {"op": "wait_idle"},
        {"op": "screenshot", "path": str(tmp_path / "after.png")},
        {"op": "state"},
        {"op": "sleep", "seconds": 2.0},  # the test presses R (reset view) now
        {"op": "wait_idle"},
        {"op": "state"},
        {"op": "quit"},
    ]

    def wait_for(report_path: Path, op: str, count: int = 1) -> Dict[str, Any]:
        return wait_for_step(report_path, op, count)

    def interact(report_path: Path) -> None:
        rep = wait_for(report_path, "grab_window")
        x0, y0, x1, y1 = step(rep, "grab_window")["result"]["box"]
        x, y = x0 + (x1 - x0) // 3, (y0 + y1) // 2  # inside the view, left of the side panel
        dpy = lx.XOpenDisplay(display.encode())
        assert dpy, f"cannot open display {display}"
        try:
            lt.XTestFakeMotionEvent(dpy, -1, x, y, 0)
            lt.XTestFakeButtonEvent(dpy, 1, 1, 0)
            lx.XFlush(dpy)
            for i in range(1, 21):
                time.sleep(0.03)
                lt.XTestFakeMotionEvent(dpy, -1, x + 5 * i, y, 0)
                lx.XFlush(dpy)
            lt.XTestFakeButtonEvent(dpy, 1, 0, 0)
            lx.XFlush(dpy)
            wait_for(report_path, "state")
            keycode = lx.XKeysymToKeycode(dpy, lx.XStringToKeysym(b"r"))
            lt.XTestFakeKeyEvent(dpy, keycode, 1, 0)
            lt.XTestFakeKeyEvent(dpy, keycode, 0, 0)
            lx.XFlush(dpy)
        finally:
            lx.XCloseDisplay(dpy)

    code, report = run_viewer(display, tmp_path, steps, ["--no-model"], during=interact)
    check_ran(code, report)
    state = step(report, "state", 0)["result"]
    yaw, limits = state["pose"]["yaw_deg"], state["limits"]
    # 100 px of drag turn half the photo's yaw range (200 px reach the limit, whatever the range)
    assert yaw == pytest.approx(100 * limits["deg_per_pixel"], rel=0.3), f"the mouse drag did not orbit (yaw {yaw})"
    assert 0.3 * limits["max_yaw_deg"] < yaw < limits["max_yaw_deg"], "the drag was clamped: speeds not relative to the range"
    assert report["stats"]["drag_clamped"] == [], "mouse moves of a 100 px drag met the range's limit"
    assert np.abs(pixels(tmp_path / "after.png") - pixels(tmp_path / "before.png")).mean() > 5
    assert step(report, "state", 1)["result"]["pose"]["yaw_deg"] == 0.0, "the R key did not reset the view"


def _send_close_request(lx, dpy, title: bytes) -> bool:
    """Send WM_DELETE_WINDOW to the top-level window named ``title`` (what a window manager's close
    button does); False if no such window."""
    lx.XDefaultRootWindow.restype = ctypes.c_ulong
    lx.XDefaultRootWindow.argtypes = [ctypes.c_void_p]
    lx.XQueryTree.argtypes = [ctypes.c_void_p, ctypes.c_ulong, ctypes.POINTER(ctypes.c_ulong),
                              ctypes.POINTER(ctypes.c_ulong), ctypes.POINTER(ctypes.POINTER(ctypes.c_ulong)),
                              ctypes.POINTER(ctypes.c_uint)]
    lx.XFetchName.argtypes = [ctypes.c_void_p, ctypes.c_ulong, ctypes.POINTER(ctypes.c_char_p)]
    lx.XInternAtom.restype = ctypes.c_ulong
    lx.XInternAtom.argtypes = [ctypes.c_void_p, ctypes.c_char_p, ctypes.c_int]
    lx.XSendEvent.argtypes = [ctypes.c_void_p, ctypes.c_ulong, ctypes.c_int, ctypes.c_long, ctypes.c_void_p]

    class ClientMessage(ctypes.Structure):
        _fields_ = [("type", ctypes.c_int), ("serial", ctypes.c_ulong), ("send_event", ctypes.c_int),
                    ("display", ctypes.c_void_p), ("window", ctypes.c_ulong), ("message_type", ctypes.c_ulong),
                    ("format", ctypes.c_int), ("data", ctypes.c_long * 5), ("pad", ctypes.c_long * 16)]

    root = lx.XDefaultRootWindow(dpy)
    r, p, n = ctypes.c_ulong(), ctypes.c_ulong(), ctypes.c_uint()
    children = ctypes.POINTER(ctypes.c_ulong)()
    lx.XQueryTree(dpy, root, ctypes.byref(r), ctypes.byref(p), ctypes.byref(children), ctypes.byref(n))
    for i in range(n.value):
        name = ctypes.c_char_p()
        if lx.XFetchName(dpy, children[i], ctypes.byref(name)) and name.value == title:
            ev = ClientMessage(type=33, send_event=1, display=dpy, window=children[i],
                               message_type=lx.XInternAtom(dpy, b"WM_PROTOCOLS", 0), format=32)
            ev.data[0] = lx.XInternAtom(dpy, b"WM_DELETE_WINDOW", 0)
            lx.XSendEvent(dpy, children[i], 0, 0, ctypes.byref(ev))
            lx.XFlush(dpy)
            return True
    return False


def test_real_events_second_drag_shows_frames_esc_and_close_during_export(display, tmp_path, untrained):
    """With the model's cost (an untrained lite checkpoint): a second drag 0.3 s after the first shows
    frames while it moves (the first rest's full frame is interrupted); Esc during an export neither quits
    nor cancels it; closing the window during an export asks first."""
    lx, lt = xtest_or_skip()
    out = tmp_path / "out"
    out.mkdir()
    steps = [
        {"op": "load_sample"},
        {"op": "wait_idle", "timeout": 240},
        {"op": "grab_window", "path": str(tmp_path / "window.png")},
        {"op": "sleep", "seconds": 6.0},  # the test drags twice now
        {"op": "wait_idle", "timeout": 120},
        {"op": "status"},
        {"op": "set_export", "frames": 120, "size": 160, "fps": 8},  # long enough for Esc to land during it
        {"op": "export", "path": str(out / "clip.mp4"), "wait": False},
        {"op": "sleep", "seconds": 2.0},  # the test presses Esc now
        {"op": "status"},
        {"op": "wait_export", "timeout": 240},
        {"op": "set_export", "frames": 400, "size": 256, "fps": 30},
        {"op": "export", "path": str(out / "long.mp4"), "wait": False},
        {"op": "sleep", "seconds": 2.0},  # the test closes the window now
        {"op": "status"},
        {"op": "quit"},
    ]
    marks: Dict[str, Any] = {}

    def wait_for(report_path: Path, op: str, count: int = 1) -> Dict[str, Any]:
        return wait_for_step(report_path, op, count, timeout=240)

    def drag(dpy, x, y, seconds, dx_per_step):
        lt.XTestFakeMotionEvent(dpy, -1, x, y, 0)
        lt.XTestFakeButtonEvent(dpy, 1, 1, 0)
        lx.XFlush(dpy)
        n = int(seconds / 0.02)
        for i in range(1, n + 1):
            time.sleep(0.02)
            lt.XTestFakeMotionEvent(dpy, -1, x + dx_per_step * i, y, 0)
            lx.XFlush(dpy)
        lt.XTestFakeButtonEvent(dpy, 1, 0, 0)
        lx.XFlush(dpy)

    def interact(report_path: Path) -> None:
        rep = wait_for(report_path, "grab_window")
        x0, y0, x1, y1 = step(rep, "grab_window")["result"]["box"]
        x, y = x0 + (x1 - x0) // 4, (y0 + y1) // 2
        dpy = lx.XOpenDisplay(display.encode())
        assert dpy, f"cannot open display {display}"
        try:
            drag(dpy, x, y, 1.0, 1)
            time.sleep(0.3)  # the full frame of this rest is rendering when the second drag starts
            marks["second_start"] = time.monotonic()
            drag(dpy, x + 50, y, 1.5, -1)
            marks["second_end"] = time.monotonic()
            wait_for(report_path, "export", 1)
            time.sleep(0.5)
            esc = lx.XKeysymToKeycode(dpy, lx.XStringToKeysym(b"Escape"))
            lt.XTestFakeKeyEvent(dpy, esc, 1, 0)
            lt.XTestFakeKeyEvent(dpy, esc, 0, 0)
            lx.XFlush(dpy)
            wait_for(report_path, "export", 2)
            time.sleep(0.5)
            marks["close_sent"] = _send_close_request(lx, dpy, b"stylize3d viewer")
        finally:
            lx.XCloseDisplay(dpy)

    code, report = run_viewer(display, tmp_path, steps, ["--model", str(untrained)], during=interact)
    check_ran(code, report)
    shown = [t for t in report["stats"]["preview_shown"] if marks["second_start"] <= t <= marks["second_end"]]
    assert len(shown) >= 2, f"the second drag showed {len(shown)} frames while it moved; {marks}, {report['stats']}"
    moved = step(report, "status", 0)["result"]
    assert moved["phase"] == "full"
    esc = step(report, "status", 1)["result"]
    assert esc["exporting"] and not esc["closing"], f"Esc stopped the export or quit: {esc}"
    assert "Exported" in step(report, "wait_export")["result"]["status"]
    assert (out / "clip.mp4").stat().st_size > 0
    assert marks["close_sent"], "no window to close"
    asked = step(report, "status", 2)["result"]
    assert asked["dialog_open"] and asked["exporting"] and not asked["closing"], asked
    assert not (out / "long.mp4").exists()  # quitting from the script cancelled it: nothing written


def test_real_wheel_up_moves_forwards(display, tmp_path):
    lx, lt = xtest_or_skip("wheel events")
    steps = [
        {"op": "load_sample"},
        {"op": "wait_idle", "timeout": 120},
        {"op": "grab_window", "path": str(tmp_path / "window.png")},
        {"op": "sleep", "seconds": 3.0},  # the test turns the wheel up now
        {"op": "state"},
        {"op": "quit"},
    ]

    def interact(report_path: Path) -> None:
        rep = wait_for_step(report_path, "grab_window")
        x0, y0, x1, y1 = step(rep, "grab_window")["result"]["box"]
        x, y = x0 + (x1 - x0) // 3, (y0 + y1) // 2
        dpy = lx.XOpenDisplay(display.encode())
        try:
            lt.XTestFakeMotionEvent(dpy, -1, x, y, 0)
            lx.XFlush(dpy)
            time.sleep(0.3)
            for i in range(3):  # X button 4 is wheel up
                lt.XTestFakeButtonEvent(dpy, 4, 1, 0)
                lt.XTestFakeButtonEvent(dpy, 4, 0, 0)
                lx.XFlush(dpy)
                time.sleep(0.2)
                lt.XTestFakeMotionEvent(dpy, -1, x + i + 1, y, 0)  # Open3D hands the wheel over with the next event
                lx.XFlush(dpy)
                time.sleep(0.1)
        finally:
            lx.XCloseDisplay(dpy)

    code, report = run_viewer(display, tmp_path, steps, ["--no-model"], during=interact)
    check_ran(code, report)
    assert step(report, "state")["result"]["pose"]["dolly"] > 0, "wheel up did not move forwards"
