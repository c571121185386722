"""Depth Anything V2 Small's time on this CPU: the real architecture (random weights: no download needed) at the
image processor's 518 px, with pre- and post-processing (``DepthAnythingModel.estimate``), for a 1 MP photo.

    .venv/bin/python tests/benchmarks/bench_depth_anything.py [--threads 2] [--repeats 5]

Prints the median and minimum seconds of ``--repeats`` runs after one warm-up, and the network's input size.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time

import numpy as np
import torch


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    from transformers import DepthAnythingConfig, DepthAnythingForDepthEstimation, Dinov2Config, DPTImageProcessor

    from stylize3d_core.depth.depth_anything import DepthAnythingModel

    backbone = Dinov2Config(hidden_size=384, num_hidden_layers=12, num_attention_heads=6, intermediate_size=1536,
                            patch_size=14, image_size=518, out_indices=[3, 6, 9, 12], reshape_hidden_states=False)
    config = DepthAnythingConfig(backbone_config=backbone, neck_hidden_sizes=[48, 96, 192, 384], fusion_hidden_size=64)
    with tempfile.TemporaryDirectory() as folder:
        DepthAnythingForDepthEstimation(config).eval().save_pretrained(folder)
        DPTImageProcessor(do_resize=True, size={"height": 518, "width": 518}, keep_aspect_ratio=True,
                          ensure_multiple_of=14, resample=3, image_mean=[0.485, 0.456, 0.406],
                          image_std=[0.229, 0.224, 0.225]).save_pretrained(folder)
        model = DepthAnythingModel(folder)
        params = sum(p.numel() for p in model.model.parameters())
        rgb = np.random.default_rng(0).random((816, 1225, 3)).astype(np.float32)
        size = tuple(model.processor(images=(rgb * 255).astype(np.uint8), return_tensors="pt")["pixel_values"].shape)
        model.estimate(rgb)  # warm-up
        times = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            model.estimate(rgb)
            times.append(time.perf_counter() - t0)
    print(f"Depth Anything V2 Small architecture ({params / 1e6:.1f} M parameters), 1225x816 photo, input {size}, "
          f"{args.threads} threads: median {statistics.median(times):.2f} s, min {min(times):.2f} s "
          f"over {args.repeats} runs")


if __name__ == "__main__":
    main()
