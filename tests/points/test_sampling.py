import pytest
import torch

from stylize3d_core.errors import InputError
from stylize3d_core.points import farthest_point_sample
from stylize3d_core.points.reference import coverage_radius, farthest_point_sample_reference
from stylize3d_core.points.sampling import _tree_height


def test_matches_textbook_fps_random():
    xyz = torch.rand(2000, 3, generator=torch.Generator().manual_seed(1))
    idx = farthest_point_sample(xyz, 500)
    assert idx.dtype == torch.long and idx.shape == (500,)
    ref = farthest_point_sample_reference(xyz, 500, first=int(idx[0]))
    assert torch.equal(idx, ref)


@pytest.mark.parametrize("n_points, n_samples", [(64 * 48, 768), (150 * 140, 300)])
def test_matches_textbook_fps_surface(n_points, n_samples, surface_cloud):
    # two sizes exercise two k-d tree heights of the bucket FPS
    h = 64 if n_points == 64 * 48 else 150
    xyz = surface_cloud(h, n_points // h, jitter=0.5)
    idx = farthest_point_sample(xyz, n_samples)
    ref = farthest_point_sample_reference(xyz, n_samples, first=int(idx[0]))
    assert torch.equal(idx, ref)


def test_coverage_radius_close_to_fps_from_point_zero(surface_cloud):
    xyz = surface_cloud(60, 80, jitter=0.5)
    fast = coverage_radius(xyz, farthest_point_sample(xyz, 300))
    ref = coverage_radius(xyz, farthest_point_sample_reference(xyz, 300, first=0))
    assert fast <= 1.1 * ref and ref <= 1.1 * fast


def test_deterministic_and_prefix_property():
    xyz = torch.rand(3000, 3, generator=torch.Generator().manual_seed(2))
    a = farthest_point_sample(xyz, 400, start=7)
    b = farthest_point_sample(xyz, 400, start=7)
    assert torch.equal(a, b)
    # FPS of fewer points from the same seed is a prefix
    assert torch.equal(farthest_point_sample(xyz, 100, start=7), a[:100])


def test_duplicates_give_distinct_indices_like_the_reference():
    base = torch.rand(10, 3, generator=torch.Generator().manual_seed(3))
    xyz = base.repeat_interleave(10, dim=0)  # (100, 3): 10 positions, 10 copies each
    idx = farthest_point_sample(xyz, 30)
    assert len(torch.unique(idx)) == 30
    # the first 10 picks cover every distinct position, in the textbook order
    # (which of the equal copies is picked is a tie)
    ref = farthest_point_sample_reference(xyz, 30, first=int(idx[0]))
    assert torch.equal(xyz[idx[:10]], xyz[ref[:10]])
    # then the unpicked points in ascending order
    rest = [i for i in range(100) if i not in idx[:10].tolist()][:20]
    assert idx[10:].tolist() == rest


def test_all_coincident_points():
    xyz = torch.full((100, 3), 0.25)
    idx = farthest_point_sample(xyz, 50)
    assert len(torch.unique(idx)) == 50 and int(idx.min()) >= 0 and int(idx.max()) < 100


@pytest.mark.parametrize("n", [1, 2, 3, 7, 16])
def test_tiny_clouds_and_all_points(n):
    xyz = torch.rand(n, 3, generator=torch.Generator().manual_seed(n))
    idx = farthest_point_sample(xyz, n)
    assert sorted(idx.tolist()) == list(range(n))
    assert len(farthest_point_sample(xyz, 1)) == 1


def test_float64_input_not_modified():
    xyz = torch.rand(500, 3, dtype=torch.float64, generator=torch.Generator().manual_seed(4))
    before = xyz.clone()
    farthest_point_sample(xyz, 100)
    assert torch.equal(xyz, before)


def test_tree_height_is_valid():
    for n in [2, 3, 8, 100, 5000, 75_000, 300_000, 1_000_000, 10_000_000]:
        h = _tree_height(n)
        assert 1 <= h and 2**h <= n
    assert _tree_height(300_000) == 8 and _tree_height(1_000_000) == 9


@pytest.mark.parametrize(
    "xyz, n, start",
    [
        (torch.rand(10, 2), 5, 0),
        (torch.rand(0, 3), 1, 0),
        (torch.rand(10, 3), 0, 0),
        (torch.rand(10, 3), 11, 0),
        (torch.rand(10, 3), 5, 10),
        (torch.rand(10, 3), 5, -1),
        (torch.rand(10, 3), 2.5, 0),
        (torch.rand(10, 3), True, 0),
        (torch.tensor([[0.0, 0.0, float("nan")]] * 4), 2, 0),
        (torch.zeros(10, 3, dtype=torch.long), 5, 0),
    ],
)
def test_bad_inputs(xyz, n, start):
    with pytest.raises(InputError):
        farthest_point_sample(xyz, n, start=start)


# --- the worker process (large clouds): the same indices, without holding the GIL ---

from stylize3d_core.points import sampling as _sampling  # noqa: E402


@pytest.fixture
def fps_worker():
    """The worker enabled (restored afterwards, whatever the environment says)."""
    before = _sampling._WORKER.enabled
    _sampling.set_fps_process(True)
    yield _sampling._WORKER
    _sampling._WORKER.enabled = before


def test_worker_process_gives_the_in_process_indices(fps_worker, surface_cloud):
    xyz = surface_cloud(200, 200, jitter=0.5)  # 40k points: above PROCESS_MIN_POINTS
    assert xyz.shape[0] >= _sampling.PROCESS_MIN_POINTS
    xyz[:500] = xyz[0]  # coincident points too
    a = farthest_point_sample(xyz, 2000, start=3)
    assert fps_worker._proc is not None and fps_worker._proc.poll() is None  # it ran in the worker
    _sampling.set_fps_process(False)
    assert fps_worker._proc is None  # turning it off ends the process
    b = farthest_point_sample(xyz, 2000, start=3)
    assert torch.equal(a, b)
    ref = farthest_point_sample_reference(xyz, 300, first=int(a[0]))
    assert torch.equal(a[:300], ref)


def test_worker_process_leaves_other_threads_running(fps_worker):
    import threading
    import time

    xyz = torch.rand(200_000, 3, generator=torch.Generator().manual_seed(4))
    _sampling.start_fps_process()
    farthest_point_sample(xyz[:40_000], 10)  # the worker's imports are done
    done = threading.Event()
    worker = threading.Thread(target=lambda: (farthest_point_sample(xyz, 50_000), done.set()))
    ticks = 0
    worker.start()
    while not done.is_set():  # in-process fpsample holds the GIL: this loop would not run until it ends
        time.sleep(0.001)
        ticks += 1
    worker.join()
    assert ticks >= 10


def test_a_killed_worker_is_replaced(fps_worker, surface_cloud):
    xyz = surface_cloud(200, 180)
    _sampling.start_fps_process()
    fps_worker._proc.kill()
    fps_worker._proc.wait()
    a = farthest_point_sample(xyz, 500)
    assert fps_worker.enabled and fps_worker._proc.poll() is None
    ref = farthest_point_sample_reference(xyz, 500, first=int(a[0]))
    assert torch.equal(a, ref)


def test_worker_failure_falls_back_to_this_process(fps_worker, surface_cloud, tmp_path, monkeypatch):
    broken = tmp_path / "broken_worker.py"
    broken.write_text("import sys\nsys.exit(3)\n")
    fps_worker.stop()
    monkeypatch.setattr(_sampling, "_WORKER_SOURCE", broken)
    xyz = surface_cloud(200, 180)
    with pytest.warns(UserWarning, match="farthest point sampling worker failed"):
        a = farthest_point_sample(xyz, 500)
    assert not fps_worker.enabled  # the rest of the session samples here
    ref = farthest_point_sample_reference(xyz, 500, first=int(a[0]))
    assert torch.equal(a, ref)


def test_stop_while_a_sampling_holds_the_worker_kills_it(fps_worker, surface_cloud):
    _sampling.start_fps_process()
    proc = fps_worker._proc
    with fps_worker._lock:  # as a daemon thread in the middle of a sampling at interpreter exit
        fps_worker.stop()  # returns (after a short wait) instead of blocking
        assert proc.wait(timeout=5) is not None
    xyz = surface_cloud(200, 180)
    a = farthest_point_sample(xyz, 300)  # a new worker
    assert fps_worker.enabled and fps_worker._proc is not proc
    assert torch.equal(a, farthest_point_sample_reference(xyz, 300, first=int(a[0])))


def test_worker_is_quiet_when_its_parent_is_gone_or_ctrl_c_reaches_it():
    """Ctrl+C in a terminal reaches the whole process group and the parent handles it; a worker whose answer
    meets a closed pipe (the parent died first) exits without a traceback on the shared stderr."""
    import signal
    import subprocess
    import sys
    import time

    source = _sampling._WORKER_SOURCE.read_text(encoding="utf-8")
    for stop in ("closed stdout", "SIGINT"):
        proc = subprocess.Popen([sys.executable, "-c", source], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE)
        if stop == "closed stdout":
            proc.stdout.close()  # its ready byte meets a broken pipe
        else:
            assert proc.stdout.read(1) == b"R"
            proc.send_signal(signal.SIGINT)
            time.sleep(0.3)
            assert proc.poll() is None  # ignored: it still waits for requests
            proc.stdout.close()
        proc.stdin.close()  # the end of its input ends it
        err = proc.stderr.read()
        proc.stderr.close()
        assert proc.wait(timeout=60) == 0 and b"Traceback" not in err, (stop, err)
