"""The shared PSNR against values worked out by hand."""

import math

import numpy as np
import pytest
import torch

from stylize3d_core.eval.metrics import psnr


def test_known_values():
    a = np.zeros((4, 4, 3))
    assert psnr(a, a) == math.inf
    assert psnr(a, a + 0.1) == pytest.approx(20.0)  # MSE 0.01
    assert psnr(np.zeros((2, 2)), np.full((2, 2), 25.5), peak=255.0) == pytest.approx(20.0)


def test_a_mask_counts_only_its_pixels():
    a, b = np.zeros((2, 2, 3)), np.zeros((2, 2, 3))
    b[0, 0] = 1.0  # one wrong pixel
    mask = np.array([[False, True], [True, True]])
    assert psnr(a, b, mask) == math.inf
    assert psnr(a, b) == pytest.approx(10 * math.log10(4.0))
    assert math.isnan(psnr(a, b, np.zeros((2, 2), bool)))


def test_tensors_and_shape_mismatch():
    assert psnr(torch.zeros(3, 3), torch.full((3, 3), 0.1)) == pytest.approx(20.0)
    with pytest.raises(ValueError, match="different shapes"):
        psnr(np.zeros((2, 2)), np.zeros((2, 3)))
