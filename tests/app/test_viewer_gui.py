"""The viewer window under Xvfb, driven through its test hooks (``--test-script``).

Each test starts its own Xvfb (a free display number chosen by Xvfb itself with
``-displayfd``), runs the viewer in a ``spawn`` subprocess with a timeout, and
checks the report, the screenshots and the files the script produced. Without
Xvfb the tests are skipped with the reason. One test also drags with the real
(XTest) mouse when libXtst is available.
"""

from __future__ import annotations

import ctypes
import json
import multiprocessing
import shutil
import time
from pathlib import Path
from typing import Any, Dict, Iterator, List, Optional, Tuple

import numpy as np
import pytest
from PIL import Image

from stylize3d_app.viewer import run_viewer_process
from stylize3d_app.viewer.xserver import start_xvfb, xtest_click, xtest_libs

pytestmark = [pytest.mark.gui, pytest.mark.slow]  # each test starts Open3D in a subprocess: 8-30 s

REPO = Path(__file__).resolve().parents[2]
OTHER_STYLE = REPO / "assets" / "styles" / "painting_style13_rocket.jpg"
SCREEN = (1280, 800)
RUN_TIMEOUT_S = 300


@pytest.fixture(scope="module")
def display() -> Iterator[str]:
    """An X display served by a private Xvfb for this module."""
    if shutil.which("Xvfb") is None:
        pytest.skip("Xvfb is not installed: the viewer window tests need an X server (apt-get install xvfb)")
    server = start_xvfb(SCREEN)
    if server is None:
        pytest.skip("Xvfb did not start (no display number reported): no X server for the window tests")
    proc, name = server
    try:
        yield name
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def run_viewer(display: str, tmp: Path, steps: List[Dict[str, Any]], args: List[str],
               during=None) -> Tuple[int, Dict[str, Any]]:
    """Run the viewer with ``steps`` in a spawn subprocess; ``during(report_path)`` runs meanwhile."""
    script, report = tmp / "steps.json", tmp / "report.json"
    script.write_text(json.dumps(steps))
    argv = args + ["--size", f"{SCREEN[0]}x{SCREEN[1]}", "--test-script", str(script), "--test-report", str(report)]
    proc = multiprocessing.get_context("spawn").Process(target=run_viewer_process, args=(argv, display))
    proc.start()
    try:
        if during is not None:
            during(report)
        proc.join(RUN_TIMEOUT_S)
        if proc.is_alive():
            pytest.fail(f"the viewer did not finish within {RUN_TIMEOUT_S} s; report so far: {read_report(report)}")
    finally:
        if proc.is_alive():
            proc.kill()
            proc.join(10)
    return proc.exitcode, read_report(report)


def read_report(path: Path) -> Dict[str, Any]:
    return json.loads(path.read_text()) if path.exists() else {}


def wait_for_step(report_path: Path, op: str, count: int = 1, timeout: float = 120.0) -> Dict[str, Any]:
    """The report once the viewer has run ``count`` steps ``op`` (polled while the test interacts)."""
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        rep = read_report(report_path)
        if sum(s["op"] == op for s in rep.get("steps", [])) >= count:
            return rep
        time.sleep(0.05)
    raise AssertionError(f"the viewer never reached the {op!r} step")


def check_ran(code: Optional[int], report: Dict[str, Any]) -> None:
    failed = [s for s in report.get("steps", []) if not s.get("ok")]
    assert code == 0, f"viewer exit code {code} (negative = crashed); failed steps: {failed}"
    assert report.get("ok") and not failed, failed


def pixels(path: Path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGB")).astype(np.float32)


def step(report: Dict[str, Any], op: str, index: int = 0) -> Dict[str, Any]:
    return [s for s in report["steps"] if s["op"] == op][index]


def test_open_orbit_export_and_survive_bad_files(display, tmp_path):
    bad_path = tmp_path / "bad_path.json"
    bad_path.write_text('{"format": "stylize3d-camera-path", "version": 1, "frames": []}')
    steps = [
        {"op": "load_sample"},
        {"op": "wait_idle", "timeout": 120},
        {"op": "screenshot", "path": str(tmp_path / "before.png")},
        {"op": "grab_window", "path": str(tmp_path / "window.png")},
        {"op": "orbit", "dx": 120, "dy": 40, "steps": 25, "interval": 0.02},
        {"op": "wait_idle"},
        {"op": "screenshot", "path": str(tmp_path / "after.png")},
        {"op": "orbit", "dx": 30, "dy": 10, "steps": 5, "mode": "pan"},
        {"op": "wheel", "ticks": 2},
        {"op": "wait_idle"},
        {"op": "set_export", "frames": 6, "size": 96, "fps": 6},
        {"op": "preview_path"},
        {"op": "export", "path": str(tmp_path / "clip.mp4")},
        {"op": "export", "path": str(tmp_path / "no_such_folder" / "clip.mp4")},
        {"op": "expect_error", "contains": "no_such_folder"},
        {"op": "save_camera_path", "path": str(tmp_path / "path.json")},
        {"op": "load_camera_path", "path": str(tmp_path / "path.json")},
        {"op": "load_camera_path", "path": str(bad_path)},
        {"op": "expect_error", "contains": "bad_path.json"},
        {"op": "open_photo", "path": str(tmp_path / "missing.jpg")},
        {"op": "expect_error", "contains": "missing.jpg"},
        {"op": "reset_view"},
        {"op": "orbit", "dx": -60, "dy": 0, "steps": 10, "interval": 0.02},
        {"op": "wait_idle"},
        {"op": "screenshot", "path": str(tmp_path / "still_usable.png")},
        {"op": "help", "visible": True},
        {"op": "state"},
        {"op": "quit"},
    ]
    code, report = run_viewer(display, tmp_path, steps, ["--no-model"])
    check_ran(code, report)
    before, after = pixels(tmp_path / "before.png"), pixels(tmp_path / "after.png")
    assert before.std() > 20, "the first view is blank"
    assert before.shape == after.shape
    assert np.abs(after - before).mean() > 5, "the view did not change after the orbit"
    orbit = step(report, "orbit")["result"]
    assert orbit["pose"]["yaw_deg"] > 0 and orbit["pose"]["pitch_deg"] < 0
    assert orbit["preview_frames"] > 0, "no live preview while dragging"
    pose = step(report, "wheel")["result"]["pose"]
    assert pose["pan_x"] < 0 and pose["dolly"] > 0
    shown = step(report, "wait_idle")["result"]["shown"]
    assert shown["stylized"] is False and shown["preview"] is False
    # the screenshot is at the view's size on screen, at least the full frame's (capped at 768)
    assert before.shape[1] >= shown["size"][1] and abs(before.shape[0] / before.shape[1] - 400 / 600) < 0.01
    assert step(report, "preview_path")["result"]["frames_shown"] > 0
    assert (tmp_path / "clip.mp4").stat().st_size > 0
    assert "Exported" in step(report, "export")["result"]["status"]
    assert not (tmp_path / "no_such_folder").exists()
    assert json.loads((tmp_path / "path.json").read_text())["format"] == "stylize3d-camera-path"
    state = step(report, "state")["result"]
    assert state["use_loaded_path"] is True  # the good path stayed loaded after the bad one failed
    assert state["spec"]["photo"].endswith("coffee.jpg")  # the bad photo did not replace the good one
    assert np.abs(pixels(tmp_path / "still_usable.png") - after).mean() > 2  # still there, still moving
    window = pixels(tmp_path / "window.png")
    assert window.shape[0] > 200 and window.std() > 20
    upright, flipped = view_orientation(window, before)
    assert upright > 0.9 and upright > flipped + 0.2, (
        f"the view on screen is not the frame upright: row-profile correlation {upright:.2f} upright, "
        f"{flipped:.2f} upside down (the image widget's orientation under the render back end)")


def view_orientation(window: np.ndarray, frame: np.ndarray) -> Tuple[float, float]:
    """Correlations of the on-screen view's row profile (mean grey per row) with ``frame``'s, upright and
    upside down. The view is found in ``window`` (a grab) as the longest run of rows of its left half that
    are not flat (the menu bar above it is a shorter run), then the longest run of columns in those rows
    that are not flat (the side panel is beside it); the frame's profile is resampled to as many rows."""
    def longest_run(busy: np.ndarray) -> Tuple[int, int]:
        edges = np.diff(np.concatenate([[0], busy.astype(np.int8), [0]]))
        starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        assert starts.size, "no view found in the window grab"
        k = int(np.argmax(ends - starts))
        return int(starts[k]), int(ends[k])

    grey = window.mean(axis=2)
    y0, y1 = longest_run(grey[:, : window.shape[1] // 2].std(axis=1) > 3.0)
    x0, x1 = longest_run(grey[y0:y1].std(axis=0) > 3.0)
    assert y1 - y0 > 50 and x1 - x0 > 50, "no view found in the window grab"
    on_screen = grey[y0:y1, x0:x1].mean(axis=1)
    profile = frame.mean(axis=(1, 2))
    resampled = np.interp(np.linspace(0, len(profile) - 1, len(on_screen)), np.arange(len(profile)), profile)
    return (float(np.corrcoef(on_screen, resampled)[0, 1]), float(np.corrcoef(on_screen, resampled[::-1])[0, 1]))


def test_closing_during_an_export_leaves_no_file_and_does_not_crash(display, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    steps = [
        {"op": "load_sample"},
        {"op": "wait_idle", "timeout": 120},
        {"op": "set_export", "frames": 400, "size": 256, "fps": 30},
        {"op": "export", "path": str(out / "long.mp4"), "wait": False},
        {"op": "sleep", "seconds": 1.0},
        {"op": "quit"},
    ]
    code, report = run_viewer(display, tmp_path, steps, ["--no-model"])
    check_ran(code, report)
    assert list(out.iterdir()) == [], "a cancelled export left a file behind"


def test_stylized_view_strength_style_export_and_no_freeze(display, tmp_path, untrained):
    steps = [
        {"op": "load_sample"},
        {"op": "sleep", "seconds": 1.0},
        {"op": "ping"},  # while the photo is built and encoded on the worker
        {"op": "wait_idle", "timeout": 240},
        {"op": "screenshot", "path": str(tmp_path / "stylized.png")},
        {"op": "orbit", "dx": 100, "dy": 0, "steps": 20, "interval": 0.03},
        {"op": "wait_idle", "timeout": 120},
        {"op": "screenshot", "path": str(tmp_path / "stylized_moved.png")},
        {"op": "set_strength", "value": 0.2},
        {"op": "wait_idle", "timeout": 120},
        {"op": "screenshot", "path": str(tmp_path / "weak.png")},
        {"op": "open_style", "path": str(OTHER_STYLE)},
        {"op": "wait_idle", "timeout": 120},
        {"op": "screenshot", "path": str(tmp_path / "other_style.png")},
        {"op": "set_export", "frames": 8, "size": 128, "fps": 8, "format": "gif"},
        {"op": "export", "path": str(tmp_path / "stylized.gif"), "wait": False},
        {"op": "ping", "count": 10},  # while exporting
        {"op": "wait_export"},
        {"op": "set_stylized", "value": False},
        {"op": "wait_idle", "timeout": 120},
        {"op": "screenshot", "path": str(tmp_path / "original.png")},
        {"op": "set_refine_depth", "value": "bilateral_median"},
        {"op": "wait_idle", "timeout": 120},
        {"op": "state"},
        {"op": "quit"},
    ]
    # full frames on 2 threads (the default on 3 or more cores)
    code, report = run_viewer(display, tmp_path, steps, ["--model", str(untrained), "--full-threads", "2"])
    check_ran(code, report)
    assert step(report, "wait_idle", 0)["result"]["shown"]["stylized"] is True
    assert step(report, "wait_idle", 4)["result"]["shown"]["stylized"] is False
    for i in (0, 1):
        ping = step(report, "ping", i)["result"]
        assert ping["max_s"] < 1.0, f"the window froze for {ping['max_s']} s while the worker was busy"
    assert "Exported" in step(report, "wait_export")["result"]["status"]
    assert Image.open(tmp_path / "stylized.gif").format == "GIF"  # (identical frames are merged: no frame count)
    stylized, moved = pixels(tmp_path / "stylized.png"), pixels(tmp_path / "stylized_moved.png")
    original = pixels(tmp_path / "original.png")
    # An untrained decoder paints an almost flat image, so only exact changes can be asserted.
    assert np.any(stylized != moved), "the stylized view did not change when the camera moved"
    assert np.any(pixels(tmp_path / "weak.png") != moved), "the strength did not change the view"
    assert np.any(pixels(tmp_path / "other_style.png") != pixels(tmp_path / "weak.png")), "the style did not change"
    assert np.abs(original - moved).mean() > 10, "stylized and original views look the same"
    assert original.std() > 20
    state = step(report, "state")["result"]
    assert state["spec"]["refine_depth"] == "bilateral_median" and state["spec"]["photo"].endswith("coffee.jpg")


def _xtest():
    """(libX11, libXtst) through ctypes, or None where they are missing."""
    return xtest_libs()


def test_real_mouse_drag_and_key_press(display, tmp_path):
    libs = _xtest()
    if libs is None:
        pytest.skip("libXtst is not installed: cannot send real mouse and key events to Xvfb")
    lx, lt = libs
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
    libs = _xtest()
    if libs is None:
        pytest.skip("libXtst is not installed: cannot send real mouse and key events to Xvfb")
    lx, lt = libs
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


def test_keyframe_editor_builds_a_path_exports_it_and_round_trips(display, tmp_path):
    keys = tmp_path / "keys.json"
    steps = [
        {"op": "load_sample"},
        {"op": "wait_idle", "timeout": 120},
        {"op": "add_keyframe"},
        {"op": "orbit", "dx": 80, "dy": 0, "steps": 8},
        {"op": "add_keyframe"},
        {"op": "orbit", "dx": -40, "dy": 30, "steps": 8},
        {"op": "wheel", "ticks": 2},
        {"op": "add_keyframe"},
        {"op": "edit_keyframe", "index": 0, "seconds": 0.5},
        {"op": "edit_keyframe", "index": 1, "fov": 45.0, "seconds": 0.25},
        {"op": "edit_keyframe", "index": 2, "move": -1},
        {"op": "edit_keyframe", "index": 0, "loop": True},
        {"op": "set_export", "size": 96, "fps": 8, "format": "gif"},
        {"op": "preview_keys"},
        {"op": "export", "path": str(tmp_path / "keys.gif")},
        {"op": "save_keyframes", "path": str(keys)},
        {"op": "edit_keyframe", "index": 0, "delete": True},
        {"op": "load_keyframes", "path": str(keys)},
        {"op": "edit_keyframe", "index": 0},
        {"op": "open_section"},
        {"op": "wait_idle"},
        {"op": "grab_window", "path": str(tmp_path / "editor.png")},
        {"op": "save_as", "what": "screenshot", "text": str(tmp_path / "typed.png")},  # an absolute path
        {"op": "save_as", "what": "screenshot", "text": "relative.png"},  # in the folder used last
        {"op": "resize", "width": 300, "height": 200},
        {"op": "quit"},
    ]
    code, report = run_viewer(display, tmp_path, steps, ["--no-model"])
    check_ran(code, report)
    assert step(report, "add_keyframe", 2)["result"]["keyframes"] == 3
    looped = step(report, "edit_keyframe", 3)["result"]
    assert looped["loop"] and looped["use_keyframes"] and looped["durations_s"] == [0.5, 2.0, 0.25]
    assert step(report, "preview_keys")["result"]["full_frames_shown"] > 0
    # 0.5 + 2.0 + 0.25 s of loop at 8 fps: 22 frames in the GIF.
    with Image.open(tmp_path / "keys.gif") as gif:
        assert gif.n_frames > 1
    doc = json.loads(keys.read_text())
    assert doc["format"] == "stylize3d-camera-path" and len(doc["frames"]) == 3
    assert doc["keyframes"] == {"durations_s": [0.5, 2.0, 0.25], "loop": True}
    assert step(report, "edit_keyframe", 5)["result"]["keyframes"] == 3  # loaded back after a delete
    assert (tmp_path / "typed.png").is_file() and (tmp_path / "relative.png").is_file()
    shot = Image.open(tmp_path / "typed.png")
    assert shot.width > 768, f"the screenshot is not at the view's size: {shot.size}"  # the view is ~944 px wide
    size = step(report, "resize")["result"]
    assert size["width"] >= 640 and size["height"] >= 480, f"no minimum window size: {size}"


def test_style_strip_mix_and_before_after(display, tmp_path, untrained):
    shots = {n: str(tmp_path / f"{n}.png") for n in ("first", "strip", "mixed", "split")}
    steps = [
        {"op": "load_sample"},
        {"op": "wait_idle", "timeout": 240},
        {"op": "screenshot", "path": shots["first"]},
        {"op": "style_strip", "index": 0},
        {"op": "wait_idle", "timeout": 120},
        {"op": "screenshot", "path": shots["strip"]},
        {"op": "mix", "path": str(OTHER_STYLE), "value": 0.5},
        {"op": "wait_idle", "timeout": 120},
        {"op": "screenshot", "path": shots["mixed"]},
        {"op": "compare", "split": 0.5},
        {"op": "wait_idle", "timeout": 120},
        {"op": "grab_window", "path": str(tmp_path / "window.png")},
        {"op": "state"},
        {"op": "quit"},
    ]
    code, report = run_viewer(display, tmp_path, steps, ["--model", str(untrained)])
    check_ran(code, report)
    strip = step(report, "style_strip")["result"]
    assert len(strip["strip"]) >= 4 and strip["style"] != ""  # the bundled styles
    first, chosen, mixed = (pixels(Path(shots[n])) for n in ("first", "strip", "mixed"))
    assert np.any(first != chosen), "clicking a thumbnail did not change the style"
    assert np.any(mixed != chosen), "mixing in a second style did not change the view"
    state = step(report, "state")["result"]
    assert state["mix"] == 0.5 and state["compare"] is True and state["style2"].endswith(OTHER_STYLE.name)
    window = pixels(tmp_path / "window.png")
    assert window.std() > 20


def test_real_wheel_up_moves_forwards(display, tmp_path):
    libs = _xtest()
    if libs is None:
        pytest.skip("libXtst is not installed: cannot send real wheel events to Xvfb")
    lx, lt = libs
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


def test_typed_paths_in_open_dialogs_and_recent_files_kept_between_runs(display, tmp_path, settings_dir):
    sample = REPO / "assets" / "samples" / "coffee.jpg"
    for folder, name in (("photos", "cat.jpg"), ("photos2", "dog.jpg")):
        (tmp_path / folder).mkdir()
        shutil.copy(sample, tmp_path / folder / name)
    first = tmp_path / "first"
    first.mkdir()
    steps = [
        {"op": "open_as", "what": "photo", "text": str(tmp_path / "photos" / "cat.jpg")},  # absolute
        {"op": "wait_idle", "timeout": 120},
        {"op": "open_as", "what": "photo", "text": "missing.jpg"},  # relative to the last folder: not there
        {"op": "expect_error", "contains": "no such file"},
        {"op": "status"},
        {"op": "open_as", "what": "photo", "text": "../photos2/dog.jpg"},  # relative to the last folder
        {"op": "wait_idle", "timeout": 120},
        {"op": "state"},
        {"op": "settings"},
        {"op": "quit"},
    ]
    code, report = run_viewer(display, first, steps, ["--no-model"])
    check_ran(code, report)
    missing = step(report, "open_as", 1)["result"]
    assert any(str(tmp_path / "photos" / "missing.jpg") + ": no such file" in e for e in missing["errors"])
    assert not step(report, "status")["result"]["dialog_open"]
    assert "Error" not in step(report, "status")["result"]["status"]  # the error's status line went with it
    assert step(report, "state")["result"]["spec"]["photo"] == str(tmp_path / "photos2" / "dog.jpg")
    saved = step(report, "settings")["result"]
    assert saved["settings_file"] == str(settings_dir / "viewer.json")
    assert saved["recent_photos"] == [str(tmp_path / "photos2" / "dog.jpg"), str(tmp_path / "photos" / "cat.jpg")]
    on_disk = json.loads((settings_dir / "viewer.json").read_text())
    assert on_disk["recent_photos"] == saved["recent_photos"] and on_disk["last_folder"] == str(tmp_path / "photos2")

    # A second run starts with them: File > Recent photos > 2 (real clicks) opens cat.jpg; a recent file
    # that is gone is forgotten.
    (tmp_path / "photos2" / "dog.jpg").unlink()
    second = tmp_path / "second"
    second.mkdir()
    steps = [
        {"op": "settings"},
        {"op": "grab_window", "path": str(second / "window.png")},
        {"op": "sleep", "seconds": 12.0},  # the test opens File > Recent photos > 2 now
        {"op": "wait_idle", "timeout": 120},
        {"op": "state"},
        {"op": "recent", "kind": "photo", "index": 1},  # dog.jpg (second since cat.jpg opened): deleted
        {"op": "expect_error", "contains": "no such file any more"},
        {"op": "quit"},
    ]
    libs = _xtest()

    def choose_from_menu(report_path: Path) -> None:
        rep = wait_for_step(report_path, "grab_window")
        if libs is None:  # no real events: choose the entry as its menu item does
            return
        lx = libs[0]
        shot = step(rep, "grab_window")["result"]
        x0, y0 = shot["box"][:2]
        em = shot["em"]
        dpy = lx.XOpenDisplay(display.encode())

        def click(x: float, y: float, press: bool = True) -> None:
            # several moves onto the target and a press held for more than a GUI frame (see xtest_click)
            xtest_click(libs, dpy, x0 + x, y0 + y, press=press)

        try:  # ImGui's menus: items 1.5 em apart below a 1.5 em bar (File's 5th item: Recent photos)
            click(1.4 * em, 0.75 * em)
            click(4 * em, (2.5 + 1.5 * 4) * em, press=False)
            click(6 * em, (2.5 + 1.5 * 4) * em, press=False)
            click(19 * em, (2.5 + 1.5 * 5) * em)  # the submenu's second entry
        finally:
            lx.XCloseDisplay(dpy)

    if libs is None:
        steps.insert(3, {"op": "recent", "kind": "photo", "index": 1})
    code, report = run_viewer(display, second, steps, ["--no-model"], during=choose_from_menu)
    check_ran(code, report)
    assert step(report, "settings")["result"]["recent_photos"] == saved["recent_photos"]
    assert step(report, "state")["result"]["spec"]["photo"] == str(tmp_path / "photos" / "cat.jpg"), \
        "File > Recent photos > 2 did not open cat.jpg"
    assert step(report, "recent")["result"]["recent_photos"] == [str(tmp_path / "photos" / "cat.jpg")]
