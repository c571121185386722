"""The temporally smoothed 2D baseline of ``bench consistency``: an exponential moving average (known values)."""

import numpy as np
import pytest

from stylize3d_core.bench.consistency import temporal_smoothing
from stylize3d_core.errors import InputError


def test_temporal_smoothing_known_values():
    frames = [np.full((2, 3, 3), v, np.float32) for v in (0.0, 1.0, 1.0)]
    out = temporal_smoothing(frames, 0.5)
    assert [float(f[0, 0, 0]) for f in out] == [0.0, 0.5, 0.75]
    assert all(f.dtype == np.float32 and f.shape == (2, 3, 3) for f in out)
    assert temporal_smoothing(frames, 0.0)[2] is not frames[2]
    np.testing.assert_array_equal(temporal_smoothing(frames, 0.0)[1], frames[1])
    assert temporal_smoothing([], 0.5) == []
    with pytest.raises(InputError):
        temporal_smoothing(frames, 1.0)
