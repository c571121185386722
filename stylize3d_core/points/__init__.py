"""Point-cloud operations: sampling, neighbourhoods and interpolation.

* :func:`farthest_point_sample` -- FPS indices (exact FPS, via ``fpsample``);
* :func:`knn`, :func:`ball_query` -- k nearest / radius-bounded k nearest
  neighbours, nearest first (an exact Numba grid search, Open3D's k-d tree where Numba
  is missing; :class:`KNNIndex` to search one cloud several times, :func:`ball_from_knn`
  for any radius from one k-NN search);
* :func:`idw_neighbours` (:func:`three_nn`), :func:`interpolate` -- inverse-distance-weighted upsampling
  of features from sparse to dense points.

Searches depend only on point positions: compute them once per point cloud and
reuse the indices. :mod:`.reference` holds slow brute-force versions for tests.
"""

from .interpolate import IDW_EPS, IDWWeights, idw_from_knn, idw_neighbours, idw_weights, interpolate, three_nn
from .neighbours import BallQueryResult, KNNIndex, KNNResult, ball_from_knn, ball_query, knn
from .sampling import farthest_point_sample

__all__ = [
    "IDW_EPS",
    "IDWWeights",
    "idw_from_knn",
    "idw_neighbours",
    "idw_weights",
    "interpolate",
    "three_nn",
    "BallQueryResult",
    "KNNResult",
    "ball_from_knn",
    "ball_query",
    "KNNIndex",
    "knn",
    "farthest_point_sample",
]
