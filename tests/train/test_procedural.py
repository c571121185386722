"""The analytic ray caster and the random depth maps of ``train/procedural.py``."""

import math

import numpy as np
import pytest

from stylize3d_core.errors import InputError
from stylize3d_core.geometry.camera import Cameras, focal_from_fov
from stylize3d_core.train.procedural import (
    RayHits,
    Scene,
    intersect,
    random_depth,
    random_scene,
    ray_cast,
    shade,
    visible_from,
)
from stylize3d_core.train.textures import random_texture

FOV = 60.0
H = W = 64
RED = np.array([1.0, 0.0, 0.0], np.float32)
BLUE = np.array([0.0, 0.0, 1.0], np.float32)
CARD_Z, CARD_HALF, WALL_Z = 0.5, 0.1, 2.0


def card_scene() -> Scene:
    """A red fronto-parallel card (|x|, |y| <= 0.1 at z = 0.5) in front of a blue wall at z = 2."""
    ex, ey = np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
    return Scene(
        centre=np.array([[0, 0, CARD_Z], [0, 0, WALL_Z]], float),
        e1=np.stack([ex, ex]), e2=np.stack([ey, ey]),
        half=np.array([[CARD_HALF, CARD_HALF], [50.0, 50.0]]),
        texel=np.array([0.05, 0.05]), offset=np.zeros((2, 2)),
        texture_id=np.array([0, 1]),
        textures=(np.broadcast_to(RED, (4, 4, 3)).copy(), np.broadcast_to(BLUE, (4, 4, 3)).copy()),
    )


def camera_at(t, fov=FOV) -> Cameras:
    pose = np.eye(4)
    pose[:3, 3] = t
    return Cameras.create(pose, fov)


def test_centre_pixel_sees_card_depth_and_colour():
    r = ray_cast(card_scene(), camera_at((0, 0, 0)), H, W, samples=3)
    assert r.rgb.shape == (H, W, 3) and r.depth.shape == (H, W) and r.hit.all()
    assert r.depth[H // 2, W // 2] == pytest.approx(CARD_Z, abs=1e-9)
    np.testing.assert_allclose(r.rgb[H // 2, W // 2], RED, atol=1e-6)
    np.testing.assert_allclose(r.rgb[0, 0], BLUE, atol=1e-6)
    assert r.depth[0, 0] == pytest.approx(WALL_Z, abs=1e-6)
    xy = 0.5 / focal_from_fov(FOV, H) * CARD_Z  # pixel centre (32.5, 32.5) is half a pixel off the axis
    np.testing.assert_allclose(r.points[H // 2, W // 2], [xy, xy, CARD_Z], atol=1e-9)


def test_forward_camera_sees_card_nearer():
    r = ray_cast(card_scene(), camera_at((0, 0, 0.1)), H, W, samples=1)
    assert r.depth[H // 2, W // 2] == pytest.approx(CARD_Z - 0.1, abs=1e-9)


@pytest.mark.parametrize("tx", [0.0, 0.02, -0.035])
def test_moved_camera_shifts_card_by_the_analytic_amount(tx):
    f = focal_from_fov(FOV, H)
    left = f * (-CARD_HALF - tx) / CARD_Z + W / 2  # card edges in pixel coordinates u
    right = f * (CARD_HALF - tx) / CARD_Z + W / 2
    r = ray_cast(card_scene(), camera_at((tx, 0, 0)), H, W, samples=1)
    u = np.arange(W) + 0.5
    want = (u >= left) & (u <= right)
    got = r.rgb[H // 2, :, 0] > 0.5
    np.testing.assert_array_equal(got, want)


def test_antialiased_edge_has_the_covered_fraction():
    tx = 0.02
    f = focal_from_fov(FOV, H)
    left = f * (-CARD_HALF - tx) / CARD_Z + W / 2  # 18.70: pixel 18 is 30 % card
    j = int(math.floor(left))
    s = 8
    r = ray_cast(card_scene(), camera_at((tx, 0, 0)), H, W, samples=s)
    covered = j + 1 - left
    assert abs(float(r.rgb[H // 2, j, 0]) - covered) <= 1.0 / s + 1e-6
    assert r.rgb[H // 2, j, 0] + r.rgb[H // 2, j, 2] == pytest.approx(1.0, abs=1e-5)  # a red / blue mix


def test_texture_lookup_known_texels():
    tex = np.zeros((2, 3, 3), np.float32)
    tex[..., 0] = np.arange(3)[None, :] / 2.0  # red grows with x (column)
    tex[..., 1] = np.arange(2)[:, None]  # green grows with y (row)
    scene = Scene(np.zeros((1, 3)), np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]), np.array([[10.0, 10.0]]),
                  np.array([0.5]), np.zeros((1, 2)), np.array([0]), (tex,))
    # s = texel * (texel centre) hits that texel exactly; texel column 3 mirrors back to column 2
    s = np.array([[0.25, 0.25], [1.25, 0.25], [0.75, 0.75], [1.25, 0.75], [1.75, 0.25]])
    out = shade(scene, RayHits(np.ones(5), np.zeros(5, np.int64), s))
    np.testing.assert_allclose(out[:, 0], [0.0, 1.0, 0.5, 1.0, 1.0], atol=1e-6)
    np.testing.assert_allclose(out[:, 1], [0.0, 0.0, 1.0, 1.0, 0.0], atol=1e-6)


def intersect_reference(scene: Scene, c2w: np.ndarray, dirs_cam: np.ndarray):
    """One ray, one quad at a time: the plane equation and the rectangle test as written."""
    origin = c2w[:3, 3]
    ts, qs = [], []
    for d_cam in dirs_cam:
        d = c2w[:3, :3] @ d_cam
        best, best_q = np.inf, -1
        for q in range(len(scene.half)):
            n = np.cross(scene.e1[q], scene.e2[q])
            if abs(d @ n) < 1e-12:
                continue
            t = ((scene.centre[q] - origin) @ n) / (d @ n)
            p = origin + t * d - scene.centre[q]
            inside = abs(p @ scene.e1[q]) <= scene.half[q, 0] and abs(p @ scene.e2[q]) <= scene.half[q, 1]
            if t > 1e-9 and inside and t < best:
                best, best_q = t, q
        ts.append(best)
        qs.append(best_q)
    return np.array(ts), np.array(qs)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_intersect_matches_reference_on_random_scenes(seed):
    rng = np.random.default_rng(seed)
    textures = [random_texture(rng, (16, 16))[1] for _ in range(3)]
    scene = random_scene(rng, textures, FOV, 1.25)
    c2w = np.eye(4)
    c2w[:3, 3] = rng.uniform(-0.05, 0.05, 3)
    f = focal_from_fov(FOV, 40)
    uv = rng.uniform(0, 1, (300, 2)) * np.array([50, 40])
    dirs = np.stack([(uv[:, 0] - 25) / f, (uv[:, 1] - 20) / f, np.ones(300)], 1)
    got = intersect(scene, c2w, dirs)
    t_ref, q_ref = intersect_reference(scene, c2w, dirs)
    np.testing.assert_allclose(got.t, t_ref, rtol=1e-9)
    np.testing.assert_array_equal(got.quad, q_ref)


def test_visible_from_source_camera():
    scene = card_scene()
    pts = np.array([
        [0.0, 0.0, WALL_Z],  # behind the card
        [0.5, 0.0, WALL_Z],  # beside it
        [0.0, 0.0, CARD_Z],  # on the card
        [50.0, 0.0, WALL_Z],  # outside the view
        [0.0, 0.0, -1.0],  # behind the camera
    ])
    got = visible_from(scene, pts, camera_at((0, 0, 0)), H, W)
    np.testing.assert_array_equal(got, [False, True, True, False, False])


def test_scaled_scene_scales_depth():
    rng = np.random.default_rng(5)
    scene = random_scene(rng, [random_texture(rng, (16, 16))[1]], FOV, 1.0)
    a = ray_cast(scene, camera_at((0, 0, 0)), 24, 24, samples=1)
    b = ray_cast(scene.scaled(3.0), camera_at((0, 0, 0)), 24, 24, samples=1)
    np.testing.assert_allclose(b.depth, 3.0 * a.depth, rtol=1e-5)
    np.testing.assert_allclose(b.rgb, a.rgb, atol=1e-5)


def test_random_scene_fills_the_view_and_is_reproducible():
    def make(seed):
        rng = np.random.default_rng(seed)
        return random_scene(rng, [random_texture(rng, (16, 16))[1] for _ in range(4)], 70.0, 1.5)

    for seed in range(5):
        r = ray_cast(make(seed), camera_at((0, 0, 0), 70.0), 32, 48, samples=1)
        assert r.hit.all() and np.isfinite(r.depth).all() and (r.depth > 0.05).all()
    np.testing.assert_array_equal(make(3).centre, make(3).centre)


def test_scene_validation():
    s = card_scene()
    with pytest.raises(InputError, match="texture_id"):
        Scene(s.centre, s.e1, s.e2, s.half, s.texel, s.offset, np.array([0, 5]), s.textures)
    with pytest.raises(InputError, match="orthogonal"):
        Scene(s.centre, s.e1, s.e1, s.half, s.texel, s.offset, s.texture_id, s.textures)
    with pytest.raises(InputError, match="half"):
        Scene(s.centre, s.e1, s.e2, -s.half, s.texel, s.offset, s.texture_id, s.textures)
    with pytest.raises(InputError, match="samples"):
        ray_cast(s, camera_at((0, 0, 0)), 8, 8, samples=0)


@pytest.mark.parametrize("with_photo", [False, True])
def test_random_depth(with_photo):
    rng = np.random.default_rng(0)
    photo = rng.random((40, 56, 3)).astype(np.float32) if with_photo else None
    for seed in range(6):
        d = random_depth(np.random.default_rng(seed), (40, 56), photo)
        assert d.shape == (40, 56) and d.dtype == np.float32
        assert np.isfinite(d).all() and d.min() >= 1.0 and d.max() <= 12.0 + 1e-4
    a = random_depth(np.random.default_rng(7), (40, 56), photo)
    b = random_depth(np.random.default_rng(7), (40, 56), photo)
    np.testing.assert_array_equal(a, b)
    with pytest.raises(InputError):
        random_depth(rng, (2, 2))
