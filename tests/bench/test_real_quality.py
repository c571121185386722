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


def _held_out_painting_names(count):
    from stylize3d_core.train.real_images import HELD_OUT_SHARE, name_fraction

    names, k = [], 0
    while len(names) < count:
        name = f"test_{k:04d}.png"
        if name_fraction(name) < HELD_OUT_SHARE:
            names.append(name)
        k += 1
    return names


def test_the_real_pairs_bench_runs_end_to_end_on_a_tiny_folder(tmp_path):
    """Two held-out photos (a box in front of a wall: a hidden layer to reveal) and two paintings: every
    figure finite for every method, the plain photo's warp below the 2D network's, boards and seam boards
    written with their keys apart."""
    import json

    import numpy as np

    from stylize3d_core.bench.real_quality import run_real_quality
    from stylize3d_core.io.images import save_image

    rng = np.random.default_rng(0)
    (tmp_path / "data" / "photos").mkdir(parents=True)
    (tmp_path / "data" / "paintings").mkdir()
    y, x = np.mgrid[0:72, 0:96].astype(np.float32)
    for k in range(2):
        photo = np.stack([0.5 + 0.3 * np.sin(x / (5 + k)), 0.5 + 0.3 * np.cos(y / 6), 0.4 + 0 * x], -1)
        photo[20:52, 30:66] = [0.9, 0.2 + 0.3 * k, 0.1]  # a bright box: the depth prior lifts it
        save_image(tmp_path / "data" / "photos" / f"kodak_{k:04d}.png", photo)
    for name in _held_out_painting_names(2):
        painting = np.repeat(np.repeat(rng.random((8, 8, 3), dtype=np.float32), 8, 0), 8, 1)
        save_image(tmp_path / "data" / "paintings" / name, painting)
    out = tmp_path / "out"
    means = run_real_quality(out, str(tmp_path / "data"), pairs=2, frames=9, frame_long_side=96, photo_size=96,
                             style_every=4, board_frame=4)
    assert set(means) == {"ours", "2d", "baked", "plain"}
    for method, figures in means.items():
        for q in ("style_dist", "edge_f1", "short", "long"):
            assert math.isfinite(figures[q]), (method, q)
    assert means["plain"]["edge_f1"] == pytest.approx(1.0)
    assert means["plain"]["short"] < means["2d"]["short"]
    assert means["ours"]["short"] < means["2d"]["short"]
    data = json.loads((out / "real_quality.json").read_text())
    assert len(data["pairs"]) == 2 and "seam_ratios" in data
    text = (out / "real_quality.md").read_text()
    assert "## Seams: disoccluded / all pixels" in text and "single-pixel test" in text
    for boards in ("boards_ours_vs_baked", "boards_ours_vs_2d"):
        assert len(list((out / boards).glob("board_*.png"))) == 2 and (out / f"{boards}_key.json").is_file()
    seams = sorted((out / "seams_ours_vs_baked").glob("board_*.png"))  # the box reveals the wall behind it
    key = json.loads((out / "seams_ours_vs_baked_key.json").read_text())
    assert len(seams) == len(key["boards"]) == 2 and {b["A"] for b in key["boards"]} <= {"ours", "baked"}
