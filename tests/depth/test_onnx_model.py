"""ONNX depth models: tiny torch models exported by the tests, run with onnxruntime."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from stylize3d_core.depth.onnx_model import (
    PRESETS,
    OnnxDepthModel,
    OnnxPreset,
    OnnxSettings,
    preset_by_name,
)
from stylize3d_core.errors import InputError

RAW_EXACT = OnnxPreset(size=64, fit="keep_aspect", multiple_of=1, mean=(0, 0, 0), std=(1, 1, 1), output="depth")


class MeanPlusOne(torch.nn.Module):
    """depth = 1 + mean over channels: (N, 3, H, W) -> (N, 1, H, W)."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return 1.0 + x.mean(dim=1, keepdim=True)


class RedChannel(torch.nn.Module):
    """inverse depth = red channel: (N, 3, H, W) -> (N, H, W)."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x[:, 0]


class ChannelsLast(torch.nn.Module):
    """(N, H, W, 3) -> (N, H, W, 1): depth = 1 + green."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return 1.0 + x[..., 1:2]


class TwoChannels(torch.nn.Module):
    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x[:, :2]


class Constant(torch.nn.Module):
    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x[:, :1] * 0.0 + 2.0


class Rank3(torch.nn.Module):
    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x[:1] + 1.0


class TwoInputs(torch.nn.Module):
    def forward(self, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        return x[:, :1] + y[:, :1]


@pytest.fixture(scope="module")
def models(export_onnx):
    img = torch.rand(1, 3, 32, 48)
    return {
        "mean": export_onnx(MeanPlusOne(), img, "mean.onnx"),
        "red": export_onnx(RedChannel(), img, "red.onnx"),
        "fixed": export_onnx(MeanPlusOne(), torch.rand(1, 3, 32, 32), "fixed.onnx", dynamic=False),
        "nhwc": export_onnx(ChannelsLast(), torch.rand(1, 32, 48, 3), "nhwc.onnx", nhwc=True),
        "two_channels": export_onnx(TwoChannels(), img, "two.onnx"),
        "constant": export_onnx(Constant(), img, "constant.onnx"),
        "rank3": export_onnx(Rank3(), torch.rand(3, 32, 48), "rank3.onnx", dynamic=False),
        "two_inputs": export_onnx(TwoInputs(), (img, img), "two_inputs.onnx", dynamic=False),
    }


def photo(h: int = 48, w: int = 64) -> np.ndarray:
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    return np.stack([xx / (w - 1), yy / (h - 1), np.full_like(xx, 0.25)], axis=-1)


def test_depth_output_known_values(models):
    rgb = photo()
    model = OnnxDepthModel(models["mean"], OnnxSettings(preset=RAW_EXACT))
    assert model.input_size(48, 64) == (48, 64) and model.layout == "NCHW" and model.fixed_size is None
    dm = model.estimate(rgb)
    assert dm.shape == (48, 64) and dm.kind == "relative" and dm.valid.all()
    np.testing.assert_allclose(dm.depth, 1.0 + rgb.mean(axis=2), atol=1e-5)
    assert dm.source == "onnx:mean.onnx"


def test_normalisation_is_applied(models):
    rgb = photo()
    preset = replace(RAW_EXACT, input_range=255.0, mean=(10.0, 20.0, 30.0), std=(2.0, 4.0, 5.0))
    model = OnnxDepthModel(models["mean"], OnnxSettings(preset=preset))
    x = model.preprocess(rgb)
    assert x.shape == (1, 3, 48, 64) and x.dtype == np.float32
    np.testing.assert_allclose(x[0, 0], (rgb[..., 0] * 255 - 10) / 2, rtol=1e-5, atol=1e-4)
    np.testing.assert_allclose(x[0, 2], (rgb[..., 2] * 255 - 30) / 5, rtol=1e-5, atol=1e-4)


def test_inverse_depth_is_converted_with_the_documented_scale(models):
    rgb = photo()
    preset = replace(RAW_EXACT, output="inverse_depth")
    dm = OnnxDepthModel(models["red"], OnnxSettings(preset=preset, far_ratio=10.0)).estimate(rgb)
    assert dm.kind == "relative" and np.isfinite(dm.depth).all()
    # Red grows to the right: inverse depth grows, depth falls.
    assert (np.diff(dm.depth[0]) <= 1e-6).all()
    # 99th percentile of the output -> depth 1, 1st percentile -> far_ratio.
    red = rgb[..., 0]
    lo, hi = np.percentile(red, [1, 99])
    n = np.clip((red - lo) / (hi - lo), 0, 1)
    np.testing.assert_allclose(dm.depth, 1.0 / (0.1 + 0.9 * n), rtol=1e-4)
    assert dm.depth.min() == pytest.approx(1.0) and dm.depth.max() == pytest.approx(10.0)


def test_fixed_input_size_is_honoured(models):
    model = OnnxDepthModel(models["fixed"], OnnxSettings(preset=PRESETS["raw"]))
    assert model.fixed_size == (32, 32) and model.input_size(480, 640) == (32, 32)
    dm = model.estimate(photo(60, 90))
    assert dm.shape == (60, 90)
    assert 1.0 < dm.depth.min() and dm.depth.max() < 2.0


def test_channels_last_model(models):
    model = OnnxDepthModel(models["nhwc"], OnnxSettings(preset=RAW_EXACT))
    assert model.layout == "NHWC"
    rgb = photo()
    np.testing.assert_allclose(model.estimate(rgb).depth, 1.0 + rgb[..., 1], atol=1e-5)


def test_metric_preset_gives_metric_kind(models):
    preset = replace(RAW_EXACT, metric=True)
    assert OnnxDepthModel(models["mean"], OnnxSettings(preset=preset)).estimate(photo()).kind == "metric"


def test_presets_sizes():
    assert preset_by_name("depth_anything").size % 14 == 0
    assert preset_by_name("midas").output == "inverse_depth"
    with pytest.raises(InputError, match="onnx preset"):
        preset_by_name("leres")


# --------------------------------------------------------------------------- bad input


def test_not_an_onnx_file(tmp_path):
    path = tmp_path / "model.onnx"
    path.write_text("this is a text file, not a model")
    with pytest.raises(InputError, match="not a valid ONNX model") as err:
        OnnxDepthModel(path)
    assert str(path) in str(err.value)
    empty = tmp_path / "empty.onnx"
    empty.write_bytes(b"")
    with pytest.raises(InputError, match="not a valid ONNX model"):
        OnnxDepthModel(empty)


def test_missing_model_file(tmp_path):
    with pytest.raises(InputError, match="no such ONNX model file"):
        OnnxDepthModel(tmp_path / "nope.onnx")


def test_wrong_input_rank(models):
    with pytest.raises(InputError, match="rank 3") as err:
        OnnxDepthModel(models["rank3"])
    assert "rank3.onnx" in str(err.value)


def test_two_inputs(models):
    with pytest.raises(InputError, match="exactly one input"):
        OnnxDepthModel(models["two_inputs"])


def test_output_that_is_not_one_map(models):
    model = OnnxDepthModel(models["two_channels"], OnnxSettings(preset=RAW_EXACT))
    with pytest.raises(InputError, match="expected one depth map"):
        model.estimate(photo())


def test_constant_output(models):
    preset = replace(RAW_EXACT, output="inverse_depth")
    with pytest.raises(InputError, match="constant"):
        OnnxDepthModel(models["constant"], OnnxSettings(preset=preset)).estimate(photo())


def test_negative_depth_output(models):
    preset = replace(RAW_EXACT, mean=(5.0, 5.0, 5.0))  # 1 + mean(x - 5) < 0 everywhere
    with pytest.raises(InputError, match="no positive finite depth"):
        OnnxDepthModel(models["mean"], OnnxSettings(preset=preset)).estimate(photo())


@pytest.mark.parametrize(
    "kwargs, message",
    [({"fit": "crop"}, "fit"), ({"output": "disparity"}, "output"), ({"std": (1.0, 0.0, 1.0)}, "std"),
     ({"output": "inverse_depth", "metric": True}, "metric")],
)
def test_bad_presets(kwargs, message):
    with pytest.raises(InputError, match=message):
        OnnxPreset(**kwargs)
