"""Signal-safe entry point of the ``stylize3d`` command (``[project.scripts]`` in pyproject.toml).

SIGINT (Ctrl-C) and SIGTERM are handled from the first line, *before* torch and
the command line are imported (importing torch takes seconds): a signal at any
moment raises :class:`Interrupted` (a ``KeyboardInterrupt``), every writer's
temporary file is removed on the way out (:mod:`stylize3d_core.io.atomic`), and
the command ends with one line on stderr and the status ``128 + signal``
(130 for SIGINT, 143 for SIGTERM), never a traceback. A second signal while the
first one is being handled is ignored, so the clean-up cannot be cut short.

Python drops an exception raised by a signal handler in a few places (a
callback of the import machinery, a finaliser: it prints "Exception ignored"
and carries on). So the handlers also register a commit check with
:mod:`stylize3d_core.io.atomic`: once a signal was received, no temporary
output is renamed over the user's file, whatever swallowed the exception.
"""

from __future__ import annotations

import signal
import sys
import warnings
from typing import List, Optional

PROG = "stylize3d"
HANDLED = (signal.SIGINT, signal.SIGTERM)


class Interrupted(KeyboardInterrupt):
    """Raised in the main thread when SIGINT or SIGTERM arrives; ``signum`` says which."""

    def __init__(self, signum: int) -> None:
        self.signum = int(signum)
        super().__init__(signal.Signals(signum).name)


_received: List[int] = []


def _on_signal(signum: int, _frame) -> None:
    if _received:  # already stopping: let the clean-up finish
        return
    _received.append(signum)
    raise Interrupted(signum)


def raise_if_interrupted() -> None:
    """Raise :class:`Interrupted` if a signal was received (its exception may have been dropped)."""
    if _received:
        raise Interrupted(_received[0])


def install_signal_handlers() -> None:
    """Turn SIGINT and SIGTERM into :class:`Interrupted` (main thread only), and stop every atomic
    write from committing once one was received (see the module docstring)."""
    _received.clear()
    for sig in HANDLED:
        signal.signal(sig, _on_signal)
    from stylize3d_core.io.atomic import add_commit_check  # light: no torch

    add_commit_check(raise_if_interrupted)


def interrupted_status(e: BaseException) -> int:
    """The exit status for an interruption: 128 + the signal (a plain KeyboardInterrupt is SIGINT)."""
    return 128 + getattr(e, "signum", int(signal.SIGINT))


def interrupted_message(e: BaseException) -> str:
    name = signal.Signals(getattr(e, "signum", int(signal.SIGINT))).name
    return "interrupted" if name == "SIGINT" else f"terminated ({name})"


def show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A ``warnings.showwarning`` that prints one clean line (no category, source file or line)."""
    text = " ".join(str(message).split())
    print(f"{PROG}: warning: {text}", file=sys.stderr if file is None else file)


def run(argv: Optional[List[str]] = None) -> int:
    """Install the signal handlers, then import and run :func:`app.cli.main`; return the exit status.

    Warnings raised while the libraries import are shown as one line too.
    """
    warnings.showwarning = show_warning
    try:
        install_signal_handlers()  # in the try: a signal may land while it imports the commit check
        try:
            from app.cli import main  # lazy: imports torch
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
