"""Validation helpers used at the public boundary of the library.

They raise :class:`~stylize3d_core.errors.InputError` (never ``assert``) with the
expected and the actual value, and never modify their argument.
"""

from __future__ import annotations

from typing import Optional, Sequence, Union

import numpy as np
import torch

from .errors import InputError

Array = Union[np.ndarray, torch.Tensor]


def check_shape(x: Array, name: str, shape: Sequence[Optional[int]]) -> None:
    """Raise unless ``x`` has ``len(shape)`` dims and matches every non-None size.

    Example: ``check_shape(points, "points", (None, 3))``.
    """
    actual = tuple(x.shape)
    ok = len(actual) == len(shape) and all(s is None or s == a for s, a in zip(shape, actual))
    if not ok:
        want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
        raise InputError(name, f"expected shape {want}, got {actual}")


def check_finite(x: Array, name: str) -> None:
    """Raise if ``x`` holds a NaN or an infinity."""
    finite = torch.isfinite(x).all().item() if isinstance(x, torch.Tensor) else bool(np.isfinite(x).all())
    if not finite:
        raise InputError(name, "contains NaN or infinite values")


def check_range(value: float, name: str, low: float, high: float, *, inclusive: bool = True) -> float:
    """Return ``float(value)`` if it lies in [low, high] (or (low, high)), else raise."""
    v = float(value)
    inside = (low <= v <= high) if inclusive else (low < v < high)
    if not inside or not np.isfinite(v):
        brackets = "[]" if inclusive else "()"
        raise InputError(name, f"must be in {brackets[0]}{low}, {high}{brackets[1]}, got {value!r}")
    return v


def check_choice(value: str, name: str, choices: Sequence[str]) -> str:
    """Return ``value`` if it is one of ``choices``; otherwise raise, listing them."""
    if value not in choices:
        raise InputError(name, f"must be one of {', '.join(map(repr, choices))}; got {value!r}")
    return value
