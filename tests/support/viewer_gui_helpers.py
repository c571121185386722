"""What the viewer's window tests share (``test_viewer_gui*.py``, ``test_viewer_applications.py``): a
private Xvfb per test module (the ``display`` fixture), the viewer run in a ``spawn`` subprocess with a
test script and a timeout, and readers of its report and screenshots.

Not a test module: the tests import it by name (pytest's ``pythonpath`` in pyproject.toml puts tests/support
on the path).
"""

from __future__ import annotations

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
from stylize3d_app.viewer.xserver import start_xvfb, xtest_libs


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



def xtest():
    """(libX11, libXtst) through ctypes, or None where they are missing."""
    return xtest_libs()


def xtest_or_skip(events: str = "mouse and key events"):
    """(libX11, libXtst), or skip the test where they are missing (it cannot send real ``events``)."""
    libs = xtest_libs()
    if libs is None:
        pytest.skip(f"libXtst is not installed: cannot send real {events} to Xvfb")
    return libs
