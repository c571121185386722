"""The analytic scenes' disoccluded PSNR against truths ray-cast with more rays per pixel.

``tests/scene/test_novel_view_scenes.py`` ray-casts the photo and the truth with 3 x 3 rays per pixel:
a truth pixel's coverage of a sharp silhouette is then quantised to thirds, and on the disoccluded
strips beside a moved silhouette (a few pixels wide) that quantisation is a large part of the error.
This prints the same figures with the photo at ``--photo-samples`` and the truth at each of
``--truth-samples`` rays per pixel side (8 x 8 is within ~1/16 of the exact coverage).

    .venv/bin/python tests/benchmarks/bench_scene_truth.py [--photo-samples 3] [--truth-samples 3 6 8]
"""

from __future__ import annotations

import argparse
import importlib.util
import math
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def _load_test_module(path: Path):
    """The test module at ``path`` (its scenes, moves and camera), loaded by file: tests are no package."""
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


scenes = _load_test_module(ROOT / "tests" / "scene" / "test_novel_view_scenes.py")

from stylize3d_core.depth.types import DepthMap  # noqa: E402
from stylize3d_core.geometry.camera import NEAR_DEPTH  # noqa: E402
from stylize3d_core.render.plain import PlainRenderer  # noqa: E402
from stylize3d_core.scene.photo3d import Photo3D, Photo3DSettings  # noqa: E402
from stylize3d_core.train.procedural import ray_cast  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--photo-samples", type=int, default=3)
    ap.add_argument("--truth-samples", type=int, nargs="+", default=[3, 6, 8])
    args = ap.parse_args()
    H, W, fov = scenes.H, scenes.W, scenes.FOV
    print(f"disoccluded PSNR (dB); photo ray-cast at {args.photo_samples}x{args.photo_samples} rays per pixel")
    print(f"{'scene':18s} {'move':18s} " + " ".join(f"truth {s}x{s}".rjust(11) for s in args.truth_samples))
    for name, make in scenes.SCENES.items():
        scene = make()
        first = ray_cast(scene, scenes.camera((0, 0, 0)), H, W, samples=1)
        scene = scene.scaled(NEAR_DEPTH / float(np.percentile(first.depth, 1.0)))
        photo = ray_cast(scene, scenes.camera((0, 0, 0)), H, W, samples=args.photo_samples)
        dm = DepthMap(photo.depth.astype(np.float32), np.ones((H, W), bool), "metric", "analytic")
        renderer = PlainRenderer(Photo3D.build(photo.rgb, dm, Photo3DSettings(fov_y_deg=fov)).points)
        for move, t in scenes.MOVES.items():
            got = renderer.render(scenes.camera(t), H, W)
            row = []
            for samples in args.truth_samples:
                truth = ray_cast(scene, scenes.camera(t), H, W, samples=samples)
                _, hidden, _ = scenes.regions(scene, truth)
                row.append(scenes.psnr(got[hidden], truth.rgb[hidden]) if hidden.mean() > 5e-4 else math.nan)
            print(f"{name:18s} {move:18s} " + " ".join(f"{p:11.2f}" for p in row), flush=True)


if __name__ == "__main__":
    main()
