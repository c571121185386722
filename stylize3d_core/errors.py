"""Exceptions raised by stylize3d.

Every error caused by something the user gave us (a file, a setting) is an
:class:`InputError` whose message names the offending file or setting and the
problem, so the command line and the viewer can show it as is.
"""

from __future__ import annotations

import os
from typing import Optional, Union

PathLike = Union[str, "os.PathLike[str]"]


class Stylize3DError(Exception):
    """Base class of every exception stylize3d raises on purpose."""


class InputError(Stylize3DError, ValueError):
    """Bad user input: a file that is missing, unreadable or malformed, or a bad setting.

    Args:
        source: the file path, or the name of the setting, that is wrong.
        problem: what is wrong with it, in plain words.
    """

    def __init__(self, source: Optional[PathLike], problem: str) -> None:
        self.source = None if source is None else os.fspath(source)
        self.problem = problem
        super().__init__(problem if self.source is None else f"{self.source}: {problem}")


class ExportError(Stylize3DError, OSError):
    """An output could not be written (disk full, permissions, encoder failure).

    Whatever was at the destination before is left untouched.
    """


class RenderInterrupted(Exception):
    """A render was abandoned on request (its ``should_stop`` check returned True between two stages).

    Not an error: the caller asked for it (the viewer's camera moved on), so it
    is not a :class:`Stylize3DError`.
    """
