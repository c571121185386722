"""Held-out view synthesis of stage-1 models: masked PSNR / SSIM per sample kind.

Scores each checkpoint on a held-out dataset folder (default ``runs/data/eval``,
written by ``stylize3d prepare-data``; the photos and seed differ from the
training split) with :func:`stylize3d_core.eval.view_synthesis.evaluate_view_synthesis`,
and, as a reference on the same views, the *plain* render of the sample's point
cloud (its RGB splatted by the core rasterizer at 1x, holes filled), i.e. what
the 3D photo shows without a neural renderer.

On ``procedural`` samples the targets are true novel views of a ray-cast scene;
on ``ldi`` samples they are pseudo views rendered from the photo's own LDI
(at the data's target supersampling, so the plain render is close to them by
construction: that column measures the renderer, not the world).

    .venv/bin/python tests/benchmarks/bench_view_synthesis.py CKPT [CKPT ...] [--data runs/data/eval] [--samples N]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[2]

from stylize3d_core.eval.quality import plain_view_scores  # noqa: E402
from stylize3d_core.eval.view_synthesis import KindScores, evaluate_view_synthesis  # noqa: E402
from stylize3d_core.train.cache import TrainDataset  # noqa: E402


def line(name: str, kind: str, sc: KindScores) -> str:
    return (f"{name:<44} {kind:<10} {sc.n_views:>5} {sc.psnr:7.2f} {sc.ssim:6.3f} "
            f"{sc.psnr_seen:7.2f} {sc.ssim_seen:6.3f} {sc.psnr_unseen:7.2f} {sc.ssim_unseen:6.3f}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("models", nargs="+", help="checkpoints to score")
    ap.add_argument("--data", default=str(ROOT / "runs/data/eval"))
    ap.add_argument("--samples", type=int, default=None, help="score only the first N samples")
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    data = TrainDataset(args.data)
    n = len(data) if args.samples is None else min(args.samples, len(data))
    print(f"held-out data: {args.data} ({n} samples)")
    print(f"{'render':<44} {'kind':<10} {'views':>5} {'PSNR':>7} {'SSIM':>6} {'PSNRsn':>7} {'SSIMsn':>6} "
          f"{'PSNRun':>7} {'SSIMun':>6}")
    for name, scores in plain_view_scores(data, n).items():
        if scores is not None:
            print(line("plain point render (reference)", name, scores))
    for path in args.models:
        t0 = time.perf_counter()
        res = evaluate_view_synthesis(path, data, max_samples=n)
        label = Path(path).name if len(Path(path).name) <= 44 else Path(path).name[-44:]
        for kind in ("procedural", "ldi"):
            sc = getattr(res, kind)
            if sc is not None:
                print(line(label, kind, sc))
        print(f"  ({time.perf_counter() - t0:.1f} s)")
    print("sn = surfaces the photo saw, un = disoccluded surfaces; PSNR in dB over masked pixels, mean over views")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
