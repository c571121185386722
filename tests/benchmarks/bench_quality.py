"""The quality measurement the model is steered by: style, sharpness, consistency, held-out stage-1 PSNR.

Runs ``stylize3d_core.bench.quality.run_quality`` (what ``stylize3d bench quality``
runs) with a strength and a thread count of your choice: 4 photos x 4 styles (2
photos and 2 styles never seen in training), the plain 3D photo, ours, the
per-frame 2D network and stylize-then-bake on the same cameras. Writes
``quality.md``, ``quality.json`` and the contact sheets to ``--out``
(docs/quality.md explains every figure).

    .venv/bin/python tests/benchmarks/bench_quality.py [--quick] --out DIR [--model CKPT]
                                                 [--eval-data runs/data/eval] [--strength 1] [--threads 2]
                                                 [--photos chelsea,stereo_motorcycle] [--styles NAME,...]

``--quick`` takes a few minutes on 2 cores, the full preset (30 frames at 384 px) about 20.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[2]

from stylize3d_core.bench.quality import run_quality  # noqa: E402
from stylize3d_core.bench.report import markdown_table  # noqa: E402
from stylize3d_core.eval.quality import QUALITY_PHOTOS, QUALITY_STYLES  # noqa: E402


def _pick(items, names, option):
    """The items of the set named in the comma-separated ``names`` (all for None)."""
    if names is None:
        return None
    by_name = {i.name: i for i in items}
    wanted = [n.strip() for n in names.split(",") if n.strip()]
    unknown = [n for n in wanted if n not in by_name]
    if unknown or not wanted:
        raise SystemExit(f"{option}: unknown {', '.join(unknown) or '(none given)'}; choose from {', '.join(by_name)}")
    return tuple(by_name[n] for n in wanted)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, help="folder for quality.md / .json and the contact sheets")
    ap.add_argument("--quick", action="store_true", help="the small preset (a few minutes)")
    ap.add_argument("--model", default=None, help="checkpoint to measure (default the shipped model)")
    ap.add_argument("--eval-data", default=None, help="held-out dataset folder (stage-1 PSNR / SSIM; skipped without)")
    ap.add_argument("--strength", type=float, default=None, help="our style strength (default the library's, 1)")
    ap.add_argument("--threads", type=int, default=2, help="torch CPU threads (default 2)")
    ap.add_argument("--photos", default=None, help="comma-separated photos of the set to measure (default all: "
                    + ",".join(p.name for p in QUALITY_PHOTOS) + ")")
    ap.add_argument("--styles", default=None, help="comma-separated styles of the set to measure (default all: "
                    + ",".join(s.name for s in QUALITY_STYLES) + ")")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    photos = _pick(QUALITY_PHOTOS, args.photos, "--photos")
    styles = _pick(QUALITY_STYLES, args.styles, "--styles")
    rows = run_quality(Path(args.out), quick=args.quick, show_progress=True,
                       log=lambda m: print(m, file=sys.stderr, flush=True), model=args.model,
                       eval_data=args.eval_data, strength=args.strength, photos=photos, styles=styles)
    held = [r for r in rows if r["pairs"] == "held-out"]
    print(markdown_table(held or rows, list((held or rows)[0].keys()), digits=3))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
