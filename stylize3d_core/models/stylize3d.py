"""The whole stylization model: encoder -> AdaAttN stylizer -> IDW upsampling -> rasterizer -> U-Net.

Data flow for one photo (N points, M ~ N_enc / 16 encoded points)::

    points (N, 3) world, rgb (N, 3)
      | prepare_geometry(..., config.neighbourhood)  (once per photo; positions only)
      v   NDC, encoder subset (<= max_points), FPS/ball-query hierarchy, 3-NN weights
    encode            -> content (M, C)                      once per photo
    stylize (+alpha)  -> features (M, C)                     once per style / strength
    dense_features    -> (N, Cr) = IDW(project(features))    once per style / strength
    render_view       -> rasterize (Cr, H, W) -> decode (3, H, W)   per camera

The projection to ``raster_channels`` happens before the IDW upsampling: both
are linear and the IDW weights sum to one, so the order does not change the
result, and projecting the M sparse points is 16x cheaper than the N dense ones.

The geometry (:mod:`.scene_geometry`) is the same for inference and training:
ball radii follow the cloud's density, and clouds larger than the neighbourhood
config's ``max_points`` are encoded from a fixed random subset (the encoder's
cost grows with the points; its radii are scaled to the subset's density); the
features reach every point through the 3-NN upsampling.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Literal, Optional, Sequence, Tuple

import torch
from torch import nn

from ..checks import check_range
from ..errors import InputError
from ..geometry.camera import Cameras
from ..points import interpolate
from ..render.rasterize import Fragments, RasterSettings
from ..render.rasterizer import PointRasterizer
from .adaattn import AdaAttNConfig, AdaAttNStylizer, blend
from .decoder import DecoderConfig, UNetDecoder
from .encoder import Encoder, EncoderConfig
from .scene_geometry import NeighbourhoodConfig, SceneGeometry, prepare_geometry

ConfigName = Literal["lite", "paper"]


@dataclass(frozen=True)
class ModelConfig:
    """Architecture of :class:`Stylize3DModel`.

    Attributes:
        name: "lite" (CPU: narrower encoder, stylizer and decoder) or "paper"
            (the public code's widths, for GPUs).
        encoder: the point-cloud encoder's layer widths.
        neighbourhood: the geometry it encodes with (FPS levels, ball-query radii and
            their density scaling, k, the 3-NN upsampling, the encoder subset size);
            ``neighbourhood.num_stages`` must equal the encoder's stages.
        stylizer: AdaAttN with phi/psi MLPs; ``content_channels`` must equal the encoder's output.
        raster_channels: channels splatted by the rasterizer (the decoder's input).
        decoder: the U-Net; ``in_channels`` must equal ``raster_channels``.
    """

    name: ConfigName = "lite"
    encoder: EncoderConfig = field(default_factory=EncoderConfig.lite)
    neighbourhood: NeighbourhoodConfig = field(default_factory=NeighbourhoodConfig)
    stylizer: AdaAttNConfig = field(default_factory=lambda: AdaAttNConfig(
        content_channels=128, hidden=128, value_channels=128, qk_channels=64))
    raster_channels: int = 32
    decoder: DecoderConfig = field(default_factory=lambda: DecoderConfig.lite(in_channels=32))

    def __post_init__(self) -> None:
        if not isinstance(self.neighbourhood, NeighbourhoodConfig):
            raise InputError("ModelConfig.neighbourhood", f"expected a NeighbourhoodConfig, got "
                                                          f"{type(self.neighbourhood).__name__}")
        if self.neighbourhood.num_stages != self.encoder.num_stages:
            raise InputError("ModelConfig", f"the neighbourhood config has {self.neighbourhood.num_stages} "
                             f"down-sampling stages, the encoder {self.encoder.num_stages}")
        if self.stylizer.content_channels != self.encoder.out_channels:
            raise InputError("ModelConfig", f"stylizer content_channels {self.stylizer.content_channels} != "
                             f"encoder output {self.encoder.out_channels}")
        if self.decoder.in_channels != self.raster_channels:
            raise InputError("ModelConfig", f"decoder in_channels {self.decoder.in_channels} != "
                             f"raster_channels {self.raster_channels}")
        if self.decoder.supersample:
            raise InputError("ModelConfig", "supersampling is done by the rasterizer; keep decoder.supersample False")

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
        """Content features (M, C) of the cloud's coarsest level.

        ``geom`` must come from :func:`prepare_geometry` with this model's ``config.neighbourhood``.
        """
        if geom.neighbourhood != self.config.neighbourhood:
            raise InputError(
                "geometry", f"was prepared with neighbourhood settings {geom.neighbourhood.key} "
                f"({geom.neighbourhood}), this model uses {self.config.neighbourhood.key} "
                f"({self.config.neighbourhood}): prepare it with prepare_geometry(..., model.config.neighbourhood)")
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
        supersample: int = 1, should_stop: Optional[Callable[[], bool]] = None,
    ) -> Tuple[torch.Tensor, Fragments]:
        """Decode one view: (3, H, W) RGB in (0, 1) and the rasterizer's fragments.

        For a fast preview pass a subset of the points (see ``Stylized3DPhoto``).
        ``should_stop`` is checked between the rasterizer's chunks of points (True
        stops with :class:`~stylize3d_core.errors.RenderInterrupted`).
        """
        settings = RasterSettings(height=int(height), width=int(width), supersample=supersample)
        frags = PointRasterizer(settings)(xyz, dense, camera, should_stop=should_stop)
        features = frags.image.unsqueeze(0)  # (1, Cr, H, W)
        mask = (~frags.hole).to(features.dtype)[None, None]  # (1, 1, H, W)
        rgb = self.decoder(features, mask)[0]  # (3, H, W)
        return rgb, frags


def count_parameters(module: nn.Module) -> int:
    """Number of trainable parameters."""
    return sum(p.numel() for p in module.parameters() if p.requires_grad)


__all__ = [
    "ModelConfig", "NeighbourhoodConfig", "SceneGeometry", "prepare_geometry", "Stylize3DModel", "count_parameters",
]
