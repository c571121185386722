"""Scanned stereo cards: a synthetic card of a known scene, with a mount, a rotation and an exposure change."""

import cv2
import numpy as np
import pytest

from stylize3d_app.cli import main
from stylize3d_core.depth.sources import StereoCardDepth, parse_depth_spec
from stylize3d_core.depth.stereo_card import CardSettings, card_depth, card_views, match_exposure
from stylize3d_core.errors import InputError
from stylize3d_core.eval.stereo_card import synthetic_card
from stylize3d_core.io.images import load_image_array, save_image

ROTATION = 1.5  # degrees, of the right print (synthetic_card's default)


@pytest.fixture(scope="module")
def card():
    made = synthetic_card(rotation_deg=ROTATION)
    return made.card, made.left, made.left_box


def test_card_is_split_aligned_and_rectified(card):
    image, left_truth, box = card
    views = card_views(image)
    assert views.boxes[0] == box and views.left.shape == (240, 240, 3)
    assert abs(views.rotation_deg - ROTATION) < 0.2 and abs(views.scale - 1) < 0.01
    assert views.matches >= 100
    assert np.abs(views.left - left_truth).mean() < 0.02  # the photo is the left print, unwarped
    lo, hi = views.disparity_range
    assert lo == pytest.approx(CardSettings().margin_px, abs=0.5) and hi > lo + 3
    # Rectified: features now lie on the same rows.
    sift = cv2.SIFT_create()
    grey = [cv2.cvtColor((v * 255).astype(np.uint8), cv2.COLOR_RGB2GRAY) for v in (views.left, views.right)]
    (kl, dl), (kr, dr) = (sift.detectAndCompute(g, None) for g in grey)
    pairs = [p[0] for p in cv2.BFMatcher().knnMatch(dl, dr, k=2) if p[0].distance < 0.6 * p[1].distance]
    dy = np.array([kl[m.queryIdx].pt[1] - kr[m.trainIdx].pt[1] for m in pairs])
    assert np.median(np.abs(dy)) < 0.5


def test_card_depth_finds_the_near_box(card):
    found = card_depth(card[0])
    d = found.depth_map.depth
    assert d.shape == (240, 240) and np.isfinite(d).all() and (d > 0).all()
    near = np.median(d[70:190, 80:160])
    far = np.median(np.concatenate([d[5:50].ravel(), d[:, 200:].ravel()]))
    assert near < 0.6 * far  # the box is nearer (the true ratio is 0.5; cards give relative depth)
    assert found.depth_map.valid.mean() > 0.7


def test_cross_eyed_card_swaps_the_prints(card):
    """A cross-eyed card (left eye's print on the right) gives the parallel card's photo and depth."""
    from stylize3d_core.depth.stereo import StereoSettings

    image, left_truth, box = card
    w = image.shape[1] // 2 * 2
    crossed = np.concatenate([image[:, w // 2:w], image[:, :w // 2]], axis=1)
    cross = CardSettings(stereo=StereoSettings(cross_eyed=True))
    views = card_views(crossed, cross)
    assert np.abs(views.left - left_truth).mean() < 0.02
    assert views.boxes[0][2] >= w // 2  # the left eye's print sat on the right half
    assert abs(views.rotation_deg - ROTATION) < 0.2
    d = card_depth(crossed, cross).depth_map.depth
    near = np.median(d[70:190, 80:160])
    far = np.median(np.concatenate([d[5:50].ravel(), d[:, 200:].ravel()]))
    assert near < 0.6 * far
    source = parse_depth_spec("stereo:card:cross")
    assert isinstance(source, StereoCardDepth) and source.settings.stereo.cross_eyed
    assert "cross" in source.describe()


def test_exposure_matching():
    g = np.random.default_rng(0)
    ref = g.random((20, 20, 3)).astype(np.float32)
    out = match_exposure(np.clip(ref * 0.6 + 0.1, 0, 1), ref)
    assert np.abs(out - ref).max() < 1e-4


def test_not_a_card(tmp_path):
    import skimage.data

    photo = skimage.data.chelsea() / 255.0  # 451 x 300: wide enough, but one photo
    with pytest.raises(InputError, match="does not look like a side-by-side stereo card"):
        card_depth(photo.astype(np.float32), name="cat.png")
    with pytest.raises(InputError, match="much wider than tall"):
        card_depth(np.zeros((100, 100, 3), np.float32))
    flat = np.full((100, 300, 3), 0.8, np.float32)
    flat[10:90, 10:140] = 0.2  # a left print, an empty right half
    with pytest.raises(InputError, match="holds no print"):
        card_depth(flat)


def test_spec_and_command_line(card, tmp_path, capsys):
    source = parse_depth_spec("stereo:card")
    assert isinstance(source, StereoCardDepth)
    found = source.estimate(load_image_array(card[0]))
    assert found.rgb.shape == (240, 240, 3)
    path = tmp_path / "card.png"
    save_image(path, card[0])
    out = tmp_path / "card.mp4"
    assert main(["render", str(path), "--stereo-card", "--frames", "3", "--size", "64", "-o", str(out), "-q"]) == 0
    import imageio.v3 as iio
    assert iio.imread(out).shape == (3, 64, 64, 3)  # the left print's square aspect, not the card's
    assert main(["render", str(path), "--stereo-card", "--depth", "prior", "-o", str(out)]) == 2
    assert "drop --depth prior" in capsys.readouterr().err
