"""The whole stylization model: encoder -> AdaAttN stylizer -> IDW upsampling -> rasterizer -> U-Net.

Data flow for one photo (N points, M ~ N_enc / 16 encoded points)::

    points (N, 3) world, rgb (N, 3)
      | prepare_geometry(..., config.neighbourhood)  (once per photo; positions only)
      v   NDC, encoder subset (<= max_points), FPS/ball-query hierarchy, 3-NN weights
    encode            -> content (M, C)                      once per photo
    stylize (+alpha)  -> features (M, C)                     once per style / strength
    dense_features    -> (N, Cr + D) = [IDW(project(features)) | rgb]   once per style / strength
    render_view       -> rasterize (Cr + D, H, W) -> decode (3, H, W)   per camera

**Detail path** (``detail_channels`` D = 3, the ``lite`` default): beside the
learned features, which live on 1/16 of the points and reach the others by 3-NN
interpolation, every point's own colour is rasterized at full resolution and
given to the decoder, so edges and fine structure survive decoding while the
style comes from the stylized features. D = 0 is the paper's layout (and that of
checkpoints written before the detail path; :func:`add_detail_path` widens such a
model without changing its output).

**Colour transform** (``decoder.transform_channels`` = 3, the default with the
detail path): the decoder does not only see the points' colours, it recolours
them: a smooth per-pixel 3 x 3 colour matrix and offset predicted from its
coarsest level map the rasterized colours towards the style, and its own
output fills holes and adds texture (see :mod:`.decoder`). Sharpness and
view-to-view consistency then come from the points themselves. Models without
it get it from :func:`add_colour_transform` (a zero head: same output, or the
identity: the points' colours).

**Colour transfer of the detail** (``detail_transfer``, the default): with a
style, the points' colours on the detail path are first moved to the style's
L*a*b* statistics (:mod:`.colour_transfer`, scaled by the strength), once per
photo, style and strength; the decoder's transform and texture start from
there. At strength 0 they are the photo's colours.

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

from dataclasses import dataclass, field, replace
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
from .decoder import IDENTITY_TRANSFORM, DecoderConfig, UNetDecoder, identity_transform, zero_texture
from .encoder import Encoder, EncoderConfig
from .scene_geometry import NeighbourhoodConfig, SceneGeometry, prepare_geometry

ConfigName = Literal["lite", "paper"]

DETAIL_CHANNELS = (0, 3)
"""Allowed ``ModelConfig.detail_channels``: none, or the points' RGB."""


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
        raster_channels: learned feature channels splatted by the rasterizer.
        detail_channels: 0 (no detail path) or 3 (each point's RGB rasterized beside the features).
        decoder: the U-Net; ``in_channels`` must equal ``raster_channels + detail_channels``.
        detail_transfer: with a style, the detail path carries the points' colours moved to the
            style's colour statistics (:mod:`.colour_transfer`); needs the detail path.
        style_prior: with a style, the detail path carries the 2D style prior's painting of the
            LDI's layers (:mod:`.style_prior`) instead; needs the detail path, excludes ``detail_transfer``.
    """

    name: ConfigName = "lite"
    encoder: EncoderConfig = field(default_factory=EncoderConfig.lite)
    neighbourhood: NeighbourhoodConfig = field(default_factory=NeighbourhoodConfig)
    stylizer: AdaAttNConfig = field(default_factory=lambda: AdaAttNConfig(
        content_channels=128, hidden=128, value_channels=128, qk_channels=64))
    raster_channels: int = 32
    decoder: DecoderConfig = field(default_factory=lambda: DecoderConfig.lite(in_channels=32 + 3,
                                                                              transform_channels=3,
                                                                              texture_channels=3))
    detail_channels: int = 3
    detail_transfer: bool = True
    style_prior: bool = False

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
        if self.detail_channels not in DETAIL_CHANNELS:
            raise InputError("ModelConfig.detail_channels", f"must be one of {DETAIL_CHANNELS}, got "
                                                            f"{self.detail_channels!r}")
        if self.decoder.in_channels != self.raster_channels + self.detail_channels:
            raise InputError("ModelConfig", f"decoder in_channels {self.decoder.in_channels} != "
                             f"raster_channels {self.raster_channels} + detail_channels {self.detail_channels}")
        if self.detail_transfer and not self.detail_channels:
            raise InputError("ModelConfig.detail_transfer", "needs the detail path (detail_channels 3)")
        if self.style_prior and (not self.detail_channels or self.detail_transfer):
            raise InputError("ModelConfig.style_prior", "needs the detail path (detail_channels 3) and "
                                                        "detail_transfer False")
        if self.decoder.transform_channels not in (0, self.detail_channels):
            raise InputError("ModelConfig", f"the decoder's colour transform recolours the detail path's "
                             f"{self.detail_channels} channels; got transform_channels "
                             f"{self.decoder.transform_channels}")
        if self.decoder.supersample:
            raise InputError("ModelConfig", "supersampling is done by the rasterizer; keep decoder.supersample False")

    @classmethod
    def lite(cls) -> "ModelConfig":
        """CPU configuration: encoder 32/64/128, AdaAttN 128 (q/k 64), 32 raster channels + the RGB detail
        path with its colour transform and texture residual, decoder width 48 (:meth:`DecoderConfig.lite`)."""
        return cls()

    @classmethod
    def paper(cls) -> "ModelConfig":
        """The public code's widths: encoder 64/128/256, AdaAttN 256, 256 raster channels + the RGB
        detail path with its colour transform and texture residual, decoder 256."""
        return cls(
            name="paper", encoder=EncoderConfig.paper(), stylizer=AdaAttNConfig.paper(),
            raster_channels=256, decoder=DecoderConfig.paper(in_channels=256 + 3, transform_channels=3,
                                                             texture_channels=3),
            detail_channels=3,
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

    def dense_features(self, sparse: torch.Tensor, geom: SceneGeometry,
                       colours: Optional[torch.Tensor] = None) -> torch.Tensor:
        """Project sparse features (M, C) to raster channels and upsample to every point: (N, Cr + D).

        With the detail path (D = 3) the points' colours follow the Cr learned channels: ``colours``
        (N, 3) when given (the colour-transferred ones, see ``detail_transfer``), else ``geom.rgb``.
        """
        raster = self.to_raster(sparse)  # (M, Cr)
        if not self.config.detail_channels:
            return interpolate(raster, geom.upsample.idx, geom.upsample.weight)
        rgb = geom.rgb if colours is None else colours
        n = geom.upsample.idx.shape[0]
        if tuple(rgb.shape) != (n, 3):
            raise InputError("colours", f"expected shape ({n}, 3), got {tuple(rgb.shape)}")
        if torch.is_grad_enabled():
            dense = interpolate(raster, geom.upsample.idx, geom.upsample.weight)
            return torch.cat([dense, rgb.to(dense.dtype)], dim=1)
        # inference: interpolated with 3 zero channels more and the colours written into them, so the
        # (N, Cr + 3) result is made once (a concatenation copied ~0.25 GB more at 1 MP); the same values
        cr = raster.shape[1]
        dense = interpolate(torch.nn.functional.pad(raster, (0, 3)), geom.upsample.idx, geom.upsample.weight)
        dense[:, cr:] = rgb.to(dense.dtype)
        return dense

    def render_view(
        self, dense: torch.Tensor, xyz: torch.Tensor, camera: Cameras, height: int, width: int,
        supersample: int = 1, should_stop: Optional[Callable[[], bool]] = None, *,
        bfloat16: bool = False, features_finite: bool = False, runtime=None,
        raster_backend: str = "auto",
    ) -> Tuple[torch.Tensor, Fragments]:
        """Decode one view: (3, H, W) RGB in (0, 1) and the rasterizer's fragments.

        For a fast preview pass a subset of the points (see ``Stylized3DPhoto``).
        ``should_stop`` is checked between the rasterizer's chunks of points and
        between the decoder's layers and strips (``UNetDecoder.forward``); True
        stops with :class:`~stylize3d_core.errors.RenderInterrupted`.

        ``bfloat16``: the decoder runs under a bfloat16 autocast (inference only; see
        ``UNetDecoder.forward``); the rasterizer stays float32 and the result is float32.

        ``features_finite``: the caller has checked that ``dense`` is finite (the rasterizer does not sum
        it again; see :func:`~stylize3d_core.render.rasterize.rasterize_points`).

        ``runtime``: the decoder's U-Net in ONNX Runtime
        (:func:`~stylize3d_core.models.decoder_onnx.onnx_unet`; float32 inference), or None: torch.

        ``raster_backend``: :attr:`~stylize3d_core.render.rasterize.RasterSettings.backend`.
        """
        settings = RasterSettings(height=int(height), width=int(width), supersample=supersample,
                                  backend=raster_backend)
        frags = PointRasterizer(settings)(xyz, dense, camera, should_stop=should_stop, features_finite=features_finite)
        features = frags.image.unsqueeze(0)  # (1, Cr, H, W)
        mask = (~frags.hole).to(features.dtype)[None, None]  # (1, 1, H, W)
        rgb = self.decoder(features, mask, should_stop=should_stop, bfloat16=bfloat16, runtime=runtime)[0]  # (3, H, W)
        return rgb, frags


def add_detail_path(model: Stylize3DModel) -> Stylize3DModel:
    """A copy of a model without the detail path, with it added and its output unchanged.

    The decoder's two first convolutions get zero weights for the three new RGB
    input channels (inserted between the learned features and the mask channel);
    every other weight is copied. Training then learns to use the new input.
    """
    cfg = model.config
    if cfg.detail_channels:
        raise InputError("model", "already has the detail path")
    d = DETAIL_CHANNELS[-1]
    new_cfg = replace(cfg, detail_channels=d, decoder=replace(cfg.decoder, in_channels=cfg.decoder.in_channels + d),
                      detail_transfer=False)
    wide = Stylize3DModel(new_cfg)
    state = dict(model.state_dict())
    c = cfg.decoder.in_channels  # learned channels; the mask channel follows them
    for key in ("decoder.skips.0.weight", "decoder.downs.0.conv1.weight"):
        w = state[key]  # (out, c + 1, k, k)
        zeros = w.new_zeros((w.shape[0], d) + tuple(w.shape[2:]))
        state[key] = torch.cat([w[:, :c], zeros, w[:, c:]], dim=1)
    wide.load_state_dict(state)
    wide.train(model.training)
    return wide


def add_colour_transform(model: Stylize3DModel, identity: bool = False,
                         transfer: Optional[bool] = None) -> Stylize3DModel:
    """A copy of a model with the detail path but no colour transform, with a transform head added.

    ``identity`` False: a zero head, so the output is unchanged until training
    moves it; True: the identity transform, so every covered pixel shows the
    rasterized point colours (the U-Net keeps filling holes). ``transfer``: the
    new model's ``detail_transfer`` (None: unchanged).
    """
    cfg = model.config
    if not cfg.detail_channels:
        raise InputError("model", "has no detail path to recolour: add_detail_path first")
    if cfg.decoder.transform_channels:
        raise InputError("model", "already has the colour transform")
    new_cfg = replace(cfg, decoder=replace(cfg.decoder, transform_channels=cfg.detail_channels,
                                           transform_gain=1.0 / cfg.decoder.width),
                      detail_transfer=cfg.detail_transfer if transfer is None else bool(transfer))
    wide = Stylize3DModel(new_cfg)
    missing, unexpected = wide.load_state_dict(model.state_dict(), strict=False)
    if unexpected or any(not k.startswith("decoder.transform.") for k in missing):
        raise InputError("model", f"unexpected weights when adding the colour transform: {missing} {unexpected}")
    identity_transform(wide.decoder.transform, identity)
    wide.train(model.training)
    return wide


def add_texture_residual(model: Stylize3DModel) -> Stylize3DModel:
    """A copy of a model with the colour transform but no texture residual, with the residual added:
    its rows of the U-Net's last convolution start at zero, so the output is unchanged."""
    cfg = model.config
    if not cfg.decoder.transform_channels:
        raise InputError("model", "has no colour transform to add the texture residual to: add_colour_transform first")
    if cfg.decoder.texture_channels:
        raise InputError("model", "already has the texture residual")
    wide = Stylize3DModel(replace(cfg, decoder=replace(cfg.decoder, texture_channels=3)))
    state = dict(model.state_dict())
    for key in ("decoder.out_rgb.weight", "decoder.out_rgb.bias"):
        w = state[key]  # (3, ...)
        state[key] = torch.cat([w, w.new_zeros((3,) + tuple(w.shape[1:]))], dim=0)
    wide.load_state_dict(state)
    zero_texture(wide.decoder.out_rgb)
    wide.train(model.training)
    return wide


def add_style_prior(model: Stylize3DModel) -> Stylize3DModel:
    """A copy of a model with the colour transform whose detail path carries the 2D style prior's colours
    (``style_prior`` True, ``detail_transfer`` False), its transform set to the identity and its texture
    residual to zero: every covered pixel shows the rasterized prior colours and the U-Net fills the holes,
    until training moves them. The encoder, stylizer and U-Net weights are kept."""
    cfg = model.config
    if not cfg.decoder.transform_channels:
        raise InputError("model", "has no colour transform for the prior's colours: add_colour_transform first")
    wide = Stylize3DModel(replace(cfg, detail_transfer=False, style_prior=True))
    wide.load_state_dict(model.state_dict())
    identity_transform(wide.decoder.transform, True)
    if cfg.decoder.texture_channels:
        zero_texture(wide.decoder.out_rgb)
    wide.train(model.training)
    return wide


def settle_pass_through(model: Stylize3DModel, tolerance: float = 2e-3) -> Tuple[Stylize3DModel, float]:
    """A copy of a model whose colour transform lies within ``tolerance`` of the identity and whose texture
    residual's weights lie within it of zero (as :func:`add_style_prior` set them, where training hardly
    moved them), with both set exactly: covered pixels then show the detail colours unchanged and the
    decoder skips the U-Net there (``UNetDecoder.passes_covered_colours``). Returns the copy and the largest
    weight change. Raises :class:`InputError` where a weight is farther than ``tolerance``: that model's
    heads do change the colours."""
    cfg = model.config
    if not (cfg.decoder.transform_channels and cfg.decoder.texture_channels):
        raise InputError("model", "has no colour transform and texture residual to settle")
    check_range(tolerance, "tolerance", 0.0, 1.0)
    dec = model.decoder
    gaps = {
        "transform weights": dec.transform.weight.detach().abs().max(),
        "transform bias": (dec.transform.bias.detach() - torch.tensor(IDENTITY_TRANSFORM)).abs().max(),
        "texture weights": dec.out_rgb.weight.detach()[3:].abs().max(),
        "texture bias": dec.out_rgb.bias.detach()[3:].abs().max(),
    }
    far = {k: float(v) for k, v in gaps.items() if float(v) > tolerance}
    if far:
        raise InputError("model", "its colour transform or texture residual is not negligible (largest "
                         + ", ".join(f"{k} {v:.3g}" for k, v in far.items()) + f" > {tolerance:g})")
    settled = Stylize3DModel(cfg)
    settled.load_state_dict(model.state_dict())
    identity_transform(settled.decoder.transform, True)
    zero_texture(settled.decoder.out_rgb)
    settled.train(model.training)
    return settled, max(float(v) for v in gaps.values())


def count_parameters(module: nn.Module) -> int:
    """Number of trainable parameters."""
    return sum(p.numel() for p in module.parameters() if p.requires_grad)


__all__ = [
    "DETAIL_CHANNELS", "add_colour_transform", "add_detail_path", "add_style_prior", "add_texture_residual", "settle_pass_through", "ModelConfig", "NeighbourhoodConfig", "SceneGeometry", "prepare_geometry", "Stylize3DModel", "count_parameters",
]
