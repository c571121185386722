"""Edge alignment: bilateral median (against a slow reference), joint bilateral, guided."""

from __future__ import annotations

import numpy as np
import pytest

from stylize3d_core.depth.refine import RefineSettings, bilateral_median, refine_depth, refine_disparity
from stylize3d_core.depth.types import DepthMap
from stylize3d_core.errors import InputError


def bilateral_median_reference(values, guide, radius, sigma_color, sigma_space, weights=None):
    """Per-pixel loops: the weighted median of the clipped-border window, as documented."""
    h, w = values.shape
    out = np.empty((h, w), np.float64)
    for i in range(h):
        for j in range(w):
            vals, wts = [], []
            for dy in range(-radius, radius + 1):
                for dx in range(-radius, radius + 1):
                    y, x = min(max(i + dy, 0), h - 1), min(max(j + dx, 0), w - 1)
                    dc = guide[y, x].astype(np.float64) - guide[i, j]
                    wk = np.exp(-(dy * dy + dx * dx) / (2 * sigma_space**2)) * np.exp(-(dc @ dc) / (2 * sigma_color**2))
                    if weights is not None:
                        wk *= weights[y, x]
                    vals.append(values[y, x])
                    wts.append(wk)
            vals, wts = np.array(vals), np.array(wts)
            if wts.sum() <= 0:
                wts = np.ones_like(wts)
            order = np.argsort(vals, kind="stable")
            cum = np.cumsum(wts[order])
            out[i, j] = vals[order][np.argmax(cum >= 0.5 * cum[-1])]
    return out


@pytest.mark.parametrize("radius", [1, 2])
@pytest.mark.parametrize("with_weights", [False, True])
def test_bilateral_median_matches_reference(radius, with_weights):
    rng = np.random.default_rng(radius)
    h, w = 13, 17
    values = rng.random((h, w)).astype(np.float32)
    guide = rng.random((h, w, 3)).astype(np.float32)
    weights = (rng.random((h, w)) > 0.3).astype(np.float32) if with_weights else None
    fast = bilateral_median(values, guide, radius, 0.3, 1.5, weights, chunk_rows=5)
    ref = bilateral_median_reference(values, guide, radius, 0.3, 1.5, weights)
    np.testing.assert_allclose(fast, ref, rtol=0, atol=1e-6)


def test_bilateral_median_moves_a_soft_edge_onto_the_colour_edge():
    h, w = 20, 40
    guide = np.zeros((h, w, 3), np.float32)
    guide[:, 20:] = 1.0  # colour edge between columns 19 and 20
    disp = np.where(np.arange(w) < 17, 1.0, 3.0).astype(np.float32)  # depth edge 3 px off
    disp = np.repeat(disp[None], h, axis=0)
    disp[:, 15:22] = np.linspace(1.0, 3.0, 7)  # and blurred
    out = refine_disparity(disp, guide, RefineSettings(radius=4, sigma_color=0.1, iterations=2))
    # Right of the colour edge: the far value only; left of it: nothing of the far side.
    assert (out[:, 20:] == 3.0).all()
    assert out[:, :20].max() <= 2.0 < disp[:, :20].max()
    # The step is now between columns 19 and 20, and sharp (one pixel).
    assert (out[:, 20] - out[:, 19] >= 1.0).all()


def test_bilateral_median_keeps_constant_and_picks_input_values():
    rng = np.random.default_rng(3)
    guide = rng.random((16, 16, 3)).astype(np.float32)
    np.testing.assert_array_equal(bilateral_median(np.full((16, 16), 2.5, np.float32), guide, 2, 0.1, 1.0), 2.5)
    values = rng.integers(1, 6, (16, 16)).astype(np.float32)
    out = bilateral_median(values, guide, 2, 0.1, 1.0)
    assert np.isin(out, values).all()


def test_invalid_pixels_are_not_chosen():
    guide = np.zeros((10, 10, 3), np.float32)
    values = np.full((10, 10), 2.0, np.float32)
    valid = np.ones((10, 10), bool)
    values[4:6, 4:6] = 100.0  # junk in invalid pixels
    valid[4:6, 4:6] = False
    out = refine_disparity(values, guide, RefineSettings(radius=2), valid)
    np.testing.assert_array_equal(out, 2.0)


def depth_map(h=24, w=32):
    depth = np.full((h, w), 4.0, np.float32)
    depth[6:18, 8:20] = 1.5
    valid = np.ones((h, w), bool)
    valid[0, 0] = False
    return DepthMap(depth, valid, "metric", "test")


@pytest.mark.parametrize("method", ["bilateral_median", "joint_bilateral", "guided"])
def test_refine_depth_keeps_range_kind_and_mask(method):
    dm = depth_map()
    rng = np.random.default_rng(0)
    rgb = np.clip(rng.normal(0.5, 0.1, (24, 32, 3)), 0, 1).astype(np.float32)
    rgb[6:18, 8:20] += 0.3
    out = refine_depth(dm, np.clip(rgb, 0, 1), RefineSettings(method=method))
    assert out.shape == dm.shape and out.depth.dtype == np.float32
    assert np.isfinite(out.depth).all() and out.depth.min() >= 1.5 - 1e-6 and out.depth.max() <= 4.0 + 1e-6
    assert out.kind == "metric" and (out.valid == dm.valid).all()
    assert out.source == f"test + {method}"
    assert out.depth[10, 12] == pytest.approx(1.5, rel=0.05) and out.depth[2, 28] == pytest.approx(4.0, rel=0.05)


def test_refine_does_not_modify_inputs():
    dm = depth_map()
    rgb = np.random.default_rng(1).random((24, 32, 3)).astype(np.float32)
    d0, r0 = dm.depth.copy(), rgb.copy()
    refine_depth(dm, rgb)
    np.testing.assert_array_equal(dm.depth, d0)
    np.testing.assert_array_equal(rgb, r0)


def test_refine_bad_input():
    dm = depth_map()
    with pytest.raises(InputError, match="same size"):
        refine_depth(dm, np.zeros((10, 10, 3), np.float32))
    with pytest.raises(InputError, match="refine method"):
        RefineSettings(method="median")
    with pytest.raises(InputError, match="refine radius"):
        RefineSettings(radius=0)
    with pytest.raises(InputError, match="refine radius"):
        RefineSettings(radius=2.5)
    with pytest.raises(InputError, match="NaN"):
        refine_depth(dm, np.full((24, 32, 3), np.nan, np.float32))
