"""Real photos in real paintings: measures that cannot be gamed, and blind boards for a person to judge.

``stylize3d bench quality --real DIR`` renders held-out photo x painting pairs
(:mod:`stylize3d_core.train.real_images`) with every method and measures each
frame:

* **style-embedding distance** (:func:`style_embedding_distance`): the Euclidean
  distance between the 100-d style vectors (the 2D network's style predictor,
  :class:`~stylize3d_core.models.style_prior.StylePrior`) of the frame and of the
  painting. It reads what the style network sees as the painting's style: its
  marks and palette together. It is never a training loss. It favours methods
  that use that network (the per-frame 2D network, stylize-then-bake, the style
  prior): use it beside the boards, not instead of them.
* **content edge F1** (:func:`edge_f1`): Canny edges of the frame against those
  of the plain frame of the same camera, matched within ``tolerance`` pixels
  (precision: share of the frame's edges near a plain edge; recall: share of
  the plain edges near one of the frame's). High: the scene's outlines survive.
* **geometric warp** (:func:`warp_split`): each view warped into another through
  the point cloud (:mod:`.consistency`), RMSE over the co-visible pixels, short
  range ``(t, t + 1)`` and long range ``(t, t + 7)``; and the same over only the
  pixels whose surface is the hidden layer (disoccluded: where a seam between
  the layers would show). A pixel counts where the bilinear sample of the other
  view reads one surface only (:func:`~.consistency.warp_view`); the bench also
  reports the figures with the single-pixel test, whose samples beside depth
  edges mix foreground and background.

**Blind boards** (:func:`write_boards`): for each pair, the photo and the
painting on top and two methods' frames below in random order ("A", "B"); the
key goes to a separate JSON file, so a reviewer who sees only the boards
judges without knowing which is which (:func:`decode_verdicts` tallies).
**Seam boards** (:func:`seam_board`): where the hidden layer shows, the crop
(:func:`seam_crop`) with the most of it, in two frames, unstylized and by two
methods in random order, enlarged: for a reviewer to judge the seams alone.

Images are (H, W, 3) float in [0, 1].
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Callable, Dict, List, Mapping, NamedTuple, Optional, Sequence, Tuple

import cv2
import numpy as np
import torch

from ..checks import check_shape
from ..errors import InputError, PathLike
from ..geometry.camera import Cameras
from ..io.atomic import write_atomically
from ..io.images import resize_image, save_image
from ..models.style_prior import StylePrior
from ..render.rasterize import RasterSettings
from ..render.rasterizer import PointRasterizer
from ..scene.ldi import INPAINTED
from ..scene.photo3d import Photo3D
from .consistency import ViewGeometry, masked_rmse, warp_view

EDGE_TOLERANCE = 2
"""Pixels within which a frame's edge matches a plain edge."""


def _grey_u8(image: np.ndarray, name: str) -> np.ndarray:
    check_shape(image, name, (None, None, 3))
    img = np.nan_to_num(np.asarray(image, np.float32), nan=0.0)
    return cv2.cvtColor((np.clip(img, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8), cv2.COLOR_RGB2GRAY)


def edges(image: np.ndarray, name: str = "image") -> np.ndarray:
    """(H, W) bool Canny edges of the grey image, smoothed by a 5 x 5 Gaussian first (thresholds 50 / 120)."""
    grey = cv2.GaussianBlur(_grey_u8(image, name), (5, 5), 1.2)
    return cv2.Canny(grey, 50, 120) > 0


def edge_f1(frame: np.ndarray, reference: np.ndarray, tolerance: int = EDGE_TOLERANCE) -> float:
    """F1 of ``frame``'s edges against ``reference``'s within ``tolerance`` pixels; nan without reference edges."""
    if np.shape(frame) != np.shape(reference):
        raise InputError("frame", f"is {np.shape(frame)}, the reference {np.shape(reference)}")
    e, r = edges(frame, "frame"), edges(reference, "reference")
    if not r.any():
        return math.nan
    if not e.any():
        return 0.0
    # distance of every pixel to the nearest edge pixel of each map
    d_r = cv2.distanceTransform((~r).astype(np.uint8), cv2.DIST_L2, 3)
    d_e = cv2.distanceTransform((~e).astype(np.uint8), cv2.DIST_L2, 3)
    precision = float((d_r[e] <= tolerance).mean())
    recall = float((d_e[r] <= tolerance).mean())
    return 0.0 if precision + recall == 0 else 2.0 * precision * recall / (precision + recall)


def style_embedding_distance(frame: np.ndarray, style_vector: np.ndarray, prior: StylePrior) -> float:
    """Euclidean distance between the style vector of ``frame`` and ``style_vector`` (the painting's)."""
    return float(np.linalg.norm(prior.style_vector(frame, "frame") - np.asarray(style_vector, np.float32)))


def hidden_views(photo3d: Photo3D, cameras: Cameras, height: int, width: int) -> List[torch.Tensor]:
    """(H, W) bool per camera: pixels whose front surface is the hidden layer (points labelled INPAINTED)."""
    pts = torch.from_numpy(np.ascontiguousarray(photo3d.points.xyz, np.float32))
    flag = torch.from_numpy((photo3d.points.label == INPAINTED).astype(np.float32))[:, None]  # (N, 1)
    raster = PointRasterizer(RasterSettings(height=int(height), width=int(width)))
    out = []
    with torch.no_grad():
        for k in range(len(cameras)):
            frags = raster(pts, flag, cameras[k])
            out.append((frags.image[0] > 0.5) & ~frags.hole)
    return out


class WarpSplit(NamedTuple):
    """Warp RMSE per method over all co-visible pixels and over the disoccluded ones (mean over pairs)."""

    all: Dict[str, float]
    disoccluded: Dict[str, float]


def warp_split(frames: Mapping[str, Sequence[np.ndarray]], cameras: Cameras, geometries: Sequence[ViewGeometry],
               hidden: Sequence[torch.Tensor], pairs: Sequence[Tuple[int, int]],
               depth_tolerance: float = 0.02, one_surface: bool = True) -> WarpSplit:
    """Each method's warp RMSE over ``pairs`` (view i warped into view j), all pixels and disoccluded ones
    (``one_surface``: :func:`~.consistency.warp_view`'s)."""
    names = list(frames)
    stacks = [torch.from_numpy(np.concatenate([np.asarray(frames[m][k], np.float32) for m in names], -1))
              .permute(2, 0, 1).contiguous() for k in range(len(cameras))]  # (3 M, H, W)
    every: Dict[str, List[float]] = {m: [] for m in names}
    dis: Dict[str, List[float]] = {m: [] for m in names}
    with torch.no_grad():
        for i, j in pairs:
            warp = warp_view(stacks[i], geometries[i], cameras[i], geometries[j], cameras[j], depth_tolerance,
                             one_surface)
            if not bool(warp.mask.any()):
                continue
            hidden_mask = warp.mask & hidden[j]
            for k, m in enumerate(names):
                c = slice(3 * k, 3 * k + 3)
                every[m].append(masked_rmse(warp.image[c], stacks[j][c], warp.mask))
                if int(hidden_mask.sum()) >= 16:
                    dis[m].append(masked_rmse(warp.image[c], stacks[j][c], hidden_mask))

    def mean(v: List[float]) -> float:
        v = [x for x in v if math.isfinite(x)]
        return float(np.mean(v)) if v else math.nan

    return WarpSplit({m: mean(v) for m, v in every.items()}, {m: mean(v) for m, v in dis.items()})


# ----------------------------------------------------------------------------- blind boards


def _label(image: np.ndarray, text: str) -> np.ndarray:
    out = (np.clip(image, 0, 1) * 255).astype(np.uint8).copy()
    scale = max(0.6, out.shape[0] / 400.0)
    thick = max(1, int(round(scale * 2)))
    (tw, th), _ = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, thick)
    cv2.rectangle(out, (0, 0), (tw + 12, th + 14), (255, 255, 255), -1)
    cv2.putText(out, text, (6, th + 6), cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), thick, cv2.LINE_AA)
    return out.astype(np.float32) / 255.0


def _fit_height(image: np.ndarray, height: int) -> np.ndarray:
    h, w = image.shape[:2]
    return resize_image(np.asarray(image, np.float32), (height, max(1, round(w * height / h))))


def board(photo: np.ndarray, painting: np.ndarray, first: np.ndarray, second: np.ndarray, gap: int = 8) -> np.ndarray:
    """One board: photo and painting on top (labelled), candidates "A" (``first``) and "B" below, side by side."""
    if np.shape(first) != np.shape(second):
        raise InputError("candidates", f"differ in size: {np.shape(first)} and {np.shape(second)}")
    h, w = first.shape[:2]
    top_h = max(16, h // 2)
    tops = [_label(_fit_height(photo, top_h), "photo"), _label(_fit_height(painting, top_h), "painting")]
    row2 = [_label(first, "A"), _label(second, "B")]
    width = 2 * w + gap
    top = np.ones((top_h, width, 3), np.float32)
    x = 0
    for t in tops:
        tw = min(t.shape[1], width - x)
        top[:, x:x + tw] = t[:, :tw]
        x += tw + gap
        if x >= width:
            break
    bottom = np.ones((h, width, 3), np.float32)
    bottom[:, :w], bottom[:, w + gap:] = row2
    return np.concatenate([top, np.ones((gap, width, 3), np.float32), bottom], 0)


SEAM_CROP = 128
"""Side (px) of a seam board's crops."""


def seam_crop(hidden: Sequence[np.ndarray], size: int = SEAM_CROP, min_pixels: int = 16) -> Optional[Tuple[int, int, int]]:
    """``(frame, y0, x0)`` of the ``size`` x ``size`` crop (inside the frame) holding the most hidden-layer
    pixels of any frame (``hidden``: (H, W) bool per frame, :func:`hidden_views`); None where no frame shows
    ``min_pixels``."""
    masks = [np.asarray(h, bool) for h in hidden]
    if not masks:
        return None
    H, W = masks[0].shape
    s = int(min(size, H, W))
    best = None
    for t, m in enumerate(masks):
        if int(m.sum()) < min_pixels:
            continue
        # hidden pixels in the s x s window at each top-left corner (an integral image)
        ii = np.pad(m.astype(np.int64).cumsum(0).cumsum(1), ((1, 0), (1, 0)))
        win = ii[s:, s:] - ii[:-s, s:] - ii[s:, :-s] + ii[:-s, :-s]  # (H - s + 1, W - s + 1)
        y0, x0 = np.unravel_index(int(np.argmax(win)), win.shape)
        if best is None or win[y0, x0] > best[0]:
            best = (int(win[y0, x0]), t, int(y0), int(x0))
    return None if best is None else best[1:]


def seam_board(reference: Sequence[np.ndarray], first: Sequence[np.ndarray], second: Sequence[np.ndarray],
               scale: int = 3, gap: int = 12) -> np.ndarray:
    """A seam board: one row per frame, the unstylized crop, candidate "A" (``first``) and "B", each
    enlarged ``scale`` times (nearest neighbour, so a seam is not smoothed away)."""
    if not (len(reference) == len(first) == len(second)) or not len(first):
        raise InputError("seam crops", "need the same number (at least one) of crops per column")
    rows = []
    for k, crops in enumerate(zip(reference, first, second)):
        if len({np.shape(c) for c in crops}) != 1:
            raise InputError("seam crops", f"row {k} mixes sizes {[np.shape(c) for c in crops]}")
        h, w = crops[0].shape[:2]
        big = [cv2.resize(np.clip(np.asarray(c, np.float32), 0, 1), (w * scale, h * scale),
                          interpolation=cv2.INTER_NEAREST) for c in crops]
        if k == 0:
            big = [_label(b, t) for b, t in zip(big, ("photo (unstylized)", "A", "B"))]
        sep = np.ones((h * scale, gap, 3), np.float32)
        rows.append(np.concatenate([big[0], sep, big[1], sep, big[2]], 1))
    out = [rows[0]]
    for r in rows[1:]:
        out += [np.ones((gap, r.shape[1], 3), np.float32), r]
    return np.concatenate(out, 0)


def write_boards(out_dir: PathLike, pairs: Sequence[Mapping[str, object]], methods: Tuple[str, str],
                 seed: int = 0, compose: Optional[Callable[[Mapping[str, object], str, str], np.ndarray]] = None) -> Path:
    """Write ``board_NN.png`` for each pair and ``key.json`` (which method is A and B on each board).

    Each pair is a mapping with ``"name"``, ``"photo"``, ``"painting"`` and the frames of both
    ``methods`` (one frame each); or, with ``compose`` (``compose(pair, a, b)`` makes the board with
    method ``a`` as "A"), whatever that reads. The order on each board is random (``seed``). Returns the
    key's path.
    """
    root = Path(out_dir)
    root.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    key = []
    for k, pair in enumerate(pairs):
        swap = bool(rng.random() < 0.5)
        a, b = (methods[1], methods[0]) if swap else methods
        image = compose(pair, a, b) if compose else board(pair["photo"], pair["painting"], pair[a], pair[b])
        save_image(root / f"board_{k:02d}.png", image)
        key.append({"board": f"board_{k:02d}.png", "pair": str(pair["name"]), "A": a, "B": b})
    path = root.parent / f"{root.name}_key.json"
    text = json.dumps({"methods": list(methods), "boards": key}, indent=1)
    write_atomically(path, "board key", lambda tmp: tmp.write_text(text, encoding="utf-8"))
    return path


def decode_verdicts(key_path: PathLike, verdicts: Mapping[str, Mapping[str, str]]) -> Dict[str, Dict[str, int]]:
    """Tally a reviewer's verdicts: ``verdicts[board] = {"style": "A"|"B", "scene": ..., "pick": ...}``.

    Returns ``{question: {method: count}}``; letters other than A and B (a tie, "=") count for neither.
    """
    key = json.loads(Path(key_path).read_text())
    methods = key["methods"]
    tally: Dict[str, Dict[str, int]] = {}
    for entry in key["boards"]:
        answer = verdicts.get(entry["board"])
        if answer is None:
            continue
        for question, letter in answer.items():
            row = tally.setdefault(question, {m: 0 for m in methods})
            if letter in ("A", "B"):
                row[entry[letter]] += 1
    return tally


__all__ = ["EDGE_TOLERANCE", "SEAM_CROP", "WarpSplit", "board", "decode_verdicts", "edge_f1", "edges", "hidden_views",
           "seam_board", "seam_crop", "style_embedding_distance", "warp_split", "write_boards"]
