"""Cameras, and the conventions every other module of stylize3d uses.

Conventions (stated here once; other modules refer to these names):

* **Axes** (OpenCV / Open3D): a camera looks along **+z**; **x** points right and
  **y** points down in the image. Depth is the z coordinate in the camera frame
  (not the distance along the ray).
* **World frame** = the camera frame of the input photo: the photo was taken by
  the camera with ``cam_to_world = identity``.
* **Poses**: ``cam_to_world`` (4, 4) maps camera coordinates to world
  coordinates; ``world_to_cam`` is its inverse. Open3D's
  ``PinholeCameraParameters.extrinsic`` is a ``world_to_cam``.
* **Pixels**: pixel ``(row i, column j)`` covers ``[j, j+1) x [i, i+1)``; its
  centre is ``(u, v) = (j + 0.5, i + 0.5)``. Image sizes are ``(H, W)``.
* **Intrinsics** from the *vertical* field of view: ``fy = (H / 2) / tan(fov_y / 2)``,
  ``fx = fy`` (square pixels), ``cx = W / 2``, ``cy = H / 2``. A camera is a pose
  plus a vertical FOV; it can be rendered at any size, and a wider image sees
  more on the sides. Public functions take the FOV in **degrees**.
* **Projection**: ``u = fx * x / z + cx``, ``v = fy * y / z + cy``.
* **Scene units**: a scene's depth is rescaled so that its near depth (1st
  percentile of the visible surface) is :data:`NEAR_DEPTH` = 1/3, as 3DPhoto
  does (its disparity is normalised to at most 3). Camera-path amplitudes such as
  the default ±0.02 sideways therefore mean the same parallax in every scene.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Tuple, Union

import numpy as np
import torch

from ..checks import check_range, check_shape
from ..errors import InputError

NEAR_DEPTH = 1.0 / 3.0
"""Depth of the nearest surface (1st percentile) after a scene is normalised."""

DEFAULT_FOV_Y_DEG = 60.0
"""Vertical field of view assumed for a photo when none is known."""

MIN_FOV_DEG = 1.0
MAX_FOV_DEG = 170.0

TensorLike = Union[torch.Tensor, np.ndarray]


def check_fov(fov_y_deg: float, name: str = "fov") -> float:
    """Return the FOV as a float if it lies in [MIN_FOV_DEG, MAX_FOV_DEG] degrees."""
    return check_range(fov_y_deg, name, MIN_FOV_DEG, MAX_FOV_DEG)


def focal_from_fov(fov_y_deg: float, height: int) -> float:
    """Focal length in pixels, ``(H / 2) / tan(fov_y / 2)``."""
    return 0.5 * height / math.tan(math.radians(check_fov(fov_y_deg)) / 2.0)


def intrinsics_from_fov(
    fov_y_deg: float, height: int, width: int, dtype: torch.dtype = torch.float32
) -> torch.Tensor:
    """Pinhole intrinsics ``K`` (3, 3) for an ``(height, width)`` image and a vertical FOV."""
    if height < 1 or width < 1:
        raise InputError("image size", f"must be positive, got {(height, width)}")
    f = focal_from_fov(fov_y_deg, height)
    return torch.tensor([[f, 0.0, width / 2.0], [0.0, f, height / 2.0], [0.0, 0.0, 1.0]], dtype=dtype)


def pixel_centres(height: int, width: int, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """Pixel-centre coordinates (H, W, 2) as ``(u, v) = (j + 0.5, i + 0.5)``."""
    v, u = torch.meshgrid(
        torch.arange(height, dtype=dtype) + 0.5, torch.arange(width, dtype=dtype) + 0.5, indexing="ij"
    )
    return torch.stack([u, v], dim=-1)


def unproject(uv: torch.Tensor, depth: torch.Tensor, K: torch.Tensor) -> torch.Tensor:
    """Back-project pixel coordinates with depth into camera coordinates.

    Args:
        uv: (..., 2) pixel coordinates (centres at +0.5).
        depth: (...) z in the camera frame, > 0.
        K: (3, 3) intrinsics.
    Returns:
        (..., 3) points ``(x, y, z)`` in the camera frame.
    """
    x = (uv[..., 0] - K[0, 2]) / K[0, 0] * depth
    y = (uv[..., 1] - K[1, 2]) / K[1, 1] * depth
    return torch.stack([x, y, depth], dim=-1)


def unproject_depth_map(depth: torch.Tensor, K: torch.Tensor) -> torch.Tensor:
    """Back-project every pixel centre of a depth map (H, W) into camera points (H, W, 3)."""
    check_shape(depth, "depth", (None, None))
    uv = pixel_centres(depth.shape[0], depth.shape[1], dtype=depth.dtype)
    return unproject(uv, depth, K.to(depth.dtype))


def project(points_cam: torch.Tensor, K: torch.Tensor, eps: float = 1e-8) -> Tuple[torch.Tensor, torch.Tensor]:
    """Project camera-frame points to pixels.

    Args:
        points_cam: (N, 3) points in the camera frame.
        K: (3, 3) intrinsics.
        eps: smallest |z| used in the division; points with ``z <= eps`` get
            finite but meaningless ``uv`` and must be culled by the caller using ``z``.
    Returns:
        uv (N, 2) pixel coordinates and z (N,) depths.
    """
    z = points_cam[:, 2]
    z_safe = torch.where(z > eps, z, torch.full_like(z, eps))
    u = K[0, 0] * points_cam[:, 0] / z_safe + K[0, 2]
    v = K[1, 1] * points_cam[:, 1] / z_safe + K[1, 2]
    return torch.stack([u, v], dim=-1), z


def transform_points(T: torch.Tensor, points: torch.Tensor) -> torch.Tensor:
    """Apply a rigid transform (4, 4) to points (N, 3)."""
    return points @ T[:3, :3].transpose(0, 1) + T[:3, 3]


def invert_pose(T: torch.Tensor) -> torch.Tensor:
    """Inverse of rigid transforms (..., 4, 4) (``cam_to_world`` <-> ``world_to_cam``)."""
    R = T[..., :3, :3]
    t = T[..., :3, 3:]
    Rt = R.transpose(-1, -2)
    out = torch.zeros_like(T)
    out[..., :3, :3] = Rt
    out[..., :3, 3:] = -Rt @ t
    out[..., 3, 3] = 1.0
    return out


@dataclass(frozen=True)
class Cameras:
    """A batch of B pinhole cameras: poses and vertical fields of view.

    Attributes:
        cam_to_world: (B, 4, 4) float64 rigid transforms, camera -> world.
        fov_y_deg: (B,) float64 vertical fields of view in degrees.

    A camera has no image size: pass it when rendering (see module docstring).
    """

    cam_to_world: torch.Tensor
    fov_y_deg: torch.Tensor

    def __post_init__(self) -> None:
        check_shape(self.cam_to_world, "cam_to_world", (None, 4, 4))
        check_shape(self.fov_y_deg, "fov_y_deg", (self.cam_to_world.shape[0],))
        if not torch.isfinite(self.cam_to_world).all():
            raise InputError("cam_to_world", "contains NaN or infinite values")
        R = self.cam_to_world[:, :3, :3].double()
        eye = torch.eye(3, dtype=torch.float64).expand_as(R)
        if not torch.allclose(R.transpose(-1, -2) @ R, eye, atol=1e-4):
            raise InputError("cam_to_world", "rotation part is not orthonormal")
        for f in self.fov_y_deg.tolist():
            check_fov(f, "fov_y_deg")

    @staticmethod
    def create(cam_to_world: TensorLike, fov_y_deg: Union[float, TensorLike]) -> "Cameras":
        """Build from arrays or tensors; a single (4, 4) pose gives a batch of one."""
        c2w = torch.as_tensor(np.asarray(cam_to_world, dtype=np.float64)) if not isinstance(
            cam_to_world, torch.Tensor) else cam_to_world.to(torch.float64)
        if c2w.ndim == 2:
            c2w = c2w.unsqueeze(0)
        fov = torch.as_tensor(fov_y_deg, dtype=torch.float64).reshape(-1)
        if fov.numel() == 1 and c2w.shape[0] > 1:
            fov = fov.expand(c2w.shape[0]).clone()
        return Cameras(c2w, fov)

    @staticmethod
    def identity(fov_y_deg: float = DEFAULT_FOV_Y_DEG) -> "Cameras":
        """The input photo's own camera."""
        return Cameras.create(torch.eye(4, dtype=torch.float64), fov_y_deg)

    def __len__(self) -> int:
        return self.cam_to_world.shape[0]

    def __getitem__(self, index: Union[int, slice]) -> "Cameras":
        if isinstance(index, int):
            index = slice(index, index + 1 if index != -1 else None)
        return Cameras(self.cam_to_world[index], self.fov_y_deg[index])

    def world_to_cam(self) -> torch.Tensor:
        """(B, 4, 4) world -> camera transforms."""
        return invert_pose(self.cam_to_world)

    def intrinsics(self, height: int, width: int, dtype: torch.dtype = torch.float32) -> torch.Tensor:
        """(B, 3, 3) intrinsics of every camera at image size ``(height, width)``."""
        return torch.stack([intrinsics_from_fov(f, height, width, dtype) for f in self.fov_y_deg.tolist()])

    def centres(self) -> torch.Tensor:
        """(B, 3) camera centres in world coordinates."""
        return self.cam_to_world[:, :3, 3]
