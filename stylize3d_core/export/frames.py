"""Write frames by the destination's suffix: what :mod:`stylize3d_core.io.video` writes, plus animated WebP.

* ``*.webp``: an animated WebP (Pillow, lossy at quality 90, loops forever),
  each frame shown ``round(1000 / fps)`` ms; Pillow keeps every frame until the
  file is written. Written atomically, like the others.
* anything else: :func:`stylize3d_core.io.video.write_video` (MP4, GIF, PNG frames).
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterable, Optional

import numpy as np
from PIL import Image

from ..errors import ExportError, InputError, PathLike, Stylize3DError
from ..io.atomic import atomic_path
from ..io.images import rgb_to_uint8
from ..io.video import Progress, video_kind, write_video

MAX_WEBP_FPS = 1000.0
"""WebP frame durations are whole milliseconds."""


def output_kind(path: PathLike) -> str:
    """"webp" for ``*.webp``, else the :func:`~stylize3d_core.io.video.video_kind` ("mp4", "gif", "png")."""
    if Path(path).suffix.lower() == ".webp" and not str(path).endswith("/"):
        return "webp"
    return video_kind(path)


def _write_webp(dest: Path, frames: Iterable[np.ndarray], fps: float, n_frames: Optional[int],
                progress: Optional[Progress]) -> Path:
    images = []
    size = None
    for i, frame in enumerate(frames):
        f = rgb_to_uint8(frame, f"frame {i}")
        if size is None:
            size = f.shape[:2]
        elif f.shape[:2] != size:
            raise InputError(f"frame {i}", f"size {f.shape[:2]} differs from frame 0's {tuple(size)}")
        images.append(Image.fromarray(f))
        if progress is not None:
            progress(i + 1, n_frames)
    if not images:
        raise InputError("frames", "no frames to write (the frame sequence is empty)")
    if n_frames is not None and len(images) != n_frames:
        raise InputError("frames", f"got {len(images)} frames, expected n_frames={n_frames}")
    duration = max(1, int(round(1000.0 / fps)))
    try:
        with atomic_path(dest) as tmp:
            images[0].save(tmp, format="WEBP", save_all=True, append_images=images[1:], duration=duration,
                           loop=0, quality=90, method=4)
    except Stylize3DError:
        raise
    except (OSError, ValueError, RuntimeError) as e:
        raise ExportError(f"{dest}: could not write the WebP animation: {e}") from e
    return dest


def write_frames(path: PathLike, frames: Iterable[np.ndarray], *, fps: float = 30, n_frames: Optional[int] = None,
                 progress: Optional[Progress] = None) -> Path:
    """Write ``frames`` to ``path`` as MP4, GIF, PNG frames or an animated WebP (by its suffix), atomically."""
    if output_kind(path) != "webp":
        return write_video(path, frames, fps=fps, n_frames=n_frames, progress=progress)
    fps_v = float(fps)
    if not (np.isfinite(fps_v) and 0 < fps_v <= MAX_WEBP_FPS):
        raise InputError("fps", f"must be a finite number in (0, {MAX_WEBP_FPS:g}], got {fps!r}")
    return _write_webp(Path(path), frames, fps_v, n_frames, progress)
