"""Before/after contact sheet of 3D photos seen from the edges of the camera range.

Three steps (the "before" frames come from another checkout's library, e.g. the
main branch before the change, put first on ``PYTHONPATH``)::

    .venv/bin/python tests/benchmarks/clean_sheet.py render --out /tmp/after.npz
    PYTHONPATH=/path/to/main .venv/bin/python tests/benchmarks/clean_sheet.py render --poses /tmp/after.npz --out /tmp/before.npz
    .venv/bin/python tests/benchmarks/clean_sheet.py compose /tmp/before.npz /tmp/after.npz --out docs/clean_contact_sheet.png

``render`` builds each test photo's 3D photo (built-in depth prior) with the
library it imports and renders, with the plain renderer at the photo's size,
the cameras of each row: the ken-burns trajectory's far corner, the default
viewer range's full forward dolly, and a far corner of the range the photo
supports (``Photo3D.camera_range``, right + down + forward). Without
``--poses`` it computes those cameras (this needs the new library); with it,
it reuses another run's. Frames are stored with their hole masks (pixels no
point covered, shown magenta on the sheet's lower half of each tile pair).

Details a 256-px tile cannot show (a silhouette's sub-pixel position, a faint grid on a magnified
surface) need the photo's own size and a magnified crop::

    .venv/bin/python tests/benchmarks/clean_sheet.py render --size 640 --photos coffee,astronaut --out /tmp/after.npz
    PYTHONPATH=/path/to/main .venv/bin/python tests/benchmarks/clean_sheet.py render --size 640 \
        --photos coffee,astronaut --poses /tmp/after.npz --out /tmp/before.npz
    .venv/bin/python tests/benchmarks/clean_sheet.py zoom /tmp/before.npz /tmp/after.npz \
        --crop coffee:0:40,300,100 --crop astronaut:1:60,330,100 --out docs/clean_zoom.png

``zoom`` lays out, per ``--crop photo:column:y,x,size``, the before and after frames' square crop
(column 0-2 as in the sheet, y and x its top-left corner in the frame), magnified 4x (nearest).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
SHEET_PHOTOS = ("astronaut", "rocket", "chelsea", "stereo_motorcycle")
COLUMNS = ("ken-burns corner", "full forward dolly", "photo range corner")
TILE = 256


def _render(args: argparse.Namespace) -> None:
    from photos import estimate_depth, test_photos
    from stylize3d_core.depth.sources import PriorDepth
    from stylize3d_core.geometry.camera import Cameras
    from stylize3d_core.render.plain import PlainRenderer
    from stylize3d_core.render.holes import fill_holes
    from stylize3d_core.render.rasterize import RasterSettings
    from stylize3d_core.render.rasterizer import PointRasterizer
    from stylize3d_core.scene.photo3d import Photo3D, Photo3DSettings

    given = np.load(args.poses) if args.poses else None
    out = {}
    wanted = args.photos.split(",") if args.photos else SHEET_PHOTOS
    for name, rgb in test_photos(args.size):
        if name not in wanted:
            continue
        p3d = Photo3D.build(rgb, estimate_depth(PriorDepth(), rgb), Photo3DSettings())
        if given is not None:
            poses = given[f"{name}/poses"]
        else:
            from bench_holes import full_dolly
            from stylize3d_core.geometry.camera_range import CameraRange, range_corner_poses

            kb = np.eye(4)
            kb[:3, 3] = (0.02, 0.02, 0.05)
            corner = range_corner_poses(p3d.camera_range, p3d.ldi.centre_depth, p3d.ldi.near_depth)[-1]
            poses = np.stack([kb, full_dolly(CameraRange(), p3d.ldi.centre_depth, p3d.ldi.near_depth), corner])
        h, w = p3d.size
        renderer = PlainRenderer(p3d.points)
        frames, holes = [], []
        for T in poses:
            cam = Cameras.create(T, p3d.fov_y_deg)
            if hasattr(renderer, "rasterize"):
                frags = renderer.rasterize(cam, h, w)
            else:  # an older library: the same default raster settings as its PlainRenderer
                frags = PointRasterizer(RasterSettings(h, w))(p3d.points.to_tensors().xyz,
                                                              p3d.points.to_tensors().rgb, cam)
            img = fill_holes(frags.image, frags.hole).clamp(0, 1).permute(1, 2, 0).numpy()
            frames.append(img)
            holes.append(frags.hole.numpy())
        out[f"{name}/poses"] = poses
        out[f"{name}/frames"] = np.stack(frames)
        out[f"{name}/holes"] = np.stack(holes)
        print(f"{name}: {len(p3d.points):,} points, hole share per column "
              + ", ".join(f"{100 * hm.mean():.2f}%" for hm in holes))
    np.savez_compressed(args.out, **out)


def _compose(args: argparse.Namespace) -> None:
    import cv2

    before, after = np.load(args.before), np.load(args.after)
    rows = []
    for name in SHEET_PHOTOS:
        if f"{name}/frames" not in after:
            continue
        tiles = []
        for c in range(len(COLUMNS)):
            for label, run in (("before", before), ("after", after)):
                img = run[f"{name}/frames"][c].copy()
                shown = img.copy()
                shown[run[f"{name}/holes"][c]] = (1.0, 0.0, 1.0)
                h, w = img.shape[:2]
                pair = np.concatenate([img, shown], axis=0)  # frame over its holes
                tile = cv2.resize(pair, (TILE * w // max(h, w), 2 * TILE * h // max(h, w)),
                                  interpolation=cv2.INTER_AREA)
                tile = (np.pad(tile, ((18, 2), (2, 2), (0, 0)), constant_values=1.0) * 255).round()
                tile = np.ascontiguousarray(tile.clip(0, 255).astype(np.uint8))
                cv2.putText(tile, f"{label}: {COLUMNS[c]}", (4, 13), cv2.FONT_HERSHEY_SIMPLEX, 0.38,
                            (0, 0, 0), 1, cv2.LINE_AA)
                tiles.append(tile)
        hmax = max(t.shape[0] for t in tiles)
        tiles = [np.pad(t, ((0, hmax - t.shape[0]), (0, 0), (0, 0)), constant_values=255) for t in tiles]
        rows.append(np.concatenate(tiles, axis=1))
    wmax = max(r.shape[1] for r in rows)
    sheet = np.concatenate([np.pad(r, ((0, 0), (0, wmax - r.shape[1]), (0, 0)), constant_values=255)
                            for r in rows], axis=0)
    cv2.imwrite(args.out, np.ascontiguousarray(sheet[..., ::-1]))
    print(f"wrote {args.out}: {sheet.shape[1]}x{sheet.shape[0]}")


def _zoom(args: argparse.Namespace) -> None:
    import cv2

    before, after = np.load(args.before), np.load(args.after)
    rows = []
    for spec in args.crop:
        name, column, box = spec.split(":")
        y, x, size = (int(v) for v in box.split(","))
        pair = []
        for label, run in (("before", before), ("after", after)):
            crop = run[f"{name}/frames"][int(column)][y:y + size, x:x + size]
            tile = (crop.repeat(4, 0).repeat(4, 1).clip(0, 1) * 255).round().astype(np.uint8)
            tile = np.ascontiguousarray(np.pad(tile, ((20, 4), (4, 4), (0, 0)), constant_values=255))
            cv2.putText(tile, f"{label}: {name}, {COLUMNS[int(column)]}", (6, 15), cv2.FONT_HERSHEY_SIMPLEX, 0.45,
                        (0, 0, 0), 1, cv2.LINE_AA)
            pair.append(tile)
        rows.append(np.concatenate(pair, axis=1))
    wmax = max(r.shape[1] for r in rows)
    sheet = np.concatenate([np.pad(r, ((0, 0), (0, wmax - r.shape[1]), (0, 0)), constant_values=255) for r in rows])
    cv2.imwrite(args.out, np.ascontiguousarray(sheet[..., ::-1]))
    print(f"wrote {args.out}: {sheet.shape[1]}x{sheet.shape[0]}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("render", help="render the sheet's frames with one checkout's library")
    r.add_argument("--poses", help="an earlier run's .npz to take the cameras from")
    r.add_argument("--out", required=True)
    r.add_argument("--size", type=int, default=TILE, help="long side the photos are loaded at (default 256)")
    r.add_argument("--photos", default=None, help="comma-separated test photos (default the sheet's four)")
    c = sub.add_parser("compose", help="lay out a before and an after run side by side")
    c.add_argument("before")
    c.add_argument("after")
    c.add_argument("--out", default=str(ROOT / "docs" / "clean_contact_sheet.png"))
    z = sub.add_parser("zoom", help="magnified crops of a before and an after run side by side")
    z.add_argument("before")
    z.add_argument("after")
    z.add_argument("--crop", action="append", required=True, metavar="PHOTO:COLUMN:Y,X,SIZE")
    z.add_argument("--out", default=str(ROOT / "docs" / "clean_zoom.png"))
    args = parser.parse_args()
    {"render": _render, "compose": _compose, "zoom": _zoom}[args.cmd](args)


if __name__ == "__main__":
    main()
