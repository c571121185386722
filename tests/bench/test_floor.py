"""``bench floor``: the work counts (known values) and the quick preset's table."""

import json

import numpy as np
import pytest
import torch

from stylize3d_app.cli import main
from stylize3d_core.bench.floor import conv_flops, decoder_work, interleaved_medians, kept_points, raster_work
from stylize3d_core.geometry.camera import Cameras
from stylize3d_core.models.decoder import DecoderConfig, UNetDecoder


def test_conv_flops_known_value():
    conv = torch.nn.Conv2d(8, 16, 3, padding=1)
    x = torch.zeros(1, 8, 10, 12)
    # 2 * (16 * 10 * 12 outputs) * (8 inputs * 9 taps)
    assert conv_flops(x, conv(x), conv) == 2 * 16 * 120 * 8 * 9
    grouped = torch.nn.Conv2d(8, 8, 3, padding=1, groups=4)
    assert conv_flops(x, grouped(x), grouped) == 2 * 8 * 120 * 2 * 9


def test_decoder_work_counts_every_conv():
    dec = UNetDecoder(DecoderConfig(in_channels=4, width=16, levels=2)).eval()
    f, m = torch.rand(1, 4, 16, 24), torch.ones(1, 1, 16, 24)
    work = decoder_work(dec, f, m)
    convs = [mod for mod in dec.modules() if isinstance(mod, torch.nn.Conv2d)]
    assert len(work) == len(convs)
    first = next(w for w in work if w.name == "skips.0")  # 1x1, 5 -> 4 channels at full size
    assert first.flops == 2 * 4 * 16 * 24 * 5
    assert first.bytes == 4 * (5 * 16 * 24 + 4 * 16 * 24 + 4 * 5)
    assert not any(h for mod in convs for h in mod._forward_hooks.values())  # hooks removed


def test_kept_points_culls_behind_and_outside():
    cam = Cameras.create(np.eye(4), 60.0)
    xyz = torch.tensor([[0.0, 0.0, 2.0], [0.0, 0.0, -2.0], [50.0, 0.0, 2.0], [0.1, -0.1, 1.0]])
    assert kept_points(xyz, cam, 32, 32, near=1e-3) == 2


def test_raster_work_formula():
    flops, moved = raster_work(10, 3, 4, 5, taps=4)
    assert flops == 10 * (20 + 4 * (4 + 6))
    assert moved == 10 * (12 + 12) + 10 * 4 * 16 + 20 * (12 + 9)


def test_interleaved_medians_calls_each_in_rounds():
    calls = []
    interleaved_medians([lambda: calls.append("a"), lambda: calls.append("b")], 2)
    assert calls == ["a", "b"] * 3  # a warm-up round, then 2 timed rounds


def test_bench_floor_quick(tmp_path):
    assert main(["bench", "floor", "--quick", "-q", "--out", str(tmp_path)]) == 0
    data = json.loads((tmp_path / "floor.json").read_text())
    rows = data["rows"]
    # the limits are their own 100 %; each floor is at most the measured time of the limit that sets it
    from stylize3d_core.models.decoder import native_bfloat16

    assert len(rows) == (8 if native_bfloat16() else 5)  # + the bfloat16 conv, decoder and frame where native
    assert rows[0]["pct_conv_peak"] == pytest.approx(100) and rows[1]["pct_bandwidth"] == pytest.approx(100)
    assert rows[0]["x_floor"] <= 1 + 1e-9 and rows[1]["x_floor"] == pytest.approx(1.0)
    assert all(r["ms"] > 0 and r["floor_ms"] > 0 for r in rows)
    dec, ras, full = rows[2], rows[3], rows[4]
    assert full["gflop"] == pytest.approx(dec["gflop"] + ras["gflop"])
    if len(rows) == 8:
        conv_bf, dec_bf, full_bf = rows[5], rows[6], rows[7]
        assert conv_bf["pct_conv_peak"] == pytest.approx(100) and conv_bf["mb_moved"] == pytest.approx(rows[0]["mb_moved"] / 2)
        assert dec_bf["gflop"] == pytest.approx(dec["gflop"]) and full_bf["gflop"] == pytest.approx(full["gflop"])
    per_conv = json.loads((tmp_path / "floor_decoder.json").read_text())["rows"]
    assert sum(r["gflop"] for r in per_conv) == pytest.approx(dec["gflop"])
