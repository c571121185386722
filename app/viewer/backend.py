"""Which of Filament's graphics back ends draws the viewer window (OpenGL by default; Open3D's own choice on request).

Open3D 0.20 draws its GUI with Filament, and where the only Vulkan device is a
software one (Mesa's llvmpipe: no GPU, Xvfb, a remote desktop) it picks
Filament's *Vulkan* back end. Open3D redraws the whole window at every turn of
its loop that had a mouse move, and through llvmpipe's Vulkan those turns were
slower and far more uneven than through its OpenGL, leaving the render worker
less of the CPU while dragging (``bench_viewer.py --window`` compares the two:
through Vulkan about half the frames are shown per second). So :data:`DEFAULT_BACKEND` is
OpenGL; ``--render-backend auto`` (or ``$STYLIZE3D_RENDER_BACKEND=auto``) leaves
Open3D's choice, ``vulkan`` forces Vulkan.

OpenGL on X needs the server's GLX extension; where the display lacks it (some
VNC or nested X servers) Filament cannot create an OpenGL engine, so
:func:`select_backend` asks the X server first (``xserver.XDisplay``) and keeps
Open3D's choice (Vulkan, which needs no GLX) there.

Open3D's Python API does not expose the choice
(``open3d::visualization::rendering::EngineInstance::SelectBackend``, a C++
static function), so :func:`select_backend` calls the exported function through
ctypes before the GUI creates its engine. Where the library or the function is
not found (another Open3D build), nothing changes and the reason is returned.

**Images in OpenGL.** Open3D 0.20's image widget shows a texture upside down
under its OpenGL back end (the view, the style thumbnails: seen in window
screenshots; the Vulkan back end shows them upright). :func:`widget_image` makes
every image given to a ``gui.ImageWidget`` and flips its rows when the OpenGL
back end was selected, so the widget shows it upright. ``open3d-cpu`` is pinned to
0.20.0 (``pyproject.toml``); ``tests/app/test_viewer_gui.py`` checks the view's
orientation on screen, so a later Open3D that fixes the widget shows up there.

**Start-up.** :func:`start_gui` opens a connection to the X display, selects the back end through it,
initializes Open3D's GUI and only then closes that connection. An X server whose last client disconnects
resets itself (Xvfb does unless started with ``-noreset``), and a client connecting during the reset is
refused; when that client was Open3D's GLFW, Open3D fell back to a windowless mode without a word and the
viewer ran with no window (on a fresh Xvfb, 2 starts in 12 with the GLX check's own connection opened and
closed before ``initialize()``; 0 in 12 with it held). A display that does not open at all is an error that
names it, rather than that windowless run.

Headless: nothing here imports Open3D's GUI at import time; :func:`select_backend` and
:func:`widget_image` import ``open3d`` only for its library and its image type, :func:`start_gui` the GUI
when it is called.
"""

from __future__ import annotations

import ctypes
import os
from pathlib import Path
from typing import Any, Dict, Optional

import numpy as np

from .xserver import XDisplay, x11_lib

BACKENDS: Dict[str, int] = {"auto": 0, "opengl": 1, "vulkan": 2}
"""``--render-backend`` choices and their ``EngineInstance::RenderingType`` values (``auto``: Open3D's own
choice, which is Vulkan on a software Vulkan device)."""

DEFAULT_BACKEND = "opengl"
"""OpenGL where the X server has GLX (else Open3D's choice): twice the frames shown while dragging on a
software renderer (the module docstring)."""

ENV_VAR = "STYLIZE3D_RENDER_BACKEND"
"""Environment variable that sets the back end when ``--render-backend`` is not given (benchmarks, tests)."""

_SELECT_BACKEND = "_ZN6open3d13visualization9rendering14EngineInstance13SelectBackendENS1_13RenderingTypeE"
"""The mangled name of ``EngineInstance::SelectBackend(RenderingType)`` (Itanium C++ ABI, as on Linux)."""


def backend_choice(cli: Optional[str] = None) -> str:
    """The back end to use: ``cli`` when given, else ``$STYLIZE3D_RENDER_BACKEND``, else :data:`DEFAULT_BACKEND`.

    Raises:
        ValueError: the choice is not one of :data:`BACKENDS` (the message names where it came from).
    """
    source, value = ("--render-backend", cli) if cli is not None else (ENV_VAR, os.environ.get(ENV_VAR))
    if value is None or value == "":
        return DEFAULT_BACKEND
    choice = value.strip().lower()
    if choice not in BACKENDS:
        raise ValueError(f"{source} must be one of {', '.join(BACKENDS)}, got {value!r}")
    return choice


def open3d_library() -> Optional[Path]:
    """The path of Open3D's shared library (``libOpen3D.so.*`` beside the ``open3d`` package), or None."""
    import open3d

    found = sorted(Path(open3d.__file__).resolve().parent.glob("libOpen3D.so*"))
    return found[0] if found else None


def select_backend(choice: str, display: Optional[XDisplay] = None) -> str:
    """Ask Filament for ``choice`` (a key of :data:`BACKENDS`) before the GUI starts; returns what happened.

    Call it before ``gui.Application.instance.initialize()``: the engine is created once, with the back end
    selected then. ``auto`` leaves Open3D's own choice, and so does ``opengl`` on an X display without GLX
    (asked through ``display``, an open connection; None: not asked). Never raises for a missing library
    or function (another Open3D build): the returned text says the default is kept. :func:`start_gui`
    calls it with the connection it holds.
    """
    value = BACKENDS[choice]
    if choice == "auto":
        return choice
    if choice == "opengl" and display is not None and not display.has_extension("GLX"):
        return "opengl not available (the X display has no GLX); Open3D's choice kept"
    lib_path = open3d_library()
    if lib_path is None:
        return f"{choice} not selectable (no libOpen3D found); Open3D's choice kept"
    try:
        fn = getattr(ctypes.CDLL(str(lib_path)), _SELECT_BACKEND)
    except (OSError, AttributeError) as e:
        return f"{choice} not selectable ({type(e).__name__}: {e}); Open3D's choice kept"
    fn.argtypes = [ctypes.c_int]
    fn.restype = None
    fn(value)
    global _flip_rows
    _flip_rows = choice == "opengl"
    return choice


_flip_rows = False
"""Whether :func:`widget_image` flips rows: set by :func:`select_backend` (the OpenGL back end selected)."""


class NoDisplayError(RuntimeError):
    """The X display does not open (not set, or no X server answers there): the viewer cannot show a window."""


def start_gui(choice: str) -> str:
    """Select ``choice`` (see :func:`select_backend`) and initialize ``gui.Application.instance``, holding a
    connection to the X display throughout (the module docstring); returns what :func:`select_backend` said.

    Raises:
        NoDisplayError: ``$DISPLAY`` is not set or does not open (where libX11 can be loaded to ask).
    """
    import open3d.visualization.gui as gui

    display = XDisplay.open()
    if display is None and x11_lib() is not None:
        name = os.environ.get("DISPLAY")
        raise NoDisplayError(
            f"cannot open the X display {name!r}: no X server answers there" if name else
            "no X display: DISPLAY is not set (the viewer needs a desktop session, or an X server such as "
            "Xvfb on a machine without one)")
    try:
        chosen = select_backend(choice, display)  # before the engine exists: initialize() creates it
        gui.Application.instance.initialize()
    finally:
        if display is not None:
            display.close()
    return chosen


def widget_image(rgb: np.ndarray) -> Any:
    """The ``open3d.geometry.Image`` to give a ``gui.ImageWidget`` so that it shows ``rgb`` (H, W, 3) uint8
    upright: a copy with its rows reversed under the OpenGL back end, else ``rgb`` as it is (contiguous)."""
    import open3d as o3d

    return o3d.geometry.Image(np.ascontiguousarray(rgb[::-1] if _flip_rows else rgb))


__all__ = ["BACKENDS", "DEFAULT_BACKEND", "ENV_VAR", "NoDisplayError", "backend_choice", "open3d_library",
           "select_backend", "start_gui", "widget_image"]
