"""Tests of the plain renderer's point order (stratified: random level prefixes, memory order inside levels)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from stylize3d_core.render.plain import PREVIEW_MIN_POINTS, StratifiedOrder, random_order


@pytest.mark.parametrize("n", [0, 1, 500, 1024, 1025, 50_000])
def test_is_a_permutation_with_boundaries_from_0_to_n(n):
    s = StratifiedOrder(n, seed=3)
    assert torch.equal(s.order.sort().values, torch.arange(n))
    assert s.bounds[0] == 0 and s.bounds[-1] == n
    assert all(a < b for a, b in zip(s.bounds[:-1], s.bounds[1:]))
    if n > PREVIEW_MIN_POINTS:
        assert s.bounds[1] == PREVIEW_MIN_POINTS
        # each level at most 1/8 of what comes before it (rounded up)
        assert all(b - a <= max(1, -(-a // 8)) for a, b in zip(s.bounds[1:-1], s.bounds[2:]))


def test_levels_are_random_subsets_in_memory_order():
    n = 50_000
    s = StratifiedOrder(n, seed=0)
    perm = random_order(n, 0)
    for lo, hi in zip(s.bounds[:-1], s.bounds[1:]):
        level = s.order[lo:hi]
        assert torch.all(level[1:] > level[:-1])  # ascending original index inside the level
        assert torch.equal(level, perm[lo:hi].sort().values)  # the same points as the random order's
    # a prefix at a boundary is spread over the whole cloud, not its beginning
    k = s.prefix(5000)
    hist = np.histogram(s.order[:k].numpy(), bins=10, range=(0, n))[0]
    assert hist.min() > 0.7 * k / 10


def test_prefix_rounds_up_to_a_boundary():
    s = StratifiedOrder(50_000, seed=0)
    for count in (0, 1, 1024, 1025, 3000, 49_999, 50_000, 10**7):
        k = s.prefix(count)
        assert k in s.bounds and k >= min(count, 50_000)
        assert k <= max(PREVIEW_MIN_POINTS, count * 1.125 + 1)
    assert s.prefix(1024) == 1024 and s.prefix(10**7) == 50_000
