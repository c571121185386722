"""Write rendered frames as an MP4 video, an animated GIF or a folder of PNG frames.

The format comes from the destination path:

* ``*.mp4``: H.264 (libx264, yuv420p, ``+faststart``) through imageio's ffmpeg
  plugin and the ffmpeg binary that ``imageio-ffmpeg`` ships (works offline).
  yuv420p needs even sizes: a frame with an odd height or width is padded by
  one row / column (a copy of the last one) at the bottom / right; even sizes
  are kept exactly (no rescaling).
* ``*.gif``: Pillow, one 256-colour median-cut palette per frame, no
  dithering, loops forever.
  GIF delays are stored in 1/100 s, so the frame delay is ``round(100 / fps)``
  hundredths (30 fps -> 0.03 s) and fps may be at most 50. Pillow merges
  identical consecutive frames into one longer frame (same playback). Pillow
  keeps every frame until the file is written.
* a folder (a path ending in ``/`` or with no suffix): ``frame_0000.png``,
  ``frame_0001.png``, ...

Every write is atomic (:func:`stylize3d_core.io.atomic.atomic_path`): frames go
to a temporary file or folder beside the destination, renamed into place only
when the last frame is written and the output reads back complete (MP4: ffmpeg
reads it back with the frame count and size written; GIF: every frame decodes;
PNG: every frame file verifies). A full disk, a file-size limit or a failing
encoder is an :class:`ExportError`; the old destination is untouched. If the frame iterator or the progress callback
raises -- a Cancel button raises :class:`ExportCancelled` from the callback --
the temporary output is removed and an existing destination is untouched.
"""

from __future__ import annotations

import contextlib
import math
import os
import re
import sys
import tempfile
from pathlib import Path
from typing import IO, Callable, Iterable, Iterator, Literal, Optional, Tuple

import numpy as np
from PIL import Image

from ..errors import ExportError, InputError, PathLike, Stylize3DError
from .atomic import atomic_path, describe_os_error
from .images import rgb_to_uint8

Progress = Callable[[int, Optional[int]], None]
"""``progress(done, total)``: called after each frame is written; ``total`` is None if unknown."""

VideoKind = Literal["mp4", "gif", "png"]
SUPPORTED = ".mp4, .gif, or a folder (path ending in '/' or without a suffix) for PNG frames"
FRAME_NAME = "frame_{:04d}.png"
_FRAME_RE = re.compile(r"^frame_\d{4,}\.png$")
_FFMPEG_PREFIX = re.compile(r"^\[[^]]*\]\s*")  # "[out#0/mp4 @ 0x55...] " before an ffmpeg message
MAX_GIF_FPS = 50.0
GIF_PALETTE_SAMPLES = 128 * 128
"""Pixels sampled per frame to build its GIF palette (see ``_gif_frame``)."""
_NO_FRAMES = "no frames to write (the frame sequence is empty)"


class ExportCancelled(Stylize3DError):
    """Raised by a progress callback to stop an export; the destination is left as it was."""


def video_kind(path: PathLike) -> VideoKind:
    """Which format ``path`` asks for; InputError for an unknown extension."""
    text = os.fspath(path)
    if text.endswith(("/", os.sep)):
        return "png"
    suffix = Path(text).suffix.lower()
    if suffix == "":
        return "png"
    if suffix == ".mp4":
        return "mp4"
    if suffix == ".gif":
        return "gif"
    raise InputError(text, f"unsupported video format {suffix!r}; supported: {SUPPORTED}")


def to_uint8_frame(frame: np.ndarray, index: int) -> np.ndarray:
    """Frame ``index`` checked and as uint8 (H, W, 3): :func:`~stylize3d_core.io.images.rgb_to_uint8`."""
    return rgb_to_uint8(frame, f"frame {index}")


class _FrameSource:
    """Validated uint8 frames from a user iterable, with progress reports and failure tracking.

    ``failed`` is set when the user's iterator or progress callback raised, so an
    exception that passes through an encoder is not mistaken for an encoder error.
    """

    def __init__(self, frames: Iterable[np.ndarray], n_frames: Optional[int], progress: Optional[Progress]):
        self._it = iter(frames)
        self.n_frames = n_frames
        self._progress = progress
        self.failed = False
        self.count = 0
        self.first = self._next()
        if self.first is None:
            raise InputError("frames", _NO_FRAMES)
        self.size = self.first.shape[:2]  # (H, W)

    def _next(self) -> Optional[np.ndarray]:
        try:
            raw = next(self._it)
        except StopIteration:
            return None
        except BaseException:
            self.failed = True
            raise
        frame = to_uint8_frame(raw, self.count)
        if self.count > 0 and frame.shape[:2] != self.size:
            raise InputError(
                f"frame {self.count}", f"size {frame.shape[:2]} differs from frame 0's {tuple(self.size)}"
            )
        self.count += 1
        if self.n_frames is not None and self.count > self.n_frames:
            raise InputError("frames", f"more frames than n_frames={self.n_frames}")
        return frame

    def _report(self, done: int) -> None:
        if self._progress is None:
            return
        try:
            self._progress(done, self.n_frames)
        except BaseException:
            self.failed = True
            raise

    def __iter__(self) -> Iterator[np.ndarray]:
        frame = self.first
        done = 0
        while frame is not None:
            yield frame
            done += 1
            self._report(done)  # the consumer asked for the next frame: frame `done - 1` is written
            frame = self._next()
        if self.n_frames is not None and done != self.n_frames:
            raise InputError("frames", f"got {done} frames, expected n_frames={self.n_frames}")


def _pad_even(frame: np.ndarray) -> np.ndarray:
    """Pad (H, W, 3) to even H and W by repeating the last row / column."""
    h, w = frame.shape[:2]
    if h % 2 == 0 and w % 2 == 0:
        return frame
    return np.pad(frame, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")  # (H', W', 3)


def _probe_mp4(path: Path) -> Tuple[int, Optional[Tuple[int, int]]]:
    """(frame count, (width, height)) of an MP4, read back by ffmpeg (packets copied, not decoded).

    Raises ExportError with ffmpeg's own words when the file does not read back.
    """
    import subprocess

    import imageio_ffmpeg

    cmd = [imageio_ffmpeg.get_ffmpeg_exe(), "-nostdin", "-hide_banner", "-i", str(path),
           "-map", "0:v:0", "-c", "copy", "-f", "null", "-"]
    try:
        run = subprocess.run(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                             timeout=600)
    except (OSError, subprocess.SubprocessError) as e:
        raise ExportError(f"could not run ffmpeg to check the written video: {e}") from e
    err = run.stderr.decode("utf-8", "replace")
    frames = re.findall(r"frame=\s*(\d+)", err)
    size = re.search(r"Video: .*?, (\d{2,5})x(\d{2,5})", err)
    if run.returncode != 0 or not frames:
        lines = [ln.strip() for ln in err.splitlines() if ln.strip() and not ln.startswith(" ")]
        raise ExportError(f"ffmpeg cannot read it back ({lines[-1] if lines else f'exit status {run.returncode}'})")
    return int(frames[-1]), (int(size.group(1)), int(size.group(2))) if size else None


def _verify_mp4(dest: Path, source: "_FrameSource", log: Optional[IO[bytes]] = None) -> Callable[[Path], None]:
    def verify(tmp: Path) -> None:
        h, w = source.size
        want = (w + w % 2, h + h % 2)
        try:
            count, size = _probe_mp4(tmp)
        except ExportError as e:
            raise ExportError(f"{dest}: the written video is incomplete{_ffmpeg_said(log)}: {e}"
                              f"{_free_hint(dest)}") from None
        if count != source.count or size != want:
            raise ExportError(f"{dest}: the written video is incomplete{_ffmpeg_said(log)}: it reads back as "
                              f"{count} frames of {size}, {source.count} frames of {want} were written"
                              f"{_free_hint(dest)}")
    return verify


def _free_hint(dest: Path) -> str:
    """'; the disk is full (N bytes free)' when the destination's disk is (nearly) full, else ''."""
    import shutil

    try:
        free = shutil.disk_usage(dest.parent if str(dest.parent) else ".").free
    except OSError:
        return ""
    return f"; the disk is full ({free:,} bytes free)" if free < 1024 * 1024 else ""


def _verify_gif(dest: Path, source: "_FrameSource") -> Callable[[Path], None]:
    def verify(tmp: Path) -> None:
        h, w = source.size
        try:
            with Image.open(tmp) as im:
                n = getattr(im, "n_frames", 1)
                ok = im.format == "GIF" and im.size == (w, h) and 1 <= n <= source.count
                for i in range(n):  # every frame decodes (a truncated GIF fails here)
                    im.seek(i)
                    im.load()
        except Exception as e:  # Pillow raises many types for a truncated file
            raise ExportError(f"{dest}: the written GIF does not read back ({e}){_free_hint(dest)}") from None
        if not ok:
            raise ExportError(f"{dest}: the written GIF is incomplete ({n} frames of {im.size}){_free_hint(dest)}")
    return verify


def _verify_png_folder(dest: Path, source: "_FrameSource") -> Callable[[Path], None]:
    def verify(tmp: Path) -> None:
        h, w = source.size
        names = sorted(p.name for p in tmp.iterdir())
        if names != [FRAME_NAME.format(i) for i in range(source.count)]:
            raise ExportError(f"{dest}: the frames folder is incomplete ({len(names)} of {source.count} files)")
        for name in names:
            try:
                with Image.open(tmp / name) as im:
                    size = im.size
                    im.verify()
            except Exception as e:
                raise ExportError(f"{dest}: frame {name} does not read back ({e}){_free_hint(dest)}") from None
            if size != (w, h):
                raise ExportError(f"{dest}: frame {name} reads back as {size}, not {(w, h)}")
    return verify


def _write_mp4(tmp: Path, source: _FrameSource, fps: float, quality: float, log: Optional[IO[bytes]] = None) -> None:
    """Encode with ffmpeg; its error messages go to ``log`` (read by the check) instead of the console."""
    import imageio.v2 as iio  # lazy: imageio's plugin registry is slow to import

    writer = iio.get_writer(
        str(tmp), format="FFMPEG", mode="I", fps=fps, codec="libx264", pixelformat="yuv420p",
        quality=quality, macro_block_size=1, ffmpeg_log_level="error",
        output_params=["-movflags", "+faststart"],
    )
    try:
        for i, frame in enumerate(source):
            if i == 0 and log is not None:
                with _stderr_to(log):  # the first frame starts ffmpeg, which inherits this stderr
                    writer.append_data(_pad_even(frame))
            else:
                writer.append_data(_pad_even(frame))
    finally:
        writer.close()


@contextlib.contextmanager
def _stderr_to(log: IO[bytes]) -> Iterator[None]:
    """Point file descriptor 2 at ``log`` while a child process starts (it keeps the file)."""
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        os.dup2(log.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def _ffmpeg_said(log: Optional[IO[bytes]]) -> str:
    """' (ffmpeg: <its last error line>)' from ffmpeg's captured stderr, or ''."""
    if log is None:
        return ""
    log.seek(0)
    lines = [ln.strip() for ln in log.read().decode("utf-8", "replace").splitlines() if ln.strip()]
    if not lines:
        return ""
    return f" (ffmpeg: {_FFMPEG_PREFIX.sub('', lines[-1])[:200]})"


def _gif_frame(frame: np.ndarray) -> Image.Image:
    """(H, W, 3) uint8 -> a 256-colour palette image.

    The palette is a median cut of a regular subsample of about
    GIF_PALETTE_SAMPLES pixels (Pillow's full-frame median cut costs ~0.1 s at
    512x512, the subsample ~15 ms at nearly the same error); every pixel then
    takes its nearest palette colour, without dithering (dither noise flickers
    from frame to frame and inflates the file).
    """
    h, w = frame.shape[:2]
    step = max(1, int(math.sqrt(h * w / GIF_PALETTE_SAMPLES)))
    sample = Image.fromarray(np.ascontiguousarray(frame[::step, ::step]))  # (H/step, W/step, 3)
    palette = sample.convert("P", palette=Image.Palette.ADAPTIVE, colors=256)
    return Image.fromarray(frame).quantize(palette=palette, dither=Image.Dither.NONE)


def _write_gif(tmp: Path, source: _FrameSource, fps: float) -> None:
    delay_ms = 10 * max(2, round(100.0 / fps))  # GIF delays are in 1/100 s
    images = (_gif_frame(f) for f in source)
    first = next(images)
    first.save(tmp, format="GIF", save_all=True, append_images=images, duration=delay_ms, loop=0)


def _write_png(tmp: Path, source: _FrameSource) -> None:
    for i, frame in enumerate(source):
        Image.fromarray(frame).save(tmp / FRAME_NAME.format(i), format="PNG", compress_level=4)


def _check_frames_folder(dest: Path) -> None:
    """Refuse to replace anything but an earlier export of PNG frames."""
    if not dest.exists():
        return
    if not dest.is_dir():
        raise InputError(dest, "exists and is not a folder; PNG frames need a folder")
    others = [p.name for p in dest.iterdir() if not _FRAME_RE.match(p.name)]
    if others:
        raise InputError(
            dest, f"folder exists and holds other files ({', '.join(sorted(others)[:3])}, ...); "
            "PNG frames replace the whole folder, so choose a new or empty folder"
        )


def write_video(
    path: PathLike,
    frames: Iterable[np.ndarray],
    *,
    fps: float = 30,
    n_frames: Optional[int] = None,
    progress: Optional[Progress] = None,
    quality: float = 8,
) -> Path:
    """Write ``frames`` to ``path`` as MP4, GIF or PNG frames (see the module docstring), atomically.

    Args:
        path: destination; its suffix picks the format.
        frames: iterable of (H, W, 3) frames, uint8 or float in [0, 1], all the same
            size. Consumed once, lazily (MP4 and PNG hold one frame at a time).
        fps: frames per second, > 0 (GIF: at most 50). Default 30 (public code).
        n_frames: how many frames ``frames`` yields, if known: passed to
            ``progress`` as the total, and a different count is an InputError.
            Default None (``len(frames)`` when ``frames`` has a length).
        progress: ``progress(done, total)`` after each written frame. Raise
            :class:`ExportCancelled` from it to cancel.
        quality: MP4 quality, 1 (smallest) to 10 (best); 8 is H.264 CRF 10. Ignored
            by GIF and PNG.
    Returns:
        The destination path.
    Raises:
        InputError: unknown format, bad settings, zero frames, a bad frame.
        ExportError: the encoder or the disk failed; the destination is untouched.
        Whatever the frame iterator or the progress callback raised (e.g.
        ExportCancelled), after removing the temporary output.
    """
    kind = video_kind(path)
    dest = Path(path)
    fps_v = float(fps)
    if not (np.isfinite(fps_v) and fps_v > 0):
        raise InputError("fps", f"must be a finite number > 0, got {fps!r}")
    if kind == "gif" and fps_v > MAX_GIF_FPS:
        raise InputError("fps", f"a GIF plays at most {MAX_GIF_FPS:g} fps (delays are in 1/100 s), got {fps!r}")
    q = float(quality)
    if not 1.0 <= q <= 10.0:
        raise InputError("quality", f"must be in [1, 10], got {quality!r}")
    if n_frames is None and hasattr(frames, "__len__"):
        n_frames = len(frames)  # type: ignore[arg-type]
        if n_frames == 0:
            raise InputError("frames", _NO_FRAMES)
    if n_frames is not None and (isinstance(n_frames, bool) or int(n_frames) != n_frames or n_frames < 1):
        raise InputError("n_frames", f"must be an integer >= 1 or None, got {n_frames!r}")
    if kind == "png":
        _check_frames_folder(dest)
    source = _FrameSource(frames, None if n_frames is None else int(n_frames), progress)
    log = tempfile.TemporaryFile() if kind == "mp4" else None  # ffmpeg's stderr
    try:
        verify = _verify_mp4(dest, source, log) if kind == "mp4" else \
            {"gif": _verify_gif, "png": _verify_png_folder}[kind](dest, source)
        with atomic_path(dest, directory=(kind == "png"), verify=verify) as tmp:
            if kind == "mp4":
                _write_mp4(tmp, source, fps_v, q, log)
            elif kind == "gif":
                _write_gif(tmp, source, fps_v)
            else:
                _write_png(tmp, source)
    except (OSError, RuntimeError, ValueError) as e:
        if source.failed or isinstance(e, Stylize3DError):
            raise
        raise ExportError(f"{dest}: could not write the {kind.upper()} output: {describe_os_error(e)}"
                          f"{_ffmpeg_said(log)}") from e
    finally:
        if log is not None:
            log.close()
    return dest


def console_progress(desc: str = "export") -> Progress:
    """A ``progress`` callback drawing a tqdm bar on the console (for the command line).

    The bar closes itself when ``done`` reaches ``total``.
    """
    from tqdm import tqdm

    bar: Optional[tqdm] = None

    def report(done: int, total: Optional[int]) -> None:
        nonlocal bar
        if bar is None:
            bar = tqdm(total=total, desc=desc, unit="frame")
        bar.update(done - bar.n)
        if total is not None and done >= total:
            bar.close()

    return report
