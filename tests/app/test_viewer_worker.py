"""The viewer's compute worker (app/viewer/worker.py): ordering, stale renders dropped, errors reported."""

from __future__ import annotations

import threading
from typing import List

import pytest

from stylize3d_app.viewer.worker import ComputeWorker, RenderResult, should_deliver

TIMEOUT = 10.0


@pytest.fixture
def worker():
    errors: List[str] = []
    w = ComputeWorker(on_error=lambda name, e: errors.append(f"{name}: {e}"))
    w.errors = errors
    w.start()
    yield w
    assert w.stop(timeout=TIMEOUT)


def wait_idle(w: ComputeWorker) -> None:
    done = threading.Event()
    w.submit("flush", lambda: None, on_done=lambda _: done.set())
    assert done.wait(TIMEOUT)


def blocker(w: ComputeWorker):
    """Occupy the worker with a task until the returned event is set."""
    started, release = threading.Event(), threading.Event()

    def task():
        started.set()
        assert release.wait(TIMEOUT)

    w.submit("block", task)
    assert started.wait(TIMEOUT)
    return release


def test_should_deliver_truth_table():
    assert should_deliver(5, 5, 4, preview=False)  # the newest: always
    assert should_deliver(5, 5, 4, preview=True)
    assert should_deliver(4, 5, 3, preview=True)  # an older preview: keeps a drag live
    assert not should_deliver(4, 5, 3, preview=False)  # an older full frame: the camera moved on
    assert not should_deliver(4, 5, 4, preview=True)  # already shown
    assert not should_deliver(3, 5, 4, preview=True)  # older than what is shown


def test_tasks_run_in_order_and_keyed_tasks_coalesce(worker):
    log: List[str] = []
    release = blocker(worker)
    worker.submit("a", lambda: log.append("a"))
    for v in (0.1, 0.2, 0.3):
        worker.submit("strength", lambda v=v: log.append(f"s{v}"), key="strength")
    worker.submit("b", lambda: log.append("b"))
    release.set()
    wait_idle(worker)
    assert log == ["a", "s0.3", "b"]


def test_newest_render_wins_and_stale_requests_are_dropped(worker):
    rendered, delivered = [], []
    release = blocker(worker)
    for i in range(5):
        worker.request_render(lambda i=i: rendered.append(i) or i, delivered.append, preview=True)
    release.set()
    wait_idle(worker)
    assert rendered == [4]
    assert [(r.generation, r.value, r.preview) for r in delivered] == [(5, 4, True)]
    assert isinstance(delivered[0], RenderResult) and delivered[0].seconds >= 0
    assert worker.dropped == 4 and worker.generation == 5


@pytest.mark.parametrize("preview", [False, True])
def test_stale_full_frame_is_not_shown_but_a_stale_preview_is(worker, preview):
    in_render, go_on = threading.Event(), threading.Event()
    delivered: List[int] = []

    def slow():
        in_render.set()
        assert go_on.wait(TIMEOUT)
        return "slow"

    g1 = worker.request_render(slow, lambda r: delivered.append(r.generation), preview=preview)
    assert in_render.wait(TIMEOUT)  # g1 is rendering when g2 arrives
    g2 = worker.request_render(lambda: "new", lambda r: delivered.append(r.generation), preview=preview)
    go_on.set()
    wait_idle(worker)
    assert delivered == ([g1, g2] if preview else [g2])


def test_render_order_respects_tasks_requested_before_it(worker):
    log: List[str] = []
    release = blocker(worker)  # task 0 runs
    worker.request_render(lambda: log.append("r1"), lambda r: None, preview=True)  # needs only task 0
    worker.submit("t1", lambda: log.append("t1"))
    release.set()
    wait_idle(worker)
    assert log == ["r1", "t1"]  # the render did not wait for a task submitted after it
    log.clear()
    release = blocker(worker)
    worker.submit("strength", lambda: log.append("strength"))
    worker.request_render(lambda: log.append("render"), lambda r: None, preview=True)
    release.set()
    wait_idle(worker)
    assert log == ["strength", "render"]  # the render sees the strength change requested before it


def test_long_task_serves_renders_between_steps(worker):
    log: List[str] = []
    step_started = threading.Event()
    requested = threading.Event()

    def export():
        for i in range(3):
            log.append(f"frame{i}")
            if i == 0:
                step_started.set()
                assert requested.wait(TIMEOUT)
            worker.serve_pending_render()

    worker.submit("export", export)
    assert step_started.wait(TIMEOUT)
    worker.request_render(lambda: log.append("view"), lambda r: None, preview=True)
    requested.set()
    wait_idle(worker)
    assert log == ["frame0", "view", "frame1", "frame2"]
    with pytest.raises(RuntimeError, match="worker thread"):
        worker.serve_pending_render()


def test_errors_are_reported_and_the_worker_keeps_running(worker):
    task_errors, render_errors, done = [], [], []

    def bad():
        raise ValueError("bad file")

    worker.submit("open photo", bad, on_error=lambda name, e: task_errors.append((name, str(e))))
    worker.submit("default handler", bad)
    worker.request_render(bad, lambda r: None, preview=False, on_error=lambda n, e: render_errors.append(str(e)))
    worker.submit("after", lambda: 42, on_done=done.append)
    wait_idle(worker)
    assert task_errors == [("open photo", "bad file")]
    assert worker.errors == ["default handler: bad file"]
    assert render_errors == ["bad file"] and done == [42]


def test_stop_drops_waiting_work_and_refuses_new_work():
    w = ComputeWorker()
    w.start()
    release = blocker(w)
    ran: List[str] = []
    w.submit("later", lambda: ran.append("later"))
    threading.Timer(0.05, release.set).start()
    assert w.stop(timeout=TIMEOUT)
    w.submit("after stop", lambda: ran.append("after"))
    assert w.request_render(lambda: ran.append("r"), lambda r: None, preview=True) == 0
    assert ran == [] and not w.thread.is_alive()


def test_a_newer_request_stops_a_running_full_render_between_stages(worker):
    from stylize3d_core.errors import RenderInterrupted

    stages: List[int] = []
    in_render = threading.Event()
    cancel = threading.Event()
    interrupted = threading.Event()
    delivered: List[str] = []

    def full():
        for i in range(1000):
            if cancel.is_set():
                raise RenderInterrupted("stopped")
            stages.append(i)
            in_render.set()
            cancel.wait(0.01)
        return "full"

    worker.request_render(full, lambda r: delivered.append(r.value), preview=False, cancel=cancel,
                          on_interrupted=interrupted.set)
    assert in_render.wait(TIMEOUT)
    worker.request_render(lambda: "preview", lambda r: delivered.append(r.value), preview=True)
    assert interrupted.wait(TIMEOUT)
    wait_idle(worker)
    assert cancel.is_set() and len(stages) < 1000
    assert delivered == ["preview"] and worker.interrupted == 1 and worker.errors == []


def test_interrupt_render_only_stops_renders_that_carry_a_cancel_event(worker):
    assert not worker.interrupt_render()  # nothing runs
    in_render, go_on = threading.Event(), threading.Event()

    def preview():
        in_render.set()
        assert go_on.wait(TIMEOUT)
        return 1

    worker.request_render(preview, lambda r: None, preview=True)
    assert in_render.wait(TIMEOUT)
    assert not worker.interrupt_render()
    go_on.set()
    wait_idle(worker)


def test_render_waiting_is_true_only_until_the_render_starts(worker):
    assert not worker.render_waiting()
    release = blocker(worker)
    worker.request_render(lambda: 1, lambda r: None, preview=True)
    assert worker.render_waiting()  # queued behind the task
    release.set()
    wait_idle(worker)
    assert not worker.render_waiting()
