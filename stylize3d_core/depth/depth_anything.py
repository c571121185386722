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
from typing import Callable, Optional, Tuple

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


def installed() -> bool:
    """Whether Transformers is on the path, without importing it (seconds at a cold start): what a window asks
    before it offers the download; :func:`available` is the full check."""
    import importlib.util

    return importlib.util.find_spec("transformers") is not None


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


def _check_reachable(endpoint: str, timeout: float = 5.0) -> None:
    """Raise :class:`InputError` at once when the hub's host cannot be reached (no DNS, no route), instead of
    huggingface_hub's half a minute of retries before the same answer."""
    import socket
    from urllib.parse import urlsplit

    url = urlsplit(endpoint)
    host, port = url.hostname or endpoint, url.port or (80 if url.scheme == "http" else 443)
    try:
        socket.create_connection((host, port), timeout=timeout).close()
    except OSError as exc:
        raise InputError(SPEC, f"cannot reach {host} ({exc.strerror or exc}): the download needs the network; "
                               "check it, or use --depth prior") from None


def _reporting_tqdm(progress: Callable[[float], None]):
    """A tqdm class for huggingface_hub's byte bars that also calls ``progress(fraction)`` (the bar itself
    still draws on stderr); whole-file counters and bars without a total are not reported."""
    from tqdm.auto import tqdm

    class ReportingTqdm(tqdm):
        def __init__(self, *args, **kwargs):
            self._bytes = kwargs.get("unit") == "B"  # a disabled bar (HF_HUB_DISABLE_PROGRESS_BARS) keeps no
            self._done = float(kwargs.get("initial") or 0)  # unit or count of its own: count here
            super().__init__(*args, **kwargs)

        def update(self, n=1):
            out = super().update(n)
            self._done += float(n or 0)
            total = getattr(self, "total", None)
            if self._bytes and total:
                progress(min(1.0, self._done / float(total)))
            return out

    return ReportingTqdm


def download(model_id: str = MODEL_ID, revision: str = REVISION,
             progress: Optional[Callable[[float], None]] = None) -> Path:
    """Fetch the pinned weights into the Hugging Face cache (progress bars on stderr, and
    ``progress(fraction of the bytes)`` where given, from the downloading thread); the folder.

    Raises:
        InputError: without Transformers, offline (``HF_HUB_OFFLINE``, or the hub's host out of reach), or
            when the download fails (no such revision, a broken connection): one line naming the problem.
    """
    _transformers()
    import huggingface_hub
    from huggingface_hub import constants

    if os.environ.get("HF_HUB_OFFLINE", "").strip().lower() in ("1", "true", "yes", "on"):
        raise InputError(SPEC, "cannot download: HF_HUB_OFFLINE is set (unset it, or use --depth prior)")
    _check_reachable(os.environ.get("HF_ENDPOINT") or constants.ENDPOINT)
    extra = {} if progress is None else {"tqdm_class": _reporting_tqdm(progress)}
    try:
        folder = huggingface_hub.snapshot_download(model_id, revision=revision, cache_dir=str(cache_dir()),
                                                   allow_patterns=["*.json", "*.safetensors", "*.txt", "*.md"],
                                                   **extra)
    except Exception as exc:  # noqa: BLE001 (huggingface_hub's many network errors): one line
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(SPEC, f"cannot download {model_id} at revision {revision[:12]} ({first}); "
                               "check the network, or use --depth prior") from None
    if progress is not None:
        progress(1.0)
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


ONNX_SIZE = (518, 518)
"""(height, width) of the exported ONNX graph: the network's 518 pixels, square (``onnx:`` stretches the photo to
the graph's fixed size, as the ``depth_anything`` preset says)."""
ONNX_TOLERANCE = 1e-3
"""Largest difference between the ONNX graph and the network it was exported from, over the output's range."""


def export_onnx(destination: PathLike, size: Tuple[int, int] = ONNX_SIZE, folder: Optional[PathLike] = None) -> float:
    """Export the network (the cached pinned weights, or ``folder``) to an ONNX file with a fixed input of
    ``size`` (height, width; multiples of the 14-pixel patch), for ``--depth onnx:FILE:depth_anything`` without
    Transformers at run time. Written atomically; before the rename the graph is run in onnxruntime on a
    normalised test image and compared with the network. Returns that difference over the output's range.

    Raises:
        InputError: a size that is not a multiple of 14 (or outside 14 - 2044), no weights, no extra.
        ExportError: the file cannot be written, or the graph does not match the network.
    """
    import torch

    from ..errors import ExportError
    from ..io.atomic import write_atomically

    h, w = (int(v) for v in size)
    if min(h, w) < 14 or max(h, w) > 2044 or h % 14 or w % 14:
        raise InputError("size", f"the ONNX input must be multiples of the 14-pixel patch in 14 - 2044, got {h}x{w}")
    net = DepthAnythingModel(folder).model

    class Graph(torch.nn.Module):  # pixel values in, relative inverse depth out: names the onnx: source reads
        def __init__(self) -> None:
            super().__init__()
            self.net = net

        def forward(self, pixel_values):
            return self.net(pixel_values=pixel_values).predicted_depth

    graph = Graph().eval()
    rng = np.random.default_rng(0)
    probe = ((rng.random((1, 3, h, w), dtype=np.float32) - 0.45) / 0.226).astype(np.float32)
    with torch.inference_mode():
        want = graph(torch.from_numpy(probe)).numpy()
    gap = [float("nan")]

    def write(tmp: Path) -> None:
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the tracer's notes on shape arithmetic: the size is fixed
            torch.onnx.export(graph, (torch.zeros(1, 3, h, w),), str(tmp), input_names=["pixel_values"],
                              output_names=["predicted_depth"], opset_version=17, dynamo=False)

    def verify(tmp: Path) -> None:
        import onnxruntime as ort

        got = ort.InferenceSession(str(tmp), providers=["CPUExecutionProvider"]).run(
            None, {"pixel_values": probe})[0]
        span = max(float(want.max() - want.min()), 1e-12)
        gap[0] = float(np.abs(got.reshape(want.shape) - want).max()) / span
        if not gap[0] <= ONNX_TOLERANCE:
            raise ExportError(f"{destination}: the exported graph differs from the network by {gap[0]:.2g} of its range; "
                              "nothing was written")

    write_atomically(destination, "ONNX depth model", write, verify=verify)
    return gap[0]


__all__ = ["MODEL_ID", "REVISION", "SPEC", "DepthAnythingModel", "available", "cached_folder", "download",
           "export_onnx", "installed", "require_weights"]
