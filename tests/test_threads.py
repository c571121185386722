"""The compiled kernels' thread pool: ranges split into parts, jobs run on the pool."""

import threading

import torch

from stylize3d_core import threads


def test_parts_cover_the_range_in_order():
    assert threads.parts(10, 3) == [(0, 3), (3, 6), (6, 10)]
    assert threads.parts(2, 4) == [(0, 1), (1, 2)]  # empty parts dropped
    assert threads.parts(0, 2) == [(0, 0)]
    for n, k in ((1, 1), (7, 2), (1000, 7)):
        p = threads.parts(n, k)
        assert p[0][0] == 0 and p[-1][1] == n and all(a[1] == b[0] for a, b in zip(p, p[1:]))


def test_run_parts_runs_every_job_and_waits():
    seen, names = [], set()

    def job(i):
        seen.append(i)
        names.add(threading.current_thread().name)

    threads.run_parts([(job, (i,)) for i in range(5)])
    assert sorted(seen) == list(range(5))
    assert threading.current_thread().name in names  # the first job in the caller's thread
    threads.run_parts([])


def test_threads_follow_torch():
    before = torch.get_num_threads()
    try:
        torch.set_num_threads(1)
        assert threads.threads() == 1
    finally:
        torch.set_num_threads(before)
    assert 1 <= threads.threads() <= threads.THREADS


def test_embedding_bag_sum_in_parts_is_bit_identical(monkeypatch):
    """Bags summed on the pool's threads: the one call's result bit for bit, in inference mode, under
    no_grad and plain (three parts of chunks, the last ones short)."""
    import torch.nn.functional as F

    monkeypatch.setattr(threads, "PARALLEL_BAG_TAPS", 1)
    monkeypatch.setattr(threads, "BAG_CHUNK", 1000)
    monkeypatch.setattr(threads, "threads", lambda: 3)
    g = torch.Generator().manual_seed(1)
    table = torch.randn(500, 7, generator=g)
    index = torch.randint(0, 500, (10_001, 3), generator=g)
    weight = torch.rand(10_001, 3, generator=g)
    ref = F.embedding_bag(index, table, mode="sum", per_sample_weights=weight)
    for mode in (torch.inference_mode, torch.no_grad, torch.enable_grad):
        with mode():
            out = threads.embedding_bag_sum(index, table, weight)
        assert out.shape == (10_001, 7) and torch.equal(out, ref)
    assert threads.embedding_bag_sum(index[:0], table, weight[:0]).shape == (0, 7)


def test_embedding_bag_sum_keeps_gradients_under_autograd(monkeypatch):
    monkeypatch.setattr(threads, "PARALLEL_BAG_TAPS", 1)
    table = torch.randn(20, 4, requires_grad=True)
    index = torch.randint(0, 20, (300, 3))
    weight = torch.rand(300, 3)
    threads.embedding_bag_sum(index, table, weight).sum().backward()
    expected = torch.zeros(20).index_add_(0, index.reshape(-1), weight.reshape(-1))
    torch.testing.assert_close(table.grad, expected[:, None].expand(20, 4))
