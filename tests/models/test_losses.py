"""Perceptual, AdaAttN content, global style losses and the style distance metric."""

from __future__ import annotations

import pytest
import torch
import torch.nn.functional as F

from stylize3d_core.errors import InputError
from stylize3d_core.models.efficientnet_lite import EfficientNetLiteFeatures
from stylize3d_core.models.losses import detail_loss, sharpness_loss
from stylize3d_core.models.losses import (
    PerceptualLoss,
    PerceptualLossConfig,
    StylizationLoss,
    StylizationLossConfig,
    adaattn_content_loss,
    adaattn_targets,
    feature_stats,
    global_style_loss,
    perceptual_loss,
    style_distance,
)

skimage_data = pytest.importorskip("skimage.data")


def _photo(name: str, size: int = 64) -> torch.Tensor:
    x = torch.from_numpy(getattr(skimage_data, name)()).permute(2, 0, 1)[None].float() / 255.0
    return F.interpolate(x, size=(size, size), mode="bilinear", antialias=True, align_corners=False)


@pytest.fixture(scope="module")
def extractor():
    return EfficientNetLiteFeatures(stages=(0, 1, 2, 3))


def test_feature_stats_known_values():
    x = torch.tensor([1.0, 3.0, 1.0, 3.0]).view(1, 1, 2, 2)
    mean, std = feature_stats(x, eps=0.0)
    assert float(mean) == 2.0 and float(std) == 1.0  # population std
    _, std = feature_stats(torch.ones(1, 2, 3, 3), eps=1e-4)
    torch.testing.assert_close(std, torch.full((1, 2), 1e-2))


def test_perceptual_zero_for_identical_and_positive_otherwise(extractor):
    loss = PerceptualLoss(PerceptualLossConfig(stages=(1, 2)), extractor)
    cat, cup = _photo("chelsea"), _photo("coffee")
    assert float(loss(cat, cat)) == 0.0
    assert float(loss(cat, cup)) > 0.0
    mse = PerceptualLoss(PerceptualLossConfig(kind="mse"), extractor)
    assert float(mse(cat, cup)) > 0.0


def test_perceptual_decreases_in_a_toy_optimisation(extractor):
    loss_fn = PerceptualLoss(PerceptualLossConfig(stages=(0, 1, 2)), extractor)
    target = _photo("chelsea", 48)
    logits = torch.zeros_like(target, requires_grad=True)  # image = sigmoid(logits), starts grey
    opt = torch.optim.Adam([logits], lr=0.1)
    losses = []
    for _ in range(15):
        opt.zero_grad()
        loss = loss_fn(torch.sigmoid(logits), target)
        loss.backward()
        opt.step()
        losses.append(float(loss.detach()))
    assert losses[-1] < 0.6 * losses[0]
    assert all(torch.isfinite(torch.tensor(losses)))


def test_global_style_loss_zero_for_identical_and_decreases(extractor):
    style = _photo("coffee", 48)
    style_feats = extractor(style)
    assert float(global_style_loss(style_feats, style_feats, (1, 2))) == 0.0
    logits = torch.zeros_like(style, requires_grad=True)
    opt = torch.optim.Adam([logits], lr=0.1)
    losses = []
    for _ in range(15):
        opt.zero_grad()
        loss = global_style_loss(extractor(torch.sigmoid(logits)), style_feats, (1, 2))
        loss.backward()
        opt.step()
        losses.append(float(loss.detach()))
    assert losses[0] > 0 and losses[-1] < 0.6 * losses[0]


def test_adaattn_content_loss_zero_at_its_target(extractor):
    content, style = extractor(_photo("chelsea")), extractor(_photo("coffee"))
    target = adaattn_targets(content, style, 2)
    assert target.shape == content[2].shape and not target.requires_grad
    pred = list(content)
    pred[2] = target
    assert float(adaattn_content_loss(pred, content, style, (2,))) == 0.0
    assert float(adaattn_content_loss(content, content, style, (2,))) > 0.0


def test_adaattn_target_of_a_constant_style_is_the_style_value(extractor):
    content = extractor(_photo("chelsea"))
    style = [torch.full((1, c.shape[1], 4, 4), 0.7) for c in content]  # zero-variance style maps
    target = adaattn_targets(content, style, 2, eps=1e-6)
    torch.testing.assert_close(target, torch.full_like(target, 0.7), atol=1e-2, rtol=0)


def test_stylization_loss_terms_and_toy_optimisation(extractor):
    loss_fn = StylizationLoss(StylizationLossConfig(), extractor)
    content, style = _photo("chelsea", 48), _photo("coffee", 48)
    style_maps = extractor(style)
    logits = torch.logit(content.clamp(0.02, 0.98)).clone().requires_grad_(True)
    opt = torch.optim.Adam([logits], lr=0.05)
    totals = []
    for _ in range(12):
        opt.zero_grad()
        terms = loss_fn(torch.sigmoid(logits), content, style_maps)
        total = terms.content + 0.3 * terms.style
        total.backward()
        opt.step()
        totals.append(float(total.detach()))
    assert terms.content.dim() == 0 and terms.style.dim() == 0
    assert totals[0] > 0 and totals[-1] < totals[0]


@pytest.mark.parametrize("value", [0.0, 0.5, 1.0])
def test_losses_finite_for_constant_images(extractor, value):
    const = torch.full((1, 3, 32, 32), value, requires_grad=True)
    other = torch.full((1, 3, 32, 32), 1.0 - value)
    terms = StylizationLoss(StylizationLossConfig(), extractor)(const, other, extractor(other))
    perc = PerceptualLoss(PerceptualLossConfig(), extractor)(const, other)
    total = terms.content + terms.style + perc
    assert torch.isfinite(total)
    total.backward()
    assert torch.isfinite(const.grad).all()


def test_style_distance(extractor):
    cat, cup = _photo("chelsea"), _photo("coffee")
    d_same = style_distance(cat, cat, extractor)
    assert d_same.shape == (1,) and float(d_same) == 0.0
    near = style_distance(0.9 * cat + 0.05, cat, extractor)
    far = style_distance(cup, cat, extractor)
    assert 0.0 < float(near) < float(far)
    batch = style_distance(torch.cat([cat, cup]), cat, extractor)  # style broadcast over the batch
    torch.testing.assert_close(batch, torch.cat([d_same, far]))
    const = style_distance(torch.full((1, 3, 40, 40), 0.3), torch.full((1, 3, 50, 50), 0.3), extractor)
    assert torch.isfinite(const).all()


def test_style_distance_gradient_is_finite_at_zero(extractor):
    cat = _photo("chelsea", 32).requires_grad_(True)
    style_distance(cat, cat.detach(), extractor).sum().backward()
    assert torch.isfinite(cat.grad).all()


def test_style_distance_default_extractor():
    assert float(style_distance(_photo("coffee", 32), _photo("coffee", 32))) == 0.0


def test_bad_inputs(extractor):
    feats = extractor(_photo("chelsea", 32))
    with pytest.raises(InputError, match="loss kind"):
        perceptual_loss(feats, feats, (1,), kind="huber")
    with pytest.raises(InputError, match="stage"):
        perceptual_loss(feats, feats, (7,))
    with pytest.raises(InputError, match="kind"):
        PerceptualLoss(PerceptualLossConfig(kind="l3"), extractor)  # type: ignore[arg-type]
    with pytest.raises(InputError, match="target"):
        PerceptualLoss(PerceptualLossConfig(), extractor)(torch.rand(1, 3, 32, 32), torch.rand(1, 3, 16, 16))
    with pytest.raises(InputError, match="batch"):
        style_distance(torch.rand(2, 3, 32, 32), torch.rand(3, 3, 32, 32), extractor)
    with pytest.raises(InputError, match="features"):
        global_style_loss(feats, [f[:, :1] for f in feats], (1,))


def test_rgb_to_lab_matches_opencv_and_colour_loss_has_finite_gradients():
    import cv2
    import numpy as np

    from stylize3d_core.models.losses import colour_statistics_loss, lab_statistics, rgb_to_lab

    g = np.random.default_rng(0)
    x = g.random((6, 9, 3)).astype(np.float32)
    x[0, 0], x[0, 1], x[0, 2] = 0.0, 1.0, 0.01  # black, white, near-black (the linear segment)
    ours = rgb_to_lab(torch.from_numpy(x).permute(2, 0, 1)[None])[0].permute(1, 2, 0).numpy()
    np.testing.assert_allclose(ours, cv2.cvtColor(x, cv2.COLOR_RGB2Lab), atol=0.5)
    assert abs(ours[0, 1, 0] - 100.0) < 0.01 and abs(ours[0, 0]).max() < 0.01  # white L 100, black 0
    # statistics of a constant image: its Lab colour and zero spread
    red = torch.zeros(1, 3, 4, 4)
    red[:, 0] = 1.0
    stats = lab_statistics(red)[0]
    np.testing.assert_allclose(stats[:3].numpy(), cv2.cvtColor(np.array([[[1.0, 0, 0]]], np.float32),
                                                               cv2.COLOR_RGB2Lab)[0, 0], atol=0.5)
    assert stats[3:].max() < 0.01
    assert colour_statistics_loss(red, red) < 1e-4
    pred = torch.rand(2, 3, 8, 8, requires_grad=True)
    loss = colour_statistics_loss(pred, torch.zeros(1, 3, 5, 5))  # towards black: a large distance
    loss.backward()
    assert loss > 0.2 and torch.isfinite(pred.grad).all() and pred.grad.abs().sum() > 0


def test_detail_loss_known_values_and_masking():
    g = torch.Generator().manual_seed(0)
    target = torch.rand(2, 3, 12, 10, generator=g)
    assert detail_loss(target, target).item() == 0.0
    # a constant or linear offset has no Laplacian: no detail difference
    ramp = torch.linspace(0, 1, 10).expand(2, 3, 12, 10)
    assert detail_loss(target + 0.3 + 0.5 * ramp, target).item() == pytest.approx(0.0, abs=1e-6)
    # one pixel raised by d: the Laplacian differs by -4d there and by d at its 4 neighbours
    pred = target.clone()
    pred[0, 1, 5, 5] += 0.25
    n = 2 * 3 * 10 * 8
    assert detail_loss(pred, target).item() == pytest.approx((4 + 4) * 0.25 / n, rel=1e-5)
    # masked: only pixels with a fully valid 3x3 neighbourhood count
    mask = torch.ones(2, 12, 10)
    mask[0, 4, 5] = 0  # (4, 5) is next to the raised pixel: (5, 5)'s and its neighbours' windows go
    got = detail_loss(pred, target, mask)
    valid = -F.max_pool2d(-mask[:, None], 3, stride=1)
    assert valid[0, 0, 4, 4] == 0 and valid[0, 0, 3, 4] == 0  # windows around (4, 5) ...
    assert got.item() == pytest.approx(1 * 0.25 / (3 * valid.sum().item()), rel=1e-5)  # ... leave (6, 5) only
    with pytest.raises(InputError):
        detail_loss(pred, target[:, :, :-1])


def test_detail_loss_charges_a_blur_and_has_gradients():
    g = torch.Generator().manual_seed(1)
    target = (torch.rand(1, 3, 32, 32, generator=g) > 0.5).float()  # sharp strokes
    blurred = F.avg_pool2d(target, 3, stride=1, padding=1, count_include_pad=False)
    pred = blurred.clone().requires_grad_(True)
    loss = detail_loss(pred, target)
    assert loss.item() > 0.5 * detail_loss(torch.full_like(target, 0.5), target).item()  # a blur keeps little detail
    loss.backward()
    assert torch.isfinite(pred.grad).all() and pred.grad.abs().sum() > 0


def test_sharpness_loss_charges_a_blur_not_added_strokes():
    g = torch.Generator().manual_seed(0)
    ref = torch.rand(2, 3, 24, 24, generator=g)
    assert sharpness_loss(ref, ref).item() == pytest.approx(0.0, abs=1e-6)
    assert sharpness_loss(torch.full_like(ref, 0.4), ref).item() == pytest.approx(1.0, abs=3e-3)  # no detail left
    # half the contrast: half the Laplacian's std, whatever the offset
    assert sharpness_loss(0.5 * ref + 0.2, ref).item() == pytest.approx(0.5, abs=1e-3)
    # stronger detail than the reference is not charged
    assert sharpness_loss(2.0 * ref, ref).item() == 0.0
    # a mask: only the valid half counts (the other half of pred is flat)
    pred = ref.clone()
    pred[..., 12:] = 0.5
    mask = torch.zeros(2, 24, 24)
    mask[..., :12] = 1.0
    assert sharpness_loss(pred, ref, mask).item() == pytest.approx(0.0, abs=1e-5)
    assert sharpness_loss(pred, ref).item() > 0.2
    with pytest.raises(InputError):
        sharpness_loss(ref[:, :2], ref[:, :2])
    with pytest.raises(InputError, match="too small"):
        sharpness_loss(ref[..., :5, :5], ref[..., :5, :5])


def test_sharpness_loss_is_not_met_by_a_pixel_checkerboard():
    g = torch.Generator().manual_seed(2)
    ref = torch.rand(1, 3, 32, 32, generator=g)
    y, x = torch.meshgrid(torch.arange(32), torch.arange(32), indexing="ij")
    checker = (0.3 * ((x + y) % 2) - 0.15).expand(1, 3, 32, 32)
    flat = torch.full_like(ref, 0.5)
    # at full resolution a checkerboard over a flat image looks as sharp as the reference, or sharper
    assert sharpness_loss(flat + checker, ref, pool=1).item() == 0.0
    # pooled by 2 (the default) it adds nothing: all the detail is still missing
    assert sharpness_loss(flat + checker, ref).item() == pytest.approx(1.0, abs=3e-3)


def test_sharpness_loss_has_gradients_towards_detail():
    g = torch.Generator().manual_seed(1)
    ref = torch.rand(1, 3, 16, 16, generator=g)
    pred = (0.3 * ref).requires_grad_(True)
    loss = sharpness_loss(pred, ref)
    loss.backward()
    assert torch.isfinite(pred.grad).all() and pred.grad.abs().sum() > 0
    stepped = (pred - 0.5 * pred.grad / pred.grad.abs().max()).detach()
    assert sharpness_loss(stepped, ref).item() < loss.item()
