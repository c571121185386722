"""Reading a user's JSON file (camera paths, trajectories, keyframes, views files) without surprises.

Python's parser recurses once per nested array or object and meets a ``RecursionError`` about 1,000
levels down; a number like ``1e999`` becomes ``inf`` and ``NaN`` is accepted. :func:`read_json_file`
checks the file's size and nesting before parsing and refuses non-finite numbers, so every bad file
is an :class:`~stylize3d_core.errors.InputError` naming the file and the problem.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError, PathLike

MAX_FILE_BYTES = 32 * 1024 * 1024
"""Largest JSON file read (a 10,000-frame camera path written by ``save_camera_path`` is about 6 MB)."""
MAX_JSON_DEPTH = 32
"""Deepest nesting of arrays and objects accepted (the deepest schema read needs 4)."""
_MAYBE_HUGE = re.compile(rb"[0-9]{309}|[eE][+-]?[0-9]{3}")
_BRACKET_STEP = np.zeros(256, np.int8)
_BRACKET_STEP[[ord("["), ord("{")]] = 1
_BRACKET_STEP[[ord("]"), ord("}")]] = -1
_STRING = re.compile(rb'"(?:[^"\\]|\\.)*"', re.DOTALL)


def _reject_constant(name: str) -> float:
    raise ValueError(f"non-finite number {name}")


def _parse_int(text: str) -> int:
    value = int(text)
    try:
        float(value)
    except OverflowError:
        raise ValueError(f"the integer {text[:20]}... ({len(text)} digits) does not fit a floating-point number")
    return value


def _parse_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"the number {text[:40]} does not fit a floating-point number")
    return value


def _json_depth(data: bytes) -> int:
    """Deepest bracket nesting of JSON text (brackets inside strings do not count)."""
    bare = np.frombuffer(_STRING.sub(b'""', data) if b'"' in data else data, dtype=np.uint8)
    step = _BRACKET_STEP[bare]  # +1 opening, -1 closing, 0 other bytes
    step = step[step != 0]
    return int(np.cumsum(step, dtype=np.int32).max(initial=0))


def read_json_file(path: PathLike, what: str, *, max_bytes: int = MAX_FILE_BYTES,
                   max_depth: int = MAX_JSON_DEPTH) -> Any:
    """Parse a user's JSON file with bounded size and nesting; numbers must fit a float64.

    Raises:
        InputError: naming the file: missing, unreadable, too large, nested too
            deeply, not JSON, or with NaN / Infinity / a number too large for a float.
    """
    src = Path(path)
    try:
        size = src.stat().st_size
        if size > max_bytes:
            raise InputError(src, f"the file is {size:,} bytes, more than the {max_bytes:,} a {what} may have")
        data = src.read_bytes()
    except FileNotFoundError:
        raise InputError(src, "file not found") from None
    except OSError as e:
        raise InputError(src, f"cannot read the file: {e.strerror or e}") from None
    if len(data) > max_bytes:  # grew while reading, or not a regular file
        raise InputError(src, f"the file is more than the {max_bytes:,} bytes a {what} may have")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise InputError(src, f"cannot read the file: not UTF-8 text ({e})") from None
    depth = _json_depth(data)
    if depth > max_depth:
        raise InputError(src, f"not a valid JSON {what}: nested {depth} levels deep (at most {max_depth})")
    # The number hooks cost a Python call per number: use them only where a number may not fit a float
    # (a run of 309+ digits, or an exponent of 3+ digits).
    hooks = {"parse_int": _parse_int, "parse_float": _parse_float} if _MAYBE_HUGE.search(data) else {}
    try:
        return json.loads(text, parse_constant=_reject_constant, **hooks)
    except RecursionError:  # not reached below max_depth; kept as a guard
        raise InputError(src, f"not a valid JSON {what}: nested too deeply") from None
    except ValueError as e:  # JSONDecodeError is a ValueError; so are NaN/Infinity and oversized numbers
        raise InputError(src, f"not a valid JSON {what}: {e}") from None


__all__ = ["MAX_FILE_BYTES", "MAX_JSON_DEPTH", "read_json_file"]
