"""A private X server and real input events for driving the viewer window (window tests, ``bench_viewer --window``).

Headless like the test hooks (:mod:`app.viewer.script`): nothing here imports
Open3D. :func:`start_xvfb` starts an Xvfb that picks a free display number
itself (``-displayfd``); :func:`xtest_libs` loads libX11 and libXtst through
ctypes, whose ``XTestFake*Event`` calls send real mouse and key events.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import select
import shutil
import subprocess
import time
from typing import Optional, Sequence, Tuple


def start_xvfb(screen: Tuple[int, int] = (1280, 800), timeout_s: float = 20.0,
               extra_args: Sequence[str] = ()) -> Optional[Tuple[subprocess.Popen, str]]:
    """(process, ":N") of a new Xvfb with one ``screen`` (width, height) x 24 bits and ``extra_args`` (e.g.
    ``("-extension", "GLX")``: a server without OpenGL), or None when Xvfb is not installed or reports no
    display number within ``timeout_s`` (it is killed then). The caller terminates it."""
    xvfb = shutil.which("Xvfb")
    if xvfb is None:
        return None
    r, w = os.pipe()
    proc = subprocess.Popen([xvfb, "-displayfd", str(w), "-screen", "0", f"{screen[0]}x{screen[1]}x24",
                             "-nolisten", "tcp", *extra_args], pass_fds=(w,), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    os.close(w)
    number = b""
    t_end = time.monotonic() + timeout_s
    while not number.endswith(b"\n") and time.monotonic() < t_end:
        ready, _, _ = select.select([r], [], [], 0.5)
        if not ready:
            continue
        chunk = os.read(r, 16)
        if not chunk:
            break
        number += chunk
    os.close(r)
    if not number.strip().isdigit():
        proc.kill()
        proc.wait()
        return None
    return proc, f":{int(number)}"


def xtest_libs() -> Optional[Tuple[ctypes.CDLL, ctypes.CDLL]]:
    """(libX11, libXtst) through ctypes with the signatures of the calls used here, or None where missing."""
    x11, xtst = ctypes.util.find_library("X11"), ctypes.util.find_library("Xtst")
    if not x11 or not xtst:
        return None
    lx, lt = ctypes.CDLL(x11), ctypes.CDLL(xtst)
    lx.XOpenDisplay.restype = ctypes.c_void_p
    lx.XOpenDisplay.argtypes = [ctypes.c_char_p]
    for name in ("XFlush", "XCloseDisplay"):
        getattr(lx, name).argtypes = [ctypes.c_void_p]
    lt.XTestFakeMotionEvent.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_int, ctypes.c_int, ctypes.c_ulong]
    lt.XTestFakeButtonEvent.argtypes = [ctypes.c_void_p, ctypes.c_uint, ctypes.c_int, ctypes.c_ulong]
    lt.XTestFakeKeyEvent.argtypes = [ctypes.c_void_p, ctypes.c_uint, ctypes.c_int, ctypes.c_ulong]
    lx.XStringToKeysym.restype = ctypes.c_ulong
    lx.XStringToKeysym.argtypes = [ctypes.c_char_p]
    lx.XKeysymToKeycode.restype = ctypes.c_ubyte
    lx.XKeysymToKeycode.argtypes = [ctypes.c_void_p, ctypes.c_ulong]
    return lx, lt
