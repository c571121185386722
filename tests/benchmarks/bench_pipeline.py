"""End to end: photo -> depth -> LDI -> points -> 90-frame video, with peak memory.

Runs each configuration in a fresh subprocess so the peak resident memory
(ru_maxrss) belongs to that run alone. Prints a table; asserts nothing.

    .venv/bin/python tests/benchmarks/bench_pipeline.py [--photo assets/samples/astronaut.jpg]

``--first-frame`` times instead what ``stylize3d bench targets`` calls the first frame (photo file + style
image -> the first stylized 512-pixel frame of a photo resized to ``--megapixels``, model and style CNN
loaded beforehand), stage by stage (and the process's CPU time, all threads, steadier under load), ``--repeats`` fresh processes; with ``--baseline ROOT`` (another
checkout, e.g. ``git worktree add /tmp/before <commit>``, whose ``stylize3d_core/bench/targets.py``
takes the model argument: copy this one's) the two checkouts alternate, run for run, and the table
adds the before / after ratio of the medians, so a burst of load on a shared machine hits both.

    .venv/bin/python tests/benchmarks/bench_pipeline.py --first-frame --repeats 3 --baseline /tmp/before
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

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


def first_frame(root: Path, megapixels: float, model: str) -> dict:
    """One fresh process of ``root``'s ``bench targets`` first-frame measurement (no video)."""
    env = {**os.environ, "PYTHONPATH": str(root)}
    r = subprocess.run([sys.executable, "-m", "stylize3d_core.bench.targets", str(megapixels), "512", "256", "0",
                        "0", "", model], capture_output=True, text=True, cwd=root, env=env, check=False)
    if r.returncode != 0:
        raise SystemExit(f"benchmark child failed ({root}):\n{r.stderr[-3000:]}")
    out = json.loads(r.stdout.strip().splitlines()[-1])
    return {"first frame": out["first_frame_s"], "cpu": out["first_frame_cpu_s"], **out["stages"],
            "points": out["points"]}


def main_first_frame(args: argparse.Namespace) -> None:
    import statistics

    roots = [("after", ROOT)] + ([("before", Path(args.baseline).resolve())] if args.baseline else [])
    runs = {name: [] for name, _ in roots}
    for _ in range(args.repeats):
        for name, root in roots:
            runs[name].append(first_frame(root, args.megapixels, args.model))
    rows = [k for k in runs["after"][0] if k != "points"]
    print(f"first stylized frame, {args.megapixels:g} MP photo ({runs['after'][0]['points']:,} points), "
          f"medians of {args.repeats} fresh processes (seconds); load average {os.getloadavg()[0]:.1f} at the end")
    head = f"{'stage':>12}" + "".join(f" {name:>8}" for name, _ in roots) + (f" {'ratio':>7}" if args.baseline else "")
    print(head)
    for k in rows:
        med = {name: statistics.median(r[k] for r in runs[name]) for name, _ in roots}
        line = f"{k:>12}" + "".join(f" {med[name]:>8.2f}" for name, _ in roots)
        if args.baseline:
            line += f" {med['before'] / max(med['after'], 1e-9):>6.2f}x"
        print(line)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--first-frame", action="store_true", help="time bench targets' first frame, stage by stage")
    ap.add_argument("--megapixels", type=float, default=1.0, help="--first-frame: photo size")
    ap.add_argument("--model", default="", help="--first-frame: checkpoint name or path (default: the shipped one)")
    ap.add_argument("--baseline", default=None, help="--first-frame: another checkout's root, timed interleaved")
    ap.add_argument("--photo", default=str(ROOT / "assets/samples/astronaut.jpg"))
    ap.add_argument("--depth", default="prior")
    ap.add_argument("--repeats", type=int, default=1)
    args = ap.parse_args()
    if args.first_frame:
        return main_first_frame(args)
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
