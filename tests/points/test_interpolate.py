import pytest
import torch

from stylize3d_core.errors import InputError
from stylize3d_core.points import idw_neighbours, idw_weights, interpolate, three_nn
from stylize3d_core.points.reference import interpolate_reference, knn_reference, three_nn_reference


def rand(shape, seed, dtype=torch.float32):
    return torch.rand(shape, generator=torch.Generator().manual_seed(seed), dtype=dtype)


def test_idw_weights_known_values():
    w = idw_weights(torch.tensor([[1.0, 2.0, 4.0], [0.0, 0.5, 0.5], [2.0, 2.0, 2.0]], dtype=torch.float64))
    torch.testing.assert_close(w[0], torch.tensor([4 / 7, 2 / 7, 1 / 7], dtype=torch.float64))
    assert w[1].tolist() == [1.0, 0.0, 0.0]  # a coincident point takes its feature exactly
    torch.testing.assert_close(w[2], torch.full((3,), 1 / 3, dtype=torch.float64))


def test_three_nn_matches_reference():
    dense, sparse = rand((3000, 3), 0), rand((200, 3), 1)
    fast, ref = three_nn(dense, sparse), three_nn_reference(dense, sparse)
    assert fast.idx.dtype == torch.long and fast.idx.shape == (3000, 3)
    assert fast.weight.dtype == torch.float32
    assert torch.equal(fast.idx, ref.idx)
    torch.testing.assert_close(fast.weight.double(), ref.weight, rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(fast.weight.sum(1), torch.ones(3000))
    assert bool((fast.weight >= 0).all())


def test_interpolate_matches_reference():
    dense, sparse = rand((1000, 3), 2), rand((100, 3), 3)
    feats = torch.randn(100, 7, generator=torch.Generator().manual_seed(4), dtype=torch.float64)
    nn3 = three_nn(dense, sparse)
    out = interpolate(feats, nn3.idx, nn3.weight)
    assert out.shape == (1000, 7) and out.dtype == torch.float64
    torch.testing.assert_close(out, interpolate_reference(feats, nn3.idx, nn3.weight))


def test_coincident_dense_points_take_sparse_features_exactly():
    sparse = rand((50, 3), 5)
    dense = torch.cat([sparse[10:20], rand((30, 3), 6)])  # 10 points on sparse points
    feats = torch.randn(50, 4, generator=torch.Generator().manual_seed(7))
    nn3 = three_nn(dense, sparse)
    out = interpolate(feats, nn3.idx, nn3.weight)
    assert torch.equal(out[:10], feats[10:20])
    assert bool(torch.isfinite(out).all())


def test_duplicate_sparse_points_no_nan():
    sparse = torch.zeros(4, 3)  # all coincident
    dense = torch.cat([torch.zeros(1, 3), rand((5, 3), 8)])
    feats = torch.arange(8.0).reshape(4, 2)
    nn3 = three_nn(dense, sparse)
    out = interpolate(feats, nn3.idx, nn3.weight)
    assert bool(torch.isfinite(nn3.weight).all()) and bool(torch.isfinite(out).all())
    torch.testing.assert_close(nn3.weight.sum(1), torch.ones(6))


def test_constant_features_are_reproduced():
    nn3 = three_nn(rand((500, 3), 9), rand((40, 3), 10))
    out = interpolate(torch.full((40, 3), 0.7), nn3.idx, nn3.weight)
    torch.testing.assert_close(out, torch.full((500, 3), 0.7))


@pytest.mark.parametrize("m", [1, 2])
def test_fewer_than_three_sparse_points(m):
    sparse, dense = rand((m, 3), 11), rand((20, 3), 12)
    fast, ref = three_nn(dense, sparse), three_nn_reference(dense, sparse)
    assert fast.idx.shape == (20, 3) and int(fast.idx.max()) < m
    assert bool((fast.weight[:, m:] == 0).all())
    torch.testing.assert_close(fast.weight.double(), ref.weight, rtol=1e-5, atol=1e-6)
    feats = torch.randn(m, 5)
    out = interpolate(feats, fast.idx, fast.weight)
    if m == 1:
        torch.testing.assert_close(out, feats.expand(20, -1))


def test_gradcheck_float64():
    dense, sparse = rand((12, 3), 13), rand((6, 3), 14)
    nn3 = three_nn(dense, sparse)
    feats = torch.randn(6, 3, dtype=torch.float64, requires_grad=True)
    weight = nn3.weight.double().requires_grad_(True)
    assert torch.autograd.gradcheck(lambda f, w: interpolate(f, nn3.idx, w), (feats, weight))
    # and backward agrees with the reference
    g = torch.randn(12, 3, dtype=torch.float64)
    (ga,) = torch.autograd.grad(interpolate(feats, nn3.idx, weight), feats, g)
    (gb,) = torch.autograd.grad(interpolate_reference(feats, nn3.idx, weight), feats, g)
    torch.testing.assert_close(ga, gb)


def test_inputs_not_modified():
    dense, sparse = rand((100, 3), 15), rand((10, 3), 16)
    d0, s0 = dense.clone(), sparse.clone()
    nn3 = three_nn(dense, sparse)
    feats = torch.randn(10, 2)
    f0, w0 = feats.clone(), nn3.weight.clone()
    interpolate(feats, nn3.idx, nn3.weight)
    assert torch.equal(dense, d0) and torch.equal(sparse, s0)
    assert torch.equal(feats, f0) and torch.equal(nn3.weight, w0)


def test_bad_inputs():
    nn3 = three_nn(rand((10, 3), 17), rand((5, 3), 18))
    feats = torch.randn(5, 2)
    with pytest.raises(InputError):
        interpolate(torch.randn(4, 2), nn3.idx, nn3.weight)  # indices out of range
    with pytest.raises(InputError):
        interpolate(feats, nn3.idx.int(), nn3.weight)
    with pytest.raises(InputError):
        interpolate(feats, nn3.idx, nn3.weight[:, :2])
    with pytest.raises(InputError):
        interpolate(feats[0], nn3.idx, nn3.weight)
    with pytest.raises(InputError):
        idw_weights(torch.tensor([[-0.1, 0.2, 0.3]]))
    with pytest.raises(InputError):
        three_nn(rand((10, 3), 19), torch.zeros(0, 3))
    with pytest.raises(InputError):
        three_nn(rand((10, 2), 19), rand((5, 3), 20))


@pytest.mark.parametrize("k", [1, 5])
def test_idw_neighbours_of_any_k_match_the_reference_knn(k):
    dense, sparse = rand((400, 3), 20), rand((60, 3), 21)
    res = idw_neighbours(dense, sparse, k)
    ref = knn_reference(sparse, dense, k)
    assert res.idx.shape == (400, k) and torch.equal(res.idx, ref.idx)
    torch.testing.assert_close(res.weight.sum(1), torch.ones(400))
    if k == 1:
        assert bool((res.weight == 1).all())  # one neighbour: its feature exactly
    d = ref.sq_dist.double().sqrt()
    expected = (1 / (d + 1e-8)) / (1 / (d + 1e-8)).sum(1, keepdim=True)
    torch.testing.assert_close(res.weight.double(), expected, rtol=1e-5, atol=1e-6)
    three = three_nn(dense, sparse)
    again = idw_neighbours(dense, sparse, 3)
    assert torch.equal(three.idx, again.idx) and torch.equal(three.weight, again.weight)


def test_interpolate_equals_the_column_loop_bit_for_bit():
    # the fused embedding_bag accumulates the neighbours in column order, as index_select + addcmul did
    feats = torch.randn(300, 19, generator=torch.Generator().manual_seed(3))
    nn3 = three_nn(rand((5000, 3), 4), rand((300, 3), 5))
    loop = feats.index_select(0, nn3.idx[:, 0]) * nn3.weight[:, 0:1]
    for j in (1, 2):
        loop.addcmul_(feats.index_select(0, nn3.idx[:, j]), nn3.weight[:, j : j + 1])
    assert torch.equal(interpolate(feats, nn3.idx, nn3.weight), loop)
    assert interpolate(feats, nn3.idx[:0], nn3.weight[:0]).shape == (0, 19)



def test_compiled_weights_match_the_torch_lines_bit_for_bit(monkeypatch):
    """idw_from_knn's weights from the points' compiled kernel against its torch lines: random distances,
    coincident and nearly coincident first neighbours, tiny negative squared distances (clamped), and a
    NaN that must still be reported by the checked path."""
    import importlib

    from stylize3d_core.points.neighbours import KNNResult

    interp = importlib.import_module("stylize3d_core.points.interpolate")
    if interp._threads.compiled("stylize3d_core.points._grid_kernels") is None:
        pytest.skip("Numba does not import here: only the torch lines run")
    n = 200_003  # several parts on the pool's threads
    sq = (rand((n, 3), 4) ** 4 * 1e-3).sort(dim=1).values
    sq[:100, 0] = 0.0
    sq[100:200, 0] = 1e-17  # sqrt below IDW_EPS: one-hot
    sq[200:300] = -1e-9
    sq[300:310, 1] = 5e-17
    res = KNNResult(torch.zeros(n, 3, dtype=torch.long), sq)
    fast = interp.idw_from_knn(res, 100).weight
    assert fast.dtype == torch.float32 and fast[:200].tolist() == [[1.0, 0.0, 0.0]] * 200
    monkeypatch.setattr(interp, "_compiled_weights", lambda sq_dist: None)
    assert torch.equal(fast, interp.idw_from_knn(res, 100).weight)
    monkeypatch.undo()
    bad = sq.clone()
    bad[n - 1, 2] = float("nan")
    with pytest.raises(InputError, match="NaN"):
        interp.idw_from_knn(KNNResult(res.idx, bad), 100)
