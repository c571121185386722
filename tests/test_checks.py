import numpy as np
import pytest
import torch

from stylize3d_core.checks import check_choice, check_finite, check_range, check_shape
from stylize3d_core.errors import InputError


def test_check_shape_messages():
    check_shape(torch.zeros(5, 3), "pts", (None, 3))
    with pytest.raises(InputError, match=r"pts: expected shape \(\*, 3\), got \(5, 2\)"):
        check_shape(torch.zeros(5, 2), "pts", (None, 3))
    with pytest.raises(InputError):
        check_shape(np.zeros((5, 3, 1)), "pts", (None, 3))


def test_check_finite_and_range_and_choice():
    check_finite(np.ones(3), "a")
    with pytest.raises(InputError, match="NaN"):
        check_finite(torch.tensor([1.0, float("inf")]), "a")
    assert check_range(0.5, "s", 0, 1) == 0.5
    with pytest.raises(InputError, match=r"s: must be in \[0, 1\]"):
        check_range(1.5, "s", 0, 1)
    with pytest.raises(InputError):
        check_range(float("nan"), "s", 0, 1)
    with pytest.raises(InputError):
        check_range(0.0, "s", 0, 1, inclusive=False)
    assert check_choice("a", "opt", ["a", "b"]) == "a"
    with pytest.raises(InputError, match="'b'"):
        check_choice("c", "opt", ["a", "b"])


def test_input_error_names_source():
    e = InputError("photo.jpg", "file is empty")
    assert str(e) == "photo.jpg: file is empty" and e.source == "photo.jpg"
    assert isinstance(e, ValueError)
