"""Contact sheet of the built-in depth prior before and after its rework, on real photos; blind boards.

    .venv/bin/python tools/make_depth_prior_sheet.py [--photos /work/shared/data/photos]
        [--out docs/depth_prior_sheet.png] [--before REV]
        [--boards /tmp/depth_boards] [--key /tmp/depth_boards_key.json] [--unseen 16 --out /tmp/unseen.png]

For each photo of :data:`PHOTOS` (chosen for variety: portrait, close-up,
indoor table top, street, vehicles in front, landscape slopes, aerial views,
a bridge, night scenes), three tiles stacked: the photo, the prior at git
revision ``--before`` (``tests/benchmarks/prior_before.py``) and this checkout's
prior. Depth is shown as in ``docs/depth_contact_sheet.png``: inverse depth
through turbo, 1st..99th percentile, red = near, blue = far. The photos are
training data and are not copied into the repository: only the sheet is.

With ``--boards``, one PNG per photo for a blind review: the photo on top, the
two depth maps below it side by side in a random order labelled only "A" and
"B"; the key (which letter is "after") goes to ``--key``, outside the boards
folder. ``--unseen N`` makes the sheet and boards of N other photos, drawn at random, for a review on
photos that did not steer the prior.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import random
from pathlib import Path
from typing import List

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _load(path: Path):
    """A script's module by its file (tests/benchmarks/ is no package)."""
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


from make_contact_sheet import colour_depth, label  # noqa: E402  (tools/, the script's folder, is on sys.path)

_before = _load(ROOT / "tests" / "benchmarks" / "prior_before.py")
BEFORE_REV, load_prior_at = _before.BEFORE_REV, _before.load_prior_at
from stylize3d_core.depth import prior as prior_after  # noqa: E402
from stylize3d_core.io.atomic import atomic_path  # noqa: E402
from stylize3d_core.io.images import load_image  # noqa: E402

PHOTOS = {
    "kodak_0004.jpg": "portrait",
    "kodak_0015.jpg": "close portrait",
    "unsplash_0055.jpg": "close-up",
    "kodak_0003.jpg": "indoor table top",
    "unsplash_0070.jpg": "street, boats in front",
    "kodak_0005.jpg": "vehicles in front",
    "kodak_0013.jpg": "landscape, river",
    "unsplash_0097.jpg": "landscape slope",
    "cc0_0040.jpg": "hill slope",
    "unsplash_0075.jpg": "aerial, forest",
    "unsplash_0107.jpg": "aerial, surf",
    "cc0_0031.jpg": "bridge",
    "kodak_0021.jpg": "lighthouse",
    "cc0_0039.jpg": "night city",
    "unsplash_0067.jpg": "night, wheel",
    "unsplash_0119.jpg": "sign on a plain",
}
"""Photos of the shared set (file name -> what it shows)."""

TILE_W = 212
COLUMNS = 4


TILE_H = 146


def tile(img: np.ndarray, width: int = TILE_W, height: int = 0) -> np.ndarray:
    """``img`` scaled to ``width`` (and at most ``height`` when > 0) keeping its aspect."""
    h, w = img.shape[:2]
    s = width / w if height <= 0 else min(width / w, height / h)
    return cv2.resize(img, (max(1, round(w * s)), max(1, round(h * s))), interpolation=cv2.INTER_AREA)


def to_u8(rgb: np.ndarray) -> np.ndarray:
    return (np.clip(rgb, 0, 1) * 255 + 0.5).astype(np.uint8)


def stack(tiles: List[np.ndarray], axis: int, gap: int = 4) -> np.ndarray:
    other = 1 - axis
    size = max(t.shape[other] for t in tiles)
    out = []
    for t in tiles:
        pad = [(0, 0), (0, 0), (0, 0)]
        pad[other] = (0, size - t.shape[other])
        out.append(np.pad(t, pad, constant_values=255))
        sep = np.full((gap, size, 3) if axis == 0 else (size, gap, 3), 255, np.uint8)
        out.append(sep)
    return np.concatenate(out[:-1], axis=axis)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--photos", type=Path, default=Path("/work/shared/data/photos"))
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "depth_prior_sheet.png")
    parser.add_argument("--before", default=BEFORE_REV)
    parser.add_argument("--boards", type=Path, default=None)
    parser.add_argument("--key", type=Path, default=Path("/tmp/depth_boards_key.json"))
    parser.add_argument("--seed", type=int, default=36)
    parser.add_argument("--unseen", type=int, default=0, metavar="N",
                        help="instead of the sheet's photos, N others of --photos drawn at random (--unseen-seed)")
    parser.add_argument("--unseen-seed", type=int, default=2026)
    args = parser.parse_args()
    photos = PHOTOS
    if args.unseen:
        others = sorted(p.name for p in args.photos.glob("*.jpg") if p.name not in PHOTOS)
        photos = {name: "not on the sheet" for name in random.Random(args.unseen_seed).sample(others, args.unseen)}
    before = load_prior_at(args.before)
    rng = np.random.default_rng(args.seed)
    blocks, key = [], {}
    if args.boards is not None:
        args.boards.mkdir(parents=True, exist_ok=True)
    for i, (name, what) in enumerate(photos.items()):
        rgb = load_image(args.photos / name).rgb
        d_before = colour_depth(before.estimate_prior(rgb).depth)
        d_after = colour_depth(prior_after.estimate_prior(rgb).depth)
        photo = to_u8(rgb)
        blocks.append(stack([label(tile(photo, TILE_W, TILE_H), f"{Path(name).stem}: {what}"),
                             label(tile(d_before, TILE_W, TILE_H), "before"),
                             label(tile(d_after, TILE_W, TILE_H), "after")], axis=0))
        print(f"{name}: {rgb.shape[1]}x{rgb.shape[0]} ({what})")
        if args.boards is not None:
            after_right = bool(rng.integers(0, 2))
            pair = [d_before, d_after] if after_right else [d_after, d_before]
            half = 480
            below = stack([label(tile(pair[0], half), "A"), label(tile(pair[1], half), "B")], axis=1, gap=8)
            board = stack([tile(photo, below.shape[1]), below], axis=0, gap=8)
            path = args.boards / f"board_{i + 1:02d}.png"
            cv2.imwrite(str(path), board[..., ::-1], [cv2.IMWRITE_PNG_COMPRESSION, 9])
            key[path.name] = {"photo": name, "after": "B" if after_right else "A"}
    lines = [stack(blocks[k:k + COLUMNS], axis=1, gap=8) for k in range(0, len(blocks), COLUMNS)]
    sheet = stack(lines, axis=0, gap=12)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(args.out) as tmp:
        if not cv2.imwrite(str(tmp), sheet[..., ::-1], [cv2.IMWRITE_PNG_COMPRESSION, 9]):
            raise SystemExit(f"could not write {args.out}")
    args.out.chmod(0o644)
    print(f"wrote {args.out} ({sheet.shape[1]}x{sheet.shape[0]}, {args.out.stat().st_size / 1e6:.2f} MB)")
    if args.boards is not None:
        args.key.write_text(json.dumps(key, indent=1) + "\n")
        print(f"wrote {len(key)} boards to {args.boards}, key to {args.key}")


if __name__ == "__main__":
    main()
