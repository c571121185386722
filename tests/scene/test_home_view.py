"""The 3D photo seen from the photo's own camera is the photo.

The hidden layer and the border may add points, but no layer-0 pixel of the photo is
recoloured or moved but the background-side pixels of the silhouettes the hidden layer
covers (``LDISettings.unmix_silhouettes``: the foreground's anti-aliased share taken out,
or, mostly foreground, joined to the foreground with their colour): every other pixel has
the photo's colour and the depth the photo's own depth gives it with no hidden layer at
all, and the plain render from the home camera matches the photo (the figures are printed).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from stylize3d_core.depth.sources import PriorDepth
from stylize3d_core.geometry.camera import Cameras
from stylize3d_core.geometry.camera_range import CameraRange
from stylize3d_core.io.images import load_image
from stylize3d_core.render.plain import PlainRenderer
from stylize3d_core.scene.ldi import LDISettings
from stylize3d_core.scene.photo3d import Photo3D, Photo3DSettings

SAMPLES = Path(__file__).resolve().parents[2] / "assets" / "samples"

HOME_FLOOR_DB = {"astronaut": 43.0, "coffee": 45.5}
"""Least home-view PSNR of the plain render: 43.6 and 46.1 dB since the foreground's silhouette pixels
cover part of their pixel (``LDISettings.subpixel_silhouettes``: the blend gives back the photo's colour
but for ``(1 - a)`` of its texture residual); 44.0 and 46.4 dB since the silhouettes' background-side
pixels lose the foreground's share (what differs is that share, on those pixels only; 80+ dB without
it, ``unmix_silhouettes=False``). 120 dB (the cap: exact) for both when written; 56.7 and 54.9 dB while
the rasterizer let a neighbour's faint (~1e-5) splat tap set a pixel's depth front on steep depth
slopes (708 and 677 hole pixels, filled); 55.1 and 44.7 dB before that, when layer 0's pixels next
to a tear (both sides, from the sources' colours) were recoloured."""


@pytest.mark.parametrize("name", list(HOME_FLOOR_DB))
def test_home_view_is_the_photo(name, capsys):
    image = load_image(str(SAMPLES / f"{name}.jpg"), max_size=512)
    depth = PriorDepth().estimate(image).depth_map
    p3d = Photo3D.build(image.rgb, depth, Photo3DSettings())
    ldi = p3d.ldi
    assert ldi.inpainted and ldi.hidden_mask.any()  # a hidden layer exists ...
    # ... yet layer 0 keeps the photo's colours but on the silhouettes' background side and on the
    # foreground's partly covering silhouette pixels (their own colour, an opacity below 1, the hidden
    # layer behind them, moved by less than half a pixel)
    silhouette = ldi.bg_edge[ldi.photo_region]
    assert ldi.alpha is not None and ldi.offset is not None
    partial = ldi.alpha[ldi.photo_region] < 1.0
    assert partial.any() and ldi.hidden_mask[ldi.photo_region][partial].all()
    assert (ldi.alpha > 0).all() and (np.abs(ldi.offset) <= 0.5).all()
    assert not (np.abs(ldi.offset[ldi.photo_region]).max(axis=2)[~partial] > 0).any()  # only they move
    recoloured = (ldi.rgb[ldi.photo_region] != image.rgb).any(axis=2)
    assert recoloured.any() and not (recoloured & ~silhouette & ~partial).any()
    # ... and its depth: the same as with no hidden layer (nothing to cover) and no border, but
    # where such a pixel joined the foreground (nearer, its colour the photo's)
    bare = LDISettings(camera_range=CameraRange().scaled(0.0), cover_trajectories=False, border=0.0)
    flat = Photo3D.build(image.rgb, depth, dataclasses.replace(Photo3DSettings(), ldi=bare)).ldi
    assert not flat.hidden_mask.any() and flat.pad == 0
    assert np.array_equal(flat.rgb, image.rgb)  # nothing to cover: nothing unmixed
    moved = ldi.depth[ldi.photo_region] != flat.depth
    assert not (moved & ~silhouette).any() and not (moved & recoloured & ~partial).any()
    assert (ldi.depth[ldi.photo_region][moved] < flat.depth[moved]).all()
    assert ldi.hidden_mask[ldi.photo_region][moved].all()  # the background behind them

    h, w = p3d.size
    renderer, home = PlainRenderer(p3d.points), Cameras.create(np.eye(4), p3d.fov_y_deg)
    holes = int(renderer.rasterize(home, h, w).hole.sum())  # before hole filling
    got = renderer.render(home, h, w)
    mse = float(((got - image.rgb) ** 2).mean())
    db = 10 * math.log10(1.0 / max(mse, 1e-12))
    with capsys.disabled():
        print(f"\n{name} {w}x{h}: home-view PSNR {db:.1f} dB, {holes} hole pixels before filling"
              f" ({len(p3d.points):,} points; {int((recoloured & ~partial).sum())} silhouette pixels unmixed,"
              f" {int(moved.sum())} joined to the foreground, {int(partial.sum())} partly covering)")
    assert holes == 0  # every photo pixel's own point shows
    assert db >= HOME_FLOOR_DB[name]
