"""A private X server and real input events for driving the viewer window (window tests, ``bench_viewer --window``).

Headless like the test hooks (:mod:`stylize3d_app.viewer.script`): nothing here imports
Open3D. :func:`start_xvfb` starts an Xvfb that picks a free display number
itself (``-displayfd``); :func:`xtest_libs` loads libX11 and libXtst through
ctypes, whose ``XTestFake*Event`` calls send real mouse and key events (:func:`xtest_click`: a click
that Open3D's GUI takes on a loaded machine);
:class:`XDisplay` holds a connection to a display and asks it for an extension
(GLX: can it run OpenGL).
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


def xtest_click(libs: Tuple[ctypes.CDLL, ctypes.CDLL], dpy: int, x: int, y: int, *, press: bool = True,
                steps: int = 7, step_s: float = 0.06, settle_s: float = 0.6, hold_s: float = 0.6,
                after_s: float = 1.0) -> None:
    """Move the pointer onto (x, y) of display connection ``dpy`` in ``steps`` moves from below, as a hand
    does, wait ``settle_s``, and (``press``) click button 1, holding it ``hold_s``, then wait ``after_s``.

    ImGui (Open3D's GUI) takes a click on an item only when one of its frames saw the pointer over the item
    and a later one the press; on a busy machine (frames of 0.2 s and more) a single move, the press and the
    release fell into one frame and a menu did not open."""
    lx, lt = libs
    for k in range(steps - 1, -1, -1):
        lt.XTestFakeMotionEvent(dpy, -1, int(x), int(y) + k, 0)
        lx.XFlush(dpy)
        time.sleep(step_s)
    time.sleep(settle_s)
    if press:
        lt.XTestFakeButtonEvent(dpy, 1, 1, 0)
        lx.XFlush(dpy)
        time.sleep(hold_s)
        lt.XTestFakeButtonEvent(dpy, 1, 0, 0)
        lx.XFlush(dpy)
        time.sleep(after_s)


class XDisplay:
    """An open connection to an X display (``XDisplay.open``); a context manager that closes it.

    The viewer holds one from before Open3D starts until Open3D has its own connection: an X server whose
    last client disconnects resets itself (Xvfb does, unless started with ``-noreset``), and a connection
    opened during that reset fails; Open3D's GLFW then fell back to a windowless mode, silently."""

    def __init__(self, lx: ctypes.CDLL, handle: int, name: str) -> None:
        self._lx, self._handle, self.name = lx, handle, name

    @classmethod
    def open(cls, display: Optional[str] = None) -> Optional["XDisplay"]:
        """A connection to ``display`` (default ``$DISPLAY``), or None where none is named, libX11 is missing
        or the display does not open."""
        display = display if display is not None else os.environ.get("DISPLAY")
        lx = x11_lib()
        if not display or lx is None:
            return None
        handle = lx.XOpenDisplay(display.encode())
        return cls(lx, handle, display) if handle else None

    def has_extension(self, name: str) -> bool:
        """Whether the server has the extension ``name`` (e.g. "GLX": OpenGL on X)."""
        if not self._handle:
            raise ValueError(f"the connection to {self.name} is closed")
        codes = [ctypes.c_int() for _ in range(3)]
        return bool(self._lx.XQueryExtension(self._handle, name.encode(), *(ctypes.byref(c) for c in codes)))

    def close(self) -> None:
        if self._handle:
            self._lx.XCloseDisplay(self._handle)
            self._handle = 0

    def __enter__(self) -> "XDisplay":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
