"""Benchmark: share of hole pixels before hole filling at the extremes of the camera range.

For each test photo (the bundled ``assets/samples/*.jpg`` and a few real photos
from ``skimage.data``) the 3D photo is built with the built-in depth prior at a
long side of ``--size`` and rendered, at the same size, from

* the 18 corners of the viewer's camera range (``geometry/camera_range.py``:
  full yaw + pan left/right, pitch + pan up/down, farthest backward and forward
  dolly), either the default range (``--range default``, the viewer's fixed
  limits) or the part of it the photo supports (``--range photo``,
  ``Photo3D.camera_range``);
* the extremes of the default trajectories (box corners of circle / ken_burns,
  the zoom's and the dolly zoom's forward ends).

It prints, per photo, the point count, the LDI build time, the covered range
scale, the largest hole share over the viewer's corners, at that range's
forward dolly alone, over the trajectories' extremes, and at the *default*
range's full forward dolly (magnification: the screen-door test). Holes are the rasterizer's ``Fragments.hole`` (no point
landed), i.e. what hole filling would have to invent. Timings are rough on a
shared CPU.

Run from the repository root: ``.venv/bin/python tests/benchmarks/bench_holes.py [--size 512] [--range photo]``
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
from pathlib import Path
from typing import List, Tuple

import numpy as np


from stylize3d_core.depth.sources import PriorDepth  # noqa: E402
from stylize3d_core.geometry.camera import Cameras  # noqa: E402
from stylize3d_core.geometry.camera_range import (  # noqa: E402
    CameraRange, clamp_dolly, range_corner_poses, trajectory_extreme_cameras,
)
from stylize3d_core.render.plain import PlainRenderer, PlainRenderSettings, frame_size  # noqa: E402
from stylize3d_core.scene.ldi import LDISettings  # noqa: E402
from stylize3d_core.scene.photo3d import Photo3D, Photo3DSettings  # noqa: E402

from photos import estimate_depth, test_photos  # noqa: E402

def full_dolly(rng: CameraRange, centre_depth: float, near_depth: float) -> np.ndarray:
    """(4, 4) ``cam_to_world`` of the range's full forward dolly (clamped by the near margin)."""
    dz = clamp_dolly(0.0, 0.0, 0.0, 0.0, rng.max_dolly * centre_depth, centre_depth, near_depth, rng)
    T = np.eye(4)
    T[2, 3] = dz
    return T


def hole_shares(p3d: Photo3D, rng: CameraRange, size: int, grow: bool = True,
                depth_tolerance: float = PlainRenderSettings().depth_tolerance,
                stretch: bool = True) -> Tuple[List[float], List[float], float]:
    """Hole share (0..1) at each corner of ``rng``, at each trajectory extreme, and at the
    default range's full forward dolly."""
    H, W = frame_size(p3d.size, size)
    renderer = PlainRenderer(p3d.points, PlainRenderSettings(grow_splats=grow, depth_tolerance=depth_tolerance,
                                                          stretch_splats=stretch))
    ldi = p3d.ldi
    corners = range_corner_poses(rng, ldi.centre_depth, ldi.near_depth)
    viewer = [float(renderer.rasterize(Cameras.create(T, p3d.fov_y_deg), H, W).hole.float().mean())
              for T in corners]
    poses, fovs = trajectory_extreme_cameras(p3d.fov_y_deg)
    traj = [float(renderer.rasterize(Cameras.create(T, f), H, W).hole.float().mean()) for T, f in zip(poses, fovs)]
    T = full_dolly(CameraRange(), ldi.centre_depth, ldi.near_depth)
    dolly = float(renderer.rasterize(Cameras.create(T, p3d.fov_y_deg), H, W).hole.float().mean())
    return viewer, traj, dolly


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=512, help="long side of the photo and of the frames")
    parser.add_argument("--range", choices=("default", "photo"), default="default",
                        help="the viewer's default range, or the part of it each photo supports")
    parser.add_argument("--bilinear", action="store_true", help="bilinear splats (no growth with magnification)")
    parser.add_argument("--no-stretch", action="store_true", help="splats grow with the magnification only")
    parser.add_argument("--photos", default="", help="comma-separated photo names (default: all)")
    parser.add_argument("--depth-tolerance", type=float, default=PlainRenderSettings().depth_tolerance,
                        help="the renderer's z-test band; 1.0 keeps every tap (holes then are pure coverage gaps)")
    parser.add_argument("--ldi", action="append", default=[], metavar="NAME=VALUE",
                        help="an LDISettings field (a Python literal), e.g. --ldi hidden_depth=\"'surface'\"; repeatable")
    args = parser.parse_args()
    only = {n for n in args.photos.split(",") if n}
    ldi_settings = LDISettings()
    for item in args.ldi:
        key, _, value = item.partition("=")
        ldi_settings = dataclasses.replace(ldi_settings, **{key: ast.literal_eval(value)})
    depth_source = PriorDepth()
    print(f"{'photo':>18} {'size':>9} {'points':>9} {'ldi s':>6} {'range':>6} "
          f"{'viewer max %':>12} {'fwd dolly %':>11} {'traj max %':>10} {'full dolly %':>12}")
    worst = 0.0
    for name, rgb in test_photos(args.size):
        if only and name not in only:
            continue
        depth = estimate_depth(depth_source, rgb)
        p3d = Photo3D.build(rgb, depth, Photo3DSettings(ldi=ldi_settings))
        rng = CameraRange() if args.range == "default" else p3d.camera_range
        viewer, traj, dolly = hole_shares(p3d, rng, args.size, grow=not args.bilinear,
                                          depth_tolerance=args.depth_tolerance, stretch=not args.no_stretch)
        # corners alternate backward / forward dolly; the 9th pair is the straight dolly
        fwd = viewer[9] if len(viewer) > 9 else float("nan")
        scale = getattr(p3d.ldi, "range_scale", 1.0) if args.range == "photo" else 1.0
        worst = max(worst, max(viewer), max(traj), dolly)
        h, w = p3d.size
        print(f"{name:>18} {w:>4}x{h:<4} {len(p3d.points):>9,} {p3d.timings['ldi']:6.2f} {scale:6.2f} "
              f"{100 * max(viewer):12.3f} {100 * fwd:11.3f} {100 * max(traj):10.3f} {100 * dolly:12.3f}")
    print(f"worst hole share: {100 * worst:.3f} %")


if __name__ == "__main__":
    main()
