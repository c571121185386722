"""Defaults shared by the library, the command line and the viewer (no heavy imports: the viewer's
and the command line's option parsers read them before torch is loaded)."""

from __future__ import annotations

DEFAULT_STRENGTH = 1.0
"""The style strength of the library, the command line and the viewer unless given: the full style. (At
0.8, the earlier default, the frames' Lab colour-statistics distance to the style was 1.6x the per-frame
2D network's over the quality set's 16 pairs, at 1.0 1.3x, with the same two-pass palette map then;
docs/quality.md.)"""
