import math

import pytest
import torch

from stylize3d_core.errors import InputError
from stylize3d_core.geometry.camera import intrinsics_from_fov, pixel_centres, unproject
from stylize3d_core.geometry.ndc import from_ndc, ndc_params, to_ndc


def test_params_known_values():
    z = torch.tensor([2.0, 3.0, 4.0, 5.0, 100.0])
    p = ndc_params(z, 90.0, 2.0)
    assert p.near == pytest.approx(1.98)
    # q95 of 5 values (index round(0.95 * 4) = 4) is 100
    assert p.far == pytest.approx(100.0)
    assert p.cot_half_fov == pytest.approx(1.0)
    # far is at least twice near
    p2 = ndc_params(torch.tensor([1.0, 1.0, 1.01]), 60.0, 1.0)
    assert p2.far == pytest.approx(2 * 0.99)


def test_image_corners_map_to_unit_square():
    H, W, fov = 30, 45, 60.0
    K = intrinsics_from_fov(fov, H, W, dtype=torch.float64)
    corners = torch.tensor([[0.0, 0.0], [W, H], [W, 0.0]], dtype=torch.float64)
    depth = torch.tensor([1.0, 2.0, 3.0], dtype=torch.float64)
    pts = unproject(corners, depth, K)
    p = ndc_params(depth, fov, W / H)
    ndc = to_ndc(pts, p)
    assert torch.allclose(ndc[:, :2], torch.tensor([[-1.0, -1.0], [1.0, 1.0], [1.0, -1.0]], dtype=torch.float64))
    # near plane -> -1, far plane -> +1
    near_far = torch.tensor([[0.0, 0.0, p.near], [0.0, 0.0, p.far]], dtype=torch.float64)
    assert torch.allclose(to_ndc(near_far, p)[:, 2], torch.tensor([-1.0, 1.0], dtype=torch.float64))


def test_round_trip_and_no_mutation():
    g = torch.Generator().manual_seed(0)
    pts = torch.randn(1000, 3, generator=g, dtype=torch.float64)
    pts[:, 2] = pts[:, 2].abs() * 3 + 0.2
    before = pts.clone()
    p = ndc_params(pts[:, 2], 50.0, 1.3)
    back = from_ndc(to_ndc(pts, p), p)
    assert torch.allclose(back, pts, atol=1e-9)
    assert torch.equal(pts, before)


def test_scale_invariance():
    # NDC does not depend on the depth scale: scaling the scene gives the same NDC.
    pts = torch.rand(500, 3, dtype=torch.float64) + torch.tensor([0.0, 0.0, 0.5], dtype=torch.float64)
    a = to_ndc(pts, ndc_params(pts[:, 2], 60.0, 1.5))
    b = to_ndc(pts * 7.3, ndc_params(pts[:, 2] * 7.3, 60.0, 1.5))
    assert torch.allclose(a, b, atol=1e-9)


@pytest.mark.parametrize("z", [torch.tensor([]), torch.tensor([1.0, -1.0]), torch.tensor([1.0, math.nan])])
def test_bad_depths(z):
    with pytest.raises(InputError):
        ndc_params(z, 60.0, 1.0)


def test_bad_fov_and_aspect():
    with pytest.raises(InputError):
        ndc_params(torch.ones(3), 0.0, 1.0)
    with pytest.raises(InputError):
        ndc_params(torch.ones(3), 60.0, 0.0)


@pytest.mark.parametrize("n", [1, 2, 7, 20, 1001])
def test_far_plane_is_the_95th_percentile_of_a_sort(n):
    z = torch.rand(n, generator=torch.Generator().manual_seed(n)) * 10 + 0.1
    zs = torch.sort(z.double()).values
    q95 = float(zs[min(n - 1, int(round(0.95 * (n - 1))))])
    assert ndc_params(z, 60.0, 1.5).far == max(q95, 2.0 * 0.99 * float(z.min()))
