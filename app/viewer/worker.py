"""The viewer's single compute thread: ordered tasks, and renders where only the newest counts.

Two kinds of work reach :class:`ComputeWorker`:

* **Tasks** (load a photo, encode it, set a style or a strength, export,
  save a screenshot) run one at a time in the order submitted. A task submitted
  with a ``key`` replaces a still-waiting task with the same key (dragging the
  strength slider queues one strength change, not fifty).
* **Renders**: one slot holding the newest request. Each request gets the next
  *generation* number; a request that is replaced before it starts is dropped,
  never queued. A render runs before waiting tasks unless it was requested after
  them (it must see their effect: a render requested after a strength change
  shows the new strength). A long task may call :meth:`ComputeWorker.serve_pending_render`
  between its steps (an export, between frames), so the view stays live.

A render may carry a *cancel* event (``request_render(..., cancel=)``): when a
newer request arrives while it runs, the worker sets it, and a render that
checks it between its stages stops with
:class:`~stylize3d_core.errors.RenderInterrupted`; the worker then reports it to
``on_interrupted`` (not as an error) and picks the newer request at once. The
viewer gives full-quality frames a cancel event, so a new drag never waits for
the full frame of the last rest.

A finished render is delivered when :func:`should_deliver` says so: the newest
request always, an older preview only if nothing newer is on screen (so a
continuous drag shows frames), an older full frame never (the camera has moved on).

Callbacks (``on_done``, ``on_error``, ``deliver``) run on the worker thread; the
window wraps them with ``post_to_main_thread``.
"""

from __future__ import annotations

import threading
import time
import traceback
from collections import deque
from dataclasses import dataclass
from typing import Any, Callable, Deque, Generic, Optional, TypeVar

from stylize3d_core.errors import RenderInterrupted

T = TypeVar("T")

ErrorCallback = Callable[[str, BaseException], None]


def should_deliver(generation: int, newest: int, delivered: int, preview: bool) -> bool:
    """Whether a finished render of ``generation`` is shown.

    Args:
        generation: the finished request's generation.
        newest: the newest generation requested so far.
        delivered: the newest generation delivered so far.
        preview: whether the finished render is a preview.
    """
    if generation <= delivered:
        return False
    return generation == newest or preview


@dataclass(frozen=True)
class RenderResult(Generic[T]):
    """A delivered render: its generation, kind, value, seconds spent, and ``time.perf_counter()`` when done."""

    generation: int
    preview: bool
    value: T
    seconds: float
    finished: float


@dataclass
class _Task:
    name: str
    fn: Callable[[], Any]
    on_done: Optional[Callable[[Any], None]]
    on_error: Optional[ErrorCallback]
    key: Optional[str]
    seq: int


@dataclass
class _Render:
    generation: int
    fn: Callable[[], Any]
    deliver: Callable[[RenderResult], None]
    on_error: Optional[ErrorCallback]
    preview: bool
    after_task: int  # tasks with seq < after_task must have run first
    cancel: Optional[threading.Event] = None  # set when a newer request arrives while this one runs
    on_interrupted: Optional[Callable[[], None]] = None


class ComputeWorker:
    """One background thread running the viewer's compute (see the module docstring).

    Thread use: ``submit``, ``request_render``, ``is_idle``, ``stop`` are called
    from any thread (usually the GUI main thread); the work and every callback
    run on the worker's own thread; ``serve_pending_render`` only from inside a task.
    """

    def __init__(self, on_error: Optional[ErrorCallback] = None, name: str = "stylize3d-compute") -> None:
        self._cv = threading.Condition()
        self._tasks: Deque[_Task] = deque()
        self._render: Optional[_Render] = None
        self._generation = 0
        self._delivered = 0
        self._submitted = 0  # task sequence numbers handed out
        self._finished = 0  # tasks finished (ok or failed); tasks finish in order
        self._busy = False
        self._stop = False
        self._dropped = 0
        self._on_error = on_error
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._in_task = False
        self._running: Optional[_Render] = None
        self._interrupted = 0

    # -- any thread ---------------------------------------------------------------
    def start(self) -> None:
        self._thread.start()

    def stop(self, timeout: Optional[float] = None) -> bool:
        """Ask the thread to finish after its current job (waiting work is dropped); True once it has ended."""
        with self._cv:
            self._stop = True
            self._tasks.clear()
            self._render = None
            self._cv.notify_all()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout)
        return not self._thread.is_alive()

    @property
    def thread(self) -> threading.Thread:
        return self._thread

    @property
    def generation(self) -> int:
        """The newest render generation requested."""
        with self._cv:
            return self._generation

    @property
    def dropped(self) -> int:
        """How many render requests were replaced before they started, or finished too late to show."""
        with self._cv:
            return self._dropped

    def submit(self, name: str, fn: Callable[[], T], *, on_done: Optional[Callable[[T], None]] = None,
               on_error: Optional[ErrorCallback] = None, key: Optional[str] = None) -> None:
        """Queue a task; with ``key``, replace a waiting task of the same key (keeping its place)."""
        with self._cv:
            if self._stop:
                return
            if key is not None:
                for t in self._tasks:
                    if t.key == key:
                        t.name, t.fn, t.on_done, t.on_error = name, fn, on_done, on_error
                        return
            self._tasks.append(_Task(name, fn, on_done, on_error, key, self._submitted))
            self._submitted += 1
            self._cv.notify_all()

    @property
    def interrupted(self) -> int:
        """How many running renders were stopped through their cancel event."""
        with self._cv:
            return self._interrupted

    def request_render(self, fn: Callable[[], T], deliver: Callable[[RenderResult[T]], None], *,
                       preview: bool, on_error: Optional[ErrorCallback] = None,
                       cancel: Optional[threading.Event] = None,
                       on_interrupted: Optional[Callable[[], None]] = None) -> int:
        """Make ``fn`` the newest render (replacing a waiting one); returns its generation.

        A render running now that carries a ``cancel`` event is told to stop (its
        event is set). ``on_interrupted`` runs (worker thread) if this render is
        stopped the same way.
        """
        with self._cv:
            if self._stop:
                return self._generation
            if self._render is not None:
                self._dropped += 1
            running = self._running
            if running is not None and running.cancel is not None:
                running.cancel.set()
            self._generation += 1
            self._render = _Render(self._generation, fn, deliver, on_error, preview, self._submitted,
                                   cancel, on_interrupted)
            self._cv.notify_all()
            return self._generation

    def interrupt_render(self) -> bool:
        """Tell the running render to stop, if it carries a cancel event; True if one was told."""
        with self._cv:
            running = self._running
            if running is not None and running.cancel is not None:
                running.cancel.set()
                return True
            return False

    def render_waiting(self) -> bool:
        """True while a render request waits for its turn (not started)."""
        with self._cv:
            return self._render is not None

    def is_idle(self) -> bool:
        """True when nothing runs and nothing waits."""
        with self._cv:
            return not self._busy and not self._tasks and self._render is None

    def pending_tasks(self) -> int:
        """Tasks waiting or running."""
        with self._cv:
            return len(self._tasks) + (1 if self._in_task else 0)

    # -- worker thread ------------------------------------------------------------
    def serve_pending_render(self) -> bool:
        """From inside a task: run the waiting render now if it needs no later task. True if one ran."""
        if threading.current_thread() is not self._thread:
            raise RuntimeError("serve_pending_render must be called on the worker thread, from inside a task")
        with self._cv:
            job = self._render
            # The running task has seq == self._finished; a render requested while it
            # runs has after_task == its seq + 1 when no later task was submitted.
            if job is None or job.after_task > self._finished + 1:
                return False
            self._render = None
        self._run_render(job)
        return True

    def _next_job(self):
        """Pick the next job under the lock: a render that needs no waiting task, else the oldest task."""
        r = self._render
        if r is not None and r.after_task <= self._finished:
            self._render = None
            return r
        if self._tasks:
            return self._tasks.popleft()
        self._render = None  # not reached: a render only ever waits on queued tasks
        return r

    def _run(self) -> None:
        while True:
            with self._cv:
                while not self._stop and not self._tasks and self._render is None:
                    self._cv.wait()
                if self._stop:
                    return
                job = self._next_job()
                self._busy = True
            try:
                if isinstance(job, _Task):
                    self._run_task(job)
                else:
                    self._run_render(job)
            finally:
                with self._cv:
                    self._busy = False
                    self._cv.notify_all()

    def _report(self, name: str, exc: BaseException, handler: Optional[ErrorCallback]) -> None:
        cb = handler or self._on_error
        if cb is None:
            traceback.print_exception(type(exc), exc, exc.__traceback__)
        else:
            cb(name, exc)

    def _run_task(self, task: _Task) -> None:
        self._in_task = True
        try:
            result = task.fn()
        except Exception as e:  # reported to the UI (a dialog); the worker keeps running
            self._report(task.name, e, task.on_error)
        else:
            if task.on_done is not None:
                task.on_done(result)
        finally:
            self._in_task = False
            with self._cv:
                self._finished = task.seq + 1

    def _run_render(self, job: _Render) -> None:
        t0 = time.perf_counter()
        with self._cv:
            self._running = job
        try:
            value = job.fn()
        except RenderInterrupted:  # asked for: a newer request is waiting
            with self._cv:
                self._interrupted += 1
                self._dropped += 1
            if job.on_interrupted is not None:
                job.on_interrupted()
            return
        except Exception as e:  # reported to the UI; the next render may succeed
            self._report("render", e, job.on_error)
            return
        finally:
            with self._cv:
                self._running = None
        seconds = time.perf_counter() - t0
        with self._cv:
            ok = should_deliver(job.generation, self._generation, self._delivered, job.preview)
            if ok:
                self._delivered = job.generation
            else:
                self._dropped += 1
        if ok:
            job.deliver(RenderResult(job.generation, job.preview, value, seconds, t0 + seconds))
