"""Benchmark: the hidden layer's colour on real textures, against the truth behind pasted cards.

Flat-coloured cards are pasted, apart from each other, in front of each test photo
(``tests/benchmarks/photos.py``: the bundled samples and three scikit-image photos) on a
receding plane of depth; what the cards hide is the photo itself, so the LDI's hidden
layer behind them can be scored against it. Prints the PSNR of
the hidden colour against the photo, on the hidden pixels within ``--near`` pixels of a
card's outline (what the viewer's small moves uncover first) and on all of them (the
layer is as wide as the camera range needs: here most of each card).

    .venv/bin/python tests/benchmarks/bench_hidden_colour.py [--size 384]
"""

from __future__ import annotations

import argparse
from typing import Iterator, Tuple

import cv2
import numpy as np

from stylize3d_core.eval import metrics
from stylize3d_core.scene.ldi import LDISettings, build_ldi

from photos import test_photos  # this folder's module



def pasted_cards(size: int) -> Iterator[Tuple[str, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """(name, photo, photo with cards, depth, card mask) for every test photo, cards seeded by name."""
    for name, rgb in test_photos(size):
        h, w = rgb.shape[:2]
        rng = np.random.default_rng(sum(map(ord, name)))
        rows = np.linspace(0.0, 1.0, h, dtype=np.float32)[:, None]
        depth = np.broadcast_to(3.0 - 1.5 * rows, (h, w)).astype(np.float32).copy()  # a receding plane
        pasted, cards = rgb.copy(), np.zeros((h, w), bool)
        gap = 12
        for _ in range(40):
            if cards.mean() > 0.12:
                break
            ch, cw = int(rng.integers(h // 10, h // 4)), int(rng.integers(w // 14, w // 6))
            y, x = int(rng.integers(gap, h - ch - gap)), int(rng.integers(gap, w - cw - gap))
            if cards[y - gap : y + ch + gap, x - gap : x + cw + gap].any():
                continue  # apart, so what a card hides is the photo, not another card
            cards[y : y + ch, x : x + cw] = True
            depth[y : y + ch, x : x + cw] = 0.8
            pasted[y : y + ch, x : x + cw] = rng.uniform(0.0, 1.0, 3)
        yield name, rgb, pasted, depth, cards


def psnr(se: np.ndarray) -> float:
    """PSNR (dB) of the squared errors ``se`` (one value per pixel and channel)."""
    return metrics.psnr(np.sqrt(se), np.zeros_like(se))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=384, help="long side of the photos")
    parser.add_argument("--near", type=float, default=4.0, help="pixels from a card's outline scored as 'near'")
    args = parser.parse_args()
    cases = list(pasted_cards(args.size))
    names = [c[0] for c in cases]
    print(f"hidden colour PSNR (dB) near the outline (<= {args.near:g} px) / over the whole hidden layer")
    print(" ".join(f"{n:>18}" for n in names) + f" {'all photos':>14}")
    settings = LDISettings()
    cells, near_se, all_se = [], [], []
    for name, rgb, pasted, depth, cards in cases:
        ldi = build_ldi(pasted, depth, settings)
        region = ldi.photo_region
        hidden = ldi.hidden_mask[region] & cards
        inside = cv2.distanceTransform(cards.astype(np.uint8), cv2.DIST_L2, 5)
        near = hidden & (inside <= args.near)
        got = ldi.hidden_rgb[region]
        se_near, se_all = (got[near] - rgb[near]) ** 2, (got[hidden] - rgb[hidden]) ** 2
        near_se.append(se_near)
        all_se.append(se_all)
        cells.append(f"{psnr(se_near):6.2f} / {psnr(se_all):6.2f}")
    total = f"{psnr(np.concatenate(near_se)):5.2f} / {psnr(np.concatenate(all_se)):5.2f}"
    print(" ".join(f"{c:>18}" for c in cells) + f" {total:>14}")


if __name__ == "__main__":
    main()
