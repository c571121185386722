"""The grid k-NN search (Numba) against brute force and Open3D's k-d tree, on clouds that stress it."""

import numpy as np
import pytest
import torch

from stylize3d_core.points import neighbours as nb

pytestmark = pytest.mark.skipif(nb._grid_kernels() is None, reason="Numba does not import")


def _brute(src: np.ndarray, qry: np.ndarray, k: int):
    d = ((qry[:, None, :] - src[None, :, :]) ** 2).sum(-1)
    return np.sort(d, axis=1)[:, :k]


def _clouds():
    g = np.random.default_rng(0)
    surface = np.stack([g.uniform(-1, 1, 3000), g.uniform(-1, 1, 3000), np.zeros(3000)], 1)
    surface[:, 2] = 0.2 * np.sin(3 * surface[:, 0])  # a thin curved sheet: most grid cells empty
    clustered = np.concatenate([g.normal(0, 0.01, (1500, 3)), g.normal(5, 2.0, (500, 3))])  # very uneven density
    grid = np.stack(np.meshgrid(np.arange(12), np.arange(12), np.arange(3), indexing="ij"), -1).reshape(-1, 3) * 0.1
    dup = np.repeat(g.random((50, 3)), 7, axis=0)  # exact duplicates
    line = np.stack([np.linspace(0, 1, 800), np.zeros(800), np.zeros(800)], 1)  # zero extent in two axes
    return {"surface": surface, "clustered": clustered, "lattice (ties)": grid, "duplicates": dup, "line": line}


@pytest.mark.parametrize("name", list(_clouds()))
@pytest.mark.parametrize("k", [1, 3, 16])
def test_grid_distances_are_the_exact_k_nearest(name, k):
    src = _clouds()[name].astype(np.float32)
    g = np.random.default_rng(1)
    # queries inside, on and far outside the cloud's box (clamped into the grid)
    qry = np.concatenate([src[::7], src[:50] + g.normal(0, 0.05, (50, 3)), g.normal(0, 30, (40, 3))]).astype(np.float32)
    idx, d = nb.GridKNN(src, k).search(qry, k)
    ref = _brute(src.astype(np.float64), qry.astype(np.float64), k)
    np.testing.assert_allclose(d, ref, rtol=1e-5, atol=1e-6)
    assert (np.diff(d, axis=1) >= 0).all()  # nearest first
    got = ((src[idx] - qry[:, None]) ** 2).sum(-1)  # the indices are of points at those distances
    np.testing.assert_allclose(got, d, rtol=1e-5, atol=1e-6)
    assert all(len(set(row)) == k for row in idx)  # no point twice


def test_grid_and_open3d_agree_through_knn_index(monkeypatch):
    """The same distances as Open3D's search to the bit, the same indices wherever there is no tie,
    and the same padding when k exceeds the points."""
    g = np.random.default_rng(2)
    src = torch.from_numpy(g.random((5000, 3)).astype(np.float32))
    qry = torch.from_numpy(g.random((3000, 3)).astype(np.float32))
    out = {}
    for backend in nb.BACKENDS:
        monkeypatch.setattr(nb, "BACKEND", backend)
        index = nb.KNNIndex(src)
        out[backend] = (index.knn(qry, 8), index.self_knn(16), nb.knn(src[:5], qry[:10], 9))
    for a, b in zip(out["grid"], out["open3d"]):
        assert torch.equal(a.sq_dist, b.sq_dist)
        assert torch.equal(a.idx, b.idx)  # random float points: no ties
    assert out["grid"][2].idx.shape == (10, 9) and torch.equal(out["grid"][2].idx[:, 5:], out["grid"][2].idx[:, :1].expand(-1, 4))


def test_grid_single_point_and_one_position():
    one = np.zeros((1, 3), np.float32)
    idx, d = nb.GridKNN(one).search(np.array([[1.0, 2.0, 3.0], [0.0, 0.0, 0.0]], np.float32), 1)
    assert idx.tolist() == [[0], [0]] and d[:, 0].tolist() == [14.0, 0.0]
    same = np.full((20, 3), 0.5, np.float32)  # zero extent, zero spacing
    idx, d = nb.GridKNN(same).search(same[:3], 4)
    assert (d == 0).all() and all(len(set(r)) == 4 for r in idx)


def test_grid_with_few_cells_is_still_exact(monkeypatch):
    """A cell budget far below the cloud's need (coarse cells of many points) changes the speed, not the answer."""
    monkeypatch.setattr(nb, "GRID_MAX_CELLS", 10)
    src = _clouds()["surface"].astype(np.float32)
    grid = nb.GridKNN(src, 3)
    assert int(np.prod(grid._dims)) <= 4096
    _, d = grid.search(src[:200], 3)
    np.testing.assert_allclose(d, _brute(src.astype(np.float64), src[:200].astype(np.float64), 3), rtol=1e-5, atol=1e-6)
