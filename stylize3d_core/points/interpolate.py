"""Inverse-distance-weighted (IDW) interpolation from sparse to dense points.

Each dense point takes a weighted mean of the features of its k (the paper: 3)
nearest sparse points, with weights ``1 / (d + eps)`` normalised to sum to 1 (``d`` the
Euclidean distance). A dense point within ``eps`` of a sparse point takes that
sparse point's feature exactly (weights ``[1, 0, 0]``), so a zero distance never
makes an infinity or a NaN.

The work splits in two, because the point positions are fixed for a photo and
only the features change (with the style, or during training):

* :func:`idw_neighbours` (:func:`three_nn` for k = 3) finds the neighbours and
  weights once (not differentiable);
* :func:`interpolate` gathers and blends features with them (differentiable
  with respect to the features), as often as needed.
"""

from __future__ import annotations

from typing import NamedTuple, Optional

import numpy as np
import torch
import torch.nn.functional as F

from .. import threads as _threads
from ..checks import check_finite, check_shape
from ..errors import InputError
from .neighbours import KNNResult, knn

IDW_EPS = 1e-8
"""Distance added before inverting, and the distance under which points coincide."""


class IDWWeights(NamedTuple):
    """Neighbours and weights of :func:`idw_neighbours`; reusable for any features."""

    idx: torch.Tensor  # (N, k) long, indices into the sparse points, nearest first
    weight: torch.Tensor  # (N, k) float32, >= 0, each row sums to 1


def idw_weights(dist: torch.Tensor, eps: float = IDW_EPS) -> torch.Tensor:
    """Normalised IDW weights from distances ``dist`` (N, K) >= 0, nearest first.

    Rows whose first distance is below ``eps`` become one-hot on column 0.
    Computed in float64; returned in the dtype of ``dist``.
    """
    check_shape(dist, "dist", (None, None))
    check_finite(dist, "dist")
    if dist.numel() and float(dist.min()) < 0:
        raise InputError("dist", f"distances must be >= 0, got {float(dist.min())}")
    d = dist.double()  # (N, K)
    coincide = d[:, 0] < eps  # (N,)
    w = (d + eps).reciprocal_()  # (N, K), finite: d >= 0; in place: fewer (N, K) float64 buffers
    w /= w.sum(dim=1, keepdim=True)
    if bool(coincide.any()):
        w[coincide] = torch.nn.functional.one_hot(torch.zeros((), dtype=torch.long), w.shape[1]).to(w.dtype)
    return w.to(dist.dtype)


def idw_neighbours(dense: torch.Tensor, sparse: torch.Tensor, k: int = 3) -> IDWWeights:
    """The ``k`` nearest ``sparse`` points of every ``dense`` point, with IDW weights.

    Args:
        dense: (N, 3) points that receive features.
        sparse: (M, 3) points that carry features, M >= 1. With M < k the
            missing neighbours repeat the nearest one with weight 0.
        k: neighbours per dense point, >= 1 (the paper: 3, see :func:`three_nn`).

    Returns:
        :class:`IDWWeights` with ``idx`` (N, k) and ``weight`` (N, k) float32.
    """
    return idw_from_knn(knn(sparse, dense, k), sparse.shape[0])


def idw_from_knn(res: KNNResult, num_sparse: int) -> IDWWeights:
    """The IDW weights of :func:`idw_neighbours` from its k-NN search ``res`` among ``num_sparse`` points.

    For a search made elsewhere (a :class:`~stylize3d_core.points.neighbours.KNNIndex` reused
    across queries): ``idw_from_knn(knn(sparse, dense, k), len(sparse)) == idw_neighbours(dense, sparse, k)``.
    """
    k = res.idx.shape[1]
    fast = _compiled_weights(res.sq_dist) if num_sparse >= k else None
    if fast is not None:
        return IDWWeights(res.idx, fast)
    dist = res.sq_dist.double().clamp_min(0.0).sqrt()  # (N, k)
    weight = idw_weights(dist)  # (N, k) float64
    if num_sparse < k:
        real = torch.arange(k) < num_sparse  # (k,)
        weight = torch.where(real, weight, torch.zeros_like(weight))
        weight = weight / weight.sum(dim=1, keepdim=True)  # row sums >= weight[:, 0] > 0
    return IDWWeights(res.idx, weight.float())


def _compiled_weights(sq_dist: torch.Tensor) -> Optional[torch.Tensor]:
    """The IDW weights (N, k) float32 of ``idw_from_knn`` from float32 CPU squared distances by the points'
    compiled kernel, the same bits, on the pool's threads (1.7M rows: ~0.1 s -> ~0.01 s); None where it does
    not apply (no Numba, another dtype or device, a non-finite distance: the checked torch lines then)."""
    g = _threads.compiled(__package__ + "._grid_kernels")
    if g is None or sq_dist.dtype != torch.float32 or sq_dist.device.type != "cpu" or sq_dist.dim() != 2:
        return None
    d2 = sq_dist.detach().contiguous().numpy()
    out = np.empty(d2.shape, np.float32)
    ok = _threads.in_parts(lambda a, b: g.idw_rows(d2, IDW_EPS, a, b, out), d2.shape[0], 1 << 16)
    return torch.from_numpy(out) if all(ok) else None


def three_nn(dense: torch.Tensor, sparse: torch.Tensor) -> IDWWeights:
    """:func:`idw_neighbours` with k = 3: ``idx`` (N, 3) and ``weight`` (N, 3) float32."""
    return idw_neighbours(dense, sparse, 3)


def interpolate(features: torch.Tensor, idx: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
    """Blend sparse ``features`` onto dense points: ``out[n] = sum_j weight[n, j] * features[idx[n, j]]``.

    Differentiable with respect to ``features`` (and ``weight``). One fused
    ``torch.nn.functional.embedding_bag`` (mode "sum" with per-sample weights): it
    accumulates the k neighbours in column order into each output row, as a loop of
    ``index_select`` + ``addcmul`` would (bit-identical on the 1 MP sample's 1.7M
    points), 3-4x faster, with no (N, K, C) tensor. In bfloat16 it accumulates in
    float32 and rounds once (the loop rounded after every neighbour).

    Args:
        features: (M, C) features of the sparse points.
        idx: (N, K) long indices into ``features`` (from :func:`three_nn`).
        weight: (N, K) weights (from :func:`three_nn`), cast to the features' dtype.

    Returns:
        (N, C) interpolated features.
    """
    check_shape(features, "features", (None, None))
    check_shape(idx, "idx", (None, None))
    check_shape(weight, "weight", tuple(idx.shape))
    if idx.dtype != torch.long:
        raise InputError("idx", f"expected a long tensor, got {idx.dtype}")
    if idx.numel() > 0 and (int(idx.min()) < 0 or int(idx.max()) >= features.shape[0]):
        lo, hi = int(idx.min()), int(idx.max())
        raise InputError("idx", f"indices must lie in [0, {features.shape[0]}), got [{lo}, {hi}]")
    check_finite(weight, "weight")
    w = weight.to(features.dtype)  # (N, K)
    return F.embedding_bag(idx, features, mode="sum", per_sample_weights=w)  # (N, C)
