"""Disk cache of training samples: ``build_dataset`` writes them, ``TrainDataset`` reads them.

A dataset folder holds ``dataset.json`` (format, sample format version, seed,
the config's ``repr`` and its hash, the neighbourhood config by name and its
key) and one ``sample_NNNNNN.pt`` per sample: a ``torch.save`` of a plain dict
of tensors, strings and numbers (load with ``weights_only=True``). Colours are
stored as uint8 (samples are quantised to 1/255, so the round trip is exact),
the geometry's index tensors (encoder subset, neighbours, FPS samples, upsampling
neighbours) as uint16 (int32 above 65536 points), the upsampling weights as
float32, the neighbourhood config as a dict of named fields; the hierarchy's
level positions are recomputed from ``xyz``, the NDC parameters and the FPS
indices on load (the same functions, bit for bit).

Sample format version 2 stores the whole
:class:`~stylize3d_core.models.scene_geometry.SceneGeometry` (version 1 held a
positional neighbourhood key and no upsampling weights). Older samples are
refused with an error saying to rebuild; :func:`build_dataset` regenerates them
in place, and :class:`TrainDataset` refuses a folder written in an older format.

Generation resumes: a sample file that exists, loads and belongs to this
dataset is kept; a missing one is generated; a corrupt or foreign one is
regenerated and reported in :class:`BuildReport`. Files are written atomically
(:func:`stylize3d_core.io.atomic.atomic_path`), so an interrupted run never
leaves a half-written sample under a final name. Run one build per folder at a
time (a build removes temporary files left in its folder by a killed run).

A held-out split uses other photos and another seed: :func:`build_splits`.
"""

from __future__ import annotations

import hashlib
import json
import pickle
import time
import zipfile
from pathlib import Path
from typing import Callable, Dict, List, NamedTuple, Optional, Sequence, Tuple

import torch
from torch.utils.data import Dataset

from ..errors import InputError, PathLike
from ..geometry.camera import Cameras
from ..geometry.ndc import NDCParams, to_ndc
from ..io.atomic import atomic_path
from ..models.scene_geometry import NeighbourhoodConfig, PointHierarchy, SceneGeometry
from ..points import IDWWeights
from ..scene.pointcloud import PointTensors
from ..threads import torch_threads
from .data import KINDS, DataConfig, TrainSample, from_u8, held_out_config, make_sample

SAMPLE_FORMAT = "stylize3d-train-sample"
SAMPLE_VERSION = 2
MANIFEST = "dataset.json"
EVAL_SEED_OFFSET = 1_000_003
""":func:`build_splits` builds the held-out split with ``seed + EVAL_SEED_OFFSET``."""


def config_key(config: DataConfig) -> str:
    """A short hash of the config's ``repr`` (every field, nested settings included)."""
    return hashlib.sha256(repr(config).encode()).hexdigest()[:16]


def sample_path(root: PathLike, index: int) -> Path:
    """Where sample ``index`` of the dataset in ``root`` lives."""
    return Path(root) / f"sample_{index:06d}.pt"


# ----------------------------------------------------------------------------- (de)serialisation


def _u8(x: torch.Tensor) -> torch.Tensor:
    return torch.round(x * 255.0).clamp(0, 255).to(torch.uint8)


def _index_dtype(n: int) -> torch.dtype:
    """uint16 for indices into at most 65536 points (half the disk of int32), else int32."""
    return torch.uint16 if n <= 1 << 16 else torch.int32


def sample_to_dict(sample: TrainSample, key: str = "") -> Dict[str, object]:
    """The sample as a plain dict of tensors / numbers / strings (see the module docstring)."""
    g = sample.geometry
    h = g.hierarchy
    idx = _index_dtype(sample.num_points)
    return {
        "format": SAMPLE_FORMAT, "version": SAMPLE_VERSION, "config_key": key,
        "kind": sample.kind, "source": sample.source, "seed": sample.seed, "index": sample.index,
        "fov_y_deg": float(sample.fov_y_deg),
        "image": _u8(sample.image), "xyz": sample.points.xyz.contiguous(), "point_rgb": _u8(sample.points.rgb),
        "label": sample.points.label.contiguous(),
        "geometry": {
            "ndc": [float(v) for v in g.ndc],
            "neighbourhood": h.neighbourhood.to_dict(),
            "neighbourhood_key": h.neighbourhood.key,
            "scale": float(h.scale),
            "encoder_idx": g.encoder_idx.to(idx),
            "stem": h.stem_neighbours.to(idx),
            "sample_idx": [t.to(idx) for t in h.sample_idx],
            "down": [t.to(idx) for t in h.down_neighbours],
            "same": [t.to(idx) for t in h.same_neighbours],
            "upsample_idx": g.upsample.idx.to(idx),
            "upsample_weight": g.upsample.weight.to(torch.float32).contiguous(),
        },
        "cam_to_world": sample.cameras.cam_to_world.to(torch.float64),
        "fov": sample.cameras.fov_y_deg.to(torch.float64),
        "targets": _u8(sample.targets), "masks": sample.masks.contiguous(), "seen": sample.seen.contiguous(),
        "timings": {k: float(v) for k, v in sample.timings.items()},
    }


def _tensor(d: dict, name: str, dtype: torch.dtype, shape: Sequence[Optional[int]], source: PathLike) -> torch.Tensor:
    t = d.get(name)
    if not isinstance(t, torch.Tensor) or t.dtype != dtype or t.ndim != len(shape) or any(
        s is not None and s != a for s, a in zip(shape, t.shape)
    ):
        got = f"{t.dtype} {tuple(t.shape)}" if isinstance(t, torch.Tensor) else type(t).__name__
        raise InputError(source, f"field {name!r}: expected {dtype} of shape {tuple(shape)}, got {got}")
    return t


def _geometry_from_dict(gd: object, points: PointTensors, source: PathLike) -> SceneGeometry:
    """The stored :class:`SceneGeometry` of a sample whose points are ``points``."""
    n = points.xyz.shape[0]
    idx = _index_dtype(n)
    try:
        ndc = NDCParams(*[float(v) for v in gd["ndc"]])
        hood = NeighbourhoodConfig.from_dict(gd["neighbourhood"], source)
        if gd.get("neighbourhood_key") != hood.key:
            raise InputError(source, "the stored neighbourhood key does not match its settings")
        scale = float(gd["scale"])
        encoder_idx = _tensor(gd, "encoder_idx", idx, (None,), source).long()
        stem = _tensor(gd, "stem", idx, (encoder_idx.shape[0], hood.k), source).long()
        samples = [t.long() for t in gd["sample_idx"]]
        down = [t.long() for t in gd["down"]]
        same = [t.long() for t in gd["same"]]
        if not len(samples) == len(down) == len(same) == hood.num_stages:
            raise InputError(source, f"the hierarchy has {len(samples)}, {len(down)}, {len(same)} stages, "
                                     f"its neighbourhood config {hood.num_stages}")
        levels = [to_ndc(points.xyz, ndc).index_select(0, encoder_idx)]
        for s in samples:
            levels.append(levels[-1].index_select(0, s))
        up = IDWWeights(_tensor(gd, "upsample_idx", idx, (n, hood.upsample_k), source).long(),
                        _tensor(gd, "upsample_weight", torch.float32, (n, hood.upsample_k), source))
        if up.idx.numel() and int(up.idx.max()) >= levels[-1].shape[0]:
            raise InputError(source, "upsampling neighbours index past the coarsest level")
    except (KeyError, IndexError, RuntimeError, TypeError, ValueError, AttributeError) as e:
        if isinstance(e, InputError):
            raise
        raise InputError(source, f"malformed scene geometry ({type(e).__name__}: {e})") from e
    hierarchy = PointHierarchy(tuple(levels), stem, tuple(samples), tuple(down), tuple(same), hood, scale)
    return SceneGeometry(points.xyz, points.rgb, ndc, encoder_idx, hierarchy, up)


def sample_from_dict(d: object, source: PathLike = "sample") -> TrainSample:
    """Inverse of :func:`sample_to_dict`; ``source`` names the file in errors."""
    if not isinstance(d, dict) or d.get("format") != SAMPLE_FORMAT:
        raise InputError(source, "not a stylize3d training sample")
    if d.get("version") != SAMPLE_VERSION:
        raise InputError(source, f"sample format version {d.get('version')!r}, expected {SAMPLE_VERSION}: rebuild it")
    try:
        kind, fov = str(d["kind"]), float(d["fov_y_deg"])
        gd = d["geometry"]
        meta = (str(d["source"]), int(d["seed"]), int(d["index"]), {str(k): float(v) for k, v in d["timings"].items()})
    except (KeyError, TypeError, ValueError) as e:
        raise InputError(source, f"malformed training sample ({type(e).__name__}: {e})") from e
    if kind not in KINDS:
        raise InputError(source, f"unknown sample kind {kind!r}")
    xyz = _tensor(d, "xyz", torch.float32, (None, 3), source)
    n = xyz.shape[0]
    image = _tensor(d, "image", torch.uint8, (None, None, 3), source)
    h, w = image.shape[:2]
    c2w = _tensor(d, "cam_to_world", torch.float64, (None, 4, 4), source)
    v = c2w.shape[0]
    targets = _tensor(d, "targets", torch.uint8, (v, 3, h, w), source)
    masks = _tensor(d, "masks", torch.bool, (v, h, w), source)
    seen = _tensor(d, "seen", torch.bool, (v, h, w), source)
    points = PointTensors(xyz, from_u8(_tensor(d, "point_rgb", torch.uint8, (n, 3), source)),
                          _tensor(d, "label", torch.uint8, (n,), source))
    geometry = _geometry_from_dict(gd, points, source)
    try:
        cameras = Cameras(c2w, _tensor(d, "fov", torch.float64, (v,), source))
    except (RuntimeError, TypeError, AttributeError) as e:
        raise InputError(source, f"malformed cameras ({e})") from e
    return TrainSample(kind, from_u8(image), points, geometry, fov, cameras, from_u8(targets),
                       masks, seen, *meta)


def save_sample(path: PathLike, sample: TrainSample, key: str = "") -> None:
    """Write one sample atomically (``key``: the dataset's :func:`config_key`)."""
    with atomic_path(path) as tmp:
        torch.save(sample_to_dict(sample, key), tmp)


def _load_dict(path: PathLike) -> dict:
    p = Path(path)
    if not p.is_file():
        raise InputError(path, "training sample not found")
    try:
        d = torch.load(p, map_location="cpu", weights_only=True)
    except (RuntimeError, OSError, EOFError, ValueError, pickle.UnpicklingError, zipfile.BadZipFile) as e:
        raise InputError(path, f"corrupt or unreadable training sample ({type(e).__name__}: {e}); "
                               "delete it, or run build_dataset again to regenerate it") from e
    return d


def load_sample(path: PathLike) -> TrainSample:
    """Read a sample written by :func:`save_sample`; any problem raises InputError naming the file."""
    return sample_from_dict(_load_dict(path), path)


# ----------------------------------------------------------------------------- building


class BuildReport(NamedTuple):
    """What :func:`build_dataset` did."""

    root: Path
    generated: int  # samples generated that did not exist
    skipped: int  # valid samples found and kept
    regenerated: Tuple[Tuple[str, str], ...]  # (file, why) of corrupt or foreign files replaced
    seconds: float


def _read_manifest(root: Path) -> Optional[dict]:
    path = root / MANIFEST
    if not path.exists():
        return None
    try:
        m = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise InputError(path, f"unreadable dataset manifest ({e})") from e
    if not isinstance(m, dict) or m.get("format") != "stylize3d-train-dataset":
        raise InputError(path, "not a stylize3d training dataset manifest")
    return m


def manifest_version(manifest: dict) -> int:
    """The sample format version a dataset manifest was written with (1: before manifests recorded it)."""
    v = manifest.get("sample_version", 1)
    return v if isinstance(v, int) and not isinstance(v, bool) else -1


def build_dataset(
    out_dir: PathLike,
    n_samples: int,
    config: DataConfig = DataConfig(),
    seed: int = 0,
    *,
    threads: int = 1,
    progress: Optional[Callable[[int, int], None]] = None,
) -> BuildReport:
    """Write samples ``0 .. n_samples - 1`` of the dataset ``(config, seed)`` to ``out_dir``, resuming.

    Args:
        out_dir: the dataset folder (created if missing). If it already holds a
            dataset with another seed or config, InputError is raised (use a new folder);
            one written in an older sample format with the same seed is rebuilt in place.
        n_samples: how many samples (an existing dataset can be grown).
        threads: torch threads while generating (restored afterwards); 1 is
            fastest on a busy 2-core machine, where the rasterizer's threads contend.
        progress: called as ``progress(done, n_samples)`` after each sample.
    """
    if isinstance(n_samples, bool) or not isinstance(n_samples, int) or n_samples < 0:
        raise InputError("n_samples", f"must be an integer >= 0, got {n_samples!r}")
    root = Path(out_dir)
    root.mkdir(parents=True, exist_ok=True)
    key = config_key(config)
    manifest = _read_manifest(root)
    if manifest is not None and manifest_version(manifest) != SAMPLE_VERSION and manifest.get("seed") == seed:
        # Written in another sample format, whose config can no longer be compared: its samples are
        # all unreadable (each is reported as regenerated below), so the folder is rebuilt in place.
        manifest = None
    if manifest is not None and (manifest.get("seed") != seed or manifest.get("config_key") != key):
        raise InputError(root / MANIFEST, f"this folder holds the dataset (seed {manifest.get('seed')}, config "
                                          f"{manifest.get('config_key')}), not (seed {seed}, config {key}): "
                                          "use another folder")
    total = max(n_samples, int(manifest["n_samples"]) if manifest else 0)
    with atomic_path(root / MANIFEST) as tmp:
        tmp.write_text(json.dumps({"format": "stylize3d-train-dataset", "sample_version": SAMPLE_VERSION,
                                   "n_samples": total, "seed": seed, "config_key": key, "config": repr(config),
                                   "neighbourhood": config.neighbourhood.to_dict(),
                                   "neighbourhood_key": config.neighbourhood.key}, indent=1))
    for stale in root.glob(".sample_*.partial.pt"):  # left by a killed run (atomic_path cleans up otherwise)
        stale.unlink()
    t0 = time.perf_counter()
    generated, skipped, regenerated = 0, 0, []
    with torch_threads(max(1, int(threads))):
        for i in range(n_samples):
            path = sample_path(root, i)
            if path.exists():
                why = _stale_reason(path, key, seed, i)
                if why is None:
                    skipped += 1
                    if progress:
                        progress(i + 1, n_samples)
                    continue
                regenerated.append((str(path), why))
            else:
                generated += 1
            save_sample(path, make_sample(i, config, seed), key)
            if progress:
                progress(i + 1, n_samples)
    return BuildReport(root, generated, skipped, tuple(regenerated), time.perf_counter() - t0)


def _stale_reason(path: Path, key: str, seed: int, index: int) -> Optional[str]:
    """None if ``path`` is a valid sample ``index`` of this dataset, else why not."""
    try:
        d = _load_dict(path)
        sample_from_dict(d, path)
    except InputError as e:
        return e.problem
    if d.get("config_key") != key or d.get("seed") != seed or d.get("index") != index:
        return "belongs to another dataset (config, seed or index differ)"
    return None


def build_splits(
    root: PathLike, n_train: int, n_eval: int, config: DataConfig = DataConfig(), seed: int = 0, *, threads: int = 1,
    eval_config: Optional[DataConfig] = None,
) -> Tuple[BuildReport, BuildReport]:
    """``root/train`` with ``(config, seed)`` and ``root/eval`` with another seed on ``eval_config`` (None: the
    held-out photos, :func:`~.data.held_out_config`)."""
    train = build_dataset(Path(root) / "train", n_train, config, seed, threads=threads)
    held_config = held_out_config(config) if eval_config is None else eval_config
    held = build_dataset(Path(root) / "eval", n_eval, held_config, seed + EVAL_SEED_OFFSET, threads=threads)
    return train, held


# ----------------------------------------------------------------------------- reading


class TrainDataset(Dataset):
    """The samples of a dataset folder written by :func:`build_dataset` (a map-style torch Dataset).

    Args:
        root: the dataset folder.
        neighbourhood: if given, the dataset must have been built with this
            neighbourhood config (a model's ``config.neighbourhood``), compared by its
            named fields: else InputError, at once from the manifest and again per sample.

    ``dataset[i]`` is a :class:`TrainSample`; samples have different numbers
    of points, so use ``collate_fn=collate_samples`` in a DataLoader.
    """

    def __init__(self, root: PathLike, neighbourhood: Optional[NeighbourhoodConfig] = None) -> None:
        self.root = Path(root)
        manifest = _read_manifest(self.root)
        if manifest is None:
            raise InputError(self.root, f"no {MANIFEST}: not a training dataset (write one with build_dataset)")
        version = manifest_version(manifest)
        if version != SAMPLE_VERSION:
            raise InputError(self.root / MANIFEST, f"written with training-sample format version {version}, this "
                                                   f"version reads {SAMPLE_VERSION}: rebuild it with build_dataset")
        self.n = int(manifest["n_samples"])
        self.seed = int(manifest["seed"])
        self.config_key = str(manifest["config_key"])
        self.config_repr = str(manifest["config"])
        self.neighbourhood = NeighbourhoodConfig.from_dict(manifest.get("neighbourhood"), self.root / MANIFEST)
        if neighbourhood is not None and self.neighbourhood != neighbourhood:
            raise InputError(self.root, _hood_mismatch(self.neighbourhood, neighbourhood))
        missing = [i for i in range(self.n) if not sample_path(self.root, i).is_file()]
        if missing:
            raise InputError(self.root, f"{len(missing)} of {self.n} samples are missing (first: "
                                        f"{sample_path(self.root, missing[0]).name}); run build_dataset again")
        self.required = neighbourhood

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, index: int) -> TrainSample:
        if not 0 <= index < self.n:
            raise IndexError(f"sample index {index} out of range [0, {self.n})")
        path = sample_path(self.root, index)
        sample = load_sample(path)
        built = sample.geometry.neighbourhood
        if built != self.neighbourhood or (self.required is not None and built != self.required):
            raise InputError(path, _hood_mismatch(built, self.required or self.neighbourhood))
        return sample


def _hood_mismatch(built: NeighbourhoodConfig, wanted: NeighbourhoodConfig) -> str:
    diff = {k: (v, getattr(wanted, k)) for k, v in built.to_dict().items() if wanted.to_dict()[k] != v}
    return (f"geometry built with neighbourhood settings {built.key}, the model uses {wanted.key} "
            f"(differing: {', '.join(f'{k} {a!r} vs {b!r}' for k, (a, b) in diff.items())}): "
            "rebuild the dataset with DataConfig(neighbourhood=model.config.neighbourhood)")


def collate_samples(batch: Sequence[TrainSample]) -> List[TrainSample]:
    """DataLoader ``collate_fn``: samples differ in size, so a batch is a list of them."""
    return list(batch)
