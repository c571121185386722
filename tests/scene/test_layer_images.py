"""The LDI's two layer images: the hidden layer continued from layer 0 across its border (match_hidden_seam)."""

from __future__ import annotations

import numpy as np
import pytest

from stylize3d_core.errors import InputError
from stylize3d_core.scene.layer_images import SEAM_SIGMA, hidden_layer_image, match_hidden_seam, seam_anchors
from stylize3d_core.scene.ldi import LDISettings, build_ldi

WALL, CARD, OFFSET = 0.3, 0.9, 0.15


@pytest.fixture(scope="module")
def card_ldi():
    """A card at depth 1 in front of a wall at depth 3: the hidden layer lies under the card's rim."""
    size, lo, hi = 192, 40, 152
    card = np.zeros((size, size), bool)
    card[lo:hi, lo:hi] = True
    rgb = np.where(card[..., None], np.float32([1, 0, 0]), np.float32([0, 0, 1])).astype(np.float32)
    depth = np.where(card, 1.0, 3.0).astype(np.float32)
    ldi = build_ldi(rgb, depth, LDISettings(band=0.25))  # a hidden rim about 48 px wide
    assert ldi.hidden_mask.sum() > 100
    return ldi


def _layers(ldi):
    """Two processed layer images of the same wall that differ by a context-dependent offset: layer 0 is WALL
    on the wall and CARD on the card; layer 1 (the wall continued under the card's rim) is WALL + OFFSET on
    the wall and the hidden pixels, and dark on the card (a step towards the occluder that must not count)."""
    on_card = ldi.depth < 2.0 * ldi.depth_scale  # card at 1, wall at 3 (scene units times the scale)
    ones = np.ones(3, np.float32)
    layer0 = np.where(on_card[..., None], CARD, WALL) * ones
    layer1 = np.where(on_card[..., None] & ~ldi.hidden_mask[..., None], 0.0, WALL + OFFSET) * ones
    return layer0.astype(np.float32), layer1.astype(np.float32)


def _distance_to_wall(ldi):
    import cv2

    wall = (ldi.depth >= 2.0 * ldi.depth_scale) & ~ldi.hidden_mask
    return cv2.distanceTransform((~wall).astype(np.uint8), cv2.DIST_L2, 5)


def test_the_hidden_layer_continues_the_surface_it_extends_and_never_the_occluder(card_ldi):
    layer0, layer1 = _layers(card_ldi)
    out = match_hidden_seam(card_ldi, layer0, layer1)
    hidden = card_ldi.hidden_mask
    dist = _distance_to_wall(card_ldi)
    at_border = hidden & (dist <= 2)
    assert at_border.sum() > 20
    # at the border layer 0's colour of the wall: the offset between the two images is gone ...
    assert np.abs(out[at_border] - WALL).max() < 0.03
    # ... never pulled by the card in front (the occluder is no anchor, its step is ignored)
    assert out[hidden].min() >= WALL - 1e-3 and out[hidden].max() <= WALL + OFFSET + 1e-6
    # far inside, the hidden layer keeps its own result
    deep = hidden & (dist >= 3.5 * SEAM_SIGMA)
    assert deep.sum() > 100
    assert np.abs(out[deep] - (WALL + OFFSET)).max() < 0.02
    # outside the hidden layer nothing changes
    np.testing.assert_array_equal(out[~hidden], layer1[~hidden])
    # the seam made once for the LDI gives the same result (what a second painting of the photo reuses)
    np.testing.assert_array_equal(match_hidden_seam(card_ldi, layer0, layer1, seam_anchors(card_ldi)), out)
    assert out.dtype == np.float32 and np.isfinite(out).all() and out.min() >= 0.0 and out.max() <= 1.0


def test_a_seamless_pair_and_a_photo_without_hidden_layer_are_unchanged(card_ldi):
    layer0, _ = _layers(card_ldi)
    same = np.where(card_ldi.hidden_mask[..., None], WALL, layer0).astype(np.float32)
    np.testing.assert_allclose(match_hidden_seam(card_ldi, layer0, same), same, atol=1e-6)  # no offset: no change
    flat = build_ldi(np.full((32, 48, 3), 0.5, np.float32), np.full((32, 48), 2.0, np.float32))
    assert not flat.hidden_mask.any() and seam_anchors(flat) is None
    image = np.random.default_rng(0).random((*flat.canvas_size, 3)).astype(np.float32)
    np.testing.assert_array_equal(match_hidden_seam(flat, image, image), image)


def test_the_layer_images_and_their_sizes_are_checked(card_ldi):
    layer0, layer1 = _layers(card_ldi)
    assert hidden_layer_image(card_ldi).shape == layer0.shape
    with pytest.raises(InputError, match="layer1"):
        match_hidden_seam(card_ldi, layer0, layer1[:-1])
    with pytest.raises(InputError, match="ldi"):
        match_hidden_seam("not an ldi", layer0, layer1)


# ----------------------------------------------------------------------------- the photo painted alone


def test_photo_with_margin_mirrors_the_photo_region_outward(card_ldi):
    from stylize3d_core.scene.layer_images import join_margin, photo_with_margin

    ldi = card_ldi
    m = join_margin(ldi)
    assert 0 < m <= ldi.pad
    image = np.random.default_rng(0).random(ldi.canvas_size + (3,)).astype(np.float32)
    part = photo_with_margin(ldi, image)
    h, w = ldi.photo_size
    assert part.shape == (h + 2 * m, w + 2 * m, 3)
    photo = image[ldi.photo_region]
    assert np.array_equal(part[m:m + h, m:m + w], photo)
    assert np.array_equal(part[m - 1, m:m + w], photo[1])  # a mirror (the edge row not repeated)
    assert np.array_equal(part[m:m + h, m + w], photo[:, w - 2])
    with pytest.raises(InputError, match="image"):
        photo_with_margin(ldi, image[1:])


def test_join_keeps_the_photo_painting_and_carries_its_colour_into_the_border(card_ldi):
    from stylize3d_core.scene.layer_images import join_margin, join_photo_painting

    ldi = build_ldi(card_ldi.rgb[card_ldi.photo_region], card_ldi.depth[card_ldi.photo_region] / card_ldi.depth_scale,
                    LDISettings(band=0.25, border=0.25))  # a border wider than the margin
    m, pad = join_margin(ldi), ldi.pad
    h, w = ldi.photo_size
    rng = np.random.default_rng(1)
    canvas = np.full(ldi.canvas_size + (3,), 0.3, np.float32) + 0.05 * rng.random(ldi.canvas_size + (3,)).astype(np.float32)
    photo = np.full((h + 2 * m, w + 2 * m, 3), 0.6, np.float32)  # the photo painted 0.3 lighter, say
    out = join_photo_painting(ldi, canvas, photo)
    assert out.shape == canvas.shape and out.dtype == np.float32
    assert np.array_equal(out[ldi.photo_region], photo[m:m + h, m:m + w])  # the photo: its own painting
    # the border keeps the canvas painting's texture, shifted by the offset at the edge (here ~0.3 everywhere)
    far = out[:pad - m, :] - canvas[:pad - m, :]
    assert abs(float(far.mean()) - 0.275) < 0.02 and float(far.std()) < 0.02
    assert np.allclose(out[:pad - m] - out[:pad - m].mean(), canvas[:pad - m] - canvas[:pad - m].mean(), atol=0.03)
    # no step at the photo's edge: across the margin the two cross-fade
    row = out[pad - m - 2 : pad + 2, pad + w // 2].mean(axis=1)
    assert np.all(np.abs(np.diff(row)) < 0.06)
    with pytest.raises(InputError, match="photo_painting"):
        join_photo_painting(ldi, canvas, photo[1:])
    with pytest.raises(InputError, match="canvas_painting"):
        join_photo_painting(ldi, canvas[:, 1:], photo)


def test_without_a_border_the_join_is_the_photo_painting(card_ldi):
    from dataclasses import replace

    from stylize3d_core.scene.layer_images import join_margin, join_photo_painting, photo_with_margin

    ldi = replace(card_ldi, pad=0, rgb=card_ldi.rgb[card_ldi.photo_region])
    assert join_margin(ldi) == 0
    img = np.random.default_rng(2).random(ldi.photo_size + (3,)).astype(np.float32)
    assert np.array_equal(photo_with_margin(ldi, img), img)
    assert np.array_equal(join_photo_painting(ldi, img * 0.5, img), img)
