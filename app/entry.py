"""Signal-safe entry point of the ``stylize3d`` command (``[project.scripts]`` in pyproject.toml).

SIGINT (Ctrl-C) and SIGTERM are handled from the first line, *before* torch and
the command line are imported (importing torch takes seconds): a signal at any
moment raises :class:`stylize3d_app.signals.Interrupted` (a ``KeyboardInterrupt``), every writer's
temporary file is removed on the way out (:mod:`stylize3d_core.io.atomic`), and
the command ends with one line on stderr and the status ``128 + signal``
(130 for SIGINT, 143 for SIGTERM), never a traceback. A second signal while the
first one is being handled is ignored, so the clean-up cannot be cut short.
The handlers and their helpers are in :mod:`stylize3d_app.signals`.
"""

from __future__ import annotations

import signal
import sys
import warnings
from typing import List, Optional

from stylize3d_app.signals import (HANDLED, PROG, install_signal_handlers, interrupted_message, interrupted_status,
                         raise_if_interrupted, show_warning)


def run(argv: Optional[List[str]] = None) -> int:
    """Install the signal handlers, then import and run :func:`stylize3d_app.cli.main`; return the exit status.

    Warnings raised while the libraries import are shown as one line too.
    """
    warnings.showwarning = show_warning
    try:
        install_signal_handlers()  # in the try: a signal may land while it imports the commit check
        try:
            from stylize3d_app.cli import main  # lazy: imports torch
        except Exception:
            # a signal that lands inside a C extension's own import (numpy importing datetime) comes out
            # as that extension's ImportError: it is the interruption, not a broken install
            raise_if_interrupted()
            raise

        return main(argv)
    except KeyboardInterrupt as e:  # while importing, or outside main's own handling
        print(f"{PROG}: {interrupted_message(e)}; nothing was written", file=sys.stderr)
        return interrupted_status(e)


def entrypoint() -> None:
    """Console-script entry point (``stylize3d``)."""
    try:
        status = run()
    except KeyboardInterrupt as e:  # a signal between main's return and here
        status = interrupted_status(e)
    for sig in HANDLED:  # the work is done: a late signal no longer interrupts the exit
        signal.signal(sig, signal.SIG_IGN)
    sys.exit(status)


if __name__ == "__main__":
    entrypoint()
