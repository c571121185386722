"""Seconds to encode a 90-frame 512x512 export as MP4, GIF and PNG frames (median of 3 runs).

Frames are made beforehand (a smooth, photo-like colour field with fine texture,
panning a little every frame, like a slow camera move), so only encoding and
writing are timed. Run: ``python tests/benchmarks/bench_export.py [--frames 90] [--size 512]``.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import List

import numpy as np

from stylize3d_core.eval.timing import median_time
from stylize3d_core.io.video import write_video


def make_frames(n: int, size: int) -> List[np.ndarray]:
    """``n`` (size, size, 3) uint8 frames of a textured colour field that pans 2 px per frame."""
    rng = np.random.default_rng(0)
    big = size + 2 * n
    yy, xx = np.mgrid[0:size, 0:big].astype(np.float32) / size
    base = np.stack([
        0.5 + 0.4 * np.sin(6 * xx + 2 * yy),
        0.5 + 0.4 * np.sin(4 * yy - 3 * xx + 1.0),
        0.5 + 0.4 * np.cos(5 * xx * yy + 2.0),
    ], axis=-1)  # (size, big, 3)
    base += rng.normal(0, 0.03, base.shape).astype(np.float32)
    base = (np.clip(base, 0, 1) * 255).astype(np.uint8)
    return [np.ascontiguousarray(base[:, 2 * i: 2 * i + size]) for i in range(n)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=90)
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    frames = make_frames(args.frames, args.size)
    print(f"{args.frames} frames of {args.size}x{args.size}, median of {args.repeats} runs")
    with tempfile.TemporaryDirectory() as tmp:
        for label, name in (("MP4 (libx264, quality 8)", "out.mp4"), ("GIF", "out.gif"), ("PNG frames", "frames")):
            seconds = median_time(lambda: write_video(Path(tmp) / name, frames, fps=30), args.repeats)
            out = Path(tmp) / name
            size = sum(p.stat().st_size for p in out.iterdir()) if out.is_dir() else out.stat().st_size
            print(f"{label:26s} {seconds:7.2f} s   ({size / 1e6:.1f} MB)")


if __name__ == "__main__":
    main()
