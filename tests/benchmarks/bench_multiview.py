"""Multi-view input (paper Sec. 4.4) on procedural scenes: held-out PSNR and consistency across views.

For each seed, a random textured scene is ray-cast from three poses (exact
depth) and a held-out pose (``stylize3d_core/eval/multiview.py``). Prints

(a) PSNR of the held-out view rendered (plain) from the merged cloud and from
    each view's own 3D photo, over the whole image and over the pixels some
    input view saw (``observed_mask``);
(b) consistency RMSE (``eval/consistency.py``, all ordered pairs of the three
    input poses and the held-out pose, warped through the merged cloud) of
    the plain merged renders, of the stylized merged renders, and of each
    view stylized on its own (its own 3D photo, rendered at the four poses);
    the shipped lite model and a shipped style.

    .venv/bin/python tests/benchmarks/bench_multiview.py [--seeds 3 5 7] [--model M] [--style S]
"""

from __future__ import annotations

import argparse
import itertools
from pathlib import Path

import numpy as np

from stylize3d_core.eval.consistency import consistency_metrics
from stylize3d_core.eval.multiview import held_out_psnr, observed_mask, procedural_views
from stylize3d_core.geometry.camera import Cameras
from stylize3d_core.io.images import load_image
from stylize3d_core.models.checkpoint import load_checkpoint
from stylize3d_core.pipeline import DEFAULT_MODEL
from stylize3d_core.render.plain import PlainRenderer
from stylize3d_core.scene.multiview import merge_views, pose_in_view
from stylize3d_core.scene.photo3d import Photo3D, Photo3DSettings
from stylize3d_core.stylize import Stylized3DPhoto, StylizeSettings

ROOT = Path(__file__).resolve().parents[2]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[3, 5, 7])
    ap.add_argument("--model", default=DEFAULT_MODEL)
    ap.add_argument("--style", default=str(ROOT / "assets/styles/painting_style03_coffee.jpg"))
    args = ap.parse_args()
    ck = load_checkpoint(args.model)
    style = load_image(args.style, max_size=512).rgb
    for seed in args.seeds:
        data = procedural_views(seed)
        scores = held_out_psnr(data)
        print(f"seed {seed}: held-out PSNR  " + "  ".join(f"{k} {v:.2f} dB" for k, v in scores.items()))
        seen = held_out_psnr(data, observed_only=True)
        print(f"seed {seed}: observed pixels ({observed_mask(data).mean():.1%}) PSNR  "
              + "  ".join(f"{k} {v:.2f} dB" for k, v in seen.items()))
        merged = merge_views(data.views, 0).photo
        h, w = data.held_out_rgb.shape[:2]
        world = [v.cam_to_world for v in data.views] + [data.held_out_pose]
        pairs = [p for p in itertools.permutations(range(len(world)), 2)]
        cams = Cameras.create(np.stack([pose_in_view(p, data.views[0], merged.ldi.depth_scale) for p in world]),
                              merged.fov_y_deg)
        plain = [PlainRenderer(merged.points).render(cams[i], h, w) for i in range(len(cams))]
        styl = Stylized3DPhoto(merged, ck, StylizeSettings(strength=1.0))
        styl.set_style(style)
        stylized = [styl.render(cams[i], h, w) for i in range(len(cams))]
        rows = {"plain merged": plain, "stylized merged": stylized}
        per_view = []
        for i, v in enumerate(data.views):  # each view stylized alone, each frame from the view that is nearest
            single = Photo3D.build(v.rgb, v.depth, Photo3DSettings(fov_y_deg=v.fov_y_deg))
            s = Stylized3DPhoto(single, ck, StylizeSettings(strength=1.0))
            s.set_style(style)
            k = i if i < len(data.views) else 0
            per_view.append(s.render(Cameras.create(pose_in_view(world[k], v, single.ldi.depth_scale),
                                                    v.fov_y_deg), h, w))
        held_single = Photo3D.build(data.views[0].rgb, data.views[0].depth, Photo3DSettings(fov_y_deg=55.0))
        s0 = Stylized3DPhoto(held_single, ck, StylizeSettings(strength=1.0))
        s0.set_style(style)
        per_view.append(s0.render(Cameras.create(pose_in_view(world[-1], data.views[0],
                                                              held_single.ldi.depth_scale), 55.0), h, w))
        rows["stylized per view"] = per_view
        for name, frames in rows.items():
            r = consistency_metrics(merged.points.xyz, frames, cams, pairs)
            print(f"seed {seed}: consistency {name:18s} RMSE {r.rmse:.4f}  feature distance {r.feature_distance:.4f}")


if __name__ == "__main__":
    main()
