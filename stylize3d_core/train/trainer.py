"""Training of the stylization model from 2D images only (paper Sec. 4).

* **Stage 1 (view synthesis):** encoder + decoder learn to render each
  sample's target views: L1 + perceptual loss (EfficientNet features) against
  the target (a pseudo view rendered from the sample's LDI, or a true view of a
  procedural scene), plus the multi-view consistency loss between the V
  predicted views.
* **Stage 2 (stylization):** the encoder is frozen; the stylizer and the decoder
  learn AdaAttN content + global style losses against a style image from the
  style bank, plus the consistency loss. A fraction of the steps keep the
  stage-1 loss at strength 0, so the decoder still renders the original photo
  when the user sets the strength to 0. With a teacher folder
  (:mod:`.teacher`, ``--teacher``), a fraction of the stylized samples use the
  style the 2D network baked onto that sample's points, and add an L1 +
  perceptual loss against those baked colours rendered into the target views.
  Every stylized view's L*a*b* colour statistics are also pulled towards the
  style image's (``LossWeights.colour``).

Consistency loss: a random subset of the sample's points is
projected into every predicted view; for every pair of views, the L1 difference
of the colours sampled at the points visible in both is averaged.

Runs anywhere from one CPU to several GPUs: under ``torchrun`` (WORLD_SIZE > 1)
every process trains on its own samples and DDP averages the gradients. The run
folder holds ``model_stage{S}.safetensors`` (weights + config, loadable by
:func:`~stylize3d_core.models.checkpoint.load_checkpoint`),
``state_stage{S}.pt`` (optimizer, iteration, RNG; resumes the run) and
``log_stage{S}.jsonl`` (one line of losses per logged iteration).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable, Dict, List, Optional, Tuple

import numpy as np
import torch
from torch import nn

from ..checks import check_range
from ..errors import InputError
from ..io.atomic import atomic_path
from ..models.checkpoint import load_checkpoint, save_checkpoint
from ..models.colour_transfer import lab_stats, transfer_colours
from ..models.efficientnet_lite import EfficientNetLiteFeatures
from ..models.losses import (PerceptualLoss, PerceptualLossConfig, StylizationLoss, StylizationLossConfig,
                             colour_statistics_loss, detail_loss, sharpness_loss)
from ..models.style_features import StyleEncoder
from ..models.stylize3d import (ConfigName, ModelConfig, Stylize3DModel, add_colour_transform, add_detail_path,
                                add_style_prior,
                                add_texture_residual)
from ..options import option
from ..render.reproject import pairwise_consistency, sample_view
from .cache import TrainDataset
from .data import TrainSample, from_u8
from .styles import StyleBank
from .teacher import TeacherSet, teacher_targets

STYLE_CROP = 160
"""Side of the random style crops shown to the stylizer in stage 2, in pixels."""

Log = Callable[[str], None]

LR_SCHEDULES = ("constant", "cosine")


@dataclass(frozen=True)
class LossWeights:
    """Weights of the loss terms (chosen so that, at the start of each stage, no
    term is negligible: the raw EfficientNet-feature losses are 10-1000x the pixel ones).

    Attributes:
        l1: stage 1, L1 between prediction and target (masked). Default 1.
        perceptual: stage 1, EfficientNet feature L1 (raw ~3x the pixel L1 at the start). Default 0.05.
        content: stage 2, AdaAttN content (local feature) loss (raw ~9 at the start). Default 1.
        style: stage 2, global mean/std style loss (raw ~60 at the start). Default 0.1.
        consistency: stage 1 (and stage-2 strength-0 steps), multi-view consistency L1. Default 1.
        consistency_stylized: stage 2, multi-view consistency L1 of stylized views (raw ~0.007). Default 50.
        teacher: stage 2 teacher samples, L1 against the baked teacher targets (masked). Default 1.
        teacher_perceptual: stage 2 teacher samples, EfficientNet feature L1 against them. Default 0.05.
        colour: stage 2, L*a*b* mean/std of every stylized view against the style image's
            (:func:`~stylize3d_core.models.losses.colour_statistics_loss`, raw ~0.02-0.3). Default 2.
        teacher_detail: stage 2 teacher samples, L1 of the Laplacian against them
            (:func:`~stylize3d_core.models.losses.detail_loss`, raw ~0.02-0.05): the teacher's
            strokes, which the pixel L1 lets a blur average away. Default 0 (off).
        sharpness: stage 2, how far each stylized view's sharpness (std of the grey Laplacian,
            the quality benchmark's measure) falls short of its plain target view's
            (:func:`~stylize3d_core.models.losses.sharpness_loss`, raw 0-1; no charge for added
            strokes). Default 0 (off).
    """

    l1: float = 1.0
    perceptual: float = 0.05
    content: float = 1.0
    style: float = 0.1
    consistency: float = 1.0
    consistency_stylized: float = 50.0
    teacher: float = 1.0
    teacher_perceptual: float = 0.05
    colour: float = 2.0
    teacher_detail: float = 0.0
    sharpness: float = 0.0


@dataclass(frozen=True)
class TrainConfig:
    """A training run.

    Attributes:
        stage: 1 (view synthesis) or 2 (stylization; needs ``init`` or a stage-1 checkpoint in ``out_dir``).
        model: "lite" or "paper" (see :class:`ModelConfig`).
        data_dir: training samples written by ``stylize3d prepare-data`` (its ``train/`` folder).
        styles_dir: style bank (stage 2) written by ``stylize3d prepare-styles``.
        out_dir: the run folder (checkpoints, state, logs).
        iterations: total optimizer steps of the stage (public code: 20k).
        batch_size: samples per step (public code: 8).
        lr: Adam learning rate (public code: 1e-4).
        lr_schedule: "constant" (public code), or "cosine": the rate at iteration
            ``it`` is ``lr * (1 + cos(pi * it / iterations)) / 2``, so it depends only on
            the iteration and a resumed run continues the same curve.
        weights: loss weights.
        consistency_points: points sampled per sample for the consistency loss.
        recon_fraction: stage 2, fraction of steps that train strength 0 with the stage-1 loss.
        checkpoint_every: write checkpoint and state every this many steps (and at the end).
        log_every: log losses every this many steps.
        max_hours: stop (after checkpointing) once this much wall time has passed; None = no limit.
        init: checkpoint to start from (stage 2: the stage-1 model).
        init_stylizer: stage 2, a checkpoint whose stylizer weights replace the
            initial ones (e.g. an earlier stage-2 run, when the encoder has only been
            trained further since); ignored when the run resumes.
        seed: base seed (sample order, style choice, consistency points).
        threads: torch CPU threads (None: torch's default).
        teacher_dir: stage 2, a folder written by :func:`~.teacher.build_teacher` for ``data_dir``; None: no teacher.
        teacher_fraction: stage 2, share of the stylized samples that use their teacher (the rest take a
            random style crop and only the AdaAttN losses). Models with the style prior use it for every
            stylized sample (they need its baked colours).
        style_prior: stage 2, start from ``init`` with the 2D style prior added
            (:func:`~stylize3d_core.models.stylize3d.add_style_prior`); ignored when the run resumes.
        style_stages: stage 2, the EfficientNet stages (0..4) whose feature mean/std the global style
            loss matches (default (1, 2), the public code's; the quality benchmark's EfficientNet
            distance measures stages 1-3).
        style_crop: stage 2, (low, high): the side of the random style crops (non-teacher samples) as a
            fraction of the style image's short side, drawn uniformly in [low, high], before they are
            resized to ``STYLE_CROP`` pixels. Default (0.5, 1.0). Smaller fractions magnify the style's
            strokes: with the 256-pixel style bank and 128-pixel training views, (0.5, 1.0) shows the strokes
            at 0.6-1.25x their size in a 256-pixel style, while the quality benchmark compares 384-pixel
            frames with the style at up to 512 pixels (2x).
    """

    stage: int = option(1, help="1 (view synthesis) or 2 (stylization)", cli=False)
    model: ConfigName = option("lite", help="model size", flags=("--config",))
    data_dir: str = option("runs/data/train", help="training samples (written by stylize3d prepare-data)",
                           flags=("--data",), metavar="DIR")
    styles_dir: str = option("runs/styles", help="style bank for stage 2", flags=("--styles",), metavar="DIR")
    out_dir: str = option("runs/train", help="run folder; a run resumes from its checkpoint", flags=("--out",),
                          metavar="DIR")
    iterations: int = option(20000, help="total steps", low=1, high=1e9)
    batch_size: int = option(8, help="samples per step", low=1, high=1e9)
    lr: float = option(1e-4, help="Adam learning rate")
    lr_schedule: str = option("constant", help="constant, or cosine decay to 0 at --iterations",
                              choices=LR_SCHEDULES)
    weights: LossWeights = option(default_factory=LossWeights, help="loss weights", cli=False)
    consistency_points: int = option(4096, help="points per sample of the consistency loss", low=1, high=1e9)
    recon_fraction: float = option(0.2, help="stage 2: share of steps that train strength 0 with the stage-1 "
                                             "loss", low=0.0, high=1.0)
    checkpoint_every: int = option(100, help="write the checkpoint every this many steps", low=1, high=1e9)
    log_every: int = option(10, help="log the losses every this many steps", low=1, high=1e9)
    max_hours: Optional[float] = option(None, help="stop (with a checkpoint) after this many hours",
                                        flags=("--hours",))
    init: Optional[str] = option(None, help="checkpoint to start from (stage 2: the stage-1 model)",
                                 metavar="CHECKPOINT")
    init_stylizer: Optional[str] = option(None, help="stage 2: take the stylizer's initial weights from this "
                                                     "checkpoint (an earlier stage-2 run)", metavar="CHECKPOINT")
    seed: int = option(0, help="base seed (sample order, style choice, consistency points)")
    threads: Optional[int] = option(None, help="torch CPU threads (default: torch's choice)")
    teacher_dir: Optional[str] = option(None, help="stage 2: a prepare-teacher folder for --data",
                                        flags=("--teacher",), metavar="DIR")
    teacher_fraction: float = option(0.7, help="stage 2: share of stylized samples that learn from their "
                                               "teacher", low=0.0, high=1.0)
    style_prior: bool = option(False, help="stage 2: add the 2D style prior to the --init model (its detail "
                                           "path carries the 2D network's painting of the points; needs "
                                           "--teacher)")
    style_stages: Tuple[int, ...] = option(StylizationLossConfig.style_stages, cli=False,
                                           help="stage 2: EfficientNet stages (0-4) of the global style loss")
    style_crop: Tuple[float, float] = option((0.5, 1.0), cli=False,
                                             help="stage 2: side of the random style crops as a fraction of "
                                                  "the style's short side")

    def __post_init__(self) -> None:
        if self.stage not in (1, 2):
            raise InputError("stage", f"must be 1 or 2, got {self.stage!r}")
        ModelConfig.by_name(self.model)
        for name in ("iterations", "batch_size", "consistency_points", "checkpoint_every", "log_every"):
            check_range(getattr(self, name), name, 1, 1e9)
        check_range(self.lr, "lr", 0.0, 1.0, inclusive=False)
        if self.lr_schedule not in LR_SCHEDULES:
            raise InputError("lr_schedule", f"must be one of {', '.join(LR_SCHEDULES)}, got {self.lr_schedule!r}")
        check_range(self.recon_fraction, "recon_fraction", 0.0, 1.0)
        if self.init_stylizer is not None and self.stage != 2:
            raise InputError("init_stylizer", "only stage 2 trains the stylizer")
        if self.teacher_dir is not None and self.stage != 2:
            raise InputError("teacher_dir", "the teacher trains stylization: stage 2 only")
        check_range(self.teacher_fraction, "teacher_fraction", 0.0, 1.0)
        if self.style_prior and (self.stage != 2 or self.teacher_dir is None):
            raise InputError("style_prior", "the style prior trains in stage 2 with a teacher (--teacher)")
        stages = tuple(self.style_stages)
        if not stages or len(set(stages)) != len(stages) or any(
                not isinstance(s, int) or not 0 <= s <= 4 for s in stages):
            raise InputError("style_stages", f"expected distinct EfficientNet stages in 0..4, got {self.style_stages!r}")
        crop = tuple(self.style_crop)
        if len(crop) != 2 or not all(isinstance(v, (int, float)) for v in crop) or not 0.05 <= crop[0] <= crop[1] <= 1.0:
            raise InputError("style_crop", f"expected (low, high) with 0.05 <= low <= high <= 1, got {self.style_crop!r}")
        if self.max_hours is not None:
            check_range(self.max_hours, "max_hours", 0.0, 1e4, inclusive=False)


def learning_rate(config: TrainConfig, iteration: int) -> float:
    """The Adam learning rate for the step that starts at ``iteration`` (see ``TrainConfig.lr_schedule``)."""
    if config.lr_schedule == "cosine":
        t = min(max(iteration / config.iterations, 0.0), 1.0)
        return config.lr * 0.5 * (1.0 + math.cos(math.pi * t))
    return config.lr


def consistency_loss(
    points: torch.Tensor, views: List[torch.Tensor], zbuffers: List[torch.Tensor], sample: TrainSample
) -> torch.Tensor:
    """Mean over view pairs of the L1 colour difference at points visible in both views."""
    samples = [sample_view(points, v, z, sample.cameras[i]) for i, (v, z) in enumerate(zip(views, zbuffers))]
    terms = []
    for a in range(len(samples)):
        for b in range(a + 1, len(samples)):
            l1, _, n = pairwise_consistency(samples[a], samples[b])
            if n > 0:
                terms.append(l1)
    return torch.stack(terms).mean() if terms else views[0].sum() * 0.0


class TrainStep(nn.Module):
    """One sample's loss (a module so DDP can wrap it). Runs on the training thread.

    The sample's cached geometry is what inference prepares
    (:func:`~stylize3d_core.models.scene_geometry.prepare_geometry`), and the style
    image goes through :class:`~stylize3d_core.models.style_features.StyleEncoder`
    as at inference; ``features`` (the frozen CNN) also computes the losses.
    """

    def __init__(self, model: Stylize3DModel, features: EfficientNetLiteFeatures, weights: LossWeights,
                 consistency_points: int, style_stages: Tuple[int, ...] = StylizationLossConfig.style_stages) -> None:
        super().__init__()
        self.model = model
        self.style_encoder = StyleEncoder(extractor=features)
        self.perceptual = PerceptualLoss(PerceptualLossConfig(), extractor=features)
        self.stylization = StylizationLoss(StylizationLossConfig(style_stages=tuple(style_stages)), extractor=features)
        self.weights = weights
        self.consistency_points = consistency_points

    def forward(self, sample: TrainSample, style: Optional[torch.Tensor], generator: torch.Generator,
                teacher: Optional[Tuple[torch.Tensor, torch.Tensor]] = None,
                prior: Optional[torch.Tensor] = None) -> Dict[str, torch.Tensor]:
        """The weighted loss terms of one sample; ``teacher``: (targets (V, 3, H, W), masks (V, H, W)) of the
        style baked by the 2D network (stylized samples only); ``prior``: (N, 3) the points' baked colours,
        which a model with the style prior carries on its detail path (stylized samples need it)."""
        geom = sample.geometry
        content = self.model.encode(geom)  # (M, C)
        if style is not None:
            maps = self.style_encoder(style.unsqueeze(0)).maps
            feats = self.model.stylizer.stylize(content, maps)
        else:
            maps, feats = None, content
        colours = None
        if style is not None and self.model.config.detail_transfer:
            colours = transfer_colours(geom.rgb, lab_stats(style))  # the style's colour statistics, at strength 1
        if style is not None and self.model.config.style_prior:
            if prior is None:
                raise InputError("prior", "a model with the style prior trains stylized samples on their teacher's "
                                          "baked colours (train with --teacher)")
            colours = prior.to(geom.rgb.device, geom.rgb.dtype)
        dense = self.model.dense_features(feats, geom, colours)  # (N, Cr)
        H, W = sample.image_size
        views, zbufs = [], []
        for v in range(len(sample.cameras)):
            rgb, frags = self.model.render_view(dense, geom.xyz, sample.cameras[v], H, W)
            views.append(rgb)
            zbufs.append(frags.depth)
        pred = torch.stack(views)  # (V, 3, H, W)
        target = sample.targets.float()
        w = self.weights
        terms: Dict[str, torch.Tensor] = {}
        if style is None:
            mask = sample.masks[:, None].float()  # (V, 1, H, W)
            terms["l1"] = w.l1 * ((pred - target).abs() * mask).sum() / (3 * mask.sum()).clamp(min=1.0)
            terms["perceptual"] = w.perceptual * self.perceptual(pred, target)
        else:
            st = self.stylization(pred, target, maps)
            terms["content"] = w.content * st.content
            terms["style"] = w.style * st.style
            if w.sharpness:
                terms["sharpness"] = w.sharpness * sharpness_loss(pred, target, sample.masks.float())
            if w.colour:
                terms["colour"] = w.colour * colour_statistics_loss(pred, style.unsqueeze(0))
            if teacher is not None:
                t_target, t_mask = teacher[0].to(pred.device), teacher[1][:, None].to(pred.device, pred.dtype)
                terms["teacher"] = w.teacher * ((pred - t_target).abs() * t_mask).sum() / (
                    3 * t_mask.sum()).clamp(min=1.0)
                terms["teacher_perceptual"] = w.teacher_perceptual * self.perceptual(pred, t_target)
                if w.teacher_detail:
                    terms["teacher_detail"] = w.teacher_detail * detail_loss(pred, t_target, t_mask[:, 0])
        n = geom.xyz.shape[0]
        pick = torch.randperm(n, generator=generator)[: self.consistency_points]
        weight = w.consistency if style is None else w.consistency_stylized
        terms["consistency"] = weight * consistency_loss(geom.xyz[pick], views, zbufs, sample)
        return terms


def _dist_info():
    world = int(os.environ.get("WORLD_SIZE", "1"))
    rank = int(os.environ.get("RANK", "0"))
    local = int(os.environ.get("LOCAL_RANK", "0"))
    return world, rank, local


def train(config: TrainConfig, log: Log = print) -> Path:
    """Run (or resume) a training stage; returns the checkpoint path."""
    world, rank, local = _dist_info()
    if config.threads:
        torch.set_num_threads(config.threads)
    device = torch.device(f"cuda:{local}" if torch.cuda.is_available() else "cpu")
    if world > 1:
        torch.distributed.init_process_group("nccl" if device.type == "cuda" else "gloo")
    out = Path(config.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    ckpt_path = out / f"model_stage{config.stage}.safetensors"
    state_path = out / f"state_stage{config.stage}.pt"
    log_path = out / f"log_stage{config.stage}.jsonl"

    start_it = 0
    if ckpt_path.exists() and state_path.exists():
        model = load_checkpoint(ckpt_path).model
        state = torch.load(state_path, weights_only=True)
        start_it = int(state["iteration"])
        log(f"resuming stage {config.stage} from {ckpt_path} at iteration {start_it}")
    elif config.init is not None:
        model = load_checkpoint(config.init).model
        state = None
        log(f"starting stage {config.stage} from {config.init}")
    elif config.stage == 2:
        stage1 = out / "model_stage1.safetensors"
        if not stage1.exists():
            raise InputError("init", "stage 2 needs a stage-1 checkpoint: pass --init or train stage 1 in this folder")
        model = load_checkpoint(stage1).model
        state = None
    else:
        model = Stylize3DModel(ModelConfig.by_name(config.model))
        state = None
    if model.config.name != config.model:
        raise InputError("model", f"the checkpoint is a {model.config.name!r} model, not {config.model!r}")
    if state is None and not model.config.detail_channels and ModelConfig.by_name(config.model).detail_channels:
        model = add_detail_path(model)
        log("added the detail path to the initial model (zero weights: same output)")
    if (state is None and model.config.detail_channels and not model.config.decoder.transform_channels
            and ModelConfig.by_name(config.model).decoder.transform_channels):
        target = ModelConfig.by_name(config.model)
        model = add_colour_transform(model, identity=True, transfer=target.detail_transfer)
        log("added the colour transform to the initial model (identity: it renders the points' colours"
            + (", moved to the style's colour statistics)" if target.detail_transfer else ")"))
    if (state is None and model.config.decoder.transform_channels and not model.config.decoder.texture_channels
            and ModelConfig.by_name(config.model).decoder.texture_channels):
        model = add_texture_residual(model)
        log("added the texture residual to the initial model (zero weights: same output)")
    if state is None and config.style_prior and not model.config.style_prior:
        model = add_style_prior(model)
        log("added the 2D style prior to the initial model (identity transform: it renders the prior's colours)")
    if state is None and config.init_stylizer is not None:
        donor = load_checkpoint(config.init_stylizer).model
        if donor.config.stylizer != model.config.stylizer or donor.config.encoder != model.config.encoder:
            raise InputError(config.init_stylizer, "its encoder or stylizer configuration differs from the one "
                                                   "being trained")
        model.stylizer.load_state_dict(donor.stylizer.state_dict())
        log(f"stylizer weights from {config.init_stylizer}")
    model.to(device).train()

    if config.stage == 2:
        model.encoder.requires_grad_(False)
        model.encoder.eval()
    else:
        model.stylizer.requires_grad_(False)  # stage 1 never uses the stylizer
    features = EfficientNetLiteFeatures(stages=(0, 1, 2, 3, 4)).to(device)
    step = TrainStep(model, features, config.weights, config.consistency_points, config.style_stages).to(device)
    ddp = torch.nn.parallel.DistributedDataParallel(step, device_ids=[local] if device.type == "cuda" else None) \
        if world > 1 else step
    params = [p for p in model.parameters() if p.requires_grad]
    opt = torch.optim.Adam(params, lr=config.lr)
    rng = np.random.default_rng(config.seed + 1000 * rank + start_it)
    gen = torch.Generator().manual_seed(config.seed + rank + start_it)
    if state is not None:
        opt.load_state_dict(state["optimizer"])

    data = TrainDataset(config.data_dir, neighbourhood=model.config.neighbourhood)
    styles = StyleBank(config.styles_dir, max_size=256) if config.stage == 2 else None
    teachers = TeacherSet(config.teacher_dir, data) if config.teacher_dir is not None else None
    style_index = {styles.name(i): i for i in range(len(styles))} if styles is not None else {}
    t_start = time.time()
    info = {"stage": config.stage, "config": asdict(config), "data": str(config.data_dir), "samples": len(data)}

    def checkpoint(it: int) -> None:
        if rank != 0:
            return
        hours = float(state["hours"] if state is not None else 0.0) + (time.time() - t_start) / 3600
        save_checkpoint(ckpt_path, model, config.stage, {**info, "iterations": it, "hours": round(hours, 3)})
        with atomic_path(state_path) as tmp:
            torch.save({"iteration": it, "optimizer": opt.state_dict(), "hours": hours}, tmp)

    it = start_it
    window: Dict[str, List[float]] = {}
    t_log = time.time()
    while it < config.iterations:
        opt.zero_grad(set_to_none=True)
        for group in opt.param_groups:
            group["lr"] = learning_rate(config, it)
        indices = rng.integers(0, len(data), size=config.batch_size)
        recon = config.stage == 2 and rng.random() < config.recon_fraction
        for b, i in enumerate(indices):
            sample = data[int(i)]
            style, teach, prior = None, None, None
            if styles is not None and not recon:
                use_teacher = teachers is not None and int(i) < len(teachers) and (
                    model.config.style_prior or rng.random() < config.teacher_fraction)
                if model.config.style_prior and not use_teacher:
                    continue  # its stylized samples are the teacher's: a sample without one trains nothing here
                if use_teacher:
                    entry = teachers.entry(int(i), sample.num_points)
                    slot = int(rng.integers(0, len(entry.styles)))
                    if entry.styles[slot] not in style_index:
                        raise InputError(config.teacher_dir, f"style {entry.styles[slot]!r} is not in {config.styles_dir}")
                    k = style_index[entry.styles[slot]]
                    style = styles.crop(k, rng, STYLE_CROP, min_scale=1.0).to(device)  # the whole style image
                    teach = teacher_targets(sample, entry.rgb[slot])
                    if model.config.style_prior:
                        prior = from_u8(entry.rgb[slot])
                else:
                    lo, hi = config.style_crop
                    style = styles.sample(rng, STYLE_CROP, lo, hi)[0].to(device)
            sync = world > 1 and b < len(indices) - 1
            ctx = ddp.no_sync() if sync else contextlib.nullcontext()
            with ctx:
                terms = ddp(sample, style, gen, teach, prior)
                loss = sum(terms.values()) / len(indices)
                if not torch.isfinite(loss):
                    raise FloatingPointError(f"non-finite loss at iteration {it}: { {k: float(v) for k, v in terms.items()} }")
                loss.backward()
            for k, v in terms.items():
                window.setdefault(k, []).append(float(v.detach()))
        torch.nn.utils.clip_grad_norm_(params, 1.0)
        opt.step()
        it += 1
        if it % config.log_every == 0 and rank == 0:
            means = {k: float(np.mean(v)) for k, v in window.items()}
            sec = (time.time() - t_log) / config.log_every
            line = {"iteration": it, **means, "total": sum(means.values()), "sec_per_it": round(sec, 3),
                    "lr": learning_rate(config, it - 1)}
            with open(log_path, "a", encoding="utf-8") as f:
                f.write(json.dumps(line) + "\n")
            log(f"stage {config.stage} it {it}/{config.iterations} " + " ".join(f"{k} {v:.4f}" for k, v in means.items())
                + f" ({sec:.2f} s/it)")
            window, t_log = {}, time.time()
        if it % config.checkpoint_every == 0 or it == config.iterations:
            checkpoint(it)
        if config.max_hours is not None and (time.time() - t_start) / 3600 >= config.max_hours:
            checkpoint(it)
            log(f"stopping after {config.max_hours} h at iteration {it}; run again to resume")
            break
    if world > 1:
        torch.distributed.destroy_process_group()
    return ckpt_path
