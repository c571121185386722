"""The real-pairs report's seam ratios (stylize3d_core/bench/real_quality.py)."""

import math

import pytest

from stylize3d_core.bench.real_quality import EDGE_METRICS, METRICS, _seam_ratios


def _row(short, short_dis, long, long_dis):
    values = {q: 0.0 for q in METRICS + EDGE_METRICS}
    values.update(short=short, short_dis=short_dis, long=long, long_dis=long_dis, short_edge=2 * short,
                  short_dis_edge=3 * short_dis if math.isfinite(short_dis) else math.nan, long_edge=long,
                  long_dis_edge=long_dis)
    return {"methods": {"ours": values}}


def test_seam_ratio_is_the_ratio_of_means_over_pairs_with_disocclusions():
    rows = [_row(0.01, 0.02, 0.01, 0.01), _row(0.03, 0.03, 0.02, 0.05), _row(0.5, math.nan, 0.5, math.nan)]
    seam = _seam_ratios(rows, ["ours"])
    assert seam["pairs"] == 2
    # the third pair has no disoccluded pixels: its all-pixel figure does not count either
    assert seam["ours"]["short"] == pytest.approx(0.025 / 0.02)
    assert seam["ours"]["long"] == pytest.approx(0.03 / 0.015)
    assert seam["ours"]["short_edge"] == pytest.approx(3 * 0.025 / (2 * 0.02))
    assert seam["ours"]["long_edge"] == pytest.approx(0.03 / 0.015)


def test_seam_ratio_without_disocclusions_is_nan():
    seam = _seam_ratios([_row(0.01, math.nan, 0.01, math.nan)], ["ours"])
    assert seam["pairs"] == 0 and math.isnan(seam["ours"]["short"])
    assert _seam_ratios([], []) == {"pairs": 0}
