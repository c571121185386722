"""Depth Anything V2 Small (``--depth depth-anything``): a learned monocular depth network through Hugging Face
Transformers, an optional extra (``pip install 'stylize3d[depth]'``).

The weights (Apache-2.0, about 99 MB) are never shipped and never fetched on their own: ``stylize3d models
download depth-anything`` downloads them once, from the pinned revision :data:`REVISION` of
:data:`MODEL_ID`, with a progress bar, into the standard Hugging Face cache (``$HF_HOME`` /
``$HF_HUB_CACHE``). Every later run loads them from the cache only (``local_files_only``), so a run is
offline whatever ``$HF_HUB_OFFLINE`` says. ``depth-anything:FOLDER`` loads a model saved with
``save_pretrained`` from a folder instead (the same architecture, e.g. a fine-tuned copy).

The network returns relative inverse depth at the image processor's size (the short side resized to 518
pixels, both sides a multiple of the ViT's patch of 14, aspect kept); it becomes a "relative"
:class:`~stylize3d_core.depth.types.DepthMap` at the photo's size by the same rule as every inverse-depth
network (:func:`~stylize3d_core.depth.onnx_model.inverse_depth_map`).

Without the extra, or without the cached weights, a source is refused with an
:class:`~stylize3d_core.errors.InputError` that names the command to run and the built-in prior as the
way on; nothing switches silently.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Optional

import numpy as np

from ..errors import InputError, PathLike
from ._util import check_rgb
from .onnx_model import inverse_depth_map
from .types import DepthMap

MODEL_ID = "depth-anything/Depth-Anything-V2-Small-hf"
"""The Hugging Face model repository."""
REVISION = "5426e4f0f36572d16453bbda7a8389317b1bef99"
"""The commit of :data:`MODEL_ID` that ``models download`` fetches and every run loads (never ``main``)."""
SPEC = "depth-anything"
"""The ``--depth`` name of this source."""
FAR_RATIO = 10.0
"""Depth of the farthest point over the nearest (the inverse-depth rule's ``far_ratio``)."""

DOWNLOAD_HINT = f"run `stylize3d models download {SPEC}` once (it needs the network), or use --depth prior"
EXTRA_HINT = "install the optional extra: pip install 'stylize3d[depth]' (or use --depth prior)"


def _transformers():
    try:
        from transformers import AutoImageProcessor, AutoModelForDepthEstimation
    except ImportError:
        raise InputError(SPEC, f"needs Hugging Face Transformers, which is not installed: {EXTRA_HINT}") from None
    return AutoImageProcessor, AutoModelForDepthEstimation


def available() -> bool:
    """Whether Transformers imports (the ``depth`` extra is installed)."""
    try:
        _transformers()
    except InputError:
        return False
    return True


def cache_dir() -> Path:
    """The Hugging Face hub cache as the environment says now: ``$HF_HUB_CACHE``, else ``$HF_HOME/hub``, else
    ``$XDG_CACHE_HOME/huggingface/hub`` (``~/.cache/huggingface/hub``). Read at each call (huggingface_hub
    reads it once, at its import)."""
    if os.environ.get("HF_HUB_CACHE"):
        return Path(os.environ["HF_HUB_CACHE"])
    if os.environ.get("HF_HOME"):
        return Path(os.environ["HF_HOME"]) / "hub"
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "huggingface" / "hub"


def cached_folder(model_id: str = MODEL_ID, revision: str = REVISION) -> Optional[Path]:
    """The cache's snapshot folder of the pinned weights (huggingface_hub's layout:
    ``models--OWNER--NAME/snapshots/REVISION``), or None where they were not downloaded. A look at the disk:
    nothing is imported, no network is used (``--depth auto`` asks it for every photo)."""
    folder = cache_dir() / ("models--" + model_id.replace("/", "--")) / "snapshots" / revision
    return folder if (folder / "config.json").is_file() else None


def require_weights() -> Path:
    """:func:`cached_folder`, or the :class:`~stylize3d_core.errors.InputError` that names the command to run."""
    folder = cached_folder()
    if folder is None:
        raise InputError(SPEC, f"the weights of {MODEL_ID} are not in the Hugging Face cache: {DOWNLOAD_HINT}")
    return folder


def download(model_id: str = MODEL_ID, revision: str = REVISION) -> Path:
    """Fetch the pinned weights into the Hugging Face cache (progress bars on stderr); the folder.

    Raises:
        InputError: without Transformers, or when the download fails (offline, no such revision): one
            line naming the problem.
    """
    _transformers()
    from huggingface_hub import snapshot_download

    if os.environ.get("HF_HUB_OFFLINE", "").strip().lower() in ("1", "true", "yes", "on"):
        raise InputError(SPEC, "cannot download: HF_HUB_OFFLINE is set (unset it, or use --depth prior)")
    try:
        folder = snapshot_download(model_id, revision=revision, cache_dir=str(cache_dir()),
                                   allow_patterns=["*.json", "*.safetensors", "*.txt", "*.md"])
    except Exception as exc:  # noqa: BLE001 (huggingface_hub's many network errors): one line
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(SPEC, f"cannot download {model_id} at revision {revision[:12]} ({first}); "
                               "check the network, or use --depth prior") from None
    return Path(folder)


class DepthAnythingModel:
    """The network and its image processor, loaded from ``folder`` (a ``save_pretrained`` layout), or from
    the cache's pinned revision where ``folder`` is None. Loading reads local files only."""

    def __init__(self, folder: Optional[PathLike] = None, far_ratio: float = FAR_RATIO) -> None:
        processor_cls, model_cls = _transformers()
        if folder is None:
            folder = require_weights()
        self.folder = Path(folder)
        if not (self.folder / "config.json").is_file():
            raise InputError(self.folder, "not a saved depth model (no config.json in the folder)")
        try:
            self.processor = processor_cls.from_pretrained(str(self.folder), local_files_only=True)
            self.model = model_cls.from_pretrained(str(self.folder), local_files_only=True).eval()
        except Exception as exc:  # noqa: BLE001 (corrupt or truncated weights, a wrong architecture)
            first = str(exc).strip().splitlines()[0][:300] if str(exc).strip() else type(exc).__name__
            raise InputError(self.folder, f"cannot load the depth model: {first}") from None
        self.far_ratio = far_ratio

    def estimate(self, rgb: np.ndarray) -> DepthMap:
        """Depth for the photo ``rgb`` (H, W, 3) in [0, 1], aligned with it (relative)."""
        import torch

        photo = check_rgb(rgb)
        image = np.clip(np.rint(photo * 255.0), 0, 255).astype(np.uint8)
        inputs = self.processor(images=image, return_tensors="pt")
        with torch.inference_mode():
            out = self.model(**inputs).predicted_depth  # (1, h, w): relative inverse depth
        raw = out[0].float().cpu().numpy()
        return inverse_depth_map(raw, photo.shape[:2], self.far_ratio, SPEC, self.folder)


__all__ = ["MODEL_ID", "REVISION", "SPEC", "DepthAnythingModel", "available", "cached_folder", "download",
           "require_weights"]
