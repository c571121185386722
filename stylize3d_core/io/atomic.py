"""Write files so that a failed or cancelled write never replaces a good file.

Writers produce a temporary file in the destination's folder (same file system,
so the final :func:`os.replace` is atomic) and rename it over the destination
only when everything was written. On any exception -- including
``KeyboardInterrupt`` and a cancellation raised by a progress callback -- the
temporary file is removed and the destination is left as it was.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path
from typing import Iterator, Union

from ..errors import ExportError

PathLike = Union[str, "os.PathLike[str]"]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(destination: PathLike, *, directory: bool = False) -> Iterator[Path]:
    """Yield a temporary path beside ``destination``; rename it into place on success.

    Args:
        destination: the final file (or folder, with ``directory=True``).
        directory: yield an empty temporary folder instead of a file path; on
            success it replaces ``destination`` (an existing folder there is
            removed only after the new one is complete).

    The temporary name keeps the destination's suffix, so writers that pick a
    format from the extension (imageio, Open3D) still see it.
    """
    dest = Path(destination)
    parent = dest.parent if str(dest.parent) else Path(".")
    if not parent.is_dir():
        raise ExportError(f"{dest}: folder {parent} does not exist")
    if directory:
        tmp = Path(tempfile.mkdtemp(prefix=f".{dest.name}.", suffix=".partial", dir=parent))
        os.chmod(tmp, 0o777 & ~_umask())
    else:
        fd, name = tempfile.mkstemp(prefix=f".{dest.stem}.", suffix=f".partial{dest.suffix}", dir=parent)
        os.close(fd)
        tmp = Path(name)
    try:
        yield tmp
        if directory:
            if dest.exists():
                old = Path(tempfile.mkdtemp(prefix=f".{dest.name}.", suffix=".old", dir=parent))
                os.replace(dest, old / dest.name)
                os.replace(tmp, dest)
                shutil.rmtree(old, ignore_errors=True)
            else:
                os.replace(tmp, dest)
        else:
            if tmp.stat().st_size == 0:
                raise ExportError(f"{dest}: the writer produced an empty file; nothing was written")
            # mkstemp (and some writers, e.g. safetensors) create 0600 files: give it a normal file's mode.
            os.chmod(tmp, 0o666 & ~_umask())
            os.replace(tmp, dest)
    except BaseException:
        if tmp.is_dir():
            shutil.rmtree(tmp, ignore_errors=True)
        else:
            tmp.unlink(missing_ok=True)
        raise
