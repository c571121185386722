"""A private X server and real input events for driving the viewer window (window tests, ``bench_viewer --window``).

Headless like the test hooks (:mod:`app.viewer.script`): nothing here imports
Open3D. :func:`start_xvfb` starts an Xvfb that picks a free display number
itself (``-displayfd``); :func:`xtest_libs` loads libX11 and libXtst through
ctypes, whose ``XTestFake*Event`` calls send real mouse and key events;
:func:`has_extension` asks a display for an extension (GLX: can it run OpenGL).
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


def x11_lib() -> Optional[ctypes.CDLL]:
    """libX11 through ctypes with the signatures of the calls used here (opening displays, flushing, keysyms,
    extensions), or None where it is missing."""
    path = ctypes.util.find_library("X11")
    if not path:
        return None
    lx = ctypes.CDLL(path)
    lx.XOpenDisplay.restype = ctypes.c_void_p
    lx.XOpenDisplay.argtypes = [ctypes.c_char_p]
    for name in ("XFlush", "XCloseDisplay"):
        getattr(lx, name).argtypes = [ctypes.c_void_p]
    lx.XStringToKeysym.restype = ctypes.c_ulong
    lx.XStringToKeysym.argtypes = [ctypes.c_char_p]
    lx.XKeysymToKeycode.restype = ctypes.c_ubyte
    lx.XKeysymToKeycode.argtypes = [ctypes.c_void_p, ctypes.c_ulong]
    lx.XQueryExtension.argtypes = [ctypes.c_void_p, ctypes.c_char_p] + [ctypes.POINTER(ctypes.c_int)] * 3
    return lx


def xtest_libs() -> Optional[Tuple[ctypes.CDLL, ctypes.CDLL]]:
    """(libX11, libXtst) through ctypes with the signatures of the calls used here, or None where missing."""
    lx, xtst = x11_lib(), ctypes.util.find_library("Xtst")
    if lx is None or not xtst:
        return None
    lt = ctypes.CDLL(xtst)
    lt.XTestFakeMotionEvent.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_int, ctypes.c_int, ctypes.c_ulong]
    lt.XTestFakeButtonEvent.argtypes = [ctypes.c_void_p, ctypes.c_uint, ctypes.c_int, ctypes.c_ulong]
    lt.XTestFakeKeyEvent.argtypes = [ctypes.c_void_p, ctypes.c_uint, ctypes.c_int, ctypes.c_ulong]
    return lx, lt


def has_extension(display: Optional[str], name: str) -> Optional[bool]:
    """Whether the X display ``display`` (default ``$DISPLAY``) has the extension ``name`` (e.g. "GLX": OpenGL
    on X); None where that cannot be asked (no display named, libX11 missing, the display does not open)."""
    display = display if display is not None else os.environ.get("DISPLAY")
    lx = x11_lib()
    if not display or lx is None:
        return None
    dpy = lx.XOpenDisplay(display.encode())
    if not dpy:
        return None
    try:
        codes = [ctypes.c_int() for _ in range(3)]
        return bool(lx.XQueryExtension(dpy, name.encode(), *(ctypes.byref(c) for c in codes)))
    finally:
        lx.XCloseDisplay(dpy)
