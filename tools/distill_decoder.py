"""Distil the shipped model's U-Net decoder into a narrower one (an experiment toward faster frames).

The decoder is most of a stylized frame's time on a CPU (its multiply-adds grow with the square of its
width). This trains a decoder of ``--width`` (narrower than the shipped one's) to reproduce the shipped decoder's
frames from the same rasterized features: the teacher model encodes, stylizes (a random style of the
bank, or none) and rasterizes the training set's views exactly as training and inference do, its
decoder gives the target frames, and the student learns them (L1 on the colours and on their
horizontal / vertical differences, which carry the texture). Everything before the decoder stays the
teacher's, so a student drops into the checkpoint in place of the decoder.

    .venv/bin/python tools/distill_decoder.py --out runs/distill48 [--width 48] [--samples 600]
        [--steps 2000] [--batch 16]

Phase 1 caches the (features, mask, teacher frame) triples of ``--samples`` training samples (and of
``--eval-samples`` samples of the evaluation split) in ``OUT/cache_*.pt``; phase 2 trains, saving
``OUT/student.pt`` every ``--save-every`` steps and resuming from it; at the end it prints the PSNR of
the student's frames against the teacher's on the evaluation views and writes ``OUT/student.safetensors``
(the teacher's checkpoint with the student's decoder).
"""

from __future__ import annotations

import argparse
import json
import math
import random
import time
from dataclasses import replace
from pathlib import Path

import torch
import torch.nn.functional as F

ROOT = Path(__file__).resolve().parents[1]

from stylize3d_core.bench.speed import psnr as speed_psnr  # noqa: E402
from stylize3d_core.io.atomic import atomic_path  # noqa: E402
from stylize3d_core.models.checkpoint import load_checkpoint, save_checkpoint  # noqa: E402
from stylize3d_core.models.colour_transfer import lab_stats, transfer_colours  # noqa: E402
from stylize3d_core.models.decoder import UNetDecoder  # noqa: E402
from stylize3d_core.models.style_features import StyleEncoder  # noqa: E402
from stylize3d_core.models.stylize3d import Stylize3DModel  # noqa: E402
from stylize3d_core.render.rasterize import RasterSettings  # noqa: E402
from stylize3d_core.render.rasterizer import PointRasterizer  # noqa: E402
from stylize3d_core.train.cache import load_sample  # noqa: E402
from stylize3d_core.train.styles import StyleBank  # noqa: E402

MODEL = ROOT / "assets" / "model" / "stylize3d_lite.safetensors"


def cache_views(model: Stylize3DModel, encoder: StyleEncoder, bank: StyleBank, folder: Path, count: int,
                seed: int, no_style: float = 0.2):
    """(features (V, C, H, W) float16, masks (V, 1, H, W) bool, frames (V, 3, H, W) float16) of the first
    ``count`` samples of ``folder``, each with a random style of the bank (none with ``no_style``)."""
    rng = random.Random(seed)
    files = sorted(folder.glob("sample_*.pt"))[:count]
    feats, masks, frames = [], [], []
    t0 = time.perf_counter()
    with torch.inference_mode():
        for i, f in enumerate(files):
            sample = load_sample(f)
            geom = sample.geometry
            content = model.encode(geom)
            colours = None
            if rng.random() < no_style:
                sparse = content
            else:
                style = bank[rng.randrange(len(bank))]
                sparse = model.stylizer.stylize(content, encoder(style[None]).maps)
                if model.config.detail_transfer:
                    colours = transfer_colours(geom.rgb, lab_stats(style))
            dense = model.dense_features(sparse, geom, colours)
            H, W = sample.image_size
            for v in range(len(sample.cameras)):
                frags = PointRasterizer(RasterSettings(height=H, width=W))(geom.xyz, dense, sample.cameras[v])
                x = frags.image.unsqueeze(0)
                m = (~frags.hole).to(x.dtype)[None, None]
                y = model.decoder(x, m)
                feats.append(x[0].half())
                masks.append(m[0].bool())
                frames.append(y[0].half())
            if (i + 1) % 50 == 0:
                print(f"  cached {i + 1}/{len(files)} samples ({time.perf_counter() - t0:.0f} s)", flush=True)
    return torch.stack(feats), torch.stack(masks), torch.stack(frames)


def loss_fn(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """L1 on the colours and on their horizontal / vertical differences (the texture)."""
    l1 = (pred - target).abs().mean()
    dx = lambda t: t[..., :, 1:] - t[..., :, :-1]  # noqa: E731
    dy = lambda t: t[..., 1:, :] - t[..., :-1, :]  # noqa: E731
    return l1 + (dx(pred) - dx(target)).abs().mean() + (dy(pred) - dy(target)).abs().mean()


def psnr(a: torch.Tensor, b: torch.Tensor) -> float:
    return speed_psnr(a.float().numpy(), b.float().numpy())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--model", default=str(MODEL))
    ap.add_argument("--data", default=str(ROOT / "runs" / "data"))
    ap.add_argument("--styles", default=str(ROOT / "runs" / "styles"))
    ap.add_argument("--width", type=int, default=48)
    ap.add_argument("--samples", type=int, default=600)
    ap.add_argument("--eval-samples", type=int, default=60)
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--batch", type=int, default=16)
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--save-every", type=int, default=100)
    ap.add_argument("--threads", type=int, default=None)
    args = ap.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    ck = load_checkpoint(args.model)
    teacher = ck.model.eval()
    bank = StyleBank(args.styles, max_size=256)
    caches = {}
    for split, n, seed in (("train", args.samples, 0), ("eval", args.eval_samples, 1)):
        path = out / f"cache_{split}.pt"
        if path.exists():
            caches[split] = torch.load(path)
        else:
            print(f"caching {split} views ...", flush=True)
            caches[split] = cache_views(teacher, StyleEncoder(), bank, Path(args.data) / split, n, seed)
            with atomic_path(path) as tmp:
                torch.save(caches[split], tmp)
    xf, xm, yt = caches["train"]
    ef, em, ey = caches["eval"]
    print(f"train views {len(xf)}, eval views {len(ef)}, {tuple(xf.shape[1:])}", flush=True)

    cfg = replace(teacher.config.decoder, width=args.width, transform_gain=1.0 / args.width)
    student = UNetDecoder(cfg)
    opt = torch.optim.Adam(student.parameters(), lr=args.lr)
    state_path = out / "student.pt"
    step, log = 0, []
    if state_path.exists():
        st = torch.load(state_path)
        student.load_state_dict(st["student"])
        opt.load_state_dict(st["opt"])
        step, log = st["step"], st["log"]
        print(f"resumed at step {step}", flush=True)
    g = torch.Generator().manual_seed(step)
    t0 = time.perf_counter()
    student.train()
    while step < args.steps:
        lr = args.lr * 0.5 * (1 + math.cos(math.pi * step / args.steps))  # cosine to 0
        for group in opt.param_groups:
            group["lr"] = lr
        idx = torch.randint(0, len(xf), (args.batch,), generator=g)
        pred = student(xf[idx].float(), xm[idx].float())
        loss = loss_fn(pred, yt[idx].float())
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        step += 1
        log.append({"step": step, "loss": float(loss.detach()), "lr": lr})
        if step % args.save_every == 0 or step == args.steps:
            student.eval()
            with torch.inference_mode():
                p = [psnr(student(ef[i:i + 16].float(), em[i:i + 16].float()), ey[i:i + 16])
                     for i in range(0, len(ef), 16)]
            student.train()
            log[-1]["eval_psnr"] = sum(p) / len(p)
            print(f"step {step} loss {float(loss.detach()):.4f} lr {lr:.2e} eval PSNR {log[-1]['eval_psnr']:.2f} dB "
                  f"({time.perf_counter() - t0:.0f} s)", flush=True)
            with atomic_path(state_path) as tmp:
                torch.save({"student": student.state_dict(), "opt": opt.state_dict(), "step": step, "log": log}, tmp)
    student.eval()
    with torch.inference_mode():
        per_view = [psnr(student(ef[i:i + 1].float(), em[i:i + 1].float()), ey[i:i + 1]) for i in range(len(ef))]
    per_view.sort()
    print(f"student width {args.width} vs teacher on {len(per_view)} eval views: PSNR median "
          f"{per_view[len(per_view) // 2]:.2f} dB, worst {per_view[0]:.2f} dB", flush=True)
    model = Stylize3DModel(replace(teacher.config, decoder=cfg))
    model.load_state_dict({**{k: v for k, v in teacher.state_dict().items() if not k.startswith("decoder.")},
                           **{f"decoder.{k}": v for k, v in student.state_dict().items()}})
    save_checkpoint(out / "student.safetensors", model, ck.stage,
                    {**ck.info, "distilled": json.dumps({"from": str(args.model), "width": args.width,
                                                         "steps": step, "samples": args.samples})})


if __name__ == "__main__":
    main()
