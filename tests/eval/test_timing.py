"""The benchmarks' timing helpers, with a fake clock."""

import pytest

from stylize3d_core.errors import InputError
from stylize3d_core.eval.timing import median_and_min, median_time, peak_rss_gib, time_runs


class FakeClock:
    """Returns the given readings in turn and counts how often it was read."""

    def __init__(self, *readings: float) -> None:
        self.readings = list(readings)
        self.reads = 0

    def __call__(self) -> float:
        self.reads += 1
        return self.readings.pop(0)


class Calls:
    def __init__(self) -> None:
        self.n = 0

    def __call__(self) -> None:
        self.n += 1


def test_each_run_is_the_difference_of_two_clock_readings():
    clock = FakeClock(0.0, 1.0, 10.0, 13.0, 20.0, 22.0)
    fn = Calls()
    assert time_runs(fn, 3, clock=clock) == [1.0, 3.0, 2.0]
    assert fn.n == 3 and clock.reads == 6


def test_warmup_calls_are_made_first_and_not_timed():
    clock = FakeClock(5.0, 5.5, 6.0, 7.0)
    order = []

    def fn():
        order.append(clock.reads)  # how many readings were taken before this call

    assert time_runs(fn, 2, warmup=3, clock=clock) == [0.5, 1.0]
    assert order == [0, 0, 0, 1, 3]  # three warm-up calls before any reading


def test_median_and_min_of_known_runs():
    # runs of 4, 1, 3, 2 s: median 2.5 (mean of the middle two), minimum 1
    readings = (0.0, 4.0, 4.0, 5.0, 5.0, 8.0, 8.0, 10.0)
    assert median_and_min(Calls(), 4, clock=FakeClock(*readings)) == (2.5, 1.0)
    assert median_time(Calls(), 4, clock=FakeClock(*readings)) == 2.5
    odd = FakeClock(0.0, 3.0, 3.0, 4.0, 4.0, 9.0)  # 3, 1, 5 s
    fn = Calls()
    assert median_and_min(fn, 3, warmup=1, clock=odd) == (3.0, 1.0) and fn.n == 4


def test_real_clock_gives_non_negative_seconds():
    times = time_runs(lambda: sum(range(1000)), 3)
    assert len(times) == 3 and all(t >= 0.0 for t in times)


@pytest.mark.parametrize("repeats, warmup", [(0, 0), (-1, 0), (2.5, 0), (True, 0), (1, -1), (1, 0.5)])
def test_bad_counts_are_input_errors(repeats, warmup):
    fn = Calls()
    with pytest.raises(InputError):
        time_runs(fn, repeats, warmup=warmup)
    assert fn.n == 0  # nothing ran


def test_peak_rss_is_a_plausible_size_in_gib():
    peak = peak_rss_gib()
    assert 0.005 < peak < 1024  # a Python process with torch imported holds well over 5 MB
    assert peak_rss_gib() >= peak  # a peak never goes down
