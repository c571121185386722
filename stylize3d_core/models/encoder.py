"""Graph-convolutional point-cloud encoder (the public code's config "r3").

Architecture (defaults of :class:`EncoderConfig` and of
:class:`~stylize3d_core.models.scene_geometry.NeighbourhoodConfig`, N input points)::

    stem     MRConv 3 -> 64 on all N points, ball radius 0.015        BN, ReLU
    stage 1  FPS N -> N/4;      MRConv 64 -> 128  (r 0.015, centres among N points)  BN, ReLU
                                MRConv 128 -> 128 (r 0.025, among the N/4)           BN
                                + 1x1 projection of the centres' input features,     ReLU
    stage 2  FPS N/4 -> N/16;   the same with 128 -> 256, radii 0.025 then 0.05
    out      linear 256 -> 256 (no activation)          -> (N/16, 256) features

Each neighbourhood is a ball query: the 16 nearest points within the radius
(:func:`stylize3d_core.points.ball_query`), searched in NDC
(:mod:`stylize3d_core.geometry.ndc`).

**MRConv** (max-relative graph convolution, DeepGCN, Li et al.)::

    out_i = W [f_i || max_j (f_j - f_i)] + b      over the neighbours j of i

where ``f_i`` is point i's own feature; in the first layer of a stage, i is an
FPS-sampled point and ``f_i`` its feature at the previous level. Because
``max_j (f_j - f_i) = max_j f_j - f_i``, only a neighbourhood max-pool of the
input features is needed, computed without any (points x k x channels) tensor:
memory stays O(points x channels).

**Features in:** the point colours, RGB in [0, 1], (N, 3), as in the paper;
positions only shape the neighbourhoods. (Set ``in_channels`` to feed more, e.g.
RGB with xyz appended.)

**Neighbourhoods are computed once.** They depend only on positions, so
:func:`~stylize3d_core.models.scene_geometry.build_hierarchy` returns a
:class:`~stylize3d_core.models.scene_geometry.PointHierarchy` of index tensors
that can be cached per photo and reused for every style and every training
step; the encoder needs only as many stages as it has ``stage_channels``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple, Optional, Tuple

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from .. import threads as _threads
from ..checks import check_finite, check_shape
from ..errors import InputError
from .scene_geometry import PointHierarchy


@dataclass(frozen=True)
class EncoderConfig:
    """Layer widths of :class:`Encoder` (its neighbourhoods are a
    :class:`~stylize3d_core.models.scene_geometry.NeighbourhoodConfig`).

    Attributes:
        in_channels: channels of the input point features (3: RGB, the paper).
        stem_channels: output channels of the stem MRConv (public code: 64).
        stage_channels: output channels of each down-sampling stage (public code:
            (128, 256)); one entry per stage of the neighbourhood config.
        out_relu: apply a ReLU after the final linear layer (public code: no).
    """

    in_channels: int = 3
    stem_channels: int = 64
    stage_channels: Tuple[int, ...] = (128, 256)
    out_relu: bool = False

    def __post_init__(self) -> None:
        name = "EncoderConfig"
        for field in ("in_channels", "stem_channels"):
            if getattr(self, field) < 1:
                raise InputError(f"{name}.{field}", f"must be >= 1, got {getattr(self, field)}")
        if any(c < 1 for c in self.stage_channels):
            raise InputError(f"{name}.stage_channels", f"must all be >= 1, got {self.stage_channels}")

    @classmethod
    def paper(cls) -> "EncoderConfig":
        """The public code's config "r3" (the defaults): 64 / 128 / 256 channels."""
        return cls()

    @classmethod
    def lite(cls) -> "EncoderConfig":
        """Half the channels (32 / 64 / 128): a cheaper CPU variant."""
        return cls(stem_channels=32, stage_channels=(64, 128))

    @property
    def num_stages(self) -> int:
        """Down-sampling stages; a hierarchy must have as many."""
        return len(self.stage_channels)

    @property
    def out_channels(self) -> int:
        """Channels of the encoder's output features."""
        return self.stage_channels[-1] if self.stage_channels else self.stem_channels


# ----------------------------------------------------------------------------- functions

_NARROW_CHANNELS = 4
"""Up to this many feature channels, :func:`neighbour_max` pools one channel at a time (inference only)."""


def neighbour_max(features: torch.Tensor, neighbour_idx: torch.Tensor) -> torch.Tensor:
    """Channel-wise max of the neighbours' features: ``out[i] = max_j features[neighbour_idx[i, j]]``.

    Args:
        features: (N, C) point features.
        neighbour_idx: (M, k) long indices into ``features``, k >= 1.

    Returns:
        (M, C). Differentiable: the gradient of ``out[i, c]`` goes to the first
        maximising neighbour in column order (as ``torch.max`` with indices does).
    """
    check_shape(features, "features", (None, None))
    check_shape(neighbour_idx, "neighbour_idx", (None, None))
    if neighbour_idx.dtype != torch.long or neighbour_idx.shape[1] < 1:
        got = f"{neighbour_idx.dtype} {tuple(neighbour_idx.shape)}"
        raise InputError("neighbour_idx", f"expected (M, k >= 1) long indices, got {got}")
    track = features.requires_grad and torch.is_grad_enabled()
    if not track:  # (checks each index itself: two passes over the indices fewer, ~20 ms of an encoding)
        fast = _compiled_max(features, neighbour_idx)
        if fast is not None:
            return fast
    if neighbour_idx.numel() and (int(neighbour_idx.min()) < 0 or int(neighbour_idx.max()) >= features.shape[0]):
        raise InputError("neighbour_idx", f"indices must lie in [0, {features.shape[0]})")
    if not track and features.shape[1] <= _NARROW_CHANNELS:
        # A few channels (the stem's RGB): rows of 12 bytes make the column loop below a loop of
        # tiny copies; one channel at a time, gathering all M x k values and taking the row max, is
        # ~2x faster for the 300k-point stem (max is exact: the same values).
        cols = features.t().contiguous()  # (C, N)
        out = features.new_empty(neighbour_idx.shape[0], features.shape[1])  # (M, C)
        for c in range(cols.shape[0]):
            torch.amax(cols[c].take(neighbour_idx), dim=1, out=out[:, c])  # (M,)
        return out
    # A running maximum over the k columns: a few (M, C) buffers and no (M, k, C)
    # tensor; on the project's busy 2-core CPU 2-4x faster than gather + amax.
    cols = neighbour_idx.t().contiguous()  # (k, M)
    with torch.no_grad():
        val = features.index_select(0, cols[0])  # (M, C)
        buf = torch.empty_like(val)
        if track:
            src = cols[0][:, None].expand_as(val).clone()  # (M, C) arg-max source point
            better = torch.empty(val.shape, dtype=torch.bool, device=val.device)
        for j in range(1, cols.shape[0]):
            torch.index_select(features, 0, cols[j], out=buf)
            if track:
                torch.gt(buf, val, out=better)
                torch.where(better, cols[j][:, None], src, out=src)
            torch.maximum(val, buf, out=val)
    if not track:
        return val
    return features.gather(0, src)  # (M, C), with autograd: O(M x C) memory for backward


def _compiled_max(features: torch.Tensor, neighbour_idx: torch.Tensor) -> Optional[torch.Tensor]:
    """:func:`neighbour_max` at inference by the models' compiled kernel, in parts of the rows on the pool's
    threads: the same values (a max is exact), one read of each neighbour's row and no (M, C) buffers per
    column; None where it does not apply (no Numba, not
    float32 on the CPU, an index out of range: the checked lines then say so)."""
    kernels = _threads.compiled(__package__ + "._kernels")
    if kernels is None or features.dtype != torch.float32 or features.device.type != "cpu":
        return None
    f = features.detach().contiguous().numpy()
    idx = neighbour_idx.contiguous().numpy()
    out = np.empty((idx.shape[0], f.shape[1]), np.float32)
    ok = _threads.in_parts(lambda a, b: kernels.neighbour_max(f, idx, a, b, out), idx.shape[0], 4096)
    return torch.from_numpy(out) if all(ok) else None  # an index out of range: the checked lines raise


def warm_up() -> None:
    """Load the compiled neighbour max (Numba's cache) on a tiny cloud, so a photo's first encoding does not wait."""
    feats = torch.zeros(2, _NARROW_CHANNELS + 1)
    with torch.no_grad():
        _compiled_max(feats, torch.zeros(1, 2, dtype=torch.long))


def mrconv(
    features: torch.Tensor,
    neighbour_idx: torch.Tensor,
    weight: torch.Tensor,
    bias: Optional[torch.Tensor] = None,
    centre_idx: Optional[torch.Tensor] = None,
) -> torch.Tensor:
    """Max-relative graph convolution: ``W [f_i || max_j (f_j - f_i)] + b``.

    Args:
        features: (N, C_in) features of the points the neighbours index.
        neighbour_idx: (M, k) long neighbours of each output point, into ``features``.
        weight: (C_out, 2 C_in); columns ``:C_in`` act on ``f_i``, the rest on the max.
        bias: (C_out,) or None.
        centre_idx: (M,) long index of each output point in ``features`` (its
            own feature ``f_i``); None when the output points are the input
            points (M = N).

    Returns:
        (M, C_out).
    """
    c_in = features.shape[1]
    if weight.shape[1] != 2 * c_in:
        raise InputError("weight", f"expected {2 * c_in} input columns for {c_in} channels, got {weight.shape[1]}")
    centre = features if centre_idx is None else features.index_select(0, centre_idx)  # (M, C_in)
    pooled = neighbour_max(features, neighbour_idx)  # (M, C_in)
    # W [f_i || m_i - f_i] = (W_a - W_b) f_i + W_b m_i: no (M, 2 C_in) concatenation
    w_a, w_b = weight[:, :c_in], weight[:, c_in:]
    return F.linear(centre, w_a - w_b, bias) + F.linear(pooled, w_b)  # (M, C_out)


# ----------------------------------------------------------------------------- modules


class MRConv(nn.Module):
    """:func:`mrconv` followed by BatchNorm over the points (no activation)."""

    def __init__(self, in_channels: int, out_channels: int) -> None:
        super().__init__()
        self.linear = nn.Linear(2 * in_channels, out_channels)
        self.norm = nn.BatchNorm1d(out_channels)

    def forward(
        self, features: torch.Tensor, neighbour_idx: torch.Tensor, centre_idx: Optional[torch.Tensor] = None
    ) -> torch.Tensor:
        """(N, C_in) features, (M, k) neighbours, optional (M,) centres -> (M, C_out)."""
        return self.norm(mrconv(features, neighbour_idx, self.linear.weight, self.linear.bias, centre_idx))


class MRConvBlock(nn.Module):
    """Down-sampling residual block: two MRConvs plus a 1x1 shortcut.

    ``relu(BN(MRConv_2(relu(BN(MRConv_1(f))))) + shortcut(f_centres))``, the
    shortcut a bias-free linear projection when channels or points change.
    """

    def __init__(self, in_channels: int, out_channels: int, downsamples: bool = True) -> None:
        super().__init__()
        self.conv1 = MRConv(in_channels, out_channels)
        self.conv2 = MRConv(out_channels, out_channels)
        project = downsamples or in_channels != out_channels
        self.shortcut = nn.Linear(in_channels, out_channels, bias=False) if project else nn.Identity()

    def forward(
        self,
        features: torch.Tensor,
        sample_idx: torch.Tensor,
        down_neighbours: torch.Tensor,
        same_neighbours: torch.Tensor,
    ) -> torch.Tensor:
        """(N, C_in) level-s features -> (M, C_out) level-(s+1) features.

        ``sample_idx`` (M,), ``down_neighbours`` (M, k) into level s,
        ``same_neighbours`` (M, k) into level s + 1.
        """
        x = F.relu(self.conv1(features, down_neighbours, sample_idx))  # (M, C_out)
        x = self.conv2(x, same_neighbours)  # (M, C_out)
        return F.relu(x + self.shortcut(features.index_select(0, sample_idx)))


class EncoderOutput(NamedTuple):
    """Result of :class:`Encoder`: features of the coarsest level and its positions."""

    features: torch.Tensor  # (N_L, C_out), N_L ~ N / 16 for the paper's config
    xyz: torch.Tensor  # (N_L, 3) NDC positions of those points


class Encoder(nn.Module):
    """The point-cloud encoder (see the module docstring); holds parameters only.

    ``forward(features (N, in_channels), hierarchy) -> EncoderOutput``; build
    the hierarchy once per cloud with
    :func:`~stylize3d_core.models.scene_geometry.build_hierarchy`.
    """

    def __init__(self, config: EncoderConfig = EncoderConfig()) -> None:
        super().__init__()
        self.config = config
        self.stem = MRConv(config.in_channels, config.stem_channels)
        blocks, c_in = [], config.stem_channels
        for c_out in config.stage_channels:
            blocks.append(MRConvBlock(c_in, c_out, downsamples=True))
            c_in = c_out
        self.blocks = nn.ModuleList(blocks)
        self.out = nn.Linear(c_in, c_in)

    def _check(self, features: torch.Tensor, hierarchy: PointHierarchy) -> None:
        if not isinstance(hierarchy, PointHierarchy):
            raise InputError("hierarchy", f"expected a PointHierarchy, got {type(hierarchy).__name__}")
        if hierarchy.num_stages != self.config.num_stages:
            raise InputError(
                "hierarchy",
                f"has {hierarchy.num_stages} down-sampling stages, this encoder {self.config.num_stages}: "
                "build it with a NeighbourhoodConfig of as many stages",
            )
        check_shape(features, "features", (hierarchy.num_points[0], self.config.in_channels))
        if not torch.is_floating_point(features):
            raise InputError("features", f"expected a floating-point tensor, got {features.dtype}")
        check_finite(features, "features")
        if self.training and min(hierarchy.num_points) < 2:
            raise InputError(
                "hierarchy",
                f"training (batch statistics) needs >= 2 points per level, got levels of {hierarchy.num_points}",
            )

    def forward(self, features: torch.Tensor, hierarchy: PointHierarchy) -> EncoderOutput:
        """(N, in_channels) point features (RGB in [0, 1]) -> (N_L, out_channels) features."""
        self._check(features, hierarchy)
        x = F.relu(self.stem(features, hierarchy.stem_neighbours))  # (N, C0)
        for s, block in enumerate(self.blocks):
            x = block(x, hierarchy.sample_idx[s], hierarchy.down_neighbours[s], hierarchy.same_neighbours[s])
        x = self.out(x)  # (N_L, C_out)
        if self.config.out_relu:
            x = F.relu(x)
        return EncoderOutput(x, hierarchy.xyz[-1])
