"""Real photos and paintings for training and evaluation: a fixed split of a folder of them.

The folder holds ``photos/`` and ``paintings/`` (JPEG or PNG files, any names;
a file's prefix up to its first ``_`` names its source, e.g. ``kodak_0003.jpg``).
Nothing of it ships: the files are read where they are, and only their names
reach a dataset's manifest or a model card.

The split is a pure function of the file names, so every machine and every run
holds out the same files:

* photos of the sources in :data:`HELD_OUT_PHOTO_SOURCES` are all held out (a
  whole source unseen in training); of the other photos, those whose name hashes
  into the lowest :data:`HELD_OUT_SHARE` are held out too;
* paintings of the sources in :data:`TRAIN_ONLY_PAINTING_SOURCES` always train
  (their rights allow training, not showing); of the others, those whose name
  hashes into the lowest :data:`HELD_OUT_SHARE` are held out.

The hash is BLAKE2b of the file name (not the path), read as a fraction in [0, 1).

Paintings whose bytes equal one of the bundled sample styles (``assets/styles``)
are on neither side: a sample style the README shows is never a training image,
and never an evaluation pair the model might have been tuned on.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import FrozenSet, Iterable, List, NamedTuple, Optional, Tuple

from ..errors import InputError, PathLike
from ..resources import style_image, style_names

IMAGE_SUFFIXES: Tuple[str, ...] = (".jpg", ".jpeg", ".png")
HELD_OUT_PHOTO_SOURCES: Tuple[str, ...] = ("kodak",)
"""Photo sources held out whole (the Kodak suite: a classic evaluation set)."""
TRAIN_ONLY_PAINTING_SOURCES: Tuple[str, ...] = ("wikiart",)
"""Painting sources that only ever train (never evaluated, shown or shipped)."""
HELD_OUT_SHARE = 0.2
"""Share of the other files held out, by name hash."""


class RealImageSplit(NamedTuple):
    """Sorted paths of each part of the split."""

    train_photos: List[Path]
    eval_photos: List[Path]
    train_paintings: List[Path]
    eval_paintings: List[Path]


def name_fraction(name: str) -> float:
    """A stable pseudo-random fraction in [0, 1) of a file name."""
    digest = hashlib.blake2b(name.encode("utf-8"), digest_size=8).digest()
    return int.from_bytes(digest, "big") / 2.0 ** 64


def source_of(name: str) -> str:
    """The source prefix of a file name (up to its first ``_``; the whole stem without one)."""
    stem = Path(name).stem
    return stem.split("_", 1)[0]


def _images(folder: Path) -> List[Path]:
    if not folder.is_dir():
        raise InputError(folder, "expected a folder of images")
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file())
    if not files:
        raise InputError(folder, f"holds no images ({', '.join(IMAGE_SUFFIXES)})")
    return files


def content_digest(path: Path) -> str:
    """BLAKE2b of a file's bytes (hex)."""
    return hashlib.blake2b(path.read_bytes(), digest_size=16).hexdigest()


def _digests(paths: Iterable[Path]) -> FrozenSet[str]:
    return frozenset(content_digest(p) for p in paths)


def split_real_images(root: PathLike, exclude: Optional[Iterable[PathLike]] = None) -> RealImageSplit:
    """Split ``root/photos`` and ``root/paintings`` (see the module docstring). Paintings with the same
    bytes as a file of ``exclude`` (default: the bundled sample styles) are left out of both sides."""
    base = Path(root)
    photos, paintings = _images(base / "photos"), _images(base / "paintings")
    excluded = _digests(Path(p) for p in ([style_image(n) for n in style_names()] if exclude is None else exclude))
    if excluded:
        paintings = [p for p in paintings if content_digest(p) not in excluded]
    eval_photo = [p for p in photos
                  if source_of(p.name) in HELD_OUT_PHOTO_SOURCES or name_fraction(p.name) < HELD_OUT_SHARE]
    eval_painting = [p for p in paintings if source_of(p.name) not in TRAIN_ONLY_PAINTING_SOURCES
                     and name_fraction(p.name) < HELD_OUT_SHARE]
    held_photos, held_paintings = set(eval_photo), set(eval_painting)
    return RealImageSplit(
        train_photos=[p for p in photos if p not in held_photos], eval_photos=eval_photo,
        train_paintings=[p for p in paintings if p not in held_paintings], eval_paintings=eval_painting,
    )


__all__ = ["RealImageSplit", "split_real_images", "content_digest", "name_fraction", "source_of", "HELD_OUT_SHARE",
           "HELD_OUT_PHOTO_SOURCES", "TRAIN_ONLY_PAINTING_SOURCES"]
