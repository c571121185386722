import pytest
import torch

from stylize3d_core.errors import InputError
from stylize3d_core.points import KNNIndex, ball_from_knn, ball_query, knn
from stylize3d_core.points.reference import ball_query_reference, knn_reference, pairwise_sq_dist


def rand(n, seed):
    return torch.rand(n, 3, generator=torch.Generator().manual_seed(seed))


def test_knn_matches_reference():
    src, qry = rand(1500, 0), rand(300, 1)
    fast, ref = knn(src, qry, 16), knn_reference(src, qry, 16)
    assert fast.idx.dtype == torch.long and fast.idx.shape == (300, 16)
    assert torch.equal(fast.idx, ref.idx)
    torch.testing.assert_close(fast.sq_dist.double(), ref.sq_dist, rtol=1e-5, atol=1e-7)


def test_ball_query_matches_reference_random():
    src, qry = rand(2000, 2), rand(400, 3)
    counts = []
    for radius in [0.03, 0.08, 0.2]:
        fast, ref = ball_query(src, qry, radius, 16), ball_query_reference(src, qry, radius, 16)
        assert torch.equal(fast.count, ref.count)
        assert torch.equal(fast.idx, ref.idx)
        counts.append(fast.count)
    counts = torch.cat(counts)
    # empty, partly filled and capped balls all occur
    assert {0, 16} <= set(counts.tolist()) and bool(((counts > 0) & (counts < 16)).any())


def test_ball_query_matches_reference_jittered_surface(surface_cloud):
    xyz = surface_cloud(48, 64, jitter=0.5)
    qry = xyz[::3]  # queries are points of the cloud, as in the encoder
    fast, ref = ball_query(xyz, qry, 0.05, 16), ball_query_reference(xyz, qry, 0.05, 16)
    assert torch.equal(fast.count, ref.count)
    assert torch.equal(fast.idx, ref.idx)
    # each point is its own nearest neighbour
    assert torch.equal(fast.idx[:, 0], torch.arange(0, len(xyz), 3))


def test_ball_query_exact_grid_ties_aside(surface_cloud):
    # A pixel grid has many equidistant neighbours: compare distances, not indices.
    xyz = surface_cloud(40, 50)
    r = 0.07  # not a multiple of the grid spacing
    fast, ref = ball_query(xyz, xyz, r, 16), ball_query_reference(xyz, xyz, r, 16)
    assert torch.equal(fast.count, ref.count)
    d_fast = pairwise_sq_dist(xyz, xyz).gather(1, fast.idx)  # (N, 16)
    d_ref = pairwise_sq_dist(xyz, xyz).gather(1, ref.idx)
    torch.testing.assert_close(d_fast, d_ref, rtol=1e-5, atol=1e-9)
    mask = fast.mask()
    # valid neighbours are distinct, within the radius
    for i in range(0, len(xyz), 97):
        valid = fast.idx[i][mask[i]]
        assert len(torch.unique(valid)) == len(valid)
    assert bool((d_fast[mask] <= r * r + 1e-9).all())


def test_index_reused_across_queries_and_radii(surface_cloud):
    # one tree, many searches: each equals its own knn / ball_query call, and rows of a subset of the
    # queries equal those rows of the whole search (grid ties included)
    xyz = surface_cloud(30, 40)
    index = KNNIndex(xyz)
    assert index.num_points == len(xyz)
    whole = index.knn(xyz, 12)
    assert torch.equal(whole.idx, knn(xyz, xyz, 12).idx) and torch.equal(whole.sq_dist, knn(xyz, xyz, 12).sq_dist)
    sub = torch.arange(5, len(xyz), 7)
    part = index.knn(xyz[sub], 12)
    assert torch.equal(part.idx, whole.idx[sub]) and torch.equal(part.sq_dist, whole.sq_dist[sub])
    for r in (0.03, 0.07, 0.3):
        want = ball_query(xyz, xyz[sub], r, 12)
        for got in (index.ball_query(xyz[sub], r, 12), ball_from_knn(part, r, len(xyz))):
            assert torch.equal(got.idx, want.idx) and torch.equal(got.count, want.count)
    small = KNNIndex(xyz[:5])  # k above the source size pads with the nearest, as knn does
    assert torch.equal(small.knn(xyz[:3], 8).idx, knn(xyz[:5], xyz[:3], 8).idx)
    assert small.knn(torch.zeros(0, 3), 4).idx.shape == (0, 4)
    with pytest.raises(InputError, match="source"):
        KNNIndex(torch.tensor([[0.0, float("nan"), 0.0]]))
    with pytest.raises(InputError, match="query"):
        index.knn(torch.zeros(4, 2), 3)
    with pytest.raises(InputError, match="k"):
        index.knn(xyz[:2], 0)
    with pytest.raises(InputError, match="radius"):
        ball_from_knn(part, 0.0, len(xyz))


def test_padding_repeats_the_nearest():
    src = torch.tensor([[0.0, 0, 0], [0.1, 0, 0], [0.2, 0, 0], [0.3, 0, 0], [5.0, 5, 5]])
    qry = torch.tensor([[0.01, 0, 0], [-3.0, 0, 0]])
    res = ball_query(src, qry, 0.15, 6)
    assert res.count.tolist() == [2, 0]
    assert res.idx.tolist() == [[0, 1, 0, 0, 0, 0], [0, 0, 0, 0, 0, 0]]
    assert res.mask().tolist() == [[True, True] + [False] * 4, [False] * 6]


def test_k_larger_than_cloud():
    src = rand(5, 4)
    res = ball_query(src, src, 10.0, 16)
    assert res.idx.shape == (5, 16)
    assert res.count.tolist() == [5] * 5
    assert torch.equal(res.idx, ball_query_reference(src, src, 10.0, 16).idx)
    k = knn(src, src[:2], 8)
    assert k.idx.shape == (2, 8) and torch.equal(k.idx[:, 5:], k.idx[:, :1].expand(-1, 3))
    assert torch.equal(k.idx, knn_reference(src, src[:2], 8).idx)


def test_coincident_points():
    src = torch.zeros(20, 3)
    res = ball_query(src, src[:3], 0.01, 16)
    assert res.count.tolist() == [16] * 3
    assert all(len(torch.unique(row)) == 16 for row in res.idx)


def test_single_point_and_empty_query():
    src = torch.tensor([[0.5, 0.5, 0.5]])
    res = ball_query(src, torch.tensor([[0.5, 0.5, 0.5], [0.0, 0.0, 0.0]]), 0.1, 4)
    assert res.count.tolist() == [1, 0] and res.idx.tolist() == [[0] * 4] * 2
    empty = ball_query(src, torch.zeros(0, 3), 0.1, 4)
    assert empty.idx.shape == (0, 4) and empty.count.shape == (0,)


def test_inputs_not_modified_and_float64_accepted():
    src = rand(300, 5).double()
    before = src.clone()
    res = ball_query(src, src, 0.1, 8)
    assert torch.equal(src, before)
    assert torch.equal(res.count, ball_query_reference(src, src, 0.1, 8).count)


@pytest.mark.parametrize(
    "src, qry, radius, k",
    [
        (torch.rand(10, 2), torch.rand(3, 3), 0.1, 4),
        (torch.rand(10, 3), torch.rand(3, 4), 0.1, 4),
        (torch.rand(0, 3), torch.rand(3, 3), 0.1, 4),
        (torch.rand(10, 3), torch.rand(3, 3), 0.0, 4),
        (torch.rand(10, 3), torch.rand(3, 3), -1.0, 4),
        (torch.rand(10, 3), torch.rand(3, 3), float("nan"), 4),
        (torch.rand(10, 3), torch.rand(3, 3), 0.1, 0),
        (torch.rand(10, 3), torch.rand(3, 3), 0.1, 2.0),
        (torch.tensor([[float("inf"), 0, 0]]), torch.rand(3, 3), 0.1, 4),
        (torch.rand(10, 3), torch.tensor([[float("nan"), 0, 0]]), 0.1, 4),
        (torch.ones(10, 3, dtype=torch.int32), torch.rand(3, 3), 0.1, 4),
    ],
)
def test_bad_inputs(src, qry, radius, k):
    with pytest.raises(InputError):
        ball_query(src, qry, radius, k)


def test_knn_in_chunks_of_queries_is_the_same_search(monkeypatch):
    """Queries go to Open3D in chunks (the GIL is free between them): the same neighbours and distances."""
    from stylize3d_core.points import neighbours
    from stylize3d_core.points.neighbours import KNNIndex

    pts = torch.rand(3000, 3, generator=torch.Generator().manual_seed(4))
    index = KNNIndex(pts)
    whole = index.knn(pts, 7)
    monkeypatch.setattr(neighbours, "QUERY_CHUNK_RESULTS", 50)  # 7 queries per call, a ragged last chunk
    parts = index.knn(pts, 7)
    assert torch.equal(parts.idx, whole.idx) and torch.equal(parts.sq_dist, whole.sq_dist)


def test_self_knn_is_the_search_of_the_source_among_itself(surface_cloud):
    src = surface_cloud(30, 40, jitter=0.5)
    index = KNNIndex(src)
    a, b = index.self_knn(6), index.knn(src, 6)
    assert torch.equal(a.idx, b.idx) and torch.equal(a.sq_dist, b.sq_dist)
    ref = knn_reference(src, src, 6)
    torch.testing.assert_close(a.sq_dist.double(), ref.sq_dist, rtol=1e-5, atol=1e-7)
    with pytest.raises(InputError):
        index.self_knn(0)
