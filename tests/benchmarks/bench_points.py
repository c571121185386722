"""Benchmark of the point operations and the encoder at several cloud sizes.

Prints, per size N (points of a synthetic photo-like cloud in NDC: a pixel grid
over a bumpy surface with a depth step, plus a 10 % background layer behind it,
as a layered depth image gives):

* FPS N -> N/4 (fpsample bucket FPS);
* ball query, k = 16, r = 0.015, all N points among all N (the stem's, the
  largest search), by the chosen method (k-NN + radius mask, on the grid search
  ``points.neighbours.GridKNN``; also on Open3D's k-d tree, ``BACKEND`` "open3d") and by the
  alternatives: scipy's cKDTree (if installed) and Open3D's ``hybrid_search``
  (only up to ``--hybrid-max`` points: it is far slower);
* three_nn: all N points from the N/16 encoder output points;
* build_hierarchy (all FPS + ball queries of the encoder) and the encoder forward
  pass (paper and lite widths) under ``torch.inference_mode``.

Median of ``--repeats`` runs (one run for the slow alternatives). No timing is
asserted; compare figures only across runs on the same machine.

Run from the repository root:
``.venv/bin/python -m benchmarks.bench_points [--sizes 75000 300000 1000000] [--repeats 3]``
"""

from __future__ import annotations

import argparse

import numpy as np
import torch

from stylize3d_core.eval.timing import median_time, peak_rss_gib
from stylize3d_core.models.encoder import Encoder, EncoderConfig
from stylize3d_core.models.scene_geometry import NeighbourhoodConfig, build_hierarchy
from stylize3d_core.points import ball_query, farthest_point_sample, three_nn
from stylize3d_core.points import neighbours


def photo_cloud(n_points: int, seed: int = 0) -> torch.Tensor:
    """(n_points, 3) NDC cloud of a 4:3 photo: 90 % front surface, 10 % background layer."""
    rng = np.random.default_rng(seed)
    n_front = int(round(n_points * 0.9))
    h = int(round((n_front * 3 / 4) ** 0.5))
    w = n_front // h
    ys, xs = np.meshgrid((np.arange(h) + 0.5) / h * 2 - 1, (np.arange(w) + 0.5) / w * 2 - 1, indexing="ij")
    x, y = xs.ravel(), ys.ravel()
    z = 0.2 * np.sin(3 * x) * np.cos(2 * y) + 0.6 * (x > 0.3) - 0.3
    front = np.stack([x, y, z], 1)
    # background layer: pixels near the depth edge, pushed back
    n_back = n_points - len(front)
    pick = rng.choice(len(front), n_back, replace=n_back > len(front))
    back = front[pick] + np.array([0.0, 0.0, 0.5])
    return torch.from_numpy(np.concatenate([front, back]).astype(np.float32))


def bench_scipy(xyz: torch.Tensor, radius: float, k: int) -> float:
    from scipy.spatial import cKDTree

    pts = xyz.numpy()

    def run() -> None:
        tree = cKDTree(pts)
        tree.query(pts, k=k, distance_upper_bound=radius, workers=-1)

    return median_time(run, 1)


def bench_hybrid(xyz: torch.Tensor, radius: float, k: int) -> float:
    import open3d.core as o3c

    pts = o3c.Tensor(xyz.numpy())

    def run() -> None:
        nns = o3c.nns.NearestNeighborSearch(pts)
        nns.hybrid_index(radius)
        nns.hybrid_search(pts, radius, k)

    return median_time(run, 1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[75_000, 300_000, 1_000_000])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--hybrid-max", type=int, default=75_000, help="largest N for Open3D hybrid_search")
    parser.add_argument("--no-alternatives", action="store_true", help="skip scipy / hybrid_search")
    parser.add_argument("--threads", type=int, default=0, help="torch threads (default: torch's choice)")
    args = parser.parse_args()
    if args.threads > 0:
        torch.set_num_threads(args.threads)

    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads; median of {args.repeats} runs, seconds")
    hood = NeighbourhoodConfig()
    enc, enc_lite = Encoder(EncoderConfig.paper()).eval(), Encoder(EncoderConfig.lite()).eval()
    ball_query(torch.rand(10, 3), torch.rand(10, 3), 0.1, 4)  # import Open3D outside the timings
    for n in args.sizes:
        xyz = photo_cloud(n)
        rgb = torch.rand(n, 3)
        r, k = hood.stem_radius, hood.k
        t_fps = median_time(lambda: farthest_point_sample(xyz, n // 4), args.repeats)
        sparse = xyz[farthest_point_sample(xyz, max(1, n // 16))]
        t_bq, t_3nn = {}, {}
        default = neighbours.BACKEND
        for backend in neighbours.BACKENDS:
            neighbours.BACKEND = backend
            t_bq[backend] = median_time(lambda: ball_query(xyz, xyz, r, k), args.repeats)
            t_3nn[backend] = median_time(lambda: three_nn(xyz, sparse), args.repeats)
        neighbours.BACKEND = default
        fill = float(ball_query(xyz, xyz, r, k).count.float().mean())
        t_build = median_time(lambda: build_hierarchy(xyz, hood), args.repeats)
        hier = build_hierarchy(xyz, hood)
        with torch.inference_mode():
            t_enc = median_time(lambda: enc(rgb, hier), args.repeats)
            t_lite = median_time(lambda: enc_lite(rgb, hier), args.repeats)
        print(f"\nN = {n:,} (levels {hier.num_points})")
        print(f"  FPS N -> N/4                   {t_fps:7.3f}")
        print(f"  ball query N x N, r={r}, k={k} {t_bq['grid']:7.3f}   (grid k-NN + mask; mean fill {fill:.1f}/{k}); "
              f"on Open3D's k-d tree {t_bq['open3d']:.3f}")
        if not args.no_alternatives:
            try:
                print(f"    alternative: scipy cKDTree   {bench_scipy(xyz, r, k):7.3f}")
            except ImportError:
                print("    alternative: scipy cKDTree   (scipy not installed)")
            if n <= args.hybrid_max:
                print(f"    alternative: O3D hybrid      {bench_hybrid(xyz, r, k):7.3f}")
        print(f"  three_nn N from N/16           {t_3nn['grid']:7.3f}   (grid); on Open3D's k-d tree {t_3nn['open3d']:.3f}")
        print(f"  build_hierarchy (all levels)   {t_build:7.3f}")
        print(f"  encoder forward, paper         {t_enc:7.3f}")
        print(f"  encoder forward, lite          {t_lite:7.3f}")
    peak = peak_rss_gib()
    print(f"\npeak RSS {peak:.2f} GiB")


if __name__ == "__main__":
    main()
