"""The export default's point budget against every point: an A/B of full frames, interleaved over many rounds.

``bench speed`` times each knob in 3 rounds; on a busy machine that leaves speed-ups under ~1.6x in the
noise. This script times only the reference (every point) and the point budgets of final frames
(``StylizeSettings.final_points_per_pixel``, the same prefix of the point order as a preview's) on the
targets' case (the sample at 1 MP, 512-pixel frames, 3 cameras), ``--rounds`` interleaved rounds, and
prints the median ms per frame, the ratio of each round's times (its median and range) and the PSNR.

    .venv/bin/python tests/benchmarks/bench_point_budget.py [--rounds 8] [--budgets 6,3]
"""

from __future__ import annotations

import argparse
import os
import statistics


from stylize3d_core.bench.speed import FULL, Variant, measure_variants, psnr, speed_scene  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=8)
    ap.add_argument("--budgets", default="6,3", help="points per pixel, comma-separated")
    args = ap.parse_args()
    budgets = [float(b) for b in args.budgets.split(",")]
    scene = speed_scene(FULL)
    vs = [Variant("every point", "reference")] + [Variant(f"{b:g} points per pixel", "point budget",
                                                          preview_points_per_pixel=b) for b in budgets]
    results = measure_variants(scene, vs, args.rounds, warmup=0, per_round=True)
    ref_frames, _, _, ref_times = results[0]
    H, W = scene.frame
    print(f"photo {scene.photo3d.size[1]}x{scene.photo3d.size[0]} ({len(scene.photo3d.points):,} points), frames "
          f"{W}x{H}, {len(scene.cameras)} cameras, {args.rounds} interleaved rounds; load {os.getloadavg()[0]:.1f}")
    for v, (frames, per_frame, _, times) in zip(vs, results):
        ratios = sorted(r / t for r, t in zip(ref_times, times))
        db = min(psnr(f, r) for f, r in zip(frames, ref_frames))
        print(f"  {v.name:<22} {1000 * per_frame:8.0f} ms/frame   speed-up {statistics.median(ratios):.2f}x "
              f"(rounds {ratios[0]:.2f}-{ratios[-1]:.2f})   worst PSNR {db:.1f} dB")


if __name__ == "__main__":
    main()
