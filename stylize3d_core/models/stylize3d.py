"""The whole stylization model: encoder -> AdaAttN stylizer -> IDW upsampling -> rasterizer -> U-Net.

Data flow for one photo (N points, M ~ N_enc / 16 encoded points)::

    points (N, 3) world, rgb (N, 3)
      | prepare_geometry (once per photo; positions only)
      v   NDC, encoder subset (<= encoder_max_points), FPS/ball-query hierarchy, 3-NN weights
    encode            -> content (M, C)                      once per photo
    stylize (+alpha)  -> features (M, C)                     once per style / strength
    dense_features    -> (N, Cr) = IDW(project(features))    once per style / strength
    render_view       -> rasterize (Cr, H, W) -> decode (3, H, W)   per camera

The projection to ``raster_channels`` happens before the IDW upsampling: both
are linear and the IDW weights sum to one, so the order does not change the
result, and projecting the M sparse points is 16x cheaper than the N dense ones.

Ball radii follow the cloud's density: the published radii suit ~512 points
across, and :func:`radius_scale` scales them for any other density, so every
ball spans about as many points as in the paper. Clouds larger than
``encoder_max_points`` are encoded from a fixed random subset (the encoder's
cost grows with the points; its radii are scaled to the subset's density); the
features reach every point through the 3-NN upsampling.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, NamedTuple, Sequence, Tuple

import torch
from torch import nn

from ..checks import check_range, check_shape
from ..errors import InputError
from ..geometry.camera import Cameras
from ..geometry.ndc import NDCParams, ndc_params, to_ndc
from ..points import IDWWeights, interpolate, three_nn
from ..render.rasterize import Fragments, RasterSettings
from ..render.rasterizer import PointRasterizer
from .adaattn import AdaAttNConfig, AdaAttNStylizer, blend
from .decoder import DecoderConfig, UNetDecoder
from .encoder import Encoder, EncoderConfig, PointHierarchy, build_hierarchy

ConfigName = Literal["lite", "paper"]

REFERENCE_POINTS_ACROSS = 512
"""Points across the long side of the clouds the published encoder radii were set for (512 x 512 photos)."""


def radius_scale(image_size: Tuple[int, int], n_encoded: int, n_total: int) -> float:
    """Factor for the encoder's ball radii so every ball spans as many points as in the paper.

    The radii are in NDC, where the photo spans [-1, 1]: a photo whose long side
    is ``L`` pixels has points ``2 / L`` apart, thinned by ``sqrt(n_encoded /
    n_total)`` when the encoder sees a subset. The factor is
    ``REFERENCE_POINTS_ACROSS / (L * sqrt(n_encoded / n_total))``: 1 at 512 px,
    4 for a 128 px training crop.
    """
    long_side = max(image_size) * (n_encoded / max(n_total, 1)) ** 0.5
    return REFERENCE_POINTS_ACROSS / max(long_side, 1.0)


@dataclass(frozen=True)
class ModelConfig:
    """Architecture of :class:`Stylize3DModel`.

    Attributes:
        name: "lite" (CPU: narrower encoder, stylizer and decoder) or "paper"
            (the public code's widths, for GPUs).
        encoder: the point-cloud encoder.
        stylizer: AdaAttN with phi/psi MLPs; ``content_channels`` must equal the encoder's output.
        raster_channels: channels splatted by the rasterizer (the decoder's input).
        decoder: the U-Net; ``in_channels`` must equal ``raster_channels``.
        encoder_max_points: clouds larger than this are encoded from a random
            subset of this size, to bound the encoder's cost (see the module docstring). Default 300k.
    """

    name: ConfigName = "lite"
    encoder: EncoderConfig = field(default_factory=EncoderConfig.lite)
    stylizer: AdaAttNConfig = field(default_factory=lambda: AdaAttNConfig(
        content_channels=128, hidden=128, value_channels=128, qk_channels=64))
    raster_channels: int = 32
    decoder: DecoderConfig = field(default_factory=lambda: DecoderConfig.lite(in_channels=32))
    encoder_max_points: int = 300_000

    def __post_init__(self) -> None:
        if self.stylizer.content_channels != self.encoder.out_channels:
            raise InputError("ModelConfig", f"stylizer content_channels {self.stylizer.content_channels} != "
                             f"encoder output {self.encoder.out_channels}")
        if self.decoder.in_channels != self.raster_channels:
            raise InputError("ModelConfig", f"decoder in_channels {self.decoder.in_channels} != "
                             f"raster_channels {self.raster_channels}")
        if self.decoder.supersample:
            raise InputError("ModelConfig", "supersampling is done by the rasterizer; keep decoder.supersample False")
        check_range(self.encoder_max_points, "encoder_max_points", 16, 100_000_000)

    @classmethod
    def lite(cls) -> "ModelConfig":
        """CPU configuration: encoder 32/64/128, AdaAttN 128 (q/k 64), 32 raster channels, decoder width 96."""
        return cls()

    @classmethod
    def paper(cls) -> "ModelConfig":
        """The public code's widths: encoder 64/128/256, AdaAttN 256, 256 raster channels, decoder 256."""
        return cls(
            name="paper", encoder=EncoderConfig.paper(), stylizer=AdaAttNConfig.paper(),
            raster_channels=256, decoder=DecoderConfig.paper(in_channels=256),
        )

    @classmethod
    def by_name(cls, name: str) -> "ModelConfig":
        if name == "lite":
            return cls.lite()
        if name == "paper":
            return cls.paper()
        raise InputError("config", f"must be 'lite' or 'paper', got {name!r}")


class SceneGeometry(NamedTuple):
    """Everything about a point cloud's positions the model needs (from :func:`prepare_geometry`).

    Attributes:
        xyz: (N, 3) float32 world points (scene units).
        rgb: (N, 3) float32 colours in [0, 1].
        ndc: NDC parameters of the cloud in the photo's camera.
        encoder_idx: (N_e,) long indices of the points the encoder sees (all when N <= max).
        hierarchy: FPS / ball-query levels of the encoder's points (in NDC).
        upsample: 3-NN IDW weights from the encoder's coarsest level to all N points.
    """

    xyz: torch.Tensor
    rgb: torch.Tensor
    ndc: NDCParams
    encoder_idx: torch.Tensor
    hierarchy: PointHierarchy
    upsample: IDWWeights


def prepare_geometry(
    xyz: torch.Tensor, rgb: torch.Tensor, fov_y_deg: float, image_size: Tuple[int, int], config: ModelConfig,
    seed: int = 0,
) -> SceneGeometry:
    """Positions-only preprocessing of a cloud: NDC, encoder subset, hierarchy, upsampling weights.

    Args:
        xyz: (N, 3) world points (= the photo's camera frame), z > 0.
        rgb: (N, 3) colours in [0, 1].
        fov_y_deg: vertical FOV of the photo's camera.
        image_size: (H, W) of the photo (sets the NDC aspect and the radius scale).
        config: the model configuration (encoder neighbourhoods, subset size).
        seed: seed of the encoder subset (reproducible features).
    """
    check_shape(xyz, "xyz", (None, 3))
    check_shape(rgb, "rgb", (xyz.shape[0], 3))
    with torch.no_grad():
        xyz = xyz.detach().float()
        params = ndc_params(xyz[:, 2], fov_y_deg, image_size[1] / image_size[0])
        ndc = to_ndc(xyz, params)  # (N, 3)
        n = xyz.shape[0]
        if n > config.encoder_max_points:
            g = torch.Generator().manual_seed(seed)
            idx = torch.randperm(n, generator=g)[: config.encoder_max_points].sort().values
        else:
            idx = torch.arange(n)
        scale = radius_scale(image_size, idx.numel(), n)
        hierarchy = build_hierarchy(ndc.index_select(0, idx), config.encoder.scaled(scale))
        up = three_nn(ndc, hierarchy.xyz[-1])
    return SceneGeometry(xyz, rgb.detach().float(), params, idx, hierarchy, up)


class Stylize3DModel(nn.Module):
    """Learned parts of the model (see the module docstring). The style CNN is separate and frozen."""

    def __init__(self, config: ModelConfig = ModelConfig()) -> None:
        super().__init__()
        self.config = config
        self.encoder = Encoder(config.encoder)
        self.stylizer = AdaAttNStylizer(config.stylizer)
        c = config.encoder.out_channels
        self.to_raster = nn.Linear(c, config.raster_channels) if config.raster_channels != c else nn.Identity()
        self.decoder = UNetDecoder(config.decoder)

    def encode(self, geom: SceneGeometry) -> torch.Tensor:
        """Content features (M, C) of the cloud's coarsest level."""
        return self.encoder(geom.rgb.index_select(0, geom.encoder_idx), geom.hierarchy).features

    def stylize(self, content: torch.Tensor, style_maps: Sequence[torch.Tensor], alpha: float = 1.0) -> torch.Tensor:
        """Stylized features (M, C); ``alpha`` in [0, 1] blends content (0) and style (1)."""
        alpha = check_range(alpha, "strength", 0.0, 1.0)
        if alpha == 0.0:
            return content
        return blend(content, self.stylizer.stylize(content, style_maps), alpha)

    def dense_features(self, sparse: torch.Tensor, geom: SceneGeometry) -> torch.Tensor:
        """Project sparse features (M, C) to raster channels and upsample to every point: (N, Cr)."""
        return interpolate(self.to_raster(sparse), geom.upsample.idx, geom.upsample.weight)

    def render_view(
        self, dense: torch.Tensor, xyz: torch.Tensor, camera: Cameras, height: int, width: int,
        supersample: int = 1,
    ) -> Tuple[torch.Tensor, Fragments]:
        """Decode one view: (3, H, W) RGB in (0, 1) and the rasterizer's fragments.

        For a fast preview pass a subset of the points (see ``Stylized3DPhoto``).
        """
        settings = RasterSettings(height=int(height), width=int(width), supersample=supersample)
        frags = PointRasterizer(settings)(xyz, dense, camera)
        features = frags.image.unsqueeze(0)  # (1, Cr, H, W)
        mask = (~frags.hole).to(features.dtype)[None, None]  # (1, 1, H, W)
        rgb = self.decoder(features, mask)[0]  # (3, H, W)
        return rgb, frags


def count_parameters(module: nn.Module) -> int:
    """Number of trainable parameters."""
    return sum(p.numel() for p in module.parameters() if p.requires_grad)


__all__ = [
    "ModelConfig", "SceneGeometry", "prepare_geometry", "Stylize3DModel", "count_parameters",
]
