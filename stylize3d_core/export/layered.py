"""Layered stylization (paper Sec. 4.5): a foreground keeps its colours while the background is stylized.

The foreground is a mask over the photo (``scene/masks.py``: a file, GrabCut
in a rectangle, or the automatic person segmentation, ``--mask person``) carried by the points of the 3D photo (:func:`~stylize3d_core.scene.masks.point_mask`:
the hidden layer behind the foreground is background), so it moves with the
scene in every view. Each frame is composed in 3D: the foreground mask is
rasterized as a point feature with the same z-buffer rule as the colours, so
``coverage`` (H, W) is the fraction of the front surface that is foreground
(1 inside it, 0 on the background, in between on its outline and 0 where the
background is in front of it), and

    frame = coverage * foreground + (1 - coverage) * background

with ``background`` the stylized render and ``foreground`` the plain render of
the points' own colours (:class:`~stylize3d_core.render.plain.PlainRenderer`), or
the stylized render at ``foreground_strength``. Inside the foreground the frame
is therefore exactly the plain render: its original colours.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterator, Optional, Protocol, Tuple

import numpy as np
import torch

from ..errors import InputError
from ..geometry.camera import Cameras
from ..options import check_options, documented, option
from ..render.holes import fill_holes
from ..render.plain import PlainRenderer, PlainRenderSettings
from ..render.rasterize import RasterSettings
from ..render.rasterizer import PointRasterizer
from ..scene.masks import check_mask, grabcut_mask, load_mask_file, parse_rect, person_mask
from ..scene.photo3d import Photo3D

PERSON = "person"
"""The ``--mask`` value that asks for the automatic person segmentation instead of a file
(a mask file called ``person`` is given as ``./person``)."""


class ViewRenderer(Protocol):
    def render(self, camera: Cameras, height: int, width: int, *, preview: bool = False,
               should_stop: Optional[Callable[[], bool]] = None) -> np.ndarray: ...


@documented
@dataclass(frozen=True)
class LayerSettings:
    """A foreground that layered stylization keeps unstylized (``stylize3d_core/export/layered.py``)."""

    mask: Optional[str] = option(None, metavar="IMAGE|person",
                                 help="foreground mask (PNG, the photo's size; white = keep the photo's colours): "
                                      "only the background is stylized. 'person': find the people "
                                      "automatically (MediaPipe selfie segmentation, offline).")
    mask_rect: Optional[str] = option(None, metavar="X,Y,W,H",
                                      help="find the foreground with GrabCut inside this rectangle (pixels of the "
                                           "photo file) instead of a mask file.")
    foreground_strength: Optional[float] = option(
        None, low=0.0, high=1.0, default_text="0: the original colours",
        help="style strength of the foreground (with --mask or --mask-rect).")

    def __post_init__(self) -> None:
        check_options(self)
        if self.mask is not None and self.mask_rect is not None:
            raise InputError("mask_rect", "give a mask file or a GrabCut rectangle, not both")
        if self.mask_rect is not None:
            parse_rect(self.mask_rect)
        if self.foreground_strength is not None and not self.active:
            raise InputError("foreground_strength", "needs a foreground: --mask or --mask-rect")

    @property
    def active(self) -> bool:
        return self.mask is not None or self.mask_rect is not None

    @property
    def mask_file(self) -> Optional[str]:
        """The mask file, or None (no mask, a GrabCut rectangle or ``--mask person``)."""
        return None if self.mask == PERSON else self.mask


def photo_mask(settings: LayerSettings, photo: Photo3D, file_size: Tuple[int, int]) -> np.ndarray:
    """The foreground (H, W) bool of the photo ``settings`` asks for; ``file_size`` is the photo file's (H, W)."""
    if settings.mask == PERSON:
        mask = person_mask(photo.rgb)
        if not mask.any():
            raise InputError("mask", "--mask person found no person in the photo; give a mask file or --mask-rect")
        return check_mask(mask, "--mask person")
    if settings.mask is not None:
        return load_mask_file(settings.mask, photo.size, file_size)
    if settings.mask_rect is None:
        raise InputError("mask", "no mask given")
    scale = photo.size[0] / file_size[0]
    return grabcut_mask(photo.rgb, parse_rect(settings.mask_rect), scale=scale)


class _AtStrength:
    """A Stylized3DPhoto rendered at a fixed strength (it switches the shared instance's strength)."""

    def __init__(self, stylized, strength: float) -> None:
        self.stylized, self.strength = stylized, float(strength)

    def render(self, camera: Cameras, height: int, width: int, *, preview: bool = False,
               should_stop: Optional[Callable[[], bool]] = None) -> np.ndarray:
        if self.stylized.strength != self.strength:
            self.stylized.set_strength(self.strength)
        return self.stylized.render(camera, height, width, preview=preview, should_stop=should_stop)


class LayeredRenderer:
    """Frames of a 3D photo whose foreground points keep their colours (see the module docstring).

    Args:
        photo: the 3D photo.
        foreground: (N,) bool over ``photo.points`` (:func:`~stylize3d_core.scene.masks.point_mask`).
        stylized: the photo's ``Stylized3DPhoto`` with its style set: the background, at its strength.
        foreground_strength: None keeps the original colours; else the foreground is stylized at this strength.
        settings: the plain renderer's settings (supersampling, depth tolerance).
    """

    def __init__(self, photo: Photo3D, foreground: np.ndarray, stylized, *,
                 foreground_strength: Optional[float] = None,
                 settings: PlainRenderSettings = PlainRenderSettings()) -> None:
        n = len(photo.points)
        if not isinstance(foreground, np.ndarray) or foreground.shape != (n,) or foreground.dtype != bool:
            raise InputError("foreground", f"expected an ({n},) bool array over the points")
        self.settings = settings
        self._xyz = torch.from_numpy(photo.points.xyz)
        self._fg = torch.from_numpy(foreground.astype(np.float32))[:, None]  # (N, 1)
        bg_strength = stylized.strength
        self.background = _AtStrength(stylized, bg_strength)
        self.foreground: ViewRenderer = (PlainRenderer(photo.points, settings) if foreground_strength is None
                                         else _AtStrength(stylized, foreground_strength))

    def coverage(self, camera: Cameras, height: int, width: int, *,
                 should_stop: Optional[Callable[[], bool]] = None) -> np.ndarray:
        """(H, W) float32 in [0, 1]: how much of each pixel's front surface is foreground."""
        raster = RasterSettings(height=int(height), width=int(width), depth_tolerance=self.settings.depth_tolerance,
                                supersample=self.settings.supersample)
        with torch.inference_mode():
            frags = PointRasterizer(raster)(self._xyz, self._fg, camera, should_stop=should_stop)
            cov = fill_holes(frags.image, frags.hole).clamp_(0.0, 1.0)[0]  # (H, W)
        return cov.numpy()

    def render(self, camera: Cameras, height: int, width: int, *, preview: bool = False,
               should_stop: Optional[Callable[[], bool]] = None) -> np.ndarray:
        """One frame (H, W, 3) float32 in [0, 1].

        ``should_stop`` is passed to each of the three renders (coverage, foreground,
        background): True stops with :class:`~stylize3d_core.errors.RenderInterrupted`.
        """
        cov = self.coverage(camera, height, width, should_stop=should_stop)[..., None]
        fg = self.foreground.render(camera, height, width, preview=preview, should_stop=should_stop)
        bg = self.background.render(camera, height, width, preview=preview, should_stop=should_stop)
        return np.clip(cov * fg + (1.0 - cov) * bg, 0.0, 1.0).astype(np.float32)

    def frames(self, cameras: Cameras, height: int, width: int) -> Iterator[np.ndarray]:
        for i in range(len(cameras)):
            yield self.render(cameras[i], height, width)
