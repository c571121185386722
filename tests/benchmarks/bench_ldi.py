"""Benchmark: layered depth image + point cloud build time at three photo sizes.

Prints the median build time of :func:`build_ldi` (and of :func:`ldi_to_points`)
for a depth map with discontinuities (a disc and a box in front of a slanted
wall: edges, islands, hidden layer) and for a discontinuity-free one (the same
wall alone: the hidden-layer step is skipped), with the number of points, the
widest hidden layer, the border and the covered fraction of the camera range
(all sized for the default camera range and trajectories). Then, for the 1 MP
photo with edges, the same figures for parts of the camera range (scaled by 0,
0.02, 0.04 and 0.08, trajectories not covered): the points grow with the range the
LDI must cover, not with a fixed band.

Run from the repository root: ``.venv/bin/python -m benchmarks.bench_ldi [--repeats 5]``
"""

from __future__ import annotations

import argparse
from typing import Tuple

import cv2
import numpy as np

from stylize3d_core.eval.timing import median_time
from stylize3d_core.geometry.camera_range import CameraRange
from stylize3d_core.scene.ldi import LDISettings, build_ldi
from stylize3d_core.scene.pointcloud import ldi_to_points

SIZES = ((512, 512), (768, 640), (1024, 1024))
"""(H, W) of the benchmarked photos: ~0.26, 0.49 and 1.05 MP."""


def synthetic_photo(h: int, w: int, edges: bool) -> Tuple[np.ndarray, np.ndarray]:
    """A textured photo (H, W, 3) and a depth map (H, W): slanted wall, optionally objects."""
    rng = np.random.default_rng(0)
    noise = rng.random((h // 8 + 1, w // 8 + 1, 3)).astype(np.float32)
    rgb = cv2.resize(noise, (w, h), interpolation=cv2.INTER_CUBIC).clip(0.0, 1.0)  # (H, W, 3)
    rows = np.linspace(0.0, 1.0, h, dtype=np.float32)[:, None]
    depth = np.broadcast_to(4.0 - 2.0 * rows, (h, w)).astype(np.float32).copy()  # (H, W)
    if edges:
        disc = np.zeros((h, w), np.uint8)
        cv2.circle(disc, (w // 3, h // 2), min(h, w) // 5, 1, -1)
        depth[disc > 0] = 1.0
        depth[h // 5 : h // 2, 2 * w // 3 : 5 * w // 6] = 1.5
        speck = rng.integers(0, min(h, w) - 3, size=(20, 2))
        for i, j in speck:  # tiny floating islands, flattened by build_ldi
            depth[i : i + 2, j : j + 2] = 0.8
    return rgb, depth


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="runs per measurement (median reported)")
    args = parser.parse_args()
    print(f"{'size':>11} {'MP':>5} {'depth':>14} {'build_ldi s':>12} {'to_points s':>12} "
          f"{'inpainted':>9} {'hidden px':>10} {'points':>10} {'width px':>8} {'pad':>4} {'range':>5}")
    for h, w in SIZES:
        for edges in (True, False):
            rgb, depth = synthetic_photo(h, w, edges)
            t_ldi = median_time(lambda: build_ldi(rgb, depth), args.repeats, warmup=1)
            ldi = build_ldi(rgb, depth)
            t_pts = median_time(lambda: ldi_to_points(ldi, 60.0), args.repeats)
            n = len(ldi_to_points(ldi, 60.0))
            kind = "discontinuous" if edges else "smooth"
            print(f"{h:>5}x{w:<5} {h * w / 1e6:5.2f} {kind:>14} {t_ldi:12.3f} {t_pts:12.3f} "
                  f"{str(ldi.inpainted):>9} {int(ldi.hidden_mask.sum()):>10} {n:>10} "
                  f"{ldi.hidden_width:8.1f} {ldi.pad:>4} {ldi.range_scale:5.2f}")
    h, w = SIZES[-1]
    rgb, depth = synthetic_photo(h, w, True)
    print(f"\n{h}x{w} with edges, sized for a part of the camera range only (no trajectories):")
    print(f"{'range part':>10} {'build_ldi s':>12} {'hidden px':>10} {'points':>10} {'width px':>8} {'pad':>4} {'covered':>7}")
    for part in (0.0, 0.02, 0.04, 0.08):
        settings = LDISettings(camera_range=CameraRange().scaled(part), cover_trajectories=False)
        t_ldi = median_time(lambda: build_ldi(rgb, depth, settings), args.repeats, warmup=1)
        ldi = build_ldi(rgb, depth, settings)
        print(f"{part:>10.2f} {t_ldi:12.3f} {int(ldi.hidden_mask.sum()):>10} {ldi.num_points:>10} "
              f"{ldi.hidden_width:8.1f} {ldi.pad:>4} {ldi.range_scale * part:7.3f}")


if __name__ == "__main__":
    main()
