"""Shared scenes and outline helpers of the LDI tests (``tests/scene/test_ldi*.py``; tests/support is on pytest's path)."""

from __future__ import annotations

import numpy as np

RED = np.array([1.0, 0.0, 0.0], np.float32)
BLUE = np.array([0.0, 0.0, 1.0], np.float32)


def square_scene(size=96, lo=30, hi=70, near=1.0, far=3.0):
    """Red square at depth ``near`` on a blue wall at depth ``far``: rgb (S, S, 3), depth (S, S), square (S, S)."""
    square = np.zeros((size, size), bool)
    square[lo:hi, lo:hi] = True
    rgb = np.where(square[..., None], RED, BLUE).astype(np.float32)
    depth = np.where(square, near, far).astype(np.float32)
    return rgb, depth, square


def photo(ldi, canvas_map):
    """The photo part of a canvas map."""
    return canvas_map[ldi.photo_region]


def inner_outline(mask):
    """Pixels of ``mask`` with a 4-neighbour outside it."""
    p = np.pad(mask, 1)
    outside = ~p[:-2, 1:-1] | ~p[2:, 1:-1] | ~p[1:-1, :-2] | ~p[1:-1, 2:]
    return mask & outside


def outer_outline(mask):
    """Pixels outside ``mask`` with a 4-neighbour inside it."""
    p = np.pad(mask, 1)
    inside = p[:-2, 1:-1] | p[2:, 1:-1] | p[1:-1, :-2] | p[1:-1, 2:]
    return ~mask & inside
