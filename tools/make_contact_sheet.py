"""Render a contact sheet of the bundled samples and their depth: photo | depth (colour-mapped).

    .venv/bin/python tools/make_contact_sheet.py [--samples assets/samples] [--out docs/depth_contact_sheet.png]

One row per photo in ``--samples`` (JPEG/PNG; files named ``*_right.*`` are
the right views of stereo pairs, not rows), with the built-in prior's depth.
Scikit-image's motorcycle stereo pair is added (from ``*_left.*`` /
``*_right.*`` files if the folder has them, else from scikit-image): once with
the prior and once with stereo depth. Depth is shown as inverse depth with the
turbo colour map, 1st..99th percentile: red is near, blue is far.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import List, Optional, Tuple

import cv2
import numpy as np


from stylize3d_core.depth.prior import estimate_prior  # noqa: E402
from stylize3d_core.depth.sources import StereoDepth  # noqa: E402
from stylize3d_core.depth.stereo import compute_disparity, disparity_to_depth, StereoSettings  # noqa: E402
from stylize3d_core.io.atomic import atomic_path  # noqa: E402
from stylize3d_core.io.images import load_image, load_image_array  # noqa: E402

ROW_HEIGHT = 200
IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".webp", ".tif", ".tiff")


def colour_depth(depth: np.ndarray) -> np.ndarray:
    """Depth (H, W) -> (H, W, 3) uint8 RGB: inverse depth through turbo, near = red."""
    inv = 1.0 / depth.astype(np.float64)
    lo, hi = np.percentile(inv, [1, 99])
    n = np.clip((inv - lo) / max(hi - lo, 1e-12), 0, 1)
    bgr = cv2.applyColorMap((n * 255 + 0.5).astype(np.uint8), cv2.COLORMAP_TURBO)
    return bgr[..., ::-1]


def label(img: np.ndarray, text: str) -> np.ndarray:
    """Write ``text`` in white on a dark box in the top-left corner of an (H, W, 3) uint8 RGB image (copy)."""
    out = img.copy()
    font, scale = cv2.FONT_HERSHEY_SIMPLEX, 0.45
    (tw, th), base = cv2.getTextSize(text, font, scale, 1)
    out[: th + base + 8, : tw + 10] //= 3
    cv2.putText(out, text, (5, th + 4), font, scale, (255, 255, 255), 1, cv2.LINE_AA)
    return out


def row(photo: np.ndarray, depth: np.ndarray, title: str, what: str) -> np.ndarray:
    """photo | depth, scaled to ROW_HEIGHT, as one (ROW_HEIGHT, W, 3) uint8 strip."""
    h, w = photo.shape[:2]
    size = (max(1, round(w * ROW_HEIGHT / h)), ROW_HEIGHT)
    p = cv2.resize((np.clip(photo, 0, 1) * 255 + 0.5).astype(np.uint8), size, interpolation=cv2.INTER_AREA)
    d = cv2.resize(colour_depth(depth), size, interpolation=cv2.INTER_NEAREST)
    gap = np.full((ROW_HEIGHT, 4, 3), 255, np.uint8)
    return np.concatenate([label(p, title), gap, label(d, what)], axis=1)


def stereo_pair(folder: Path) -> Tuple[np.ndarray, np.ndarray, str, Optional[Path]]:
    """(left, right, name, right_path) of the motorcycle pair: from the folder if there, else scikit-image."""
    lefts = sorted(p for p in folder.glob("*_left.*") if p.suffix.lower() in IMAGE_SUFFIXES)
    for left_path in lefts:
        stem = left_path.name[: -len("_left" + left_path.suffix)]
        rights = [p for p in folder.glob(f"{stem}_right.*") if p.suffix.lower() in IMAGE_SUFFIXES]
        if rights:
            left = load_image(left_path).rgb
            right = load_image(rights[0], max_size=max(left.shape[:2])).rgb
            return left, right, stem, rights[0]
    from skimage import data

    left, right, _ = data.stereo_motorcycle()
    return left.astype(np.float32) / 255.0, right.astype(np.float32) / 255.0, "motorcycle", None


def build_sheet(folder: Path) -> np.ndarray:
    rows: List[np.ndarray] = []
    photos = sorted(p for p in folder.glob("*") if p.suffix.lower() in IMAGE_SUFFIXES
                    and not p.stem.endswith("_right")) if folder.is_dir() else []
    for path in photos:
        if path.stem.endswith("_left"):
            continue  # shown with the stereo rows below
        rgb = load_image(path).rgb
        rows.append(row(rgb, estimate_prior(rgb).depth, path.stem, "prior"))
        print(f"{path.name}: {rgb.shape[1]}x{rgb.shape[0]}")
    left, right, name, right_path = stereo_pair(folder)
    rows.append(row(left, estimate_prior(left).depth, f"{name} (left view)", "prior"))
    if right_path is not None:
        depth = StereoDepth(right_path).estimate(load_image_array(left)).depth_map.depth
    else:
        result = compute_disparity(left, right)
        depth = disparity_to_depth(result.disparity, result.valid, StereoSettings())[0]
    rows.append(row(left, depth, f"{name} (left view)", "stereo (SGBM)"))
    width = max(r.shape[1] for r in rows)
    sep = np.full((4, width, 3), 255, np.uint8)
    padded = []
    for r in rows:
        padded += [np.pad(r, ((0, 0), (0, width - r.shape[1]), (0, 0)), constant_values=255), sep]
    return np.concatenate(padded[:-1], axis=0)


def main() -> None:
    root = Path(__file__).resolve().parents[1]
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=Path, default=root / "assets" / "samples")
    parser.add_argument("--out", type=Path, default=root / "docs" / "depth_contact_sheet.png")
    args = parser.parse_args()
    sheet = build_sheet(args.samples)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(args.out) as tmp:
        if not cv2.imwrite(str(tmp), sheet[..., ::-1], [cv2.IMWRITE_PNG_COMPRESSION, 9]):
            raise SystemExit(f"could not write {args.out}")
    args.out.chmod(0o644)  # the temporary file was private
    print(f"wrote {args.out} ({sheet.shape[1]}x{sheet.shape[0]})")


if __name__ == "__main__":
    main()
