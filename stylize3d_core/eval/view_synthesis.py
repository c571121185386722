"""Held-out view-synthesis accuracy of a stage-1 model: masked PSNR and SSIM.

For every sample of a training-data folder (:class:`~stylize3d_core.train.cache.TrainDataset`,
usually the held-out split written by ``build_splits``) the model renders the
sample's target cameras from its point cloud without a style (strength 0: the
view-synthesis path that stage 1 trains), and each predicted view is compared
with its target:

* inside ``masks`` (pixels whose target is trustworthy, not a filled hole);
* on ``seen & masks``: surfaces the source photo saw;
* on ``masks & ~seen``: disoccluded surfaces the model had to make up.

Scores are reported per sample kind: ``"procedural"`` targets are *true* novel
views of a ray-cast scene; ``"ldi"`` targets are *pseudo* views rendered from
the photo's own LDI (so they measure how well the model reproduces the
renderer, not the world).

PSNR per view is ``10 log10(1 / MSE)`` over the region's pixels and the three
channels (colours in [0, 1]; MSE floored at 1e-10, i.e. at most 100 dB); SSIM
per view is the mean over the region of the SSIM map (:func:`ssim_map`: Wang et
al. 2004 with an 11-tap Gaussian window of sigma 1.5, K1 = 0.01, K2 = 0.03,
population statistics, symmetric border; the map of
``skimage.metrics.structural_similarity(..., gaussian_weights=True,
use_sample_covariance=False, data_range=1)``). Means are over views.
"""

from __future__ import annotations

import math
import os
from typing import List, NamedTuple, Optional, Union

import numpy as np
import torch
import torch.nn.functional as F

from ..checks import check_range, check_shape
from ..errors import InputError
from ..models.checkpoint import Checkpoint, load_checkpoint
from ..models.stylize3d import Stylize3DModel
from ..train.cache import TrainDataset
from ..train.data import KINDS, TrainSample
from .metrics import psnr

PSNR_MSE_FLOOR = 1e-10
"""Smallest MSE used in PSNR (identical images score 100 dB, not infinity)."""


# ----------------------------------------------------------------------------- metrics


def gaussian_window(size: int = 11, sigma: float = 1.5) -> torch.Tensor:
    """(size,) float64 normalised 1D Gaussian taps centred on the middle tap (size odd)."""
    if isinstance(size, bool) or not isinstance(size, int) or size < 1 or size % 2 == 0:
        raise InputError("window size", f"must be an odd integer >= 1, got {size!r}")
    check_range(sigma, "sigma", 0.0, math.inf, inclusive=False)
    x = torch.arange(size, dtype=torch.float64) - (size - 1) / 2
    g = torch.exp(-(x**2) / (2.0 * sigma**2))
    return g / g.sum()


def _symmetric_index(n: int, r: int) -> torch.Tensor:
    """Indices of a length-``n`` axis padded by ``r`` on both sides, mirrored with the edge repeated."""
    i = torch.arange(-r, n + r) % (2 * n)  # (n + 2r,)
    return torch.where(i < n, i, 2 * n - 1 - i)


def _blur(x: torch.Tensor, g: torch.Tensor) -> torch.Tensor:
    """Separable Gaussian filter of (B, C, H, W) with symmetric borders; same size out."""
    B, C, H, W = x.shape
    r = g.numel() // 2
    x = x.index_select(2, _symmetric_index(H, r)).index_select(3, _symmetric_index(W, r))
    flat = x.reshape(B * C, 1, H + 2 * r, W + 2 * r)
    flat = F.conv2d(flat, g.view(1, 1, -1, 1).to(x.dtype))  # (BC, 1, H, W + 2r)
    flat = F.conv2d(flat, g.view(1, 1, 1, -1).to(x.dtype))  # (BC, 1, H, W)
    return flat.view(B, C, H, W)


def ssim_map(
    a: torch.Tensor, b: torch.Tensor, data_range: float = 1.0, window: int = 11, sigma: float = 1.5,
    k1: float = 0.01, k2: float = 0.03,
) -> torch.Tensor:
    """Per-pixel SSIM (B, C, H, W) of two images (B, C, H, W), computed in float64.

    Local statistics use the Gaussian window with population (co)variances and
    symmetric borders; ``C1 = (k1 * data_range)**2``, ``C2 = (k2 * data_range)**2``.
    """
    if a.shape != b.shape or a.dim() != 4:
        raise InputError("images", f"expected two (B, C, H, W) images of one shape, got {tuple(a.shape)} "
                                   f"and {tuple(b.shape)}")
    data_range = check_range(data_range, "data_range", 0.0, math.inf, inclusive=False)
    g = gaussian_window(window, sigma)
    x, y = a.detach().double(), b.detach().double()
    mx, my = _blur(x, g), _blur(y, g)
    vx = _blur(x * x, g) - mx * mx
    vy = _blur(y * y, g) - my * my
    cxy = _blur(x * y, g) - mx * my
    c1, c2 = (k1 * data_range) ** 2, (k2 * data_range) ** 2
    return ((2 * mx * my + c1) * (2 * cxy + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2))


def masked_psnr(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> float:
    """PSNR (dB) of (C, H, W) images in [0, 1] over ``mask`` (H, W); nan if the mask is empty."""
    if not bool(mask.any()):
        return math.nan
    hwc = lambda t: t.detach().cpu().permute(1, 2, 0)  # noqa: E731
    return min(psnr(hwc(pred), hwc(target), mask.detach().cpu().numpy()), 10.0 * math.log10(1.0 / PSNR_MSE_FLOOR))


def masked_ssim(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> float:
    """Mean SSIM of (C, H, W) images in [0, 1] over ``mask`` (H, W) and the channels; nan if empty."""
    if not bool(mask.any()):
        return math.nan
    s = ssim_map(pred[None], target[None])[0]  # (C, H, W)
    return float(s[:, mask].mean())


# ----------------------------------------------------------------------------- evaluation


class ViewRecord(NamedTuple):
    """Scores of one predicted view (nan where its region is empty)."""

    sample: int
    kind: str
    view: int
    psnr: float
    ssim: float
    psnr_seen: float
    ssim_seen: float
    psnr_unseen: float
    ssim_unseen: float


class KindScores(NamedTuple):
    """Means over the views of one sample kind.

    Attributes:
        psnr, ssim: inside the masks.
        psnr_seen, ssim_seen: on pixels the source photo saw (views without any excluded).
        psnr_unseen, ssim_unseen: on disoccluded pixels (nan when no view has any).
        n_samples, n_views: how many samples and views were scored.
        n_views_unseen: views with at least one disoccluded pixel.
    """

    psnr: float
    ssim: float
    psnr_seen: float
    ssim_seen: float
    psnr_unseen: float
    ssim_unseen: float
    n_samples: int
    n_views: int
    n_views_unseen: int


class ViewSynthesisResult(NamedTuple):
    """Held-out view synthesis per kind (None when the dataset holds no sample of that kind)."""

    procedural: Optional[KindScores]
    ldi: Optional[KindScores]
    views: tuple  # every ViewRecord


def predict_views(model: Stylize3DModel, sample: TrainSample) -> torch.Tensor:
    """The model's renders (V, 3, H, W) in [0, 1] of a sample's target cameras, without a style."""
    H, W = sample.image_size
    with torch.inference_mode():
        geom = sample.geometry
        dense = model.dense_features(model.encode(geom), geom)  # (N, Cr)
        views = [model.render_view(dense, geom.xyz, sample.cameras[v], H, W)[0] for v in range(len(sample.cameras))]
        return torch.nan_to_num(torch.stack(views), nan=0.0).clamp(0.0, 1.0)


def score_views(pred: torch.Tensor, sample: TrainSample, sample_index: int = 0) -> List[ViewRecord]:
    """Score predicted views (V, 3, H, W) in [0, 1] against a sample's targets, masks and ``seen``."""
    check_shape(pred, "predicted views", tuple(sample.targets.shape))
    if not torch.isfinite(pred).all():
        raise InputError("predicted views", "contain NaN or infinite values")
    records = []
    for v in range(pred.shape[0]):
        p, t = pred[v], sample.targets[v].float()
        mask = sample.masks[v]
        seen, unseen = mask & sample.seen[v], mask & ~sample.seen[v]
        records.append(ViewRecord(
            sample_index, sample.kind, v, masked_psnr(p, t, mask), masked_ssim(p, t, mask),
            masked_psnr(p, t, seen), masked_ssim(p, t, seen), masked_psnr(p, t, unseen), masked_ssim(p, t, unseen),
        ))
    return records


def _nanmean(values: List[float]) -> float:
    finite = [v for v in values if not math.isnan(v)]
    return float(np.mean(finite)) if finite else math.nan


def summarize_views(records: List[ViewRecord], n_samples: int) -> Optional[KindScores]:
    """Means over views of scored records (NaN regions skipped); None for no records."""
    if not records:
        return None
    col = {f: [getattr(r, f) for r in records] for f in ViewRecord._fields[3:]}
    return KindScores(
        *(_nanmean(col[f]) for f in ViewRecord._fields[3:]),
        n_samples=n_samples, n_views=len(records),
        n_views_unseen=sum(not math.isnan(v) for v in col["psnr_unseen"]),
    )


def evaluate_view_synthesis(
    model: Union[Stylize3DModel, Checkpoint, str, "os.PathLike[str]"],
    dataset: Union[TrainDataset, str, "os.PathLike[str]"],
    max_samples: Optional[int] = None,
) -> ViewSynthesisResult:
    """Masked PSNR / SSIM of ``model``'s renders against a dataset's target views (module docstring).

    Args:
        model: a model, a loaded checkpoint, or a checkpoint path.
        dataset: a :class:`TrainDataset` or its folder.
        max_samples: score only the first this many samples (default all).
    """
    if isinstance(model, (str, os.PathLike)):
        model = load_checkpoint(model)
    if isinstance(model, Checkpoint):
        model = model.model
    if not isinstance(model, Stylize3DModel):
        raise InputError("model", f"expected a Stylize3DModel, Checkpoint or path, got {type(model).__name__}")
    data = dataset if isinstance(dataset, TrainDataset) else TrainDataset(dataset)
    n = len(data)
    if max_samples is not None:
        if isinstance(max_samples, bool) or not isinstance(max_samples, int) or max_samples < 1:
            raise InputError("max_samples", f"must be an integer >= 1, got {max_samples!r}")
        n = min(n, max_samples)
    was_training = model.training
    model.eval()
    records: List[ViewRecord] = []
    counts = {k: 0 for k in KINDS}
    try:
        for s in range(n):
            sample = data[s]
            counts[sample.kind] += 1
            records.extend(score_views(predict_views(model, sample), sample, s))
    finally:
        model.train(was_training)
    by_kind = {k: [r for r in records if r.kind == k] for k in KINDS}
    return ViewSynthesisResult(
        procedural=summarize_views(by_kind["procedural"], counts["procedural"]),
        ldi=summarize_views(by_kind["ldi"], counts["ldi"]),
        views=tuple(records),
    )
