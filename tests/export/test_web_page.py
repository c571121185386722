"""--export html's web page: the stored points, the size cap, and the page in headless Chromium."""

import os
import shutil

import numpy as np
import pytest

from stylize3d_core.errors import ExportError, InputError
from stylize3d_core.eval.metrics import psnr
from stylize3d_core.export.web_page import (budget_stride, decode_points, encode_points, orbit_centre,
                                            quantise_points, read_page, write_page)
from stylize3d_core.geometry.camera import focal_from_fov
from stylize3d_core.geometry.camera_range import range_corner_poses
from stylize3d_core.render.plain import PlainRenderer


def _page(photo3d, path, **kw):
    p = photo3d.points
    scene = orbit_centre(photo3d.ldi.depth[photo3d.ldi.photo_region])
    return write_page(path, p.xyz, p.rgb, photo3d.size, photo3d.fov_y_deg, photo3d.camera_range, scene, **kw)


def test_points_read_back_within_their_quanta(photo3d, tmp_path):
    out = _page(photo3d, tmp_path / "p.html")
    meta, q, rgb = read_page(out)
    p = photo3d.points
    h, w = photo3d.size
    f = focal_from_fov(photo3d.fov_y_deg, h)
    uvd = np.asarray(meta["lo"]) + q * np.asarray(meta["step"])
    want_uv = p.xyz[:, :2] / p.xyz[:, 2:] * f + (w / 2, h / 2)
    assert np.abs(uvd[:, :2] - want_uv).max() <= 0.5 * meta["step"][0] + 1e-4
    z = 1.0 / uvd[:, 2]
    assert np.abs(z / p.xyz[:, 2] - 1).max() < 1e-3
    assert np.abs(rgb.astype(int) - np.rint(p.rgb * 255)).max() <= 1
    assert meta["count"] == len(p.xyz) and meta["range"]["max_yaw_deg"] == photo3d.camera_range.max_yaw_deg


def test_budget_thins_on_a_lattice_and_grows_splats(photo3d, tmp_path):
    n = len(photo3d.points.xyz)
    meta, q, _ = read_page(_page(photo3d, tmp_path / "b.html", max_points=n // 3))
    assert n // 9 < meta["count"] <= n // 3 and meta["splat"] == pytest.approx(1.5 * 2)
    uv = np.asarray(meta["lo"][:2]) + q[:, :2] * np.asarray(meta["step"][:2])
    assert (np.floor(uv + 1e-6).astype(int) % 2 == 0).all()
    assert budget_stride(np.array([[0.5, 0.5], [1.5, 0.5]]), 1) == 2
    with pytest.raises(InputError, match="max_points"):
        budget_stride(np.zeros((1, 2)), 0)


def test_encoding_round_trips():
    g = np.random.default_rng(1)
    from stylize3d_core.export.web_page import WebPoints

    pts = WebPoints(g.integers(0, 65536, (500, 3)).astype(np.uint16), g.integers(0, 256, (500, 3)).astype(np.uint8),
                    np.zeros(3), np.ones(3), 1)
    q, rgb = decode_points(encode_points(pts), 500)
    assert np.array_equal(q, pts.q) and np.array_equal(rgb, pts.rgb)


def test_bad_outputs_name_the_file_and_overwrite_nothing(photo3d, tmp_path):
    keep = tmp_path / "keep.html"
    keep.write_text("old")
    with pytest.raises(ExportError, match="over the cap.*--max-points.*nothing was written") as e:
        _page(photo3d, keep, max_bytes=10_000)
    assert str(keep) in str(e.value) and keep.read_text() == "old"
    assert sorted(os.listdir(tmp_path)) == ["keep.html"]
    with pytest.raises(InputError, match="html"):
        _page(photo3d, tmp_path / "p.png")
    with pytest.raises(ExportError, match="does not exist"):
        _page(photo3d, tmp_path / "missing" / "p.html")
    if os.geteuid() != 0:  # root writes anywhere
        locked = tmp_path / "locked"
        locked.mkdir()
        locked.chmod(0o500)
        with pytest.raises(ExportError, match=str(locked)):
            _page(photo3d, locked / "p.html")
    with pytest.raises(InputError, match="finite"):
        bad = photo3d.points.xyz.copy()
        bad[0, 0] = np.nan
        quantise_points(bad, photo3d.points.rgb, photo3d.size, photo3d.fov_y_deg, 10 ** 6)


HOME_PSNR_DB = 24.0
"""The page's home view against the desktop's plain render of the same camera at the same size (square
splats and no coverage blending against tent splats: edges differ by up to a pixel)."""


def test_page_in_chromium(photo3d, tmp_path):
    if shutil.which("chromium") is None and not os.environ.get("CI"):
        pytest.skip("chromium is not installed (setup.sh installs it)")
    from stylize3d_core.eval.browser import PageBrowser

    scale = 4
    h, w = (s * scale for s in photo3d.size)
    page = _page(photo3d, tmp_path / "p.html")
    renderer = PlainRenderer(photo3d.points)
    with PageBrowser((w, h)) as b:
        assert b.open(page) < 10.0
        home = b.canvas()
        assert home.shape == (h, w, 3)
        cams = photo3d_cameras(photo3d)
        desk = np.rint(np.clip(renderer.render(cams[0], h, w), 0, 1) * 255).astype(np.uint8)
        assert psnr(home, desk, peak=255.0) > HOME_PSNR_DB
        b.drag(100, 0)
        moved = b.canvas()
        pose = b.script("return stylize3d.getPose();")
        # the desktop's speed for this range: 200 px from the input view to the yaw limit
        assert pose["yaw"] == pytest.approx(0.5 * photo3d.camera_range.max_yaw_deg, rel=0.05)
        assert np.abs(moved.astype(int) - home).mean() > 2  # the view changed
        b.script("document.getElementById('reset').click(); stylize3d.render();")
        assert b.script("return stylize3d.getPose();")["yaw"] == 0
        # Holes at the corners of the range: pixels left at a background the scene does not have.
        b.set_background((1.0, 0.0, 1.0))
        rng = photo3d.camera_range
        for sx in (-1, 1):
            for sy in (-1, 1):
                b.set_pose(-sx * rng.max_yaw_deg, sy * rng.max_pitch_deg, sx * rng.max_pan, sy * rng.max_pan, 0.0)
                img = b.canvas().astype(int)
                hole = (img[..., 0] > 240) & (img[..., 1] < 15) & (img[..., 2] > 240)
                assert hole.mean() < 0.002, (sx, sy, hole.mean())


def photo3d_cameras(photo3d):
    from stylize3d_core.geometry.camera import Cameras

    return Cameras.create(np.eye(4)[None], photo3d.fov_y_deg)
