"""Nearest-neighbour search and ball query on point clouds.

Both run on :class:`GridKNN`, an exact search on a uniform grid compiled with Numba (the
rasterizer's dependency already), where Numba imports, else on a k-d tree from Open3D's tensor API
(``open3d.core.nns``; ``BACKEND = "open3d"`` chooses it): the same distances to the bit, the same
neighbours but for the order among equidistant points. The grid is faster on photo clouds (below) and
runs without the GIL. A *ball query* here is a
radius-bounded k-nearest-neighbour search: the ``k`` nearest source points of
each query, nearest first, keeping those within the radius. That is what the
encoder wants (the closest points of a neighbourhood, never an arbitrary subset
of a crowded ball), and it costs one k-NN search plus a mask.

Why not the alternatives (``tests/benchmarks/bench_points.py``, photo-like NDC clouds,
the encoder's stem search, k=16, r=0.015, all N points among all N, on the
project's busy 2-core CPU): k-NN + mask takes 0.25 / 0.5-1.0 / 1.5-3.6 s at
75k / 300k / 1M points. Open3D's ``hybrid_search`` (its own radius-bounded
k-NN) costs in proportion to the points inside each ball, not to k: 0.07 / 1.0 /
6.1 s here, and 19 s for r=0.05 over 300k points. ``scipy.spatial.cKDTree``
is about as fast as Open3D (0.12 / 0.8 / 2.1 s) but scipy is not a runtime
dependency.

A :class:`KNNIndex` keeps the tree of one cloud for several searches, and
:func:`ball_from_knn` turns one k-NN result into the ball query of any radius
(and, row by row, of any subset of its queries): the encoder's hierarchy
(:mod:`stylize3d_core.models.scene_geometry`) makes one search per level that way.

The search itself is not differentiable and does not need to be: neighbourhoods
depend only on point positions, which are fixed for a photo. All searches run in
float32.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Optional, Tuple

import numpy as np
import torch

from .. import threads as _threads
from ..checks import check_finite, check_range, check_shape
from ..errors import InputError


class KNNResult(NamedTuple):
    """The ``k`` nearest source points of each query, nearest first."""

    idx: torch.Tensor  # (M, k) long, indices into the source points
    sq_dist: torch.Tensor  # (M, k) float32, squared Euclidean distances


class BallQueryResult(NamedTuple):
    """Up to ``k`` source points within a radius of each query, nearest first.

    Row ``i`` holds ``count[i]`` valid neighbours followed by padding. Padding
    repeats the nearest neighbour (as PointNet++ repeats the first one found),
    so max- or min-pooling over a row ignores it. A query with no source point
    inside the ball has ``count == 0`` and a row filled with its nearest source
    point, which lies outside the ball.
    """

    idx: torch.Tensor  # (M, k) long, indices into the source points
    count: torch.Tensor  # (M,) long, number of neighbours inside the ball, in [0, k]

    def mask(self) -> torch.Tensor:
        """(M, k) bool: True where ``idx`` is a neighbour inside the ball."""
        k = self.idx.shape[1]
        return torch.arange(k, device=self.count.device) < self.count[:, None]


def check_count(value: int, name: str, low: int) -> int:
    """Return ``value`` if it is an integer >= ``low`` (bools rejected), else raise."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
        raise InputError(name, f"must be an integer >= {low}, got {value!r}")
    return int(value)


def _as_f32_array(points: torch.Tensor, name: str, allow_empty: bool = False) -> np.ndarray:
    """Validated (N, 3) float32 C-contiguous numpy copy/view of ``points``."""
    check_shape(points, name, (None, 3))
    if points.shape[0] == 0 and not allow_empty:
        raise InputError(name, "the point cloud is empty")
    if not torch.is_floating_point(points):
        raise InputError(name, f"expected a floating-point tensor, got {points.dtype}")
    check_finite(points, name)
    return np.ascontiguousarray(points.detach().cpu().numpy(), dtype=np.float32)


QUERY_CHUNK_RESULTS = 1 << 19
"""Neighbours (queries x k) found per call of Open3D's search (:meth:`KNNIndex.knn`): ~50-100 ms each."""


def _grid_kernels():
    """The compiled grid search (None where Numba is missing or fails to import: Open3D's k-d tree then)."""
    return _threads.compiled(__package__ + "._grid_kernels")


BACKENDS = ("grid", "open3d")
BACKEND = "grid"
"""The search :class:`KNNIndex` builds: ``"grid"`` (:class:`GridKNN`, where Numba imports) or ``"open3d"``
(Open3D's k-d tree; also wherever the grid cannot run)."""

GRID_SAMPLE = 64
"""Points whose nearest-neighbour distance (brute force) sizes the grid (:class:`GridKNN`)."""

GRID_MAX_CELLS_PER_POINT = 16
"""The grid has at most this many cells per point (and at least 4096 in all): a photo's cloud is a
surface, most cells of its bounding box are empty, and coarser cells hold tens of points each."""

GRID_MAX_CELLS = 1 << 24
"""And at most this many in all (its cell table: 128 MB), whatever the cloud's size."""


class GridKNN:
    """Exact k-NN of query points among fixed ``source`` points on a uniform grid (Numba kernels).

    The cells are sized from the source's nearest-neighbour spacing (the median over a sample) times
    ``sqrt(k)``-ish, so a query's k nearest lie a shell or two of cells away; the search visits the cells
    in shells of growing Chebyshev distance and stops once no unvisited cell can hold a point nearer than
    the k-th found, so the answer is exact (the k nearest, nearest first; among equidistant points the
    first one found). Squared distances are float32, summed as ``dx*dx + dy*dy + dz*dz``.

    It is faster than Open3D's k-d tree for these queries (``tests/benchmarks/bench_points.py`` compares the
    two), most of all for the 3-NN of many points among few: queries run on the pool's threads without
    the GIL, where Open3D's search holds it.

    Args:
        source: (N, 3) float32 C-contiguous finite points, N >= 1 (validated by the caller).
        k: the neighbour count the grid is sized for (any k works; others cost more).
    """

    def __init__(self, source: np.ndarray, k: int = 8) -> None:
        g = _grid_kernels()
        self._g = g
        n = source.shape[0]
        lo = source.min(axis=0).astype(np.float32)
        extent = (source.max(axis=0) - lo).astype(np.float64)
        sample = np.linspace(0, n - 1, min(n, GRID_SAMPLE)).astype(np.int64)
        d = float(np.sqrt(np.median(g.nn_distance_sample(source, sample)))) if n > 1 else math.inf
        h = d * math.sqrt(max(1, k))  # a cube of 3x3x3 cells holds about k points of a surface
        if not (math.isfinite(h) and h > 0):
            h = float(extent.max()) if extent.max() > 0 else 1.0
        cap = max(min(GRID_MAX_CELLS_PER_POINT * n, GRID_MAX_CELLS), 4096)
        while True:
            dims = np.maximum(np.ceil(extent / h), 1).astype(np.int64)
            if int(np.prod(dims)) <= cap:
                break
            h *= (float(np.prod(dims)) / cap) ** (1.0 / 3.0) * 1.01
        self._lo, self._h, self._dims = lo, np.float32(h), dims
        cells = g.cell_of(source, lo, np.float32(1.0 / h), dims)
        self._start, self._order = g.bucket(cells, int(np.prod(dims)))
        self._sorted = np.ascontiguousarray(source[self._order])  # (N, 3) by cell: each cell's points together
        self.num_points = n

    def search(self, qry: np.ndarray, k: int) -> Tuple[np.ndarray, np.ndarray]:
        """(M, k) int64 indices and (M, k) float32 squared distances of the k <= N nearest source points."""
        m = qry.shape[0]
        idx = np.empty((m, k), np.int64)
        d = np.empty((m, k), np.float32)
        g = self._g
        _threads.in_parts(lambda a, b: g.knn_query(self._sorted, self._order, self._start, self._lo, self._h,
                                                   self._dims, qry, a, b, k, idx, d), m, 4096)
        return idx, d


def warm_up() -> None:
    """Load the grid search's compiled kernels (Numba's cache) with a search of four points, so that a
    photo's first geometry does not wait for them (``pipeline.warm_up``)."""
    if BACKEND == "grid" and _grid_kernels() is not None:
        pts = np.eye(4, 3, dtype=np.float32)
        GridKNN(pts, 2).search(pts, 2)
        _grid_kernels().idw_rows(pts, 1e-8, 0, 1, np.empty_like(pts))  # interpolate's IDW weights


class KNNIndex:
    """A k-d tree over fixed ``source`` points, built once and queried any number of times.

    :func:`knn` and :func:`ball_query` build one per call; code that searches the
    same points several times (the encoder's hierarchy: each level among itself,
    then the next level and the dense points among it) builds it once. A query's
    answer depends only on the tree and the query point, so searching a subset
    of the queries gives the rows of the whole search (``knn(s, q)[i] ==
    knn(s, q[i])``).

    Args:
        source: (N, 3) finite points, N >= 1 (validated and copied to float32 once).
    """

    def __init__(self, source: torch.Tensor) -> None:
        self._build(_as_f32_array(source, "source"))

    @classmethod
    def _from_array(cls, source: np.ndarray) -> "KNNIndex":
        index = cls.__new__(cls)
        index._build(source)
        return index

    def _build(self, source: np.ndarray) -> None:
        """Build the search over validated (N, 3) float32 ``source``: :class:`GridKNN` (``BACKEND``
        "grid", where Numba imports), else Open3D's k-d tree."""
        self._src = source
        self.num_points = len(self._src)
        self._grid: Optional[GridKNN] = None
        self._nns = None
        if BACKEND == "grid" and _grid_kernels() is not None:
            self._grid = GridKNN(self._src)
            return
        import open3d.core as o3c  # the tensor core only; no GUI module is used

        self._o3c = o3c
        self._nns = o3c.nns.NearestNeighborSearch(o3c.Tensor(self._src))
        if not self._nns.knn_index():
            raise RuntimeError("Open3D could not build a k-d tree index")

    def knn(self, query: torch.Tensor, k: int) -> KNNResult:
        """The ``k`` nearest source points of each ``query`` point (M, 3): as :func:`knn`."""
        return self._search(_as_f32_array(query, "query", allow_empty=True), check_count(k, "k", 1))

    def self_knn(self, k: int) -> KNNResult:
        """The ``k`` nearest source points of every source point: ``knn(source, k)`` without checking and
        copying the source a second time (the tree's own array is the query)."""
        return self._search(self._src, check_count(k, "k", 1))

    def _search(self, qry: np.ndarray, k: int) -> KNNResult:
        """k-NN of validated (M, 3) float32 queries, ``k`` >= 1."""
        if len(qry) == 0:
            return KNNResult(torch.zeros(0, k, dtype=torch.long), torch.zeros(0, k))
        k_eff = min(k, self.num_points)
        if self._grid is not None:
            idx, sq = self._grid.search(np.ascontiguousarray(qry, dtype=np.float32), k_eff)
            idx_t, d_t = torch.from_numpy(idx), torch.from_numpy(sq)
            return self._pad(idx_t, d_t, k)
        # In chunks of queries: Open3D's search holds the GIL for the whole call (~0.8 s for every point
        # of a photo), which froze the viewer's window while its worker thread prepared a photo; between
        # chunks other threads run. Each query's answer depends only on the tree: the same result.
        rows = max(1, QUERY_CHUNK_RESULTS // k_eff)
        idx_t = torch.empty((len(qry), k_eff), dtype=torch.long)
        d_t = torch.empty((len(qry), k_eff), dtype=torch.float32)
        for r0 in range(0, len(qry), rows):
            part = qry[r0:r0 + rows]
            idx, sq_dist = self._nns.knn_search(self._o3c.Tensor(part), k_eff)
            # Copied out of Open3D's memory: a torch tensor still viewing it at interpreter
            # exit makes Open3D print a memory-leak warning.
            idx_t[r0:r0 + len(part)] = torch.from_numpy(idx.numpy().reshape(len(part), k_eff))
            d_t[r0:r0 + len(part)] = torch.from_numpy(sq_dist.numpy().reshape(len(part), k_eff))
        return self._pad(idx_t, d_t, k)

    @staticmethod
    def _pad(idx_t: torch.Tensor, d_t: torch.Tensor, k: int) -> KNNResult:
        """The result with columns ``k_eff..k-1`` repeating the nearest neighbour (k > N)."""
        k_eff = idx_t.shape[1]
        if k_eff == k:
            return KNNResult(idx_t, d_t)
        pad = k - k_eff
        idx_t = torch.cat([idx_t, idx_t[:, :1].expand(-1, pad)], dim=1)  # (M, k)
        d_t = torch.cat([d_t, d_t[:, :1].expand(-1, pad)], dim=1)  # (M, k)
        return KNNResult(idx_t, d_t)

    def ball_query(self, query: torch.Tensor, radius: float, k: int) -> BallQueryResult:
        """Up to ``k`` nearest source points within ``radius`` of each query point: as :func:`ball_query`."""
        r = check_range(radius, "radius", 0.0, float("inf"), inclusive=False)
        return ball_from_knn(self.knn(query, k), r, self.num_points)


def ball_from_knn(res: KNNResult, radius: float, num_source: int) -> BallQueryResult:
    """The ball query of radius ``radius`` (> 0) from a k-NN result among ``num_source`` points.

    A ball query is a k-NN search plus a mask, so one k-NN result serves every
    radius (and the rows of any subset of its queries: ``ball_from_knn(res[i], r)``
    is the ball query of the queries ``i``).
    """
    r = check_range(radius, "radius", 0.0, float("inf"), inclusive=False)
    # (M, k), a prefix of each row since distances ascend; columns >= N are padding
    inside = (res.sq_dist <= r * r) & (torch.arange(res.idx.shape[1]) < num_source)
    count = inside.sum(dim=1)  # (M,)
    idx = torch.where(inside, res.idx, res.idx[:, :1])  # (M, k)
    return BallQueryResult(idx, count)


def knn(source: torch.Tensor, query: torch.Tensor, k: int) -> KNNResult:
    """The ``k`` nearest ``source`` points of every ``query`` point, nearest first.

    Args:
        source: (N, 3) points searched, N >= 1.
        query: (M, 3) points whose neighbours are wanted (M may be 0).
        k: number of neighbours, >= 1. If ``k > N``, columns ``N..k-1`` repeat
            the nearest neighbour (index and distance).

    Returns:
        :class:`KNNResult` with ``idx`` (M, k) long and ``sq_dist`` (M, k).
        Among equidistant points the order is unspecified. To search the same
        source several times, build a :class:`KNNIndex` once.
    """
    src = _as_f32_array(source, "source")
    qry = _as_f32_array(query, "query", allow_empty=True)
    k = check_count(k, "k", 1)
    return KNNIndex._from_array(src)._search(qry, k)


def ball_query(source: torch.Tensor, query: torch.Tensor, radius: float, k: int) -> BallQueryResult:
    """Up to ``k`` nearest ``source`` points within ``radius`` of each query point.

    Args:
        source: (N, 3) points searched, N >= 1.
        query: (M, 3) ball centres (often a subset of ``source``).
        radius: ball radius (inclusive: distance <= radius counts), > 0.
        k: the most neighbours kept per query, >= 1.

    Returns:
        :class:`BallQueryResult` with ``idx`` (M, k) and ``count`` (M,); see its
        docstring for the padding.
    """
    r = check_range(radius, "radius", 0.0, float("inf"), inclusive=False)
    return ball_from_knn(knn(source, query, k), r, source.shape[0])
