"""Tests of push-pull hole filling."""

from __future__ import annotations

import math

import pytest
import torch

from stylize3d_core.errors import InputError
from stylize3d_core.render import fill_holes


def test_fully_valid_image_is_unchanged():
    image = torch.rand(3, 9, 7)
    out = fill_holes(image, torch.zeros(9, 7, dtype=torch.bool))
    assert torch.equal(out, image) and out.data_ptr() != image.data_ptr()


def test_one_hole_in_2x2_gets_the_mean_of_the_others():
    image = torch.tensor([[[1.0, 2.0], [4.0, 99.0]]])
    hole = torch.tensor([[False, False], [False, True]])
    out = fill_holes(image, hole)
    assert torch.allclose(out, torch.tensor([[[1.0, 2.0], [4.0, 7.0 / 3.0]]]))


def test_hole_in_constant_image_gets_the_constant():
    image = torch.full((2, 13, 11), 0.25)
    image[0] = -3.0
    hole = torch.zeros(13, 11, dtype=torch.bool)
    hole[2:9, 3:10] = True
    image[:, hole] = math.nan  # values at holes are ignored
    out = fill_holes(image, hole)
    assert torch.allclose(out[0], torch.full((13, 11), -3.0)) and torch.allclose(out[1], torch.full((13, 11), 0.25))


@pytest.mark.parametrize("size", [(1, 1), (1, 6), (5, 1), (7, 5), (16, 16), (33, 20)])
def test_all_holes_give_zeros(size):
    image = torch.full((3, *size), math.nan)
    out = fill_holes(image, torch.ones(size, dtype=torch.bool))
    assert out.shape == image.shape and torch.equal(out, torch.zeros_like(out))


def test_large_hole_filled_from_plausible_neighbours():
    H, W = 64, 64
    ramp = torch.linspace(0.0, 1.0, W).expand(H, W)  # horizontal gradient
    image = torch.stack([ramp, 1.0 - ramp])  # (2, H, W)
    hole = torch.zeros(H, W, dtype=torch.bool)
    hole[20:44, 16:48] = True
    out = fill_holes(image.masked_fill(hole, 0.0), hole)
    assert torch.isfinite(out).all()
    assert torch.equal(out[:, ~hole], image[:, ~hole])
    filled = out[0, hole]
    lo, hi = float(image[0, ~hole].min()), float(image[0, ~hole].max())
    assert lo <= filled.min() and filled.max() <= hi
    # the filled area follows the ramp: left part darker than right part, close to the truth
    inside = out[0, 20:44, 16:48]
    assert inside[:, :8].mean() < inside[:, -8:].mean() - 0.15
    assert (out - image).abs()[:, hole].mean() < 0.1


def test_two_colours_each_side():
    H, W = 32, 48
    image = torch.zeros(3, H, W)
    image[0, :, : W // 2] = 1.0  # red left
    image[2, :, W // 2:] = 1.0  # blue right
    hole = torch.zeros(H, W, dtype=torch.bool)
    hole[10:20, 4:12] = True  # inside the red half, far from the blue one
    hole[10:20, 36:44] = True  # inside the blue half
    out = fill_holes(image, hole)
    assert out[0, 10:20, 4:12].min() > 0.8 and out[2, 10:20, 4:12].max() < 0.2
    assert out[2, 10:20, 36:44].min() > 0.8 and out[0, 10:20, 36:44].max() < 0.2


def test_sparse_valid_pixels_fill_everything_without_nan():
    g = torch.Generator().manual_seed(0)
    image = torch.rand(4, 37, 29, generator=g)
    hole = torch.rand(37, 29, generator=g) > 0.03
    out = fill_holes(image, hole)
    assert torch.isfinite(out).all()
    assert out.min() >= image[:, ~hole].min() - 1e-6 and out.max() <= image[:, ~hole].max() + 1e-6


def test_gradcheck():
    g = torch.Generator().manual_seed(1)
    image = torch.rand(2, 5, 6, generator=g, dtype=torch.float64, requires_grad=True)
    hole = torch.rand(5, 6, generator=g) > 0.6
    assert torch.autograd.gradcheck(lambda x: fill_holes(x, hole), (image,))


def test_bad_inputs():
    image = torch.rand(3, 4, 5)
    hole = torch.zeros(4, 5, dtype=torch.bool)
    with pytest.raises(InputError, match="hole"):
        fill_holes(image, torch.zeros(4, 6, dtype=torch.bool))
    with pytest.raises(InputError, match="hole"):
        fill_holes(image, hole.float())
    with pytest.raises(InputError, match="image"):
        fill_holes(image[0], hole)
    with pytest.raises(InputError, match="image"):
        fill_holes(image.long(), hole)
    bad = image.clone()
    bad[0, 1, 1] = math.inf
    with pytest.raises(InputError, match="image"):
        fill_holes(bad, hole)
