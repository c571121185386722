"""End to end: photo -> depth -> LDI -> points -> 90-frame video, with peak memory.

Runs each configuration in a fresh subprocess so the peak resident memory
(ru_maxrss) belongs to that run alone. Prints a table; asserts nothing.

    .venv/bin/python benchmarks/bench_pipeline.py [--photo assets/samples/astronaut.jpg]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, sys, time
import numpy as np
from PIL import Image
from stylize3d_core.pipeline import PhotoSpec, RenderJob, run_render
photo, long_side, size, frames, out, fmt, depth = sys.argv[1:8]
img = Image.open(photo).convert("RGB")
s = int(long_side) / max(img.size)
img = img.resize((round(img.size[0] * s), round(img.size[1] * s)), Image.LANCZOS)
src = out + ".input.png"
img.save(src)
t0 = time.perf_counter()
res = run_render(RenderJob(PhotoSpec(src, depth, max_size=int(long_side)), output=out + "." + fmt,
                           size=int(size), frames=int(frames)))
total = time.perf_counter() - t0
from stylize3d_core.eval.timing import peak_rss_gib
print(json.dumps({"pixels": img.size[0] * img.size[1], "points": res.n_points, "total": total,
                  "timings": res.timings, "peak_gib": peak_rss_gib()}))
"""


def run(photo: str, long_side: int, size: int, frames: int, fmt: str, depth: str) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "video")
        r = subprocess.run(
            [sys.executable, "-c", CHILD, photo, str(long_side), str(size), str(frames), out, fmt, depth],
            capture_output=True, text=True, cwd=ROOT, check=False,
        )
        if r.returncode != 0:
            raise SystemExit(f"benchmark child failed:\n{r.stderr}")
        return json.loads(r.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--photo", default=str(ROOT / "assets/samples/astronaut.jpg"))
    ap.add_argument("--depth", default="prior")
    ap.add_argument("--repeats", type=int, default=1)
    args = ap.parse_args()
    print(f"photo {args.photo}, depth {args.depth}; torch threads = cores ({os.cpu_count()})")
    print(f"{'photo px':>10} {'points':>10} {'depth s':>8} {'LDI s':>7} {'points s':>8} "
          f"{'video s':>8} {'frames':>6} {'total s':>8} {'peak GiB':>8}")
    for long_side, size, frames in ((512, 512, 90), (768, 512, 90), (1024, 512, 90)):
        runs = [run(args.photo, long_side, size, frames, "mp4", args.depth) for _ in range(args.repeats)]
        runs.sort(key=lambda r: r["total"])
        r = runs[len(runs) // 2]
        t = r["timings"]
        print(f"{r['pixels']:>10,} {r['points']:>10,} {t['depth']:>8.2f} {t['ldi']:>7.2f} {t['points']:>8.2f} "
              f"{t['render+encode']:>8.2f} {frames:>6} {r['total']:>8.2f} {r['peak_gib']:>8.2f}")


if __name__ == "__main__":
    main()
