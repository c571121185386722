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
import secrets
import shutil
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
    # The name is chosen before anything is created, and the creation happens inside the ``try``
    # whose clean-up removes it: a signal (Ctrl-C raises in the main thread between any two
    # bytecodes) landing the instant the temporary exists still has it removed.
    tmp: Optional[Path] = None
    try:
        if directory:
            tmp = _unused_name(parent, f".{dest.name}.", ".partial")
        else:
            tmp = _unused_name(parent, f".{dest.stem}.", f".partial{dest.suffix}")
        try:
            _create(tmp, directory=directory, dest=dest)
        except ExportError:
            tmp = None  # nothing of ours exists under that name (it may be another process's)
            raise
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
            # some writers (safetensors) recreate the file as 0600: give it a normal file's mode.
            _rename(lambda: (os.chmod(tmp, 0o666 & ~_umask()), os.replace(tmp, dest)), dest)
    except BaseException:
        if tmp is None:
            pass
        elif tmp.is_dir():
            shutil.rmtree(tmp, ignore_errors=True)
        else:
            tmp.unlink(missing_ok=True)
        raise


def _unused_name(parent: Path, prefix: str, suffix: str) -> Path:
    """A random name in ``parent`` that nothing has yet (created by :func:`_create`, exclusively)."""
    for _ in range(100):
        candidate = parent / f"{prefix}{secrets.token_hex(5)}{suffix}"
        if not os.path.lexists(candidate):
            return candidate
    raise ExportError(f"{parent}: cannot find an unused temporary name; nothing was written")


def _create(tmp: Path, *, directory: bool, dest: Path) -> None:
    """Create the empty temporary file or folder ``tmp`` (the umask gives it a normal mode).

    Exclusive: if something appeared under that name meanwhile (another process), this fails rather
    than take it over.
    """
    try:
        if directory:
            os.mkdir(tmp, 0o777)
        else:
            os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
    except OSError as e:
        raise ExportError(f"{dest}: cannot create a file in {tmp.parent}: {describe_os_error(e)}") from e


def _rename(step: Callable[[], object], dest: Path) -> None:
    """Run a finishing step (flush, rename); an OSError is an ExportError naming ``dest``."""
    try:
        step()
    except ExportError:
        raise
    except OSError as e:
        raise ExportError(f"{dest}: could not finish writing: {describe_os_error(e)}; nothing was written") from e


def _replace_folder(tmp: Path, dest: Path, parent: Path) -> None:
    if not dest.exists():
        os.replace(tmp, dest)
        return
    old = _unused_name(parent, f".{dest.name}.", ".old")
    try:
        os.replace(dest, old)  # two renames of folders, each atomic
        os.replace(tmp, dest)
    finally:  # also on an interruption between the two: the user's folder goes back in place
        if old.exists():
            if dest.exists():
                shutil.rmtree(old, ignore_errors=True)
            else:
                os.replace(old, dest)


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
