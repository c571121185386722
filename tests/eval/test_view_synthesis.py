"""Tests of masked PSNR / SSIM and the held-out view-synthesis evaluation."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import torch
from skimage.metrics import structural_similarity

from stylize3d_core.errors import InputError
from stylize3d_core.eval.view_synthesis import (
    KindScores,
    evaluate_view_synthesis,
    gaussian_window,
    masked_psnr,
    masked_ssim,
    predict_views,
    score_views,
    ssim_map,
)
from stylize3d_core.models.checkpoint import save_checkpoint
from stylize3d_core.models.stylize3d import ModelConfig, Stylize3DModel
from stylize3d_core.train.cache import TrainDataset, build_dataset
from stylize3d_core.train.data import DataConfig

SMALL = DataConfig(image_size=(32, 40), scene_textures=3, texture_size=32)


def _pair(seed=0, h=37, w=29):
    g = np.random.default_rng(seed)
    a = g.random((h, w, 3))
    b = np.clip(a + g.normal(0, 0.1, a.shape), 0, 1)
    return a, b


def _t(x):
    return torch.from_numpy(np.ascontiguousarray(x.transpose(2, 0, 1)))  # (C, H, W)


def test_gaussian_window():
    g = gaussian_window(11, 1.5)
    assert g.shape == (11,) and float(g.sum()) == pytest.approx(1.0)
    assert torch.equal(g, g.flip(0)) and int(g.argmax()) == 5
    assert float(g[6] / g[5]) == pytest.approx(math.exp(-1 / (2 * 1.5**2)))
    for bad in (10, 0, 2.0):
        with pytest.raises(InputError):
            gaussian_window(bad)


def test_ssim_of_identical_images_is_one():
    a, _ = _pair()
    s = ssim_map(_t(a)[None], _t(a)[None])
    assert torch.allclose(s, torch.ones_like(s), atol=1e-12)
    assert masked_ssim(_t(a), _t(a), torch.ones(a.shape[:2], dtype=torch.bool)) == pytest.approx(1.0)


@pytest.mark.parametrize("seed,h,w", [(0, 37, 29), (1, 64, 64), (2, 12, 50)])
def test_ssim_matches_skimage(seed, h, w):
    a, b = _pair(seed, h, w)
    mean, full = structural_similarity(a, b, gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
                                       data_range=1.0, channel_axis=-1, full=True)
    ours = ssim_map(_t(a)[None], _t(b)[None])[0].numpy().transpose(1, 2, 0)  # (H, W, C)
    assert np.allclose(ours, full, atol=1e-10)
    # skimage's mean leaves out a border of 5 pixels: the same with a mask.
    interior = torch.zeros(h, w, dtype=torch.bool)
    interior[5:-5, 5:-5] = True
    assert masked_ssim(_t(a), _t(b), interior) == pytest.approx(mean, abs=1e-10)


def test_masked_psnr_known_values():
    a = torch.full((3, 8, 8), 0.5)
    b = a.clone()
    b[:, :4] += 0.1  # error 0.1 on the top half only
    top = torch.zeros(8, 8, dtype=torch.bool)
    top[:4] = True
    assert masked_psnr(b, a, top) == pytest.approx(20.0, abs=1e-4)  # MSE 0.01
    assert masked_psnr(b, a, ~top) == pytest.approx(100.0)  # identical: capped
    assert masked_psnr(b, a, torch.ones(8, 8, dtype=torch.bool)) == pytest.approx(10 * math.log10(200), abs=1e-4)
    assert math.isnan(masked_psnr(b, a, torch.zeros(8, 8, dtype=torch.bool)))
    assert math.isnan(masked_ssim(b, a, torch.zeros(8, 8, dtype=torch.bool)))


@pytest.fixture(scope="module")
def datasets(tmp_path_factory):
    root = tmp_path_factory.mktemp("vs")
    build_dataset(root / "proc", 1, dataclasses.replace(SMALL, procedural_fraction=1.0), seed=3)
    build_dataset(root / "ldi", 2, dataclasses.replace(SMALL, procedural_fraction=0.0), seed=3)
    return root


def test_predict_views_shape(datasets):
    torch.manual_seed(0)
    model = Stylize3DModel(ModelConfig.lite())
    sample = TrainDataset(datasets / "ldi")[0]
    pred = predict_views(model, sample)
    assert pred.shape == sample.targets.shape and torch.isfinite(pred).all()
    assert float(pred.min()) >= 0 and float(pred.max()) <= 1


def test_evaluate_by_kind(datasets, tmp_path):
    torch.manual_seed(0)
    model = Stylize3DModel(ModelConfig.lite())
    ldi = evaluate_view_synthesis(model, datasets / "ldi")
    assert ldi.procedural is None and isinstance(ldi.ldi, KindScores)
    assert ldi.ldi.n_samples == 2 and ldi.ldi.n_views == 4 and len(ldi.views) == 4
    s = ldi.ldi
    assert 0 < s.psnr < 100 and -1 <= s.ssim <= 1 and math.isfinite(s.psnr_seen)
    # The summary is the mean of the per-view records.
    assert s.psnr == pytest.approx(np.mean([r.psnr for r in ldi.views]))
    assert s.ssim_seen == pytest.approx(np.mean([r.ssim_seen for r in ldi.views]))
    # Checkpoint paths work too; max_samples limits the samples.
    path = save_checkpoint(tmp_path / "m.safetensors", model, 1, {})
    proc = evaluate_view_synthesis(path, TrainDataset(datasets / "proc"), max_samples=1)
    assert proc.ldi is None and proc.procedural.n_samples == 1 and proc.procedural.n_views == 2
    assert math.isfinite(proc.procedural.psnr)
    one = evaluate_view_synthesis(model, datasets / "ldi", max_samples=1)
    assert one.ldi.n_samples == 1
    assert one.views[0] == ldi.views[0]  # deterministic


def test_score_views_known_values(datasets):
    sample = TrainDataset(datasets / "ldi")[0]
    perfect = score_views(sample.targets.float(), sample, 7)
    assert len(perfect) == 2 and perfect[0].sample == 7 and perfect[1].view == 1 and perfect[0].kind == "ldi"
    assert all(r.psnr == pytest.approx(100.0) and r.ssim == pytest.approx(1.0) for r in perfect)
    off = (sample.targets.float() + 0.1).clamp(0, 1)
    rec = score_views(off, sample)
    t, m = sample.targets.float(), sample.masks
    assert max(r.psnr for r in rec) < 25
    # Per view: the masked MSE of that view alone.
    mse0 = ((off[0] - t[0]) ** 2)[:, m[0]].mean()
    assert rec[0].psnr == pytest.approx(10 * math.log10(1 / float(mse0)), rel=1e-6)
    with pytest.raises(InputError):
        score_views(off[:1], sample)
    bad = off.clone()
    bad[0, 0, 0, 0] = math.nan
    with pytest.raises(InputError):
        score_views(bad, sample)


def test_bad_inputs(datasets):
    with pytest.raises(InputError):
        evaluate_view_synthesis("nope.safetensors", datasets / "ldi")
    with pytest.raises(InputError):
        evaluate_view_synthesis(object(), datasets / "ldi")
    with pytest.raises(InputError):
        evaluate_view_synthesis(Stylize3DModel(ModelConfig.lite()), datasets / "ldi", max_samples=0)
    with pytest.raises(InputError):
        ssim_map(torch.zeros(1, 3, 8, 8), torch.zeros(1, 3, 8, 9))
