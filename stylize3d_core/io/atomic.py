"""Write files so that a failed or cancelled write never replaces a good file.

Writers produce a temporary file in the destination's folder (same file system,
so the final :func:`os.replace` is atomic) and rename it over the destination
only when everything was written *and checked*: the file is flushed to disk
(``fsync``, which also reports delayed write errors), must not be empty, and is
read back before the rename -- by the writer's own ``verify`` function, else by
a check chosen from the suffix (images must decode their header and data
chunks, ``.json`` must parse). On any exception -- including
``KeyboardInterrupt`` and a cancellation raised by a progress callback -- the
temporary file is removed and the destination is left as it was.

**Commit checks** (:func:`add_commit_check`): functions called just before
every rename; one that raises stops the commit the same way. The command line
registers one that raises when a signal was received: Python drops an
exception raised by a signal handler in some places (a callback run by the
import machinery or a finaliser prints it as "Exception ignored" and goes on),
and without the check such an export would run to its end and replace the
user's file after the user pressed Ctrl-C.

:func:`write_atomically` wraps the common case: write, verify, rename, and turn
any write error (disk full, file too large, I/O error, broken pipe, permission
denied) into an :class:`~stylize3d_core.errors.ExportError` that names the
destination, with an up-front free-space check when the size is known.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Callable, Iterator, List, Optional, Union

from ..errors import ExportError

PathLike = Union[str, "os.PathLike[str]"]
Verify = Callable[[Path], None]
"""``verify(tmp)``: raise :class:`ExportError` if the written temporary file (or folder) is incomplete."""

FREE_SPACE_MARGIN = 64 * 1024
"""Bytes kept free on top of a known output size by :func:`check_free_space` (file-system metadata)."""

_IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".webp", ".tif", ".tiff", ".gif")
_REASONS = {
    errno.ENOSPC: "the disk is full",
    errno.EDQUOT: "the disk quota is exhausted",
    errno.EFBIG: "the file is larger than the file system or the file-size limit allows",
    errno.EIO: "an input/output error on the disk",
    errno.EPIPE: "the encoder stopped reading (broken pipe)",
    errno.EACCES: "permission denied",
    errno.EPERM: "permission denied",
    errno.EROFS: "the file system is read-only",
}


_commit_checks: List[Callable[[], None]] = []


def add_commit_check(check: Callable[[], None]) -> None:
    """Call ``check()`` before every rename of :func:`atomic_path`; if it raises, nothing is renamed
    (the temporary output is removed) and the exception propagates. Added once per function."""
    if check not in _commit_checks:
        _commit_checks.append(check)


def remove_commit_check(check: Callable[[], None]) -> None:
    """Undo :func:`add_commit_check` (no error if ``check`` was not added)."""
    if check in _commit_checks:
        _commit_checks.remove(check)


def _run_commit_checks() -> None:
    for check in tuple(_commit_checks):
        check()


def describe_os_error(e: BaseException) -> str:
    """A short plain-words reason for a write error (``the disk is full (No space left on device)``)."""
    if isinstance(e, ExportError):
        return str(e)
    code = getattr(e, "errno", None)
    text = getattr(e, "strerror", None) or str(e) or type(e).__name__
    reason = _REASONS.get(code) if code is not None else None
    return f"{reason} ({text})" if reason else text


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def check_free_space(destination: PathLike, size: int) -> None:
    """ExportError if the destination's file system has less than ``size`` bytes (plus a margin) free."""
    dest = Path(destination)
    parent = dest.parent if str(dest.parent) else Path(".")
    try:
        free = shutil.disk_usage(parent).free
    except OSError:
        return  # cannot tell: the write itself will report a full disk
    if free < size + FREE_SPACE_MARGIN:
        raise ExportError(
            f"{dest}: not enough free space: the output needs about {size:,} bytes, "
            f"the disk has {free:,} bytes free; nothing was written"
        )


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def verify_by_suffix(path: Path, destination: Path) -> None:
    """The default read-back check of a written file: images decode, ``.json`` parses."""
    suffix = destination.suffix.lower()
    if suffix in _IMAGE_SUFFIXES:
        from PIL import Image

        try:
            with Image.open(path) as im:
                im.verify()  # chunk structure and checksums, without decoding the pixels
            with Image.open(path) as im:
                im.load()  # and the pixels of the (first) image decode
        except Exception as e:  # Pillow raises many types for a truncated file
            raise ExportError(f"{destination}: the written image does not read back ({e}); nothing was written") from e
    elif suffix == ".json":
        try:
            json.loads(path.read_text(encoding="utf-8"))
        except (UnicodeDecodeError, ValueError) as e:
            raise ExportError(f"{destination}: the written JSON does not read back ({e}); nothing was written") from e


@contextlib.contextmanager
def atomic_path(
    destination: PathLike, *, directory: bool = False, verify: Optional[Verify] = None
) -> Iterator[Path]:
    """Yield a temporary path beside ``destination``; check it and rename it into place on success.

    Args:
        destination: the final file (or folder, with ``directory=True``).
        directory: yield an empty temporary folder instead of a file path; on
            success it replaces ``destination`` (an existing folder there is
            removed only after the new one is complete).
        verify: ``verify(tmp)`` runs after the writer finished and before the
            rename; it raises :class:`ExportError` when the output is incomplete.
            Default: :func:`verify_by_suffix` for files, nothing for folders.

    The temporary name keeps the destination's suffix, so writers that pick a
    format from the extension (imageio, Open3D) still see it. Failures of the
    temporary file itself (cannot create, flush or rename it) are ExportErrors.
    """
    dest = Path(destination)
    parent = dest.parent if str(dest.parent) else Path(".")
    if not parent.is_dir():
        raise ExportError(f"{dest}: folder {parent} does not exist")
    try:
        if directory:
            tmp = Path(tempfile.mkdtemp(prefix=f".{dest.name}.", suffix=".partial", dir=parent))
            os.chmod(tmp, 0o777 & ~_umask())
        else:
            fd, name = tempfile.mkstemp(prefix=f".{dest.stem}.", suffix=f".partial{dest.suffix}", dir=parent)
            os.close(fd)
            tmp = Path(name)
    except OSError as e:
        raise ExportError(f"{dest}: cannot create a file in {parent}: {describe_os_error(e)}") from e
    try:
        yield tmp
        if directory:
            if verify is not None:
                verify(tmp)
            _run_commit_checks()
            _rename(lambda: _replace_folder(tmp, dest, parent), dest)
        else:
            if tmp.stat().st_size == 0:
                raise ExportError(f"{dest}: the writer produced an empty file; nothing was written")
            _rename(lambda: _fsync(tmp), dest)
            if verify is not None:
                verify(tmp)
            else:
                verify_by_suffix(tmp, dest)
            _run_commit_checks()
            # mkstemp (and some writers, e.g. safetensors) create 0600 files: give it a normal file's mode.
            _rename(lambda: (os.chmod(tmp, 0o666 & ~_umask()), os.replace(tmp, dest)), dest)
    except BaseException:
        if tmp.is_dir():
            shutil.rmtree(tmp, ignore_errors=True)
        else:
            tmp.unlink(missing_ok=True)
        raise


def _rename(step: Callable[[], object], dest: Path) -> None:
    """Run a finishing step (flush, rename); an OSError is an ExportError naming ``dest``."""
    try:
        step()
    except ExportError:
        raise
    except OSError as e:
        raise ExportError(f"{dest}: could not finish writing: {describe_os_error(e)}; nothing was written") from e


def _replace_folder(tmp: Path, dest: Path, parent: Path) -> None:
    if dest.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{dest.name}.", suffix=".old", dir=parent))
        os.replace(dest, old / dest.name)
        os.replace(tmp, dest)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.replace(tmp, dest)


def write_atomically(
    destination: PathLike,
    what: str,
    write: Callable[[Path], object],
    *,
    verify: Optional[Verify] = None,
    size: Optional[int] = None,
) -> Path:
    """``write(tmp)`` then check and rename into ``destination``; any write error is an ExportError.

    Args:
        destination: the final file.
        what: what is written, for messages ("point cloud", "camera path").
        write: writes the whole output to the temporary path it is given.
        verify: the read-back check (see :func:`atomic_path`).
        size: the output's size in bytes when known: checked against the free
            space before anything is written.
    Returns:
        The destination path.
    Raises:
        ExportError: naming the destination and the reason (disk full, ...);
            the destination is untouched and no temporary file is left.
    """
    dest = Path(destination)
    if size is not None:
        check_free_space(dest, size)
    try:
        with atomic_path(dest, verify=verify) as tmp:
            write(tmp)
    except ExportError:
        raise
    except OSError as e:
        raise ExportError(f"{dest}: could not write the {what}: {describe_os_error(e)}; nothing was written") from e
    return dest
