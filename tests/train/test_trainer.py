import json

import numpy as np
import pytest
import torch

from stylize3d_core.errors import InputError
from stylize3d_core.io.images import save_image
from stylize3d_core.models.checkpoint import load_checkpoint, save_checkpoint
from stylize3d_core.models.efficientnet_lite import EfficientNetLiteFeatures
from stylize3d_core.models.scene_geometry import NeighbourhoodConfig
from stylize3d_core.models.style_features import StyleEncoder
from stylize3d_core.models.stylize3d import ModelConfig, Stylize3DModel
from stylize3d_core.train.cache import TrainDataset, build_dataset
from stylize3d_core.train.data import DataConfig
from stylize3d_core.train.trainer import LossWeights, TrainConfig, TrainStep, learning_rate, train

SMALL = DataConfig(image_size=(32, 40), scene_textures=3, texture_size=32)


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    root = tmp_path_factory.mktemp("data")
    build_dataset(root / "train", 2, SMALL, seed=1)
    styles = root / "styles"
    styles.mkdir()
    g = np.random.default_rng(0)
    for i in range(2):
        save_image(styles / f"s{i}.png", g.random((64, 64, 3)).astype(np.float32))
    return root


def _log(out, stage):
    return [json.loads(line) for line in (out / f"log_stage{stage}.jsonl").read_text().splitlines()]


def test_stage1_reduces_the_loss_and_resumes(data, tmp_path):
    torch.manual_seed(0)
    out = tmp_path / "run"
    cfg = TrainConfig(stage=1, data_dir=str(data / "train"), out_dir=str(out), iterations=40, batch_size=2,
                      lr=2e-3, log_every=10, checkpoint_every=20, seed=0, threads=1)
    path = train(cfg, log=lambda _: None)
    log = _log(out, 1)
    assert [r["iteration"] for r in log] == [10, 20, 30, 40]
    assert log[-1]["l1"] < 0.7 * log[0]["l1"]
    ck = load_checkpoint(path)
    assert ck.stage == 1 and ck.info["iterations"] == 40
    # Resuming continues from the saved iteration.
    messages = []
    train(TrainConfig(**{**cfg.__dict__, "iterations": 50}), log=messages.append)
    assert any("resuming" in m and "40" in m for m in messages)
    assert load_checkpoint(path).info["iterations"] == 50


def test_stage2_trains_stylizer_with_frozen_encoder(data, tmp_path):
    out = tmp_path / "run"
    s1 = TrainConfig(stage=1, data_dir=str(data / "train"), out_dir=str(out), iterations=2, batch_size=1,
                     log_every=1, threads=1)
    train(s1, log=lambda _: None)
    before = load_checkpoint(out / "model_stage1.safetensors").model
    s2 = TrainConfig(stage=2, data_dir=str(data / "train"), styles_dir=str(data / "styles"), out_dir=str(out),
                     iterations=3, batch_size=1, log_every=1, recon_fraction=0.0, threads=1)
    train(s2, log=lambda _: None)
    after = load_checkpoint(out / "model_stage2.safetensors").model
    for (k, a), (_, b) in zip(before.encoder.state_dict().items(), after.encoder.state_dict().items()):
        assert torch.equal(a, b), f"encoder changed: {k}"
    changed = [k for (k, a), (_, b) in zip(before.stylizer.state_dict().items(), after.stylizer.state_dict().items())
               if not torch.equal(a, b)]
    assert changed
    log = _log(out, 2)
    assert {"content", "style", "consistency"} <= set(log[0])
    assert all(np.isfinite(r["total"]) for r in log)


def test_training_style_features_are_the_style_encoders(data):
    """The stylizer sees StyleEncoder's maps of the style image (resized as at inference), nothing else."""
    sample = TrainDataset(data / "train")[0]
    features = EfficientNetLiteFeatures(stages=(0, 1, 2, 3, 4))
    step = TrainStep(Stylize3DModel(ModelConfig.lite()), features, LossWeights(), 64)
    seen = []
    stylize = step.model.stylizer.stylize
    step.model.stylizer.stylize = lambda content, maps: seen.append(maps) or stylize(content, maps)
    style = torch.rand(3, 40, 48, generator=torch.Generator().manual_seed(0))  # short side < 64: upscaled
    terms = step(sample, style, torch.Generator().manual_seed(0))
    assert {"content", "style", "colour", "consistency"} == set(terms)  # no teacher given: no teacher terms
    with torch.no_grad():
        expected = StyleEncoder(extractor=features)(style[None])
    assert expected.size == (64, 77)
    assert len(seen) == 1 and len(seen[0]) == len(expected.maps)
    for got, want in zip(seen[0], expected.maps):
        assert got.shape == want.shape and torch.allclose(got, want)


def test_style_stages_reach_the_global_style_loss():
    """The style loss matches the stages it is given: stage 3 changes the loss, and only through stage 3."""
    torch.manual_seed(0)
    features = EfficientNetLiteFeatures(stages=(0, 1, 2, 3, 4))
    pred, content, style = torch.rand(1, 3, 64, 64), torch.rand(1, 3, 64, 64), torch.rand(1, 3, 64, 64)
    maps = features(style)
    losses = {}
    for stages in ((1, 2), (1, 2, 3), (3,)):
        step = TrainStep(Stylize3DModel(ModelConfig.lite()), features, LossWeights(), 64, stages)
        losses[stages] = float(step.stylization(pred, content, maps).style)
    assert losses[(1, 2, 3)] == pytest.approx(losses[(1, 2)] + losses[(3,)], rel=1e-5)
    assert losses[(3,)] > 0
    assert TrainConfig().style_stages == (1, 2)


def test_training_refuses_data_of_other_neighbourhoods(data, tmp_path):
    other = tmp_path / "other"
    build_dataset(other, 1, DataConfig(image_size=(32, 40), scene_textures=3, texture_size=32,
                                       neighbourhood=NeighbourhoodConfig(k=8)), seed=1)
    with pytest.raises(InputError, match="neighbourhood.*k 8 vs 16"):
        train(TrainConfig(stage=1, data_dir=str(other), out_dir=str(tmp_path / "run"), iterations=1, batch_size=1,
                          threads=1), log=lambda _: None)


def test_cosine_schedule_depends_only_on_the_iteration():
    const = TrainConfig(lr=3e-4, iterations=100)
    assert learning_rate(const, 0) == learning_rate(const, 99) == 3e-4
    cos = TrainConfig(lr=3e-4, iterations=100, lr_schedule="cosine")
    assert learning_rate(cos, 0) == pytest.approx(3e-4)
    assert learning_rate(cos, 50) == pytest.approx(1.5e-4)
    assert learning_rate(cos, 100) == pytest.approx(0.0, abs=1e-15)
    assert learning_rate(cos, 250) == pytest.approx(0.0, abs=1e-15)  # past the end (a run extended later)
    rates = [learning_rate(cos, i) for i in range(101)]
    assert all(a >= b for a, b in zip(rates, rates[1:]))


def test_cosine_run_logs_the_rate_and_resumes_on_the_curve(data, tmp_path):
    out = tmp_path / "run"
    cfg = TrainConfig(stage=1, data_dir=str(data / "train"), out_dir=str(out), iterations=4, batch_size=1,
                      lr=1e-3, lr_schedule="cosine", log_every=1, checkpoint_every=2, threads=1)
    train(TrainConfig(**{**cfg.__dict__, "max_hours": 1e-9}), log=lambda _: None)  # stops after one step
    train(cfg, log=lambda _: None)
    log = _log(out, 1)
    assert [r["iteration"] for r in log] == [1, 2, 3, 4]
    assert [r["lr"] for r in log] == pytest.approx([learning_rate(cfg, i) for i in range(4)])


def test_stage2_can_take_the_stylizer_from_another_checkpoint(data, tmp_path):
    out = tmp_path / "run"
    train(TrainConfig(stage=1, data_dir=str(data / "train"), out_dir=str(out), iterations=1, batch_size=1,
                      threads=1), log=lambda _: None)
    stage1 = load_checkpoint(out / "model_stage1.safetensors").model
    donor = load_checkpoint(out / "model_stage1.safetensors").model
    torch.manual_seed(3)
    for p in donor.stylizer.parameters():
        p.data.normal_()
    donor_path = tmp_path / "donor.safetensors"
    save_checkpoint(donor_path, donor, 2, {})
    messages = []
    train(TrainConfig(stage=2, data_dir=str(data / "train"), styles_dir=str(data / "styles"), out_dir=str(out),
                      iterations=1, batch_size=1, lr=1e-12, recon_fraction=0.0, threads=1,
                      init_stylizer=str(donor_path)), log=messages.append)
    assert any("stylizer weights from" in m for m in messages)
    after = load_checkpoint(out / "model_stage2.safetensors").model
    for (k, a), (_, b) in zip(donor.stylizer.state_dict().items(), after.stylizer.state_dict().items()):
        assert torch.allclose(a.float(), b.float(), atol=1e-6), f"stylizer weight {k} not taken from the donor"
    for (k, a), (_, b) in zip(stage1.encoder.state_dict().items(), after.encoder.state_dict().items()):
        assert torch.equal(a, b), f"encoder weight {k} not the stage-1 one"
    with pytest.raises(InputError, match="stage 2"):
        TrainConfig(stage=1, init_stylizer=str(donor_path))


def test_bad_settings(data, tmp_path):
    with pytest.raises(InputError):
        TrainConfig(stage=3)
    with pytest.raises(InputError):
        TrainConfig(model="huge")
    with pytest.raises(InputError, match="lr_schedule"):
        TrainConfig(lr_schedule="step")
    for stages in ((), (1, 1), (5,), (-1,), (1.0,)):
        with pytest.raises(InputError, match="style_stages"):
            TrainConfig(style_stages=stages)
    for crop in ((0.5,), (0.6, 0.5), (0.0, 1.0), (0.5, 1.5), ("a", 1.0)):
        with pytest.raises(InputError, match="style_crop"):
            TrainConfig(style_crop=crop)
    assert TrainConfig(style_crop=(0.25, 0.5)).style_crop == (0.25, 0.5)
    with pytest.raises(InputError, match="stage-1"):
        train(TrainConfig(stage=2, data_dir=str(data / "train"), out_dir=str(tmp_path / "x")), log=lambda _: None)
    with pytest.raises(InputError):
        train(TrainConfig(stage=1, data_dir=str(tmp_path / "missing"), out_dir=str(tmp_path / "y")), log=lambda _: None)


@pytest.mark.slow
def test_two_process_ddp_run(data, tmp_path):
    """torchrun with 2 CPU processes (gloo): gradients are averaged and rank 0 writes the checkpoint."""
    import subprocess
    import sys

    out = tmp_path / "ddp"
    cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node=2",
           "-m", "stylize3d_app.cli", "train", "--stage", "1", "--data", str(data / "train"), "--out", str(out),
           "--iterations", "2", "--batch-size", "1", "--threads", "1", "--log-every", "1"]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=180, check=False)
    assert r.returncode == 0, r.stderr[-2000:]
    assert load_checkpoint(out / "model_stage1.safetensors").info["iterations"] == 2
    assert [row["iteration"] for row in _log(out, 1)] == [1, 2]
