"""Benchmark of the point rasterizer (stylize3d_core.render.rasterize).

Run from the repository root:  .venv/bin/python tests/benchmarks/bench_rasterizer.py [--quick]

Prints the median and the minimum over several runs, in ms, at three sizes with
the same density (75k x 64 -> 256^2, 300k x 64 -> 512^2, 1.2M x 64 -> 1024^2), under
``torch.inference_mode`` and with autograd (forward + backward to the
features), plus supersample=2 at 512^2, and the time per point relative to the
smallest size (about 1.0 everywhere means linear scaling); then the push-pull
hole filling of a 3-channel 512^2 frame. Target: 300k x 64 ->
512^2 in <= 100 ms (inference) on the 2-core CPU. The last column is the
interruptible inference (``should_stop=``, as the viewer's full frames): the
same result in steps of ``CHUNK_POINTS`` points.

The scenes look like a layered depth image seen from a slightly moved camera:
~85 % of the points are a jittered, wavy front surface in raster order (as the
LDI produces them) covering the view and a margin, the rest a background layer
behind it, and a few are behind the camera. ``--random-order`` shuffles the
points instead (worst case for memory locality).
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import torch


from stylize3d_core.eval.timing import median_and_min  # noqa: E402
from stylize3d_core.geometry.camera import intrinsics_from_fov  # noqa: E402
from stylize3d_core.render.holes import fill_holes  # noqa: E402
from stylize3d_core.render.rasterize import RasterSettings, rasterize_points  # noqa: E402

CHANNELS = 64
SIZES = ((75_000, 256), (300_000, 512), (1_200_000, 1024))


def make_scene(n: int, side: int, random_order: bool, seed: int = 0):
    """Points (n, 3), features (n, C) and K (3, 3) for a side x side view."""
    g = torch.Generator().manual_seed(seed)
    K = intrinsics_from_fov(60.0, side, side)
    f = float(K[0, 0])
    n_front = int(n * 0.85)
    n_back = n - n_front
    cols = int(math.sqrt(n_front))
    rows = n_front // cols
    n_front = rows * cols
    n_back = n - n_front
    margin = 0.04 * side
    v, u = torch.meshgrid(torch.linspace(-margin, side + margin, rows),
                          torch.linspace(-margin, side + margin, cols), indexing="ij")
    u, v = u.reshape(-1), v.reshape(-1)
    z = 1.0 + 0.3 * torch.sin(u / side * 9.0) * torch.cos(v / side * 7.0)
    ub = torch.rand(n_back, generator=g) * side
    vb = torch.rand(n_back, generator=g) * side
    order = torch.argsort(vb.floor() * side + ub)
    ub, vb = ub[order], vb[order]
    zb = 2.5 + torch.rand(n_back, generator=g)
    u = torch.cat([u, ub]) + 0.3 * torch.randn(n, generator=g)
    v = torch.cat([v, vb]) + 0.3 * torch.randn(n, generator=g)
    z = torch.cat([z, zb])
    z[:: 997] = -1.0  # a few points behind the camera
    pts = torch.stack([(u - side / 2) / f * z, (v - side / 2) / f * z, z], dim=1)
    feats = torch.randn(n, CHANNELS, generator=g)
    if random_order:
        perm = torch.randperm(n, generator=g)
        pts, feats = pts[perm], feats[perm]
    return pts, feats, K


def make_case(n: int, side: int, supersample: int, random_order: bool):
    """Two closures: inference (inference_mode) and training (forward + backward)."""
    pts, feats, K = make_scene(n, side, random_order)
    settings = RasterSettings(side, side, supersample=supersample)
    feats_g = feats.clone().requires_grad_(True)

    def infer():
        with torch.inference_mode():
            rasterize_points(pts, feats, K, settings)

    def chunked():  # as the viewer's full frames: interruptible, checked between chunks of points
        with torch.inference_mode():
            rasterize_points(pts, feats, K, settings, should_stop=lambda: False)

    def train():
        frag = rasterize_points(pts, feats_g, K, settings)
        frag.image.sum().backward()
        feats_g.grad = None

    return infer, train, chunked


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=9, help="timed runs per case (median reported)")
    parser.add_argument("--quick", action="store_true", help="skip the 1024^2 size")
    parser.add_argument("--random-order", action="store_true", help="shuffle the points")
    args = parser.parse_args()
    sizes = SIZES[:2] if args.quick else SIZES
    specs = [(n, s, 1) for n, s in sizes] + [(300_000, 512, 2)]
    cases = [make_case(n, s, ss, args.random_order) for n, s, ss in specs]
    # Round-robin over the cases, so that a burst of load from other processes
    # spreads over all of them; two warm-up rounds (allocator, thread pool).
    times = [([], [], []) for _ in cases]
    for r in range(args.runs + 2):
        for (infer, train, chunked), (t_inf, t_train, t_chunk) in zip(cases, times):
            for fn, out in ((infer, t_inf), (train, t_train), (chunked, t_chunk)):
                t = time.perf_counter()
                fn()
                if r >= 2:
                    out.append(1e3 * (time.perf_counter() - t))
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads, C = {CHANNELS}, "
          f"{args.runs} runs, {'random' if args.random_order else 'LDI (raster)'} point order")
    print(f"{'case':34s} {'inference ms':>16s} {'fwd+bwd ms':>16s} {'ns/pt':>6s} {'rel':>5s} {'chunked ms':>16s}")
    print(f"{'':34s} {'median   min':>16s} {'median   min':>16s} {'':12s} {'median   min':>16s}")
    base = None
    for (n, side, ss), (t_inf, t_train, t_chunk) in zip(specs, times):
        med = statistics.median(t_inf)
        per_pt = min(t_inf) * 1e6 / n
        base = base or per_pt
        label = f"{n // 1000}k x {CHANNELS} -> {side}^2" + (" (supersample 2)" if ss == 2 else "")
        print(f"{label:34s} {med:8.1f} {min(t_inf):7.1f} {statistics.median(t_train):8.1f} {min(t_train):7.1f}"
              f" {per_pt:6.0f} {per_pt / base:5.2f} {statistics.median(t_chunk):8.1f} {min(t_chunk):7.1f}")
    print("ns/pt, rel: minimum inference time per point, and relative to the first row (1.0 = linear).")
    print("chunked: inference with should_stop (the viewer's interruptible full frames: steps of "
          "CHUNK_POINTS points, the same result).")
    print("On a machine shared with other jobs the minimum is the better estimate of the cost.")

    # Hole filling of a plain 3D photo frame (3 channels) rendered at 512^2.
    pts, feats, K = make_scene(300_000, 512, args.random_order)
    with torch.inference_mode():
        frag = rasterize_points(pts, feats[:, :3].contiguous(), K, RasterSettings(512, 512))
        image = frag.image.contiguous()
        extra = torch.rand(512, 512, generator=torch.Generator().manual_seed(1)) < 0.05
        hole = frag.hole | extra  # a few more holes than this dense scene has
        fill_med, fill_min = median_and_min(lambda: fill_holes(image, hole), args.runs, warmup=2)
    print(f"{'fill_holes 3 x 512^2':34s} {1e3 * fill_med:8.1f} {1e3 * fill_min:7.1f}"
          f"   ({int(hole.sum())} holes)")


if __name__ == "__main__":
    main()
