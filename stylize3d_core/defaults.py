"""Defaults shared by the library, the command line and the viewer (no heavy imports: the viewer's
and the command line's option parsers read them before torch is loaded)."""

from __future__ import annotations

DEFAULT_STRENGTH = 1.0
"""The style strength of the library, the command line and the viewer unless given: the full style (lower
values keep more of the photo's own colours; ``docs/quality.md`` measures the default)."""
