"""Run a monocular depth network that the user supplies as an ONNX file (CPU, onnxruntime).

Any network exported to ONNX that maps one image to one depth-like map works:
MiDaS, DPT, Depth Anything, ... A :class:`OnnxPreset` says how to feed it (input
size, value range, mean / std) and what it returns:

* ``"inverse_depth"`` -- relative inverse depth (MiDaS, DPT, Depth Anything):
  known only up to an unknown scale **and shift**. It is converted to relative
  depth with a documented scale: the 1st percentile of the output is taken as
  the farthest point, the 99th as the nearest, the output is mapped linearly
  onto nearness ``n`` in [0, 1] (clipped) and
  ``depth = 1 / (1/far_ratio + (1 - 1/far_ratio) * n)``, so depth lies in
  [1, far_ratio] (``far_ratio`` defaults to 10).
* ``"depth"`` -- depth (relative, or in metres for metric models): used as is;
  non-finite or non-positive pixels are invalid and filled from neighbours.

A model whose input has fixed spatial dimensions is fed at exactly that size
(stretched); a model with dynamic dimensions is fed at the preset's size. The
layout (NCHW or NHWC) is read from the model's input shape.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Dict, Literal, Tuple

import cv2
import numpy as np
import onnxruntime as ort
from onnxruntime.capi.onnxruntime_pybind11_state import (
    Fail,
    InvalidArgument,
    InvalidGraph,
    InvalidProtobuf,
    NoSuchFile,
    RuntimeException,
)

from ..checks import check_choice, check_range
from ..errors import InputError, PathLike
from ._util import check_rgb, nearness_to_depth
from .fill import fill_nearest
from .types import DepthMap

_ORT_LOAD_ERRORS = (Fail, InvalidArgument, InvalidGraph, InvalidProtobuf, NoSuchFile)

IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)


@dataclass(frozen=True)
class OnnxPreset:
    """How to feed a depth network and read its output."""

    size: int = 384
    """Side of the input for models with dynamic spatial dimensions (see ``fit``)."""
    fit: Literal["stretch", "keep_aspect"] = "stretch"
    """"stretch": feed size x size; "keep_aspect": longer side = size, both sides multiples of ``multiple_of``."""
    multiple_of: int = 32
    """Input sides are rounded to a multiple of this (patch size 14 for ViT-based Depth Anything)."""
    input_range: float = 1.0
    """Pixel values are scaled to [0, input_range] before normalisation (1 or 255)."""
    mean: Tuple[float, float, float] = IMAGENET_MEAN
    """Per-channel mean (RGB) subtracted after scaling."""
    std: Tuple[float, float, float] = IMAGENET_STD
    """Per-channel standard deviation (RGB) divided after subtracting the mean."""
    output: Literal["inverse_depth", "depth"] = "inverse_depth"
    """What the network returns (see the module docstring)."""
    metric: bool = False
    """True when a "depth" output is in metres (the DepthMap is then kind "metric")."""

    def __post_init__(self) -> None:
        check_range(self.size, "preset size", 8, 4096)
        check_choice(self.fit, "preset fit", ("stretch", "keep_aspect"))
        check_range(self.multiple_of, "preset multiple_of", 1, 512)
        check_range(self.input_range, "preset input_range", 0.0, 1e4, inclusive=False)
        check_choice(self.output, "preset output", ("inverse_depth", "depth"))
        if len(self.mean) != 3 or len(self.std) != 3 or min(self.std) <= 0:
            raise InputError("preset", f"mean and std need 3 values and std > 0, got {self.mean}, {self.std}")
        if self.metric and self.output != "depth":
            raise InputError("preset", "only a 'depth' output can be metric")


PRESETS: Dict[str, OnnxPreset] = {
    # MiDaS v2.1 / v3 exports: 384 x 384, ImageNet statistics, relative inverse depth.
    "midas": OnnxPreset(size=384, fit="stretch"),
    # MiDaS v2.1 small: 256 x 256.
    "midas_small": OnnxPreset(size=256, fit="stretch"),
    # DPT (Large / Hybrid): 384 x 384, mean = std = 0.5.
    "dpt": OnnxPreset(size=384, fit="stretch", mean=(0.5, 0.5, 0.5), std=(0.5, 0.5, 0.5)),
    # Depth Anything (v1 / v2) relative: 518 x 518 (multiple of the ViT patch 14).
    "depth_anything": OnnxPreset(size=518, fit="stretch", multiple_of=14),
    # Depth Anything metric fine-tunes: depth in metres.
    "depth_anything_metric": OnnxPreset(size=518, fit="stretch", multiple_of=14, output="depth", metric=True),
    # A network fed the photo in [0, 1] without normalisation, returning relative depth.
    "raw": OnnxPreset(size=384, fit="keep_aspect", mean=(0.0, 0.0, 0.0), std=(1.0, 1.0, 1.0), output="depth"),
}
DEFAULT_PRESET = "midas"


@dataclass(frozen=True)
class OnnxSettings:
    """Settings of :class:`OnnxDepthModel`."""

    preset: OnnxPreset = PRESETS[DEFAULT_PRESET]
    """Input/output conventions of the network (see :data:`PRESETS`)."""
    far_ratio: float = 10.0
    """For inverse-depth outputs: depth of the farthest point / nearest (see the module docstring)."""
    threads: int = 0
    """onnxruntime intra-op threads; 0 = onnxruntime's default (all cores)."""

    def __post_init__(self) -> None:
        check_range(self.far_ratio, "far_ratio", 1.0, 1e4, inclusive=False)
        check_range(self.threads, "threads", 0, 256)


def inverse_depth_map(raw: np.ndarray, shape: Tuple[int, int], far_ratio: float, source: str,
                      path: PathLike) -> DepthMap:
    """A network's relative inverse depth (h, w) -> a "relative" :class:`DepthMap` at ``shape`` (H, W): resized
    bilinearly, its 1st / 99th percentiles taken as the farthest / nearest point and mapped onto depth in
    [1, ``far_ratio``] (see the module docstring); non-finite pixels invalid and filled from neighbours.
    ``path`` names the model in errors."""
    out = cv2.resize(np.asarray(raw, np.float32), (shape[1], shape[0]), interpolation=cv2.INTER_LINEAR)
    valid = np.isfinite(out)
    if not valid.any():
        raise InputError(path, "model output has no finite value")
    lo, hi = np.percentile(out[valid], [1.0, 99.0])
    if not hi - lo > 1e-12 * max(1.0, abs(hi)):
        raise InputError(path, f"model output is constant ({hi:g}); it gives no depth (check the preset)")
    n = np.where(valid, (out - lo) / (hi - lo), 0.0)
    depth = nearness_to_depth(n, far_ratio)
    if not valid.all():
        depth = fill_nearest(depth, valid)
    return DepthMap(depth, valid, "relative", source)


def preset_by_name(name: str) -> OnnxPreset:
    """The preset called ``name`` (one of :data:`PRESETS`), or an InputError listing them."""
    return PRESETS[check_choice(name, "onnx preset", tuple(PRESETS))]


def _round_to(x: float, m: int) -> int:
    return max(m, int(round(x / m)) * m)


class OnnxDepthModel:
    """A depth network loaded from an ONNX file, run on the CPU.

    The file is loaded and its input and output checked in the constructor, so
    a bad file fails early with an :class:`InputError` that names it.
    """

    def __init__(self, path: PathLike, settings: OnnxSettings = OnnxSettings()) -> None:
        self.path = os.fspath(path)
        self.settings = settings
        if not os.path.isfile(self.path):
            raise InputError(self.path, "no such ONNX model file")
        options = ort.SessionOptions()
        options.intra_op_num_threads = settings.threads
        options.log_severity_level = 3
        try:
            self.session = ort.InferenceSession(self.path, options, providers=["CPUExecutionProvider"])
        except _ORT_LOAD_ERRORS as exc:
            raise InputError(self.path, f"not a valid ONNX model ({exc})") from exc
        inputs = self.session.get_inputs()
        if len(inputs) != 1:
            names = ", ".join(i.name for i in inputs)
            raise InputError(
                self.path,
                f"a depth model must take exactly one input (an image), this one takes {len(inputs)}: {names}",
            )
        inp = inputs[0]
        self.input_name = inp.name
        shape = list(inp.shape)
        if len(shape) != 4:
            raise InputError(
                self.path,
                f"input {inp.name!r} has rank {len(shape)} (shape {shape}); "
                "expected an image batch of rank 4, (N, 3, H, W) or (N, H, W, 3)",
            )
        if shape[1] == 3:
            self.layout = "NCHW"
        elif shape[3] == 3:
            self.layout = "NHWC"
        elif isinstance(shape[1], int) or isinstance(shape[3], int):
            raise InputError(self.path, f"input {inp.name!r} has shape {shape}: expected 3 colour channels")
        else:
            self.layout = "NCHW"
        if inp.type not in ("tensor(float)", "tensor(float16)"):
            raise InputError(self.path, f"input {inp.name!r} has type {inp.type}; expected float32 or float16")
        self.input_dtype = np.float16 if inp.type == "tensor(float16)" else np.float32
        hw = shape[2:4] if self.layout == "NCHW" else shape[1:3]
        self.fixed_size = tuple(hw) if all(isinstance(v, int) and v > 0 for v in hw) else None
        if isinstance(shape[0], int) and shape[0] != 1:
            raise InputError(self.path, f"input {inp.name!r} has a fixed batch of {shape[0]}; expected 1 or dynamic")

    # ------------------------------------------------------------------ steps

    def input_size(self, height: int, width: int) -> Tuple[int, int]:
        """The (h, w) the network is fed for a photo of (height, width)."""
        if self.fixed_size is not None:
            return self.fixed_size
        p = self.settings.preset
        if p.fit == "stretch":
            side = _round_to(p.size, p.multiple_of)
            return side, side
        scale = p.size / max(height, width)
        return _round_to(height * scale, p.multiple_of), _round_to(width * scale, p.multiple_of)

    def preprocess(self, rgb: np.ndarray) -> np.ndarray:
        """Photo (H, W, 3) in [0, 1] -> network input (1, 3, h, w) or (1, h, w, 3)."""
        p = self.settings.preset
        h, w = self.input_size(rgb.shape[0], rgb.shape[1])
        interp = cv2.INTER_AREA if h * w < rgb.shape[0] * rgb.shape[1] else cv2.INTER_CUBIC
        x = cv2.resize(rgb, (w, h), interpolation=interp).astype(np.float32)  # (h, w, 3)
        x = (x * p.input_range - np.asarray(p.mean, np.float32)) / np.asarray(p.std, np.float32)
        x = x[None] if self.layout == "NHWC" else x.transpose(2, 0, 1)[None]
        return np.ascontiguousarray(x, dtype=self.input_dtype)

    def run(self, x: np.ndarray) -> np.ndarray:
        """Run the network on a prepared input; returns its first output as (h, w) float32."""
        try:
            out = self.session.run(None, {self.input_name: x})[0]
        except _ORT_LOAD_ERRORS + (RuntimeException,) as exc:
            raise InputError(self.path, f"the model failed to run on a {x.shape} input ({exc})") from exc
        out = np.asarray(out, dtype=np.float32)
        squeezed = np.squeeze(out)
        if squeezed.ndim != 2:
            raise InputError(
                self.path, f"output has shape {out.shape}; expected one depth map, e.g. (1, 1, H, W) or (1, H, W)"
            )
        return squeezed

    def to_depth(self, raw: np.ndarray, shape: Tuple[int, int]) -> DepthMap:
        """Network output (h, w) -> DepthMap at the photo's ``shape`` (see the module docstring)."""
        p = self.settings.preset
        source = f"onnx:{os.path.basename(self.path)}"
        if p.output == "inverse_depth":
            return inverse_depth_map(raw, shape, self.settings.far_ratio, source, self.path)
        out = cv2.resize(raw, (shape[1], shape[0]), interpolation=cv2.INTER_LINEAR)
        valid = np.isfinite(out) & (out > 0)
        if not valid.any():
            raise InputError(
                self.path, "model output has no positive finite depth (is it inverse depth? check the preset)"
            )
        depth = fill_nearest(np.where(valid, out, 0.0).astype(np.float32), valid)
        return DepthMap(depth.astype(np.float32), valid, "metric" if p.metric else "relative", source)

    def estimate(self, rgb: np.ndarray) -> DepthMap:
        """Depth for the photo ``rgb`` (H, W, 3) in [0, 1], aligned with it."""
        photo = check_rgb(rgb)
        return self.to_depth(self.run(self.preprocess(photo)), photo.shape[:2])
