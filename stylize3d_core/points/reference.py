"""Slow, obvious reference implementations of the point operations.

They compute everything from the full pairwise distance matrix in float64, so
they are only for small clouds (a few thousand points): the tests compare the
fast operations of :mod:`stylize3d_core.points` against them. Ties are broken
by the lower index.
"""

from __future__ import annotations

import numpy as np
import torch

from .interpolate import IDWWeights, idw_weights
from .neighbours import BallQueryResult, KNNResult


def pairwise_sq_dist(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """(M, N) float64 squared distances between points ``a`` (M, 3) and ``b`` (N, 3)."""
    diff = a.double()[:, None, :] - b.double()[None, :, :]  # (M, N, 3)
    return (diff * diff).sum(dim=-1)


def farthest_point_sample_reference(xyz: torch.Tensor, n_samples: int, first: int = 0) -> torch.Tensor:
    """Textbook FPS starting at point ``first``: (n_samples,) long indices.

    Each step picks the not-yet-picked point whose distance to the nearest pick
    is largest (the lowest index among equals).
    """
    pts = xyz.detach().cpu().double().numpy()  # (N, 3); numpy: cheap per-step ops
    picked = np.zeros(len(pts), dtype=bool)
    out = [first]
    picked[first] = True
    min_d = ((pts - pts[first]) ** 2).sum(axis=1)  # (N,)
    for _ in range(n_samples - 1):
        nxt = int(np.argmax(np.where(picked, -1.0, min_d)))  # first maximum: lowest index
        out.append(nxt)
        picked[nxt] = True
        min_d = np.minimum(min_d, ((pts - pts[nxt]) ** 2).sum(axis=1))
    return torch.tensor(out, dtype=torch.long)


def coverage_radius(xyz: torch.Tensor, idx: torch.Tensor) -> float:
    """Largest distance from a point of ``xyz`` (N, 3) to its nearest pick ``xyz[idx]``."""
    d = pairwise_sq_dist(xyz, xyz[idx])  # (N, n)
    return float(d.min(dim=1).values.max().sqrt())


def _sorted_neighbours(source: torch.Tensor, query: torch.Tensor):
    """Squared distances (M, N) and, per row, source indices by (distance, index)."""
    d = pairwise_sq_dist(query, source)  # (M, N)
    order = torch.sort(d, dim=1, stable=True).indices  # (M, N)
    return d, order


def knn_reference(source: torch.Tensor, query: torch.Tensor, k: int) -> KNNResult:
    """Brute-force k nearest neighbours (same padding as :func:`points.knn`)."""
    d, order = _sorted_neighbours(source, query)
    cols = [j if j < source.shape[0] else 0 for j in range(k)]  # pad with the nearest
    idx = order[:, cols]  # (M, k)
    return KNNResult(idx, d.gather(1, idx))


def ball_query_reference(source: torch.Tensor, query: torch.Tensor, radius: float, k: int) -> BallQueryResult:
    """Brute-force radius-bounded k-NN with :func:`points.ball_query`'s padding."""
    d, order = _sorted_neighbours(source, query)
    n = source.shape[0]
    cols = [j if j < n else 0 for j in range(k)]
    inside = d.gather(1, order) <= radius * radius  # (M, N), a prefix of each row
    count = inside.sum(dim=1).clamp_max(k)  # (M,)
    idx = order[:, cols]  # (M, k)
    idx = torch.where(torch.arange(k) < count[:, None], idx, order[:, :1])  # (M, k)
    return BallQueryResult(idx, count)


def three_nn_reference(dense: torch.Tensor, sparse: torch.Tensor) -> IDWWeights:
    """Brute-force 3 nearest sparse points and IDW weights, all in float64."""
    d, order = _sorted_neighbours(sparse, dense)
    m = sparse.shape[0]
    cols = [j if j < m else 0 for j in range(3)]
    idx = order[:, cols]  # (N, 3)
    weight = idw_weights(d.gather(1, idx).sqrt())  # (N, 3) float64
    if m < 3:
        weight[:, m:] = 0.0
        weight = weight / weight.sum(dim=1, keepdim=True)
    return IDWWeights(idx, weight)


def interpolate_reference(features: torch.Tensor, idx: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
    """``(features[idx] * weight[..., None]).sum(1)``: (N, C) from (M, C)."""
    return (features[idx] * weight.to(features.dtype)[..., None]).sum(dim=1)
