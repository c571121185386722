"""Fixtures shared by the point-operation tests."""

from typing import Callable

import pytest
import torch


def _surface_cloud(h: int, w: int, jitter: float = 0.0, seed: int = 0) -> torch.Tensor:
    """(h*w, 3) NDC-like points of a photo: a pixel grid over a bumpy surface with a depth step."""
    g = torch.Generator().manual_seed(seed)
    ys, xs = torch.meshgrid(torch.linspace(-1, 1, h), torch.linspace(-1, 1, w), indexing="ij")
    xy = torch.stack([xs, ys], -1).reshape(-1, 2)
    xy = xy + jitter * (torch.rand(xy.shape, generator=g) - 0.5) * (2.0 / w)
    z = 0.2 * torch.sin(3 * xy[:, 0]) * torch.cos(2 * xy[:, 1]) + 0.6 * (xy[:, 0] > 0.3)
    return torch.cat([xy, z[:, None]], 1)


@pytest.fixture
def surface_cloud() -> Callable[..., torch.Tensor]:
    """``surface_cloud(h, w, jitter=0.0, seed=0)``: (h*w, 3) points of a photo-like surface (see ``_surface_cloud``)."""
    return _surface_cloud
