"""Layered stylization in the viewer (paper Sec. 4.5): a foreground of the open photo kept unstylized.

:class:`ViewerLayers` holds the foreground mask over the photo (a mask file or
GrabCut in a rectangle, ``stylize3d_core/scene/masks.py``), the points it selects
(:func:`~stylize3d_core.scene.masks.point_mask`: it follows the LDI, the hidden
layer behind the foreground is background) and the foreground's strength. The
session's stylized views go through the library's
:class:`~stylize3d_core.export.layered.LayeredRenderer` built from them, so the
view, the screenshots and every export show the same composition. No GUI here:
the session (compute worker) uses it.
"""

from __future__ import annotations

from typing import Optional, Tuple

import numpy as np

from stylize3d_core.errors import InputError
from stylize3d_core.export.layered import LayeredRenderer
from stylize3d_core.scene.masks import check_mask, point_mask
from stylize3d_core.scene.photo3d import Photo3D


class ViewerLayers:
    """A foreground mask on one 3D photo and the layered renderer of its stylized views.

    Args:
        photo: the 3D photo the mask is over.
        name: the photo's file (a rebuild of the same file keeps the mask, :meth:`rebase`).
        mask: (H, W) bool over the photo as loaded, True on the foreground (with some background).
        foreground_strength: the foreground's style strength; 0 (or None) keeps its original colours.
        source: where the mask came from (for messages), e.g. the mask file or "GrabCut".

    Thread use: the compute worker's (as the session).
    """

    def __init__(self, photo: Photo3D, name: str, mask: np.ndarray, foreground_strength: Optional[float] = None,
                 source: str = "mask") -> None:
        if not isinstance(mask, np.ndarray) or mask.dtype != bool or mask.shape != tuple(photo.size):
            h, w = photo.size
            raise InputError(source, f"expected a {w}x{h} bool mask over the photo, got "
                                     f"{getattr(mask, 'shape', None)} {getattr(mask, 'dtype', '')}")
        check_mask(mask, source)
        if foreground_strength is not None and not 0.0 <= float(foreground_strength) <= 1.0:
            raise InputError("foreground strength", f"must be in [0, 1], got {foreground_strength!r}")
        self.photo, self.name, self.mask, self.source = photo, str(name), mask, str(source)
        fs = None if foreground_strength is None or float(foreground_strength) == 0.0 else float(foreground_strength)
        self.foreground_strength = fs  # None: the original colours (the library's convention)
        self.points = point_mask(photo.ldi, mask)  # (N,) bool over photo.points
        self._renderer: Optional[LayeredRenderer] = None
        self._key: Optional[Tuple[int, float]] = None

    @property
    def fraction(self) -> float:
        """The share of the photo's pixels that are foreground."""
        return float(self.mask.mean())

    def with_strength(self, foreground_strength: Optional[float]) -> "ViewerLayers":
        """The same mask with another foreground strength."""
        return ViewerLayers(self.photo, self.name, self.mask, foreground_strength, self.source)

    def rebase(self, photo: Photo3D, name: str) -> Optional["ViewerLayers"]:
        """This mask on ``photo`` (the same file rebuilt, e.g. with another depth source: the mask follows
        its new LDI), or None when ``photo`` is another file or size."""
        if str(name) != self.name or tuple(photo.size) != tuple(self.photo.size):
            return None
        return ViewerLayers(photo, name, self.mask, self.foreground_strength, self.source)

    def renderer(self, stylized, strength: float) -> LayeredRenderer:
        """The layered renderer over ``stylized`` (the session's ``Stylized3DPhoto``) with the background at
        ``strength``; rebuilt when either changes (the library's renderer keeps the background strength it
        was made with)."""
        key = (id(stylized), float(strength))
        if self._renderer is None or self._key != key:
            if stylized.strength != float(strength):
                stylized.set_strength(float(strength))
            self._renderer = LayeredRenderer(self.photo, self.points, stylized,
                                             foreground_strength=self.foreground_strength)
            self._key = key
        return self._renderer
