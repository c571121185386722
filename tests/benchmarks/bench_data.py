"""Benchmark: training-sample generation (``stylize3d_core.train``) at 128^2 and 160^2.

For each image size and sample kind ("ldi": pseudo views of a photo's LDI, with
prior or random depth; "procedural": ray-cast scenes with true novel views) it
generates ``--samples`` samples and prints the median seconds per sample, the
median number of points, the median share of the time spent on each step (depth,
scene ray casting, LDI, targets, model geometry), the bytes one cached sample
takes on disk, and the projected minutes for 2000 samples at the default mix
(25 % procedural). Torch runs on one thread, as ``build_dataset`` does by default.

Run from the repository root: ``.venv/bin/python -m benchmarks.bench_data [--samples 8]``
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time

import torch

from stylize3d_core.train.cache import save_sample
from stylize3d_core.train.data import DataConfig, make_sample
from stylize3d_core.train.styles import StyleBankConfig, build_style_bank

SIZES = ((128, 128), (160, 160))
STEPS = ("depth", "scene", "ldi", "targets", "geometry")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=8, help="samples per size and kind (medians reported)")
    parser.add_argument("--styles", type=int, default=12, help="style images for the style-bank timing (0: skip)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    make_sample(0, DataConfig(image_size=(64, 64)), seed=99, kind="ldi")  # warm-up (imports, Open3D, caches)
    print(f"{'size':>9} {'kind':>10} {'s/sample':>9} {'points':>7} {'MB/file':>8}  time share per step")
    with tempfile.TemporaryDirectory() as tmp:
        for size in SIZES:
            cfg = DataConfig(image_size=size)
            per_kind = {}
            for kind in ("ldi", "procedural"):
                totals, points, shares, sizes = [], [], {k: [] for k in STEPS}, []
                for i in range(args.samples):
                    t0 = time.perf_counter()
                    s = make_sample(i, cfg, seed=0, kind=kind)
                    totals.append(time.perf_counter() - t0)
                    points.append(s.num_points)
                    for k in STEPS:
                        shares[k].append(s.timings.get(k, 0.0) / s.timings["total"])
                    path = os.path.join(tmp, f"{kind}_{i}.pt")
                    save_sample(path, s)
                    sizes.append(os.path.getsize(path) / 1e6)
                per_kind[kind] = statistics.median(totals)
                share = "  ".join(f"{k} {100 * statistics.median(v):4.1f}%" for k, v in shares.items() if max(v) > 0)
                print(f"{size[0]:>4}x{size[1]:<4} {kind:>10} {per_kind[kind]:9.3f} {int(statistics.median(points)):7d} "
                      f"{statistics.median(sizes):8.2f}  {share}")
            mix = 0.75 * per_kind["ldi"] + 0.25 * per_kind["procedural"]
            print(f"{'':>9} {'mix':>10} {mix:9.3f}  -> 2000 samples in ~{2000 * mix / 60:.1f} min")
        if args.styles > 0:
            t0 = time.perf_counter()
            build_style_bank(os.path.join(tmp, "styles"), args.styles, seed=0, config=StyleBankConfig())
            dt = time.perf_counter() - t0
            print(f"style bank: {args.styles} images of 256^2 (half paintings) in {dt:.1f} s "
                  f"({dt / args.styles:.2f} s per image)")


if __name__ == "__main__":
    main()
