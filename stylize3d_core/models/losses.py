"""Feature-space losses and the style metric, on frozen EfficientNet-Lite0 features.

Stage indices refer to the extractor's maps (see
:mod:`~stylize3d_core.models.efficientnet_lite`: 0..4 at strides 2..32, in the
role of VGG relu1_1..relu5_1). The defaults follow the paper's public code,
translated index for index:

* **perceptual loss** (stage 1, view synthesis): L1 between the features of the
  prediction and of the target at stage 2 (public: VGG relu3_1, L1).
* **AdaAttN content loss** (stage 2, stylization; Liu et al. 2021's local
  feature loss): L1 between the prediction's features and the parameter-free
  AdaAttN of the content image's features with the style's, at stage 2 (public:
  relu3_1, L1). The key of stage s concatenates stages 0..s resized to stage s.
* **global style loss**: MSE between the per-channel spatial mean and std of the
  prediction's and the style's features at stages 1, 2 (public: relu2_1,
  relu3_1, mean + std, MSE).
* :func:`style_distance` (evaluation): per stage, the RMS difference of the
  channel means plus that of the channel stds, averaged over stages 1..3.

Every std is ``sqrt(var + eps)`` (population variance), so constant images give
finite values and gradients. The multi-view consistency loss lives with the renderer.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Literal, NamedTuple, Optional, Sequence, Tuple

import torch
import torch.nn.functional as F
from torch import nn

from ..checks import check_choice
from ..errors import InputError
from .adaattn import adaattn, style_tokens
from .efficientnet_lite import EfficientNetLiteFeatures
from .style_features import check_image01, resize_style_image

LossKind = Literal["l1", "mse"]
_KINDS = ("l1", "mse")


def _distance(a: torch.Tensor, b: torch.Tensor, kind: str) -> torch.Tensor:
    check_choice(kind, "loss kind", _KINDS)
    if a.shape[1:] != b.shape[1:] or b.shape[0] not in (1, a.shape[0]):
        raise InputError("features", f"shapes {tuple(a.shape)} and {tuple(b.shape)} do not match")
    b = b.expand_as(a)
    return F.l1_loss(a, b) if kind == "l1" else F.mse_loss(a, b)


def _stages_ok(stages: Sequence[int], n: int, name: str) -> None:
    if not stages or any(not 0 <= s < n for s in stages):
        raise InputError(name, f"stage indices must be in 0..{n - 1}, got {tuple(stages)}")


def feature_stats(feat: torch.Tensor, eps: float = 1e-5) -> Tuple[torch.Tensor, torch.Tensor]:
    """Per-channel spatial mean and std of (B, C, h, w): two (B, C) tensors, std = sqrt(var + eps)."""
    flat = feat.flatten(2)  # (B, C, h*w)
    return flat.mean(-1), torch.sqrt(flat.var(-1, unbiased=False) + eps)


def perceptual_loss(
    pred_feats: Sequence[torch.Tensor], target_feats: Sequence[torch.Tensor], stages: Sequence[int], kind: str = "l1"
) -> torch.Tensor:
    """Mean over ``stages`` of the L1/MSE distance between feature maps (B, C_s, h_s, w_s)."""
    _stages_ok(stages, min(len(pred_feats), len(target_feats)), "stages")
    return torch.stack([_distance(pred_feats[s], target_feats[s], kind) for s in stages]).mean()


def global_style_loss(
    pred_feats: Sequence[torch.Tensor], style_feats: Sequence[torch.Tensor], stages: Sequence[int],
    kind: str = "mse", eps: float = 1e-5,
) -> torch.Tensor:
    """Sum over ``stages`` of dist(mean_p, mean_s) + dist(std_p, std_s); style batch may be 1 (broadcast)."""
    _stages_ok(stages, min(len(pred_feats), len(style_feats)), "stages")
    total = pred_feats[0].new_zeros(())
    for s in stages:
        mp, sp = feature_stats(pred_feats[s], eps)
        ms, ss = feature_stats(style_feats[s], eps)
        total = total + _distance(mp, ms, kind) + _distance(sp, ss, kind)
    return total


def adaattn_targets(
    content_feats: Sequence[torch.Tensor], style_feats: Sequence[torch.Tensor], stage: int,
    eps: float = 1e-5, chunk_size: int = 4096,
) -> torch.Tensor:
    """Parameter-free AdaAttN of the content features at ``stage`` (B, C, h, w), keys from stages 0..stage.

    Returned detached: it is the fixed target of :func:`adaattn_content_loss`.
    """
    b = content_feats[stage].shape[0]
    style_feats = [m.expand(b, -1, -1, -1) if m.shape[0] == 1 else m for m in style_feats]
    keys = tuple(range(stage + 1))
    with torch.no_grad():
        c_val, c_key = style_tokens(content_feats, stage, keys)  # (B, M, C), (B, M, Ck)
        s_val, s_key = style_tokens(style_feats, stage, keys)  # (B, L, C), (B, L, Ck)
        out = adaattn(c_val, c_key, s_val, s_key, eps=eps, chunk_size=chunk_size)  # (B, M, C)
    h, w = content_feats[stage].shape[-2:]
    return out.transpose(1, 2).reshape(b, -1, h, w)


def adaattn_content_loss(
    pred_feats: Sequence[torch.Tensor], content_feats: Sequence[torch.Tensor], style_feats: Sequence[torch.Tensor],
    stages: Sequence[int], kind: str = "l1", eps: float = 1e-5, chunk_size: int = 4096,
) -> torch.Tensor:
    """Sum over ``stages`` of dist(pred features, :func:`adaattn_targets`)."""
    _stages_ok(stages, min(len(pred_feats), len(content_feats), len(style_feats)), "stages")
    total = pred_feats[0].new_zeros(())
    for s in stages:
        total = total + _distance(pred_feats[s], adaattn_targets(content_feats, style_feats, s, eps, chunk_size), kind)
    return total


@dataclass(frozen=True)
class PerceptualLossConfig:
    """Settings of :class:`PerceptualLoss`.

    Attributes:
        stages: feature stages compared (default (2,): public code's relu3_1).
        kind: "l1" (default, public code) or "mse".
    """

    stages: Tuple[int, ...] = (2,)
    kind: LossKind = "l1"


class PerceptualLoss(nn.Module):
    """``forward(pred, target)``: images (B, 3, H, W) in [0, 1] -> scalar; target features carry no gradient."""

    def __init__(self, config: PerceptualLossConfig = PerceptualLossConfig(), extractor: Optional[nn.Module] = None) -> None:
        super().__init__()
        check_choice(config.kind, "PerceptualLossConfig.kind", _KINDS)
        _stages_ok(config.stages, 5, "PerceptualLossConfig.stages")
        self.config = config
        self.extractor = EfficientNetLiteFeatures(stages=tuple(range(max(config.stages) + 1))) if extractor is None else extractor

    def forward(self, pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        if pred.shape != target.shape:
            raise InputError("target", f"shape {tuple(target.shape)} differs from prediction {tuple(pred.shape)}")
        with torch.no_grad():
            target_feats = self.extractor(target)
        return perceptual_loss(self.extractor(pred), target_feats, self.config.stages, self.config.kind)


@dataclass(frozen=True)
class StylizationLossConfig:
    """Settings of :class:`StylizationLoss` (defaults: the public code's stylization losses).

    Attributes:
        content_stages: stages of the AdaAttN content loss (default (2,)).
        style_stages: stages of the global style loss (default (1, 2)).
        content_kind: "l1" (default) or "mse".
        style_kind: "mse" (default) or "l1".
        eps: variance epsilon.
        chunk_size: queries per AdaAttN attention chunk.
    """

    content_stages: Tuple[int, ...] = (2,)
    style_stages: Tuple[int, ...] = (1, 2)
    content_kind: LossKind = "l1"
    style_kind: LossKind = "mse"
    eps: float = 1e-5
    chunk_size: int = 4096


class StylizationLossTerms(NamedTuple):
    """The two stylization loss terms (scalars); the trainer weighs them (public: 1 and 0.3)."""

    content: torch.Tensor
    style: torch.Tensor


class StylizationLoss(nn.Module):
    """``forward(pred, content, style_maps)`` -> :class:`StylizationLossTerms`.

    ``pred`` and ``content`` are images (B, 3, H, W) in [0, 1] (the stylized
    view and the unstylized view of the same camera); ``style_maps`` are the
    style image's maps from the same extractor stages (batch B or 1), e.g.
    ``StyleEncoder()(style).maps``.
    """

    def __init__(self, config: StylizationLossConfig = StylizationLossConfig(), extractor: Optional[nn.Module] = None) -> None:
        super().__init__()
        check_choice(config.content_kind, "StylizationLossConfig.content_kind", _KINDS)
        check_choice(config.style_kind, "StylizationLossConfig.style_kind", _KINDS)
        _stages_ok(config.content_stages, 5, "StylizationLossConfig.content_stages")
        _stages_ok(config.style_stages, 5, "StylizationLossConfig.style_stages")
        self.config = config
        deepest = max(config.content_stages + config.style_stages)
        self.extractor = EfficientNetLiteFeatures(stages=tuple(range(deepest + 1))) if extractor is None else extractor

    def forward(self, pred: torch.Tensor, content: torch.Tensor, style_maps: Sequence[torch.Tensor]) -> StylizationLossTerms:
        cfg = self.config
        if pred.shape != content.shape:
            raise InputError("content", f"shape {tuple(content.shape)} differs from prediction {tuple(pred.shape)}")
        pred_feats = self.extractor(pred)
        with torch.no_grad():
            content_feats = self.extractor(content)
        c = adaattn_content_loss(pred_feats, content_feats, style_maps, cfg.content_stages, cfg.content_kind, cfg.eps, cfg.chunk_size)
        s = global_style_loss(pred_feats, style_maps, cfg.style_stages, cfg.style_kind, cfg.eps)
        return StylizationLossTerms(c, s)


@functools.lru_cache(maxsize=1)
def _default_extractor() -> EfficientNetLiteFeatures:
    return EfficientNetLiteFeatures(stages=(0, 1, 2, 3))


def style_distance(
    image: torch.Tensor, style_image: torch.Tensor, extractor: Optional[nn.Module] = None,
    stages: Sequence[int] = (1, 2, 3), eps: float = 1e-5,
) -> torch.Tensor:
    """How far ``image``'s feature statistics are from ``style_image``'s: (B,), 0 for identical images.

    Both images (B or 1, 3, H, W) in [0, 1] are first resized like style images
    (long side <= 512, see :mod:`.style_features`). Per stage: RMS over channels of
    (mean difference) + RMS of (std difference); averaged over ``stages``.
    """
    ext = extractor if extractor is not None else _default_extractor()
    a = resize_style_image(check_image01(image, "image"))
    b = resize_style_image(check_image01(style_image, "style image"))
    if b.shape[0] not in (1, a.shape[0]):
        raise InputError("style image", f"batch {b.shape[0]} does not match image batch {a.shape[0]}")
    fa, fb = ext(a), ext(b)
    _stages_ok(stages, min(len(fa), len(fb)), "stages")
    per_stage = []
    for s in stages:
        ma, sa = feature_stats(fa[s], eps)  # (B, C)
        mb, sb = feature_stats(fb[s], eps)
        root_c = ma.shape[-1] ** 0.5  # RMS = norm / sqrt(C); the norm's gradient at 0 is 0, not NaN
        dm = torch.linalg.vector_norm(ma - mb, dim=-1) / root_c  # (B,)
        ds = torch.linalg.vector_norm(sa - sb, dim=-1) / root_c
        per_stage.append(dm + ds)
    return torch.stack(per_stage).mean(0)


_SRGB_TO_XYZ = torch.tensor([[0.412453, 0.357580, 0.180423],
                             [0.212671, 0.715160, 0.072169],
                             [0.019334, 0.119193, 0.950227]])
"""Linear sRGB -> CIE XYZ (D65), the matrix OpenCV's ``cvtColor(..., COLOR_RGB2Lab)`` uses."""
_WHITE = (0.950456, 1.0, 1.088754)


def rgb_to_lab(rgb: torch.Tensor) -> torch.Tensor:
    """sRGB (B, 3, H, W) in [0, 1] -> CIE L*a*b* (B, 3, H, W), L in [0, 100]; differentiable.

    The same conversion as OpenCV's float ``COLOR_RGB2Lab`` (sRGB gamma, D65 white).
    The cube root is replaced by its linear segment below (6/29)^3 as the standard
    prescribes, so gradients stay finite at black.
    """
    x = rgb.clamp(0.0, 1.0)
    lin = torch.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)
    xyz = torch.einsum("ij,bjhw->bihw", _SRGB_TO_XYZ.to(x), lin)
    xyz = xyz / torch.tensor(_WHITE, dtype=x.dtype, device=x.device)[None, :, None, None]
    d = 6.0 / 29.0
    f = torch.where(xyz > d**3, xyz.clamp_min(d**3) ** (1.0 / 3.0), xyz / (3 * d * d) + 4.0 / 29.0)
    fx, fy, fz = f[:, 0], f[:, 1], f[:, 2]
    return torch.stack([116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)], dim=1)


def lab_statistics(rgb: torch.Tensor, eps: float = 1e-6) -> torch.Tensor:
    """Per-image mean and std of L*, a*, b* over all pixels: (B, 6) = (mean L, a, b, std L, a, b)."""
    lab = rgb_to_lab(rgb).flatten(2)  # (B, 3, HW)
    return torch.cat([lab.mean(-1), torch.sqrt(lab.var(-1, unbiased=False) + eps)], dim=1)


def colour_statistics_loss(pred: torch.Tensor, style: torch.Tensor) -> torch.Tensor:
    """Mean absolute difference of :func:`lab_statistics`, in units of 100 (L*'s range): a scalar.

    ``pred`` (B, 3, H, W), ``style`` (B or 1, 3, h, w), both in [0, 1]: the colour
    statistics of every view are pulled towards the style image's.
    """
    a, b = lab_statistics(pred), lab_statistics(style)
    if b.shape[0] not in (1, a.shape[0]):
        raise InputError("style", f"batch {b.shape[0]} does not match prediction batch {a.shape[0]}")
    return (a - b).abs().mean() / 100.0


_LAPLACIAN = torch.tensor([[0.0, 1.0, 0.0], [1.0, -4.0, 1.0], [0.0, 1.0, 0.0]])


def detail_loss(pred: torch.Tensor, target: torch.Tensor, mask: Optional[torch.Tensor] = None) -> torch.Tensor:
    """Mean absolute difference of the images' Laplacians (their fine detail): a scalar.

    ``pred``, ``target`` (B, 3, H, W); ``mask`` (B, H, W) or None: where the target is
    valid. Only pixels whose whole 3x3 neighbourhood is valid count, so a mask's own edge
    adds no detail. An L1 on the pixels lets a blurred prediction sit close to a sharp target
    (the blur halves the error of a stroke it cannot place); this term charges the missing
    strokes themselves, which is what keeps the teacher's texture in the model's frames.
    """
    if pred.shape != target.shape or pred.dim() != 4:
        raise InputError("pred", f"expected two (B, C, H, W) tensors of one shape, got {tuple(pred.shape)} "
                         f"and {tuple(target.shape)}")
    c = pred.shape[1]
    kernel = _LAPLACIAN.to(pred)[None, None].expand(c, 1, 3, 3)
    diff = F.conv2d(pred - target, kernel, groups=c)  # (B, C, H-2, W-2): linear, so lap(p) - lap(t)
    if mask is None:
        return diff.abs().mean()
    valid = -F.max_pool2d(-mask[:, None].to(pred), 3, stride=1)  # (B, 1, H-2, W-2): 1 where all 9 are valid
    return (diff.abs() * valid).sum() / (c * valid.sum()).clamp(min=1.0)


def sharpness_loss(pred: torch.Tensor, reference: torch.Tensor, mask: Optional[torch.Tensor] = None,
                   pool: int = 2, eps: float = 1e-6) -> torch.Tensor:
    """How far the images' sharpness falls short of the references': a scalar >= 0.

    Sharpness is what the quality benchmark measures: the standard deviation of the
    Laplacian of the grey image (BT.601 weights), here over the pixels whose whole 3x3
    neighbourhood is valid in ``mask`` (B, H, W) (all when None). Per image the loss is
    ``max(0, 1 - sharp(pred) / sharp(reference))``, the mean over the batch: no charge for
    strokes a style adds, only for detail a blur takes away. ``reference`` is detached.

    ``pool`` > 1 measures both on the images average-pooled by that factor (the mask: pixels
    whose whole pooling cell is valid). At full resolution a decoder meets the charge most
    cheaply with a pixel-period checkerboard, which the 3x3 Laplacian weights most (a trained
    model learned one: a halftone grid over its frames); pooling by 2 cancels that pattern
    exactly, so only detail at two pixels and coarser counts.
    """
    if pred.shape != reference.shape or pred.dim() != 4 or pred.shape[1] != 3:
        raise InputError("pred", f"expected two (B, 3, H, W) tensors of one shape, got {tuple(pred.shape)} "
                         f"and {tuple(reference.shape)}")
    grey_w = pred.new_tensor([0.299, 0.587, 0.114]).view(1, 3, 1, 1)
    kernel = _LAPLACIAN.to(pred)[None, None]

    def lap_std(img: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
        lap = F.conv2d((img * grey_w).sum(1, keepdim=True), kernel)  # (B, 1, H-2, W-2)
        n = valid.sum(dim=(1, 2, 3)).clamp(min=1.0)
        mean = (lap * valid).sum(dim=(1, 2, 3)) / n
        var = (((lap - mean.view(-1, 1, 1, 1)) ** 2) * valid).sum(dim=(1, 2, 3)) / n
        return torch.sqrt(var + eps)

    m = None if mask is None else mask[:, None].to(pred)
    if pool > 1:
        pred, reference = F.avg_pool2d(pred, pool), F.avg_pool2d(reference, pool)
        m = None if m is None else -F.max_pool2d(-m, pool)
    if pred.shape[2] < 3 or pred.shape[3] < 3:
        raise InputError("pred", f"too small for the sharpness measure: {tuple(pred.shape)} after pooling by {pool}")
    if m is None:
        valid = pred.new_ones(pred.shape[0], 1, pred.shape[2] - 2, pred.shape[3] - 2)
    else:
        valid = -F.max_pool2d(-m, 3, stride=1)
    ratio = lap_std(pred, valid) / lap_std(reference.detach(), valid).clamp(min=1e-3)
    return torch.relu(1.0 - ratio).mean()
