"""The viewer window under Xvfb, driven through its test hooks (``--test-script``): scripted sessions.

Opening, orbiting and exporting (and surviving bad files), closing during an export,
the stylized view, the keyframe editor, the style strip and its mix, typed paths in
the file dialogs and the recent files kept between runs. The real (XTest) mouse,
key and wheel events are in ``test_viewer_gui_events.py``.

Each test module starts its own Xvfb (a free display number chosen by Xvfb itself
with ``-displayfd``); each test runs the viewer in a ``spawn`` subprocess with a
timeout (``viewer_gui_helpers.py``), and checks the report, the screenshots and the
files the script produced. Without Xvfb the tests are skipped with the reason.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Tuple

import numpy as np
import pytest
from PIL import Image

from stylize3d_app.viewer.xserver import xtest_click

from viewer_gui_helpers import display  # noqa: F401 (the module's Xvfb, a fixture)
from viewer_gui_helpers import OTHER_STYLE, REPO, check_ran, pixels, run_viewer, step, wait_for_step
from viewer_gui_helpers import xtest as _xtest

pytestmark = [pytest.mark.gui, pytest.mark.slow]  # each test starts Open3D in a subprocess: 8-30 s


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
