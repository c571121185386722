"""Model checkpoints: safetensors weights plus the architecture and provenance as metadata.

A checkpoint is one ``.safetensors`` file. Its metadata holds::

    format   "stylize3d-model"
    version  "6"
    config   the ModelConfig as JSON (so the file alone rebuilds the model)
    stage    "1" (view synthesis) or "2" (stylization)
    info     free JSON: iterations, data, command, hours...

Version "5" files have no style prior (``style_prior`` False; added in version 6).
Version "4" files have no texture residual (``decoder.texture_channels`` 0; added in version 5).
Version "3" files have no colour transform (``decoder.transform_channels`` 0)
nor colour transfer (``detail_transfer`` False), both added in version 4, version "2" files no detail path either
(``detail_channels`` 0; added in version 3). Version "1" files are still read too: their
config kept the neighbourhood settings (k, radii, down-sampling, FPS start)
inside ``encoder`` and the subset size as ``encoder_max_points``;
:func:`config_from_json` maps them to ``neighbourhood``, with the settings that
were fixed then (512 reference points across, 3-NN upsampling).

Loading checks everything and raises :class:`InputError` naming the file for a
missing or truncated file, a file that is not a stylize3d checkpoint, or weights
that do not fit the architecture. Writing is atomic.
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path
from typing import Any, Dict, NamedTuple, Union

import torch

from ..errors import InputError
from ..io.atomic import atomic_path
from .adaattn import AdaAttNConfig
from .decoder import DecoderConfig
from .encoder import EncoderConfig
from .scene_geometry import NeighbourhoodConfig
from .stylize3d import ModelConfig, Stylize3DModel

FORMAT = "stylize3d-model"
VERSION = "6"
READABLE_VERSIONS = ("1", "2", "3", "4", "5", "6")
_V1_NEIGHBOURHOOD = ("k", "stem_radius", "stage_radii", "downsample", "fps_start")
PathLike = Union[str, "os.PathLike[str]"]


class Checkpoint(NamedTuple):
    """A loaded checkpoint: the model (eval mode, CPU), its training stage and provenance."""

    model: Stylize3DModel
    stage: int
    info: Dict[str, Any]


def config_to_json(config: ModelConfig) -> str:
    """The configuration as JSON (tuples become lists)."""
    return json.dumps(dataclasses.asdict(config), sort_keys=True)


def _tuples(x: Any) -> Any:
    if isinstance(x, list):
        return tuple(_tuples(v) for v in x)
    return x


def _v1_layout(d: Dict[str, Any]) -> Dict[str, Any]:
    """A version-1 config dict in the version-2 layout (neighbourhood settings out of ``encoder``)."""
    enc = dict(d["encoder"])
    hood = {k: enc.pop(k) for k in _V1_NEIGHBOURHOOD if k in enc}
    hood["max_points"] = d["encoder_max_points"]
    rest = {k: v for k, v in d.items() if k != "encoder_max_points"}
    return {**rest, "encoder": enc, "neighbourhood": hood}


def config_from_json(text: str, source: PathLike, version: str = VERSION) -> ModelConfig:
    """Rebuild a :class:`ModelConfig` from :func:`config_to_json`'s output (``version`` "1": the old layout)."""
    try:
        d = json.loads(text)
        if version == "1":
            d = _v1_layout(d)
        enc = EncoderConfig(**{k: _tuples(v) for k, v in d["encoder"].items()})
        hood = NeighbourhoodConfig.from_dict(d["neighbourhood"], source)
        sty = AdaAttNConfig(**{k: _tuples(v) for k, v in d["stylizer"].items()})
        dec = DecoderConfig(**d["decoder"])
        return ModelConfig(
            name=d["name"], encoder=enc, neighbourhood=hood, stylizer=sty, raster_channels=int(d["raster_channels"]),
            decoder=dec, detail_channels=int(d.get("detail_channels", 0)),
            detail_transfer=bool(d.get("detail_transfer", False)), style_prior=bool(d.get("style_prior", False)),
        )
    except RecursionError:
        raise InputError(source, "the checkpoint's model configuration is unreadable (nested too deeply)") from None
    except (ValueError, KeyError, TypeError, AttributeError) as e:
        raise InputError(source, f"the checkpoint's model configuration is unreadable ({e})") from None


def save_checkpoint(path: PathLike, model: Stylize3DModel, stage: int, info: Dict[str, Any]) -> Path:
    """Write ``model``'s weights (float32) with its configuration to ``path`` atomically."""
    from safetensors.torch import save_file

    if stage not in (1, 2):
        raise InputError("stage", f"must be 1 or 2, got {stage!r}")
    tensors = {k: v.detach().to("cpu", torch.float32).contiguous() for k, v in model.state_dict().items()
               if v.is_floating_point()}
    tensors.update({k: v.detach().cpu().contiguous() for k, v in model.state_dict().items()
                    if not v.is_floating_point()})
    meta = {"format": FORMAT, "version": VERSION, "config": config_to_json(model.config),
            "stage": str(stage), "info": json.dumps(info, sort_keys=True)}
    with atomic_path(path) as tmp:
        save_file(tensors, str(tmp), metadata=meta)
    return Path(path)


def load_checkpoint(path: PathLike) -> Checkpoint:
    """Load a checkpoint written by :func:`save_checkpoint` (see the module docstring)."""
    from safetensors import SafetensorError
    from safetensors.torch import load_file

    p = Path(path)
    if not p.exists():
        raise InputError(p, "model checkpoint not found")
    if not p.is_file():
        raise InputError(p, "is not a file")
    if p.stat().st_size == 0:
        raise InputError(p, "the checkpoint file is empty")
    try:
        from safetensors import safe_open

        with safe_open(str(p), framework="pt") as f:
            meta = f.metadata() or {}
        tensors = load_file(str(p))
    except (SafetensorError, OSError, ValueError, RuntimeError) as e:
        raise InputError(p, f"not a readable safetensors checkpoint (truncated or corrupt?): {e}") from None
    if meta.get("format") != FORMAT:
        raise InputError(p, f"not a stylize3d model checkpoint (format {meta.get('format')!r})")
    if meta.get("version") not in READABLE_VERSIONS:
        raise InputError(p, f"checkpoint version {meta.get('version')!r} is not supported "
                            f"(expected one of {', '.join(READABLE_VERSIONS)})")
    config = config_from_json(meta.get("config", ""), p, meta["version"])
    try:  # shapes only, no memory: a configuration may ask for any size; the file's own tensors bound it
        with torch.device("meta"):
            own = Stylize3DModel(config).state_dict()
    except (RuntimeError, ValueError, TypeError, OverflowError, MemoryError) as e:
        raise InputError(p, f"the checkpoint's model configuration cannot be built ({e})") from None
    missing, unexpected = [], []
    for k in own:
        if k not in tensors:
            missing.append(k)
    for k in tensors:
        if k not in own:
            unexpected.append(k)
    if missing or unexpected:
        raise InputError(p, f"weights do not match the architecture: missing {missing[:5]}, unexpected {unexpected[:5]}")
    for k, v in own.items():
        if tuple(tensors[k].shape) != tuple(v.shape):
            raise InputError(p, f"weight {k} has shape {tuple(tensors[k].shape)}, the architecture needs {tuple(v.shape)}")
        if tensors[k].is_floating_point() and not torch.isfinite(tensors[k]).all():
            raise InputError(p, f"weight {k} contains NaN or infinite values")
    model = Stylize3DModel(config)  # as large as the weights just checked
    model.load_state_dict({k: tensors[k].to(v.dtype) for k, v in own.items()})
    model.eval()
    try:
        stage = int(meta.get("stage", ""))
        info = json.loads(meta.get("info", "{}"))
    except (ValueError, RecursionError):
        raise InputError(p, "the checkpoint's stage or info metadata is unreadable") from None
    return Checkpoint(model, stage, info)
