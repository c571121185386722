"""Novel views of analytic scenes against the truth, on what the photo did not see.

Three scenes of textured quads, ray-cast exactly (``train/procedural.py``): a card
before a wall, a card standing on a slanted ground plane before a wall, and thin
poles before a wall. Each photo (and its exact depth) becomes a 3D photo, which
is rendered from the moves of the default trajectories (sideways, vertical,
forward, and the ken-burns corner that combines them) and compared with the
ray-cast truth on the *disoccluded* pixels: those whose pixel-centre surface
point lies inside the photo's frame but was hidden there behind a nearer
surface. Pixels that show what lay outside the photo's frame (the border
extension, a continuation rather than a reconstruction) are counted apart and
not scored. The figures are printed.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from stylize3d_core.depth.types import DepthMap
from stylize3d_core.eval.metrics import psnr
from stylize3d_core.geometry.camera import NEAR_DEPTH, Cameras
from stylize3d_core.geometry.trajectories import DEFAULT_XY, DEFAULT_Z
from stylize3d_core.render.plain import PlainRenderer
from stylize3d_core.scene.photo3d import Photo3D, Photo3DSettings
from stylize3d_core.train.procedural import Scene, ray_cast, visible_from

FOV = 60.0
H, W = 240, 320
MOVES = {
    "sideways": (DEFAULT_XY, 0.0, 0.0),
    "sideways-left": (-DEFAULT_XY, 0.0, 0.0),
    "vertical": (0.0, DEFAULT_XY, 0.0),
    "vertical-up": (0.0, -DEFAULT_XY, 0.0),
    "forward": (0.0, 0.0, max(DEFAULT_Z)),
    "ken-burns corner": (DEFAULT_XY, DEFAULT_XY, max(DEFAULT_Z)),
}
"""The extreme camera offsets of the default trajectories (scene units)."""


def smooth_texture(seed: int, size: int = 96) -> np.ndarray:
    """A smooth colour field (size, size, 3) in [0.1, 0.9]: sums of low-frequency sinusoids."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[:size, :size] / size
    out = np.zeros((size, size, 3))
    for c in range(3):
        fx, fy, ph = rng.uniform(1.0, 3.0), rng.uniform(1.0, 3.0), rng.uniform(0, 2 * math.pi)
        out[..., c] = 0.5 + 0.3 * np.sin(2 * math.pi * (fx * x + fy * y) + ph)
    return out.astype(np.float32)


def quads(rows, textures) -> Scene:
    """Scene from rows (centre, e1, e2, half, texel, texture id)."""
    cols = list(zip(*rows))
    return Scene(np.array(cols[0], float), np.array(cols[1], float), np.array(cols[2], float),
                 np.array(cols[3], float), np.array(cols[4], float), np.zeros((len(rows), 2)),
                 np.array(cols[5], np.int64), tuple(textures))


X, Y, Z = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)


def card_scene() -> Scene:
    return quads([((0, 0, NEAR_DEPTH), X, Y, (0.07, 0.07), 0.002, 0), ((0, 0, 1.0), X, Y, (5, 5), 0.012, 1)],
                 [smooth_texture(1), smooth_texture(2)])


def ground_scene() -> Scene:
    return quads([
        ((0.07, 0.09, 0.42), X, Y, (0.05, 0.06), 0.002, 0),  # a card standing on the ground
        ((0, 0.15, 0.9), X, Z, (3, 0.85), 0.03, 1),  # the ground, from z = 0.05 to 1.75
        ((0, 0, 1.75), X, Y, (5, 5), 0.03, 2),  # the back wall
    ], [smooth_texture(3), smooth_texture(4), smooth_texture(5)])


def poles_scene() -> Scene:
    rows = [((x, 0, z), X, Y, (0.004, 0.5), 0.001, 0)
            for x, z in ((-0.11, 0.4), (-0.05, 0.45), (0.0, 0.5), (0.06, 0.42), (0.12, 0.48))]
    rows.append(((0, 0, 1.2), X, Y, (5, 5), 0.015, 1))
    return quads(rows, [smooth_texture(6), smooth_texture(7)])


SCENES = {"card before wall": card_scene, "slanted ground": ground_scene, "thin poles": poles_scene}

TRUTH_SAMPLES = 8
"""Rays per pixel side of the ray-cast truth (the photo itself: 3): a truth's coverage of a silhouette's
pixel is quantised to 1 / TRUTH_SAMPLES, and the disoccluded strips beside a moved silhouette are a few
pixels wide, so a 3 x 3 truth moved the figures by 2-11 dB from denser ones (session 19,
``tests/benchmarks/bench_scene_truth.py``); 8 x 8 is within ~1/16 of the exact coverage."""

FLOOR_DB = 30.0
"""Least PSNR on the disoccluded pixels (the issue's target), every scene and move: 30.4 dB and up since
the foreground's silhouette pixels cover their share of the pixel (``LDISettings.subpixel_silhouettes``;
the card's vertical moves were 29.1 dB against this truth before)."""

BEFORE_DB = {
    ("card before wall", "sideways"): 30.2, ("card before wall", "sideways-left"): 30.2,
    ("card before wall", "vertical"): 29.1, ("card before wall", "vertical-up"): 29.1,
    ("card before wall", "ken-burns corner"): 38.5,
    ("slanted ground", "sideways"): 34.2, ("slanted ground", "sideways-left"): 33.6,
    ("slanted ground", "vertical-up"): 32.7, ("slanted ground", "forward"): 33.1,
    ("slanted ground", "ken-burns corner"): 33.3,
    ("thin poles", "sideways"): 44.6, ("thin poles", "sideways-left"): 44.5,
    ("thin poles", "forward"): 40.8, ("thin poles", "ken-burns corner"): 40.7,
}
"""Disoccluded PSNR against the same truth before the silhouette pixels covered their share (every layer-0
point opaque at its pixel's centre; session 19). Printed next to today's. (Against a 3 x 3 truth, before
the hidden layer followed the surface that opposite sources agree on, the slanted ground's moves were
17-28 dB and its ken-burns corner 23.6.)"""


def camera(t) -> Cameras:
    pose = np.eye(4)
    pose[:3, 3] = t
    return Cameras.create(pose, FOV)


def regions(scene: Scene, truth) -> tuple:
    """(seen, hidden, outside) (H, W) bool masks of a truth ray-cast from a moved camera: what the photo saw,
    what lay inside the photo's frame but behind a nearer surface there (the disoccluded pixels), and what
    lay beyond the photo's frame."""
    pts = truth.points.reshape(-1, 3)
    seen = visible_from(scene, pts, camera((0, 0, 0)), H, W).reshape(H, W)
    f = 0.5 * H / math.tan(math.radians(FOV) / 2.0)
    z = np.maximum(pts[:, 2], 1e-9)
    u, v = f * pts[:, 0] / z + W / 2, f * pts[:, 1] / z + H / 2
    in_frame = ((pts[:, 2] > 1e-9) & (u >= 0) & (u < W) & (v >= 0) & (v < H)).reshape(H, W)
    return seen, truth.hit & ~seen & in_frame, truth.hit & ~in_frame


@pytest.fixture(scope="module", params=list(SCENES))
def built(request):
    """(name, scene in scene units, renderer of its 3D photo)."""
    scene = SCENES[request.param]()
    first = ray_cast(scene, camera((0, 0, 0)), H, W, samples=1)
    scene = scene.scaled(NEAR_DEPTH / float(np.percentile(first.depth, 1.0)))  # near depth 1/3
    photo = ray_cast(scene, camera((0, 0, 0)), H, W, samples=3)
    dm = DepthMap(photo.depth.astype(np.float32), np.ones((H, W), bool), "metric", "analytic")
    p3d = Photo3D.build(photo.rgb, dm, Photo3DSettings(fov_y_deg=FOV))
    assert p3d.ldi.depth_scale == pytest.approx(1.0, rel=1e-3)
    return request.param, scene, PlainRenderer(p3d.points)


@pytest.mark.parametrize("move", list(MOVES))
def test_disoccluded_regions_match_the_truth(built, move, capsys):
    name, scene, renderer = built
    t = MOVES[move]
    truth = ray_cast(scene, camera(t), H, W, samples=TRUTH_SAMPLES)
    seen, hidden, outside = regions(scene, truth)
    got = renderer.render(camera(t), H, W)
    frags = renderer.rasterize(camera(t), H, W)
    holes = float(frags.hole.float().mean())
    p_seen = psnr(got[seen], truth.rgb[seen])
    p_hidden = psnr(got[hidden], truth.rgb[hidden]) if hidden.any() else math.inf
    with capsys.disabled():
        print(f"\n{name:>16} {move:>16} {str(t):>20}: disoccluded {100 * hidden.mean():5.2f}% of the view, "
              f"PSNR {p_hidden:6.2f} dB there (was {BEFORE_DB.get((name, move), math.nan):4.1f}), {p_seen:6.2f} dB on what the photo saw, "
              f"{100 * outside.mean():4.2f}% beyond the photo's frame, holes before filling {100 * holes:.3f}%")
    assert holes <= 0.002  # no hole before filling, from any of the trajectories' extremes
    assert p_seen > 29.5  # the thin poles: 30.2 dB before this change, 30.4 after
    if hidden.mean() > 5e-4:  # at least ~40 pixels
        # The disoccluded surface is filled with background-like colours: much closer to the
        # truth than the nearest foreground colour would be (the target; see the print).
        assert p_hidden >= FLOOR_DB
