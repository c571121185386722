"""Which of Filament's graphics back ends draws the viewer window (OpenGL by default).

Open3D 0.20 draws its GUI with Filament, and where the only Vulkan device is a
software one (Mesa's llvmpipe: no GPU, Xvfb, a remote desktop) it picks
Filament's *Vulkan* back end. On such a machine each redraw of the window costs
several times what the same redraw costs through llvmpipe's OpenGL, and Open3D
redraws the whole window for every mouse-motion event, so the software Vulkan
path left the render worker a fraction of a core while dragging
(``bench_viewer.py --window`` on a quiet 2-core machine, the back ends
alternating: 28.3-32.6 frames shown per second while dragging through OpenGL,
11.7-15.3 through Vulkan; GUI-loop turns p90 18-19 ms against 90-159 ms). With a
GPU either back end redraws quickly; ``--render-backend auto`` restores Open3D's
own choice.

OpenGL on X needs the server's GLX extension; where the display lacks it (some
VNC or nested X servers) Filament cannot create an OpenGL engine, so
:func:`select_backend` asks the X server first (:func:`glx_on_display`) and keeps
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

Headless: nothing here imports Open3D's GUI; :func:`select_backend` and
:func:`widget_image` import ``open3d`` only for its library and its image type.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
from pathlib import Path
from typing import Any, Dict, Optional

import numpy as np

BACKENDS: Dict[str, int] = {"auto": 0, "opengl": 1, "vulkan": 2}
"""``--render-backend`` choices and their ``EngineInstance::RenderingType`` values (``auto``: Open3D's own
choice, which is Vulkan on a software Vulkan device)."""

DEFAULT_BACKEND = "opengl"

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

    folder = Path(open3d.__file__).resolve().parent
    found = sorted(folder.glob("libOpen3D.so*")) + sorted(folder.glob("*/libOpen3D.so*"))
    return found[0] if found else None


def glx_on_display(display: Optional[str] = None) -> Optional[bool]:
    """Whether the X display ``display`` (default ``$DISPLAY``) has the GLX extension (OpenGL on X); None
    where that cannot be asked (no display named, libX11 missing, the display does not open)."""
    name = display if display is not None else os.environ.get("DISPLAY")
    path = ctypes.util.find_library("X11")
    if not name or not path:
        return None
    lx = ctypes.CDLL(path)
    lx.XOpenDisplay.restype = ctypes.c_void_p
    lx.XOpenDisplay.argtypes = [ctypes.c_char_p]
    lx.XQueryExtension.argtypes = [ctypes.c_void_p, ctypes.c_char_p] + [ctypes.POINTER(ctypes.c_int)] * 3
    lx.XCloseDisplay.argtypes = [ctypes.c_void_p]
    dpy = lx.XOpenDisplay(name.encode())
    if not dpy:
        return None
    try:
        codes = [ctypes.c_int() for _ in range(3)]
        return bool(lx.XQueryExtension(dpy, b"GLX", *(ctypes.byref(c) for c in codes)))
    finally:
        lx.XCloseDisplay(dpy)


def select_backend(choice: str) -> str:
    """Ask Filament for ``choice`` (a key of :data:`BACKENDS`) before the GUI starts; returns what happened.

    Call it before ``gui.Application.instance.initialize()``: the engine is created once, with the back end
    selected then. ``auto`` leaves Open3D's own choice, and so does ``opengl`` on an X display without GLX.
    Never raises for a missing library or function (another Open3D build): the returned text says the
    default is kept.
    """
    value = BACKENDS[choice]
    if choice == "auto":
        return choice
    if choice == "opengl" and glx_on_display() is False:
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


def rows_flipped() -> bool:
    """Whether images for ``gui.ImageWidget`` are given upside down (the OpenGL back end; see the module doc)."""
    return _flip_rows


def widget_image(rgb: np.ndarray) -> Any:
    """The ``open3d.geometry.Image`` to give a ``gui.ImageWidget`` so that it shows ``rgb`` (H, W, 3) uint8
    upright: a copy with its rows reversed under the OpenGL back end, else ``rgb`` as it is (contiguous)."""
    import open3d as o3d

    return o3d.geometry.Image(np.ascontiguousarray(rgb[::-1] if _flip_rows else rgb))


__all__ = ["BACKENDS", "DEFAULT_BACKEND", "ENV_VAR", "backend_choice", "glx_on_display", "open3d_library",
           "rows_flipped", "select_backend", "widget_image"]
