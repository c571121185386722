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



def test_in_parts_covers_the_range_and_returns_each_parts_result_in_order():
    seen = []

    def job(a, b):
        seen.extend(range(a, b))
        return (a, b)

    out = threads.in_parts(job, 10, k=3)
    assert out == [(0, 3), (3, 6), (6, 10)] and sorted(seen) == list(range(10))
    assert threads.in_parts(job, 10, min_split=100, k=3) == [(0, 10)]  # below min_split: one part


def test_beside_runs_in_another_thread_and_halves_runs_every_job():
    main = threading.current_thread().name
    assert threads.beside(lambda: threading.current_thread().name).result() != main
    names = {}
    threads.halves(lambda i: names.__setitem__(i, threading.current_thread().name), 5)
    assert sorted(names) == list(range(5))
    assert {names[0], names[1]} == {main} and all(names[i] != main for i in (2, 3, 4))
    failed = threads.beside(lambda: 1 / 0)
    try:
        failed.result()
        raise AssertionError("the exception was lost")
    except ZeroDivisionError:
        pass


def test_torch_threads_sets_the_count_for_the_block_and_restores_it():
    before = torch.get_num_threads()
    try:
        torch.set_num_threads(1)
        with threads.torch_threads(2) as n:
            assert n == 2 and torch.get_num_threads() == 2
        assert torch.get_num_threads() == 1
        with threads.torch_threads(None) as n:  # unchanged
            assert n == 1 and torch.get_num_threads() == 1
        try:
            with threads.torch_threads(2):
                raise KeyError("inside")
        except KeyError:
            pass
        assert torch.get_num_threads() == 1  # restored after an error too
        try:
            with threads.torch_threads(0):
                pass
        except ValueError as e:
            assert "n >= 1" in str(e)
        else:
            raise AssertionError("0 threads accepted")
    finally:
        torch.set_num_threads(before)
