"""What ``stylize3d info`` reports: the facts a bug report needs, gathered without side effects.

:func:`collect` returns a plain dict (``stylize3d info --json`` prints it as
JSON); :func:`format_report` turns it into aligned ``key: value`` lines. Every
probe is guarded: a library that fails to import is reported with its error
(the most useful line of a bug report about a broken install), never raised.
Nothing here imports a GUI toolkit; whether Open3D was built with its GUI comes
from Open3D's build configuration, and whether a display is there from the
environment (and the X server's socket for a local display).
"""

from __future__ import annotations

import importlib.metadata
import os
import platform
import re
import sys
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Tuple

from . import __version__, resources

Report = Dict[str, Any]


def _guard(probe: Callable[[], Any]) -> Any:
    try:
        return probe()
    except Exception as e:  # noqa: BLE001 -- a failing probe is itself the fact to report
        return {"error": f"{type(e).__name__}: {e}"}


def _dist_version(*names: str) -> Optional[str]:
    for name in names:
        try:
            return importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            continue
    return None


def _torch() -> Report:
    import torch

    return {
        "version": torch.__version__,
        "cuda_build": torch.version.cuda,  # None for a CPU build
        "threads": torch.get_num_threads(),
        "interop_threads": torch.get_num_interop_threads(),
    }


def _open3d() -> Report:
    import open3d

    config = getattr(open3d, "_build_config", {}) or {}
    return {
        "version": open3d.__version__,
        "distribution": next((d for d in ("open3d-cpu", "open3d") if _dist_version(d)), None),
        "gui_built": config.get("BUILD_GUI"),
        "cuda_built": config.get("BUILD_CUDA_MODULE"),
    }


def _opencv() -> Report:
    import cv2

    return {"version": cv2.__version__, "threads": cv2.getNumThreads()}


def _ffmpeg() -> Report:
    import imageio_ffmpeg

    return {"imageio_ffmpeg": imageio_ffmpeg.__version__, "exe": imageio_ffmpeg.get_ffmpeg_exe()}


def _cpus() -> Report:
    affinity = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
    env = {k: os.environ[k] for k in ("OMP_NUM_THREADS", "MKL_NUM_THREADS") if k in os.environ}
    return {"count": os.cpu_count(), "usable": affinity, **({"env": env} if env else {})}


def display_status(environ: Optional[Dict[str, str]] = None, x11_socket_dir: str = "/tmp/.X11-unix") -> Report:
    """Whether a window can be opened: ``{"available": bool, "detail": str}``.

    On Linux and the BSDs that means ``WAYLAND_DISPLAY`` or ``DISPLAY`` is set;
    for a local X display (``:N``) the server's socket must also exist. Other
    systems (macOS, Windows) always have a desktop session unless told otherwise.
    """
    env = os.environ if environ is None else environ
    if not sys.platform.startswith(("linux", "freebsd", "openbsd", "netbsd")):
        return {"available": True, "detail": f"{sys.platform}: desktop session assumed"}
    if env.get("WAYLAND_DISPLAY"):
        return {"available": True, "detail": f"WAYLAND_DISPLAY={env['WAYLAND_DISPLAY']}"}
    display = env.get("DISPLAY", "")
    if not display:
        return {"available": False, "detail": "neither DISPLAY nor WAYLAND_DISPLAY is set "
                                              "(the viewer needs a desktop or xvfb-run)"}
    local = re.fullmatch(r"(?:unix)?:(\d+)(?:\.\d+)?", display)
    if local is not None:
        socket = Path(x11_socket_dir) / f"X{local.group(1)}"
        if not socket.exists():
            return {"available": False, "detail": f"DISPLAY={display} but no X server socket {socket}"}
    return {"available": True, "detail": f"DISPLAY={display}"}


def _gpu() -> Report:
    import torch

    if torch.cuda.is_available():
        names = [torch.cuda.get_device_name(i) for i in range(torch.cuda.device_count())]
        return {"available": True, "detail": f"CUDA: {', '.join(names)}"}
    mps = getattr(torch.backends, "mps", None)
    if mps is not None and mps.is_available():
        return {"available": True, "detail": "Apple MPS"}
    why = "torch is a CPU build" if torch.version.cuda is None else "no CUDA device visible"
    return {"available": False, "detail": f"none ({why}; stylize3d runs on the CPU)"}


def _data() -> Report:
    loc = resources.assets_location()
    models: Dict[str, Any] = {}
    for name in resources.model_names():
        try:
            path = resources.model_path(name)
            models[name] = {"path": str(path), "bytes": path.stat().st_size}
        except Exception as e:  # noqa: BLE001 -- reported, see _guard
            models[name] = {"error": str(e)}
    return {
        "package": resources.ASSETS_PACKAGE,
        "location": None if loc.root is None else str(loc.root),
        "found_as": loc.how,
        "models": models,
        "samples": {"folder": None if loc.root is None else str(loc.root / "samples"),
                    "names": resources.sample_names()},
        "styles": {"folder": None if loc.root is None else str(loc.root / "styles"),
                   "names": resources.style_names()},
    }


def _depth_anything() -> Report:
    from .depth import depth_anything as da

    folder = da.cached_folder()
    return {"model": da.MODEL_ID, "revision": da.REVISION, "transformers": _dist_version("transformers"),
            "weights_cached": folder is not None, "folder": None if folder is None else str(folder),
            "detail": ("ready: --depth depth-anything (auto uses it)" if folder is not None and da.available()
                       else "not ready: " + (da.EXTRA_HINT if not da.available() else da.DOWNLOAD_HINT))}


def collect() -> Report:
    """Everything ``stylize3d info`` prints, as a JSON-serialisable dict."""
    import stylize3d_core

    return {
        "stylize3d": {"version": __version__, "library": str(Path(stylize3d_core.__file__).resolve().parent),
                      "installed_version": _dist_version("stylize3d")},
        "python": {"version": platform.python_version(), "executable": sys.executable,
                   "platform": platform.platform()},
        "torch": _guard(_torch),
        "open3d": _guard(_open3d),
        "opencv": _guard(_opencv),
        "numpy": _guard(lambda: {"version": __import__("numpy").__version__}),
        "onnxruntime": _guard(lambda: {"version": __import__("onnxruntime").__version__}),
        "onnx": _guard(lambda: {"version": __import__("onnx").__version__}),
        "ffmpeg": _guard(_ffmpeg),
        "cpus": _guard(_cpus),
        "data": _guard(_data),
        "depth_anything": _guard(_depth_anything),
        "display": _guard(display_status),
        "gpu": _guard(_gpu),
    }


def _pairs(value: Any, key: str) -> List[Tuple[str, str]]:
    if isinstance(value, dict):
        if not value:
            return [(key, "-")]
        out: List[Tuple[str, str]] = []
        for k, v in value.items():
            out += _pairs(v, f"{key}.{k}" if key else str(k))
        return out
    if isinstance(value, list):
        return [(key, ", ".join(map(str, value)) if value else "-")]
    return [(key, "-" if value is None else str(value))]


def format_report(report: Report) -> str:
    """``section.key  value`` lines, one fact each, keys aligned."""
    pairs = _pairs(report, "")
    width = max(len(k) for k, _ in pairs)
    return "\n".join(f"{k.ljust(width)}  {v}" for k, v in pairs)
