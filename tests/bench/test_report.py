"""Bench tables and plots (stylize3d_core/bench/report.py) and the stress suite's table."""

import json

import cv2
import pytest

from stylize3d_core.bench.report import pareto_front, scatter_plot, write_table
from stylize3d_core.errors import InputError


def test_pareto_front():
    # (seconds, quality): lower x and higher y are better
    pts = [(1.0, 30.0), (2.0, 35.0), (1.5, 29.0), (3.0, 34.0), (0.5, 20.0)]
    assert pareto_front(pts) == [4, 0, 1]
    assert pareto_front([(1.0, 1.0)]) == [0]


def test_write_table_and_plot(tmp_path):
    rows = [{"knob": "a|b", "ms": 1.23456, "ok": True}, {"knob": "c", "ms": float("nan"), "ok": False}]
    md, js = write_table(tmp_path, "t", "Title", rows, notes=["a note"])
    data = json.loads(js.read_text())
    assert data["columns"] == ["knob", "ms", "ok"] and data["rows"][1]["ms"] == "nan"
    assert "load_average" in data["machine"]
    text = md.read_text()
    assert "| a\\|b | 1.235 | yes |" in text and "a note" in text
    with pytest.raises(InputError):
        write_table(tmp_path, "empty", "Empty", [])
    png = scatter_plot(tmp_path / "p.png", [(1, 2), (2, 3), (float("nan"), 1)], ["x", "y", "z"], "s", "dB", "T",
                       front=[0, 1])
    img = cv2.imread(str(png))
    assert img is not None and img.shape == (640, 900, 3) and img.min() < 255


def test_sharpness_and_psnr():
    import numpy as np

    from stylize3d_core.bench.consistency import sharpness
    from stylize3d_core.bench.speed import psnr

    flat = np.full((32, 32, 3), 0.5, np.float32)
    noisy = np.clip(flat + np.random.default_rng(0).normal(0, 0.1, flat.shape), 0, 1).astype(np.float32)
    assert sharpness(flat) == 0.0 and sharpness(noisy) > 0.1
    assert psnr(flat, flat) == float("inf")
    assert abs(psnr(flat, flat + 0.1) - 20.0) < 1e-3
