"""Generate the inputs of the four applications, and (optionally) the figures of docs/applications.md.

    .venv/bin/python tools/make_application_samples.py --out samples/ [--figures docs/images]

Writes to ``--out``:

* ``stereo_card.png``: a synthetic scanned stereo card (``eval/stereo_card.py``);
* ``views/views.json`` (poses inline) and ``views/views_open3d.json`` (poses in an
  Open3D ``trajectory.json``), with ``view0.png`` ... and their depth files: a
  procedural scene ray-cast from three poses (``eval/multiview.py``).

With ``--figures``, renders one figure per application (the shipped lite model, Renoir's *The Bridge
at Chatou*, a shipped public-domain painting): ``apps_multiview.png``, ``apps_layered.png``,
``apps_layered_person.png``, ``apps_stereo_card.png``, ``apps_exports.png``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]

from stylize3d_core.depth.stereo_card import card_depth  # noqa: E402
from stylize3d_core.eval.multiview import held_out_psnr, procedural_views  # noqa: E402
from stylize3d_core.eval.stereo_card import synthetic_card  # noqa: E402
from stylize3d_core.export.bake import bake_cameras, bake_colours  # noqa: E402
from stylize3d_core.export.layered import LayeredRenderer  # noqa: E402
from stylize3d_core.export.stereo import anaglyph, eye_cameras, side_by_side  # noqa: E402
from stylize3d_core.geometry.camera import Cameras  # noqa: E402
from stylize3d_core.io.images import load_image, save_image  # noqa: E402
from stylize3d_core.models.checkpoint import load_checkpoint  # noqa: E402
from stylize3d_core.multiview import save_views  # noqa: E402
from stylize3d_core.pipeline import DEFAULT_MODEL, PhotoSpec, load_photo3d  # noqa: E402
from stylize3d_core.render.plain import PlainRenderer  # noqa: E402
from stylize3d_core.scene.masks import grabcut_mask, person_mask, point_mask  # noqa: E402
from stylize3d_core.scene.multiview import merge_views, pose_in_view  # noqa: E402
from stylize3d_core.scene.photo3d import Photo3D, Photo3DSettings  # noqa: E402
from stylize3d_core.scene.pointcloud import PointCloud  # noqa: E402
from stylize3d_core.stylize import Stylized3DPhoto, StylizeSettings  # noqa: E402

STYLE = ROOT / "assets/styles/renoir_bridge_at_chatou.jpg"  # a public-domain painting (assets/styles/README.md)
SIDE = np.eye(4)
SIDE[0, 3], SIDE[1, 3] = 0.05, -0.02  # a view to the right of the photo's camera


def _row(images, height=192):
    out = []
    for im in images:
        h, w = im.shape[:2]
        out.append(cv2.resize(np.asarray(im, np.float32), (max(1, round(w * height / h)), height),
                              interpolation=cv2.INTER_AREA))
    gap = np.ones((height, 4, 3), np.float32)
    return np.concatenate([x for im in out for x in (im, gap)][:-1], axis=1)


def _stylized(p3d, ck, style, strength=1.0):
    s = Stylized3DPhoto(p3d, ck, StylizeSettings(strength=strength))
    s.set_style(style)
    return s


def multiview_figure(ck, style, out: Path) -> None:
    data = procedural_views(3)
    merged = merge_views(data.views, 0).photo
    h, w = data.held_out_rgb.shape[:2]
    cam = Cameras.create(pose_in_view(data.held_out_pose, data.views[0], merged.ldi.depth_scale), merged.fov_y_deg)
    v0 = Photo3D.build(data.views[0].rgb, data.views[0].depth, Photo3DSettings(fov_y_deg=55.0))
    single = PlainRenderer(v0.points).render(cam, h, w)
    styl = _stylized(merged, ck, style).render(cam, h, w)
    scores = held_out_psnr(data)
    print("multi-view held-out PSNR:", {k: round(v, 2) for k, v in scores.items()})
    save_image(out, _row([*(v.rgb for v in data.views), data.held_out_rgb, single,
                          PlainRenderer(merged.points).render(cam, h, w), styl]))


def layered_figure(ck, style, out: Path) -> None:
    p3d = load_photo3d(PhotoSpec(photo=str(ROOT / "assets/samples/astronaut.jpg"), max_size=256))
    mask = grabcut_mask(p3d.rgb, (60, 20, 330, 492), scale=p3d.size[0] / 512)
    s = _stylized(p3d, ck, style)
    layered = LayeredRenderer(p3d, point_mask(p3d.ldi, mask), s)
    cam = Cameras.create(SIDE, p3d.fov_y_deg)
    h, w = p3d.size
    save_image(out, _row([p3d.rgb, np.repeat(mask[..., None], 3, 2).astype(np.float32), s.render(cam, h, w),
                          layered.render(cam, h, w)]))


def person_figure(ck, style, out: Path) -> None:
    """The astronaut: the automatic person mask over the photo (red), fully stylized, layered with it."""
    p3d = load_photo3d(PhotoSpec(photo=str(ROOT / "assets/samples/astronaut.jpg"), max_size=256))
    mask = person_mask(p3d.rgb)
    s = _stylized(p3d, ck, style)
    layered = LayeredRenderer(p3d, point_mask(p3d.ldi, mask), s)
    cam = Cameras.identity(p3d.fov_y_deg)
    h, w = p3d.size
    tinted = np.where(mask[..., None], 0.5 * p3d.rgb + 0.5 * np.array([1.0, 0.0, 0.0], np.float32), p3d.rgb)
    save_image(out, _row([tinted, s.render(cam, h, w), layered.render(cam, h, w)], height=256))


def card_figure(ck, style, card: np.ndarray, out: Path) -> None:
    found = card_depth(card)
    d = found.depth_map.depth
    inv = 1 / d
    vis = cv2.applyColorMap((255 * (inv - inv.min()) / (np.ptp(inv) + 1e-9)).astype(np.uint8), cv2.COLORMAP_TURBO)
    from stylize3d_core.scene.photo3d import Photo3D as P3D

    p3d = P3D.build(found.rgb, found.depth_map)
    frame = _stylized(p3d, ck, style, 0.8).render(Cameras.create(SIDE, p3d.fov_y_deg), 240, 240)
    save_image(out, _row([card, vis[..., ::-1] / 255.0, frame]))


def exports_figure(ck, style, out: Path) -> None:
    p3d = load_photo3d(PhotoSpec(photo=str(ROOT / "assets/samples/chelsea.jpg"), max_size=256))
    s = _stylized(p3d, ck, style, 0.8)
    h, w = p3d.size
    left, right = eye_cameras(Cameras.identity(p3d.fov_y_deg), 0.02)
    lv, rv = s.render(left, h, w), s.render(right, h, w)
    pts = p3d.points
    baked = bake_colours(pts.xyz, s.render, bake_cameras(p3d.fov_y_deg), (h, w)).rgb
    side = np.eye(4)
    side[:3, :3] = cv2.Rodrigues(np.array([0.0, 0.35, 0.0]))[0]
    side[0, 3] = -0.15
    cloud = PlainRenderer(PointCloud(pts.xyz, baked, pts.label, pts.image_size, pts.fov_y_deg))
    save_image(out, _row([side_by_side(lv, rv, "half"), anaglyph(lv, rv),
                          cloud.render(Cameras.create(side, p3d.fov_y_deg), h, w)]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--figures", default=None)
    ap.add_argument("--model", default=DEFAULT_MODEL)
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    card = synthetic_card().card
    save_image(out / "stereo_card.png", card)
    views = procedural_views(3).views
    print("wrote", out / "stereo_card.png", save_views(out / "views", views),
          save_views(out / "views", views, trajectory=True))
    if args.figures:
        fig = Path(args.figures)
        fig.mkdir(parents=True, exist_ok=True)
        ck = load_checkpoint(args.model)
        style = load_image(STYLE, max_size=512).rgb
        multiview_figure(ck, style, fig / "apps_multiview.png")
        layered_figure(ck, style, fig / "apps_layered.png")
        person_figure(ck, style, fig / "apps_layered_person.png")
        card_figure(ck, style, card, fig / "apps_stereo_card.png")
        exports_figure(ck, style, fig / "apps_exports.png")
        print("wrote figures to", fig)


if __name__ == "__main__":
    main()
