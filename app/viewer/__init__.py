"""``stylize3d-viewer``: the interactive desktop viewer (Open3D GUI).

    stylize3d-viewer [PHOTO] [--style STYLE] [--depth SPEC] [--refine-depth METHOD]
                     [--model CHECKPOINT | --no-model]
                     [--max-size 640] [--fov DEG] [--strength 1] [--threads 1] [--size 1280x800] [--invert-wheel]
                     [--full-threads N] [--decoder-threads N] [--render-backend opengl|vulkan|auto]

Modules: :mod:`.orbit` (camera math), :mod:`.state` (view state, preview sizes,
typed paths), :mod:`.render_state` (when the view needs which frame), :mod:`.backend` (the
graphics back end that draws the window),
:mod:`.settings` (recent files, kept between runs), :mod:`.worker` (the compute
thread), :mod:`.session` (3D photo, model, renders, export), :mod:`.panel`,
:mod:`.window` and :mod:`.actions` (widgets, the window and its controllers, main
thread), :mod:`.script` (test hooks). Only the last
four import Open3D's GUI, and only when the viewer starts, so the rest can be
imported and tested headless.

The photo options (the photo, ``--depth``, ``--refine-depth``, ``--max-size``,
``--fov``, ...) are derived from ``stylize3d_core.pipeline.PhotoSpec``'s fields,
as ``stylize3d render``'s are; only the viewer's own options are written here.
"""

from __future__ import annotations

import argparse
import os
import sys
from typing import List, Optional

from stylize3d_core.defaults import DEFAULT_STRENGTH
from stylize3d_core.errors import InputError
from stylize3d_core.memory import keep_freed_memory
from stylize3d_core.pipeline import PhotoSpec
from stylize3d_core.resources import resolve_model

from ..options import add_options, from_args
from .backend import BACKENDS, DEFAULT_BACKEND, ENV_VAR, NoDisplayError, backend_choice, start_gui
from .session import DEFAULT_MODEL
from .state import VIEWER_MAX_SIZE

PROG = "stylize3d-viewer"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG,
        description="Browse a stylized 3D photo: drag to orbit (right/shift-drag pans, wheel moves "
                    "forwards), change the style and its strength, export videos.")
    add_options(p, PhotoSpec, defaults={"max_size": VIEWER_MAX_SIZE}, positional={"photo": "?"})
    p.add_argument("--style", default=None, help="style image to apply")
    models = p.add_mutually_exclusive_group()
    models.add_argument("--model", default=None, metavar="CHECKPOINT",
                        help="model: a shipped model's name (lite) or a checkpoint (.safetensors); default: "
                             f"the shipped lite model ({DEFAULT_MODEL}) when it is installed, else the plain "
                             "3D photo is shown")
    models.add_argument("--no-model", action="store_true",
                        help="show the plain 3D photo even if a model is available")
    p.add_argument("--strength", type=float, default=DEFAULT_STRENGTH,
                   help=f"style strength in [0, 1] (default {DEFAULT_STRENGTH:g})")
    p.add_argument("--threads", type=int, default=1,
                   help="torch threads of the compute worker (default 1: on a 2-core machine the other core "
                        "draws the window; more threads only help on an otherwise idle machine with more cores)")
    p.add_argument("--full-threads", type=int, default=None,
                   help="torch threads of the view's full-quality frames, rendered once the camera rests and the "
                        "window no longer redraws (default: one less than the cores where there are 3 or more, "
                        "else 1)")
    p.add_argument("--decoder-threads", type=int, default=None,
                   help="ONNX Runtime threads of the decoder in the view's full-quality frames (default: the "
                        "cores; its threads sleep when idle, unlike torch's)")
    p.add_argument("--invert-wheel", action="store_true",
                   help="wheel up moves backwards (default: wheel up moves forwards, as in common 3D viewers)")
    p.add_argument("--render-backend", default=None, choices=sorted(BACKENDS),
                   help=f"graphics back end that draws the window (default {DEFAULT_BACKEND}, or "
                        f"${ENV_VAR}; opengl needs the X server's GLX and keeps Open3D's choice without it; "
                        "auto: Open3D's choice, Vulkan where the only Vulkan device is the software llvmpipe, "
                        "where opengl doubled the frames shown while dragging: see app/viewer/backend.py)")
    p.add_argument("--size", default="1280x800", metavar="WxH", help="window size in pixels (default 1280x800)")
    # the test harness (app/viewer/script.py; docs/architecture.md, "Driving the viewer"): not in --help
    p.add_argument("--test-script", default=None, metavar="JSON", help=argparse.SUPPRESS)
    p.add_argument("--test-report", default=None, metavar="JSON", help=argparse.SUPPRESS)
    return p


def default_full_threads(cores: int) -> int:
    """Torch threads of the view's full-quality frames on a machine of ``cores`` (torch's default count):
    one less than the cores where there are 3 or more (the window and the rest of the desktop keep one),
    else 1. On 2 cores a second thread made a 768x512 full frame 1.38 -> 1.0-1.16 s on a quiet machine but
    4-18 s where another process's OpenMP threads spun on the other core (``bench_viewer --window``)."""
    return max(1, int(cores) - 1) if int(cores) >= 3 else 1


GUI_SWITCH_INTERVAL_S = 0.0005
"""``sys.setswitchinterval`` of the viewer: how long a thread may hold the GIL before another takes it."""

def main(argv: Optional[List[str]] = None) -> int:
    """Run the viewer until its window closes; returns the exit status (1 if a test script failed)."""
    args = build_parser().parse_args(argv)
    try:
        width, height = (int(v) for v in args.size.lower().split("x"))
    except ValueError:
        print(f"{PROG}: --size must look like 1280x800, got {args.size!r}", file=sys.stderr)
        return 2
    if not 0.0 <= args.strength <= 1.0:
        print(f"{PROG}: --strength must be in [0, 1], got {args.strength}", file=sys.stderr)
        return 2
    try:
        spec = from_args(PhotoSpec, args)
    except InputError as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
        return 2
    for flag, value in (("--threads", args.threads), ("--full-threads", args.full_threads),
                        ("--decoder-threads", args.decoder_threads)):
        if value is not None and value < 1:
            print(f"{PROG}: {flag} must be >= 1, got {value}", file=sys.stderr)
            return 2
    try:
        backend = backend_choice(args.render_backend)
    except ValueError as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
        return 2
    model = args.model
    if model is not None:
        try:
            model = resolve_model(model)  # a name ("lite") or a path
        except InputError as e:
            print(f"{PROG}: error: {e}", file=sys.stderr)
            return 2
    import open3d.visualization.gui as gui
    import torch

    cores = torch.get_num_threads()  # torch's default: the cores
    full_threads = args.full_threads or default_full_threads(cores)
    decoder_threads = args.decoder_threads or cores
    torch.set_num_threads(args.threads)
    # The compute worker runs Python between its torch calls; with the default 5 ms switch interval every
    # GUI callback (mouse moves, ticks, frames handed over) could wait that long for the GIL, several times per
    # frame: a busy Python thread would halve the window's image updates.
    sys.setswitchinterval(GUI_SWITCH_INTERVAL_S)
    keep_freed_memory()  # stylize3d_core.memory: freed memory kept for the next frame
    from stylize3d_core.pipeline import warm_up

    warm_up()  # in the background while the window opens: the first photo's once-per-process costs

    from .script import ScriptRunner, read_script
    from .window import ViewerOptions, ViewerWindow

    steps = read_script(args.test_script) if args.test_script else None
    app = gui.Application.instance
    try:
        chosen = start_gui(backend)  # the back end, then Open3D's GUI (and its engine)
    except NoDisplayError as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
        return 2
    if chosen != backend:
        print(f"{PROG}: render back end: {chosen}", file=sys.stderr)
    viewer = ViewerWindow(ViewerOptions(spec=spec, style=args.style, model=model, use_model=not args.no_model,
                                        strength=args.strength, width=width, height=height,
                                        invert_wheel=args.invert_wheel, full_threads=full_threads,
                                        decoder_threads=decoder_threads))
    import signal  # SIGINT / SIGTERM close the window like its close button (handled at the next GUI callback)

    received: List[int] = []

    def _close_on_signal(signum: int, _frame) -> None:
        received.append(signum)
        viewer.request_close()

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _close_on_signal)
    runner = None
    if steps is not None:
        runner = ScriptRunner(viewer, steps, args.test_report or "viewer-test-report.json")
        runner.start()
    app.run()
    viewer.worker.stop(timeout=10.0)
    if runner is not None:
        runner.thread.join(timeout=10.0)
        return 0 if runner.ok else 1
    return 128 + received[0] if received else 0


def run_viewer_process(argv: List[str], display: str) -> None:
    """Entry point of a ``multiprocessing`` "spawn" child that runs the viewer on X display ``display``.

    The child exits with the viewer's status (0, or 1 when a test script failed);
    a crash shows as a negative exit code in the parent.
    """
    os.environ["DISPLAY"] = display
    sys.exit(main(argv))


def entrypoint() -> None:
    """Console-script entry point (``stylize3d-viewer``)."""
    sys.exit(main())


__all__ = ["entrypoint", "main", "build_parser", "default_full_threads", "run_viewer_process"]
