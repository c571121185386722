"""Signals as exceptions for the ``stylize3d`` command: SIGINT (Ctrl-C) and SIGTERM raise
:class:`Interrupted` (a ``KeyboardInterrupt``) in the main thread, and the helpers that turn one into
the command's last line and exit status.

Python drops an exception raised by a signal handler in a few places (a callback of the import
machinery, a finaliser: it prints "Exception ignored" and carries on). So the handlers also register a
commit check with :mod:`stylize3d_core.io.atomic`: once a signal was received, no temporary output is
renamed over the user's file, whatever swallowed the exception.

Light on purpose (the standard library only until the handlers are installed): :mod:`stylize3d_app.entry`
installs them before torch is imported; :mod:`stylize3d_app.cli` uses the helpers.
"""

from __future__ import annotations

import signal
import sys
from typing import List

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
