"""AdaAttN stylizer for point features (Liu et al. 2021, adapted to point clouds as in Mu et al. 2022).

AdaAttN ("attention-weighted AdaIN") gives every content point its own style
statistics: with ``norm`` the mean-variance normalisation over the points (or
pixels) of one sample, per channel, with ``eps``::

    Q = f(norm(content_key))          (M, D)   one query per content point
    K = g(norm(style_key))            (L, D)   one key per style-map pixel
    V = h(style)                      (L, C)
    A = softmax(Q K^T)                (M, L)   (unscaled, as in AdaAttN)
    mean = A V,  std = sqrt(relu(A V^2 - mean^2) + eps)
    out  = std * norm(content) + mean (M, C)

:func:`adaattn` is this formula (f, g, h optional callables; identity gives
the parameter-free version used by the AdaAttN content loss).
:class:`AdaAttNStylizer` adds the learned parts of the 3D Photo Stylization
stylizer: point-wise MLPs phi before (one for the query, one for the content
value, as in the public code) and psi after, each two layers of
``hidden`` = 256 units with LeakyReLU(0.2), and 1x1 projections f, g, h.

**Style stages.** The public code attends to a single VGG layer (relu3_1).
Here the value is one EfficientNet-Lite0 map (default stage 3: stride 16,
112 channels, a 32 x 32 grid for a 512-pixel style image, L = 1024), and the
key concatenates the maps of stages 0..3 after area-resizing each to the value
grid, as AdaAttN builds its relu4_1 key from relu1_1..relu4_1. The content key
is the point feature itself (points have one feature level).

**Memory.** The (M, L) attention is never formed for all points at once: the
queries are processed ``chunk_size`` (default 4096) at a time with
``torch.nn.functional.scaled_dot_product_attention`` on ``[V | V^2]``, so the
extra memory is about ``chunk_size * L`` floats (16 MB for L = 1024) whatever
M is. Content statistics are computed over all M points first, so the result
does not depend on the chunk size.

**Cost.** For M points and L keys, about ``2 M L (D + 2 Cv)`` FLOPs of attention
plus the MLPs (``AdaAttNConfig.paper()``: ~150 GFLOP at M = 60k, L = 1024;
``AdaAttNConfig.lite()``: ~60). The style-independent half (phi, the query,
the normalised content) is computed by :meth:`AdaAttNStylizer.prepare` and can
be cached, so a new style or strength does not redo it.

**Numerics.** Zero-variance style (a constant-colour style image) gives
``std = sqrt(eps)`` and a uniform attention: finite values and gradients.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, List, NamedTuple, Optional, Sequence, Tuple

import torch
import torch.nn.functional as F
from torch import nn

from ..checks import check_range
from ..errors import InputError

Projection = Optional[Callable[[torch.Tensor], torch.Tensor]]


def mean_variance_norm(x: torch.Tensor, eps: float = 1e-5) -> torch.Tensor:
    """Normalise (..., N, C) to zero mean, unit variance over N, per channel: (x - mu) / sqrt(var + eps)."""
    mu = x.mean(dim=-2, keepdim=True)  # (..., 1, C)
    var = x.var(dim=-2, unbiased=False, keepdim=True)  # (..., 1, C)
    return (x - mu) * torch.rsqrt(var + eps)


def attention_statistics(
    query: torch.Tensor, key: torch.Tensor, value: torch.Tensor, *, eps: float = 1e-5, chunk_size: int = 4096
) -> Tuple[torch.Tensor, torch.Tensor]:
    """Attention-weighted mean and std of ``value`` for every query.

    Args:
        query: (..., M, D); key: (..., L, D); value: (..., L, C).
        eps: added to the variance before the square root.
        chunk_size: queries per chunk (bounds memory to about chunk_size * L floats).

    Returns:
        mean (..., M, C) = A V and std (..., M, C) = sqrt(relu(A V^2 - mean^2) + eps),
        with A = softmax(query key^T) (no 1/sqrt(D) scaling).
    """
    if chunk_size < 1:
        raise InputError("chunk_size", f"must be >= 1, got {chunk_size}")
    c = value.shape[-1]
    moments = torch.cat([value, value * value], dim=-1)  # (..., L, 2C)
    parts: List[torch.Tensor] = []
    for start in range(0, query.shape[-2], chunk_size):
        q = query[..., start : start + chunk_size, :]  # (..., m, D)
        parts.append(F.scaled_dot_product_attention(q, key, moments, scale=1.0))  # (..., m, 2C)
    stats = torch.cat(parts, dim=-2) if len(parts) > 1 else parts[0]  # (..., M, 2C)
    mean, second = stats[..., :c], stats[..., c:]
    std = torch.sqrt(F.relu(second - mean * mean) + eps)
    return mean, std


def adaattn(
    content: torch.Tensor,
    content_key: torch.Tensor,
    style: torch.Tensor,
    style_key: torch.Tensor,
    *,
    query_proj: Projection = None,
    key_proj: Projection = None,
    value_proj: Projection = None,
    eps: float = 1e-5,
    chunk_size: int = 4096,
) -> torch.Tensor:
    """AdaAttN (see the module docstring): returns std * norm(content) + mean, (..., M, C).

    Args:
        content: (..., M, C) content values (point features).
        content_key: (..., M, Dq) content key, normalised here then passed to ``query_proj``.
        style: (..., L, Cs) style values, passed to ``value_proj`` (whose output must have C channels).
        style_key: (..., L, Dk) style key, normalised here then passed to ``key_proj``.
        query_proj, key_proj, value_proj: f, g, h; None = identity (the parameter-free AdaAttN).
        eps: variance epsilon of the normalisations and of the std.
        chunk_size: queries per attention chunk.
    """
    if content.shape[:-1] != content_key.shape[:-1]:
        raise InputError("content_key", f"shape {tuple(content_key.shape)} does not match content {tuple(content.shape)}")
    if style.shape[:-1] != style_key.shape[:-1]:
        raise InputError("style_key", f"shape {tuple(style_key.shape)} does not match style {tuple(style.shape)}")
    q = mean_variance_norm(content_key, eps)
    k = mean_variance_norm(style_key, eps)
    v = style
    if query_proj is not None:
        q = query_proj(q)
    if key_proj is not None:
        k = key_proj(k)
    if value_proj is not None:
        v = value_proj(v)
    if q.shape[-1] != k.shape[-1]:
        raise InputError("style_key", f"query has {q.shape[-1]} channels but key has {k.shape[-1]}")
    if v.shape[-1] != content.shape[-1]:
        raise InputError("style", f"value has {v.shape[-1]} channels but content has {content.shape[-1]}")
    mean, std = attention_statistics(q, k, v, eps=eps, chunk_size=chunk_size)
    return std * mean_variance_norm(content, eps) + mean


def blend(content: torch.Tensor, stylized: torch.Tensor, alpha: float) -> torch.Tensor:
    """Style strength: ``content + alpha * (stylized - content)``; alpha = 0 gives ``content`` exactly."""
    a = check_range(alpha, "alpha", 0.0, 1.0)
    if a == 0.0:
        return content.clone()
    if a == 1.0:
        return stylized
    return torch.lerp(content, stylized, a)


def style_tokens(
    style_maps: Sequence[torch.Tensor], value_stage: int, key_stages: Sequence[int]
) -> Tuple[torch.Tensor, torch.Tensor]:
    """Flatten style maps into AdaAttN tokens.

    Args:
        style_maps: maps (B, C_i, h_i, w_i) from a feature extractor.
        value_stage: index of the value map; its grid (h, w) sets L = h * w.
        key_stages: indices of the maps concatenated into the key, each area-resized
            (bilinear if smaller) to (h, w).

    Returns:
        style (B, L, C_value), style_key (B, L, sum of key channels).
    """
    n = len(style_maps)
    for s in (value_stage, *key_stages):
        if not -n <= s < n:
            raise InputError("style stage", f"index {s} out of range for {n} style maps")
    value = style_maps[value_stage]  # (B, Cv, h, w)
    size = value.shape[-2:]
    keys = []
    for s in key_stages:
        m = style_maps[s]
        if m.shape[-2:] != size:
            larger = m.shape[-2] >= size[0] and m.shape[-1] >= size[1]
            m = F.adaptive_avg_pool2d(m, size) if larger else F.interpolate(m, size=size, mode="bilinear", align_corners=False)
        keys.append(m)
    key = torch.cat(keys, dim=1)  # (B, Ck, h, w)
    return value.flatten(2).transpose(1, 2), key.flatten(2).transpose(1, 2)


@dataclass(frozen=True)
class AdaAttNConfig:
    """Settings of :class:`AdaAttNStylizer`.

    Attributes:
        content_channels: C of the point features (encoder output: 256).
        style_channels: channels of the style maps given to the stylizer, in order
            (EfficientNet-Lite0 stages 0..4: 16, 24, 40, 112, 320).
        value_stage: style map used as the value (3: stride 16, 112 channels).
        key_stages: style maps concatenated into the key (0..3, as AdaAttN's relu1_1..relu4_1).
        hidden: width of the phi/psi MLPs (paper: 256).
        value_channels: channels in which AdaIN happens (phi's output, h's output; public code: 256).
        qk_channels: query/key channels D after f and g (public code: 256).
        eps: variance epsilon.
        chunk_size: queries per attention chunk (see the module docstring).
    """

    content_channels: int = 256
    style_channels: Tuple[int, ...] = (16, 24, 40, 112, 320)
    value_stage: int = 3
    key_stages: Tuple[int, ...] = (0, 1, 2, 3)
    hidden: int = 256
    value_channels: int = 256
    qk_channels: int = 256
    eps: float = 1e-5
    chunk_size: int = 4096

    def __post_init__(self) -> None:
        n = len(self.style_channels)
        for s in (self.value_stage, *self.key_stages):
            if not 0 <= s < n:
                raise InputError("AdaAttNConfig", f"style stage {s} out of range 0..{n - 1}")
        if not self.key_stages:
            raise InputError("AdaAttNConfig.key_stages", "must name at least one stage")
        if any(c < 1 for c in self.style_channels):
            raise InputError("AdaAttNConfig.style_channels", f"must all be >= 1, got {self.style_channels}")
        for name in ("content_channels", "hidden", "value_channels", "qk_channels", "chunk_size"):
            if getattr(self, name) < 1:
                raise InputError(f"AdaAttNConfig.{name}", f"must be >= 1, got {getattr(self, name)}")
        if not self.eps > 0:
            raise InputError("AdaAttNConfig.eps", f"must be > 0, got {self.eps}")

    @classmethod
    def paper(cls) -> "AdaAttNConfig":
        """The public code's widths: 256-unit MLPs, 256-channel query/key and value (the default)."""
        return cls()

    @classmethod
    def lite(cls) -> "AdaAttNConfig":
        """About 2.5x fewer FLOPs for CPU re-styling: 128-unit MLPs and value, 64-channel query/key.

        See ``tests/benchmarks/bench_decoder.py`` for timings at M = 20k and 60k points.
        """
        return cls(hidden=128, value_channels=128, qk_channels=64)


class PreparedContent(NamedTuple):
    """Style-independent part of :class:`AdaAttNStylizer` for one point cloud.

    Attributes:
        query: (B, M, D) f(norm(phi_query(content))).
        value_norm: (B, M, Cv) norm(phi_value(content)).
        batched: whether the content came as (B, M, C) (else (M, C)).
    """

    query: torch.Tensor
    value_norm: torch.Tensor
    batched: bool


def _mlp(c_in: int, hidden: int, c_out: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(c_in, hidden), nn.LeakyReLU(0.2), nn.Linear(hidden, c_out))


class AdaAttNStylizer(nn.Module):
    """Learned AdaAttN between point features and style maps (see the module docstring).

    ``prepare(content)`` -> cacheable style-independent part;
    ``stylize_prepared(prepared, style_maps)`` / ``stylize(content, style_maps)``
    -> full-strength stylized features;
    ``forward(content, style_maps, alpha)`` blends them with ``content`` by
    ``alpha`` (cache :meth:`stylize`'s result and call :func:`blend` when only
    the strength changes).
    """

    def __init__(self, config: AdaAttNConfig = AdaAttNConfig()) -> None:
        super().__init__()
        self.config = cfg = config
        key_ch = sum(cfg.style_channels[s] for s in cfg.key_stages)
        self.phi_query = _mlp(cfg.content_channels, cfg.hidden, cfg.hidden)
        self.phi_value = _mlp(cfg.content_channels, cfg.hidden, cfg.value_channels)
        self.query_proj = nn.Linear(cfg.hidden, cfg.qk_channels)  # f
        self.key_proj = nn.Linear(key_ch, cfg.qk_channels)  # g
        self.value_proj = nn.Linear(cfg.style_channels[cfg.value_stage], cfg.value_channels)  # h
        self.psi = _mlp(cfg.value_channels, cfg.hidden, cfg.content_channels)

    def _check_content(self, content: torch.Tensor) -> None:
        c = self.config.content_channels
        if content.dim() not in (2, 3) or content.shape[-1] != c or content.shape[-2] < 1:
            raise InputError("content", f"expected (M, {c}) or (B, M, {c}), got {tuple(content.shape)}")

    def _check_style(self, style_maps: Sequence[torch.Tensor], batch: int) -> None:
        channels = self.config.style_channels
        if len(style_maps) != len(channels):
            raise InputError("style_maps", f"expected {len(channels)} maps, got {len(style_maps)}")
        for i, (m, c) in enumerate(zip(style_maps, channels)):
            if m.dim() != 4 or m.shape[1] != c or m.shape[0] != batch:
                raise InputError(f"style_maps[{i}]", f"expected ({batch}, {c}, h, w), got {tuple(m.shape)}")

    def prepare(self, content: torch.Tensor) -> PreparedContent:
        """The style-independent half: content (M, C) or (B, M, C) -> :class:`PreparedContent`.

        Cache it to re-style the same point cloud: it holds phi's outputs, so a new
        style costs only the attention and psi.
        """
        self._check_content(content)
        cfg = self.config
        batched = content.dim() == 3
        x = content if batched else content.unsqueeze(0)  # (B, M, C)
        query = self.query_proj(mean_variance_norm(self.phi_query(x), cfg.eps))  # (B, M, D)
        value = mean_variance_norm(self.phi_value(x), cfg.eps)  # (B, M, Cv)
        return PreparedContent(query, value, batched)

    def stylize_prepared(self, prepared: PreparedContent, style_maps: Sequence[torch.Tensor]) -> torch.Tensor:
        """Full-strength stylized features (content's shape) from :meth:`prepare`'s result."""
        cfg = self.config
        self._check_style(style_maps, prepared.query.shape[0])
        style, style_key = style_tokens(style_maps, cfg.value_stage, cfg.key_stages)  # (B, L, Cs), (B, L, Ck)
        key = self.key_proj(mean_variance_norm(style_key, cfg.eps))  # (B, L, D)
        value = self.value_proj(style)  # (B, L, Cv)
        mean, std = attention_statistics(prepared.query, key, value, eps=cfg.eps, chunk_size=cfg.chunk_size)
        out = self.psi(std * prepared.value_norm + mean)  # (B, M, C)
        return out if prepared.batched else out.squeeze(0)

    def stylize(self, content: torch.Tensor, style_maps: Sequence[torch.Tensor]) -> torch.Tensor:
        """Content (M, C) or (B, M, C), style maps (B, C_i, h_i, w_i) -> stylized features, content's shape.

        Equals ``psi(adaattn(phi_value(x), phi_query(x), style, style_key, f, g, h))``.
        """
        return self.stylize_prepared(self.prepare(content), style_maps)

    def forward(self, content: torch.Tensor, style_maps: Sequence[torch.Tensor], alpha: float = 1.0) -> torch.Tensor:
        a = check_range(alpha, "alpha", 0.0, 1.0)
        if a == 0.0:
            self._check_content(content)
            self._check_style(style_maps, content.shape[0] if content.dim() == 3 else 1)
            return content.clone()
        return blend(content, self.stylize(content, style_maps), a)
