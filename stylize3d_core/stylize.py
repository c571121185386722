"""Stylized 3D photos: a 3D photo plus a trained model renders any camera in a style.

:class:`Stylized3DPhoto` caches everything that does not depend on the camera,
so each new view costs only a rasterization and a decode:

=====================  ==========================================  ==================
what changes           what is recomputed                           typical cost (CPU)
=====================  ==========================================  ==================
photo                  geometry (NDC, FPS, ball queries, 3-NN),     seconds
                       content features
style                  style CNN features (kept for the last few    < 1 s
                       style images: a new photo reuses them),
                       AdaAttN
second style / mix     (its features once) then a blend             ~0.1 s (at the next render)
strength               blend + IDW upsampling to every point        ~0.1 s (at the next render)
camera                 rasterize + U-Net decode                     see benchmarks
=====================  ==========================================  ==================

**Deferred learned inputs.** A model whose decoder passes covered pixels through (the style prior's
colours, ``UNetDecoder.passes_covered_colours``: the shipped model) needs its geometry, content features
and stylizer only where a view has uncovered pixels. Such an instance makes them at the first view that
has one, or at :meth:`Stylized3DPhoto.prepare`; a view every pixel of which the points cover is the
rasterized colours (prepared or not: a 3-channel raster), the same pixels the full path gives
(``tests/test_stylize_deferred.py``). Most views of
a 3D photo along its default paths are covered (the LDI's border and hidden layer fill them), so the first
frame does not wait for the learned parts, and an export along such a path never makes them.

Previews render a random subset of the points (about ``preview_points_per_pixel``
per output pixel, up to 1/8 more): the points are stored in a fixed
:class:`~stylize3d_core.render.plain.StratifiedOrder`, so a preview is a prefix
of the arrays, not a copy, and a full frame reads the features in nearly the
photo's raster order (cache friendly).

Thread use: an instance is not thread-safe; call it from one (worker) thread.
"""

from __future__ import annotations

import hashlib
import math
import time
import weakref
from collections import OrderedDict
from dataclasses import dataclass
from typing import Callable, Dict, Iterator, Optional, Tuple

import numpy as np
import torch

from .checks import check_range, check_shape
from .defaults import DEFAULT_STRENGTH
from .errors import InputError, RenderInterrupted
from .geometry.camera import MAX_FOV_DEG, Cameras
from .models.adaattn import blend
from .models.checkpoint import Checkpoint, load_checkpoint
from .models.colour_transfer import ColourTransfer, LabStats, lab_stats, mix_stats
from .models import decoder_onnx
from .models.decoder import native_bfloat16
from .models.palette import Palette, apply_palette, fit_palette, palette_target
from .models.style_prior import StylePrior, StylePriorSettings, interpolate_vectors, paint_layer_images
from .models.style_features import StyleEncoder, StyleFeatures
from .models.scene_geometry import SceneGeometry, prepare_geometry
from .models.stylize3d import Stylize3DModel
from .points.sampling import start_fps_process
from .render.plain import StratifiedOrder, preview_point_count
from .render.rasterize import RASTER_BACKENDS, warm_up_async
from .render.raster_settings import RasterSettings
from .render.rasterizer import PointRasterizer, columns
from .scene.layer_images import layer_colours, match_hidden_seam, seam_anchors
from .scene.photo3d import Photo3D


DECODER_RUNTIMES = ("auto", "onnxruntime", "torch")


@dataclass(frozen=True)
class StylizeSettings:
    """Options of :class:`Stylized3DPhoto`.

    Attributes:
        strength: style strength in [0, 1]; 0 renders the photo through the model. Default
            :data:`DEFAULT_STRENGTH` (1: the full style).
        supersample: 1 (default) or 2 for full-quality frames (previews never supersample).
        preview_points_per_pixel: points kept per output pixel in previews. Default 5: the fewest that keep
            a preview within the 30 dB target of the full frame (``bench targets``); with the border margin as
            wide as the full frame's, the point subset is most of what remains of a preview's error.
        seed: seed of the point order and the encoder's subset.
        final_points_per_pixel: None (default): full frames rasterize every point. A number: full frames
            keep about this many points per output (super)pixel, as previews do (a prefix of the point
            order), where more would land on each pixel (``bench speed`` measures the error).
        match_palette: True (default): after the model, one colour matrix, the same for every view, brings
            the frames' L*a*b* statistics to the style's (by the strength; the frames' lightness contrast
            kept, within a few percent), fitted once per photo, style and strength on a small render of the photo's own
            view (:mod:`~stylize3d_core.models.palette`). False: the model's colours as they are.
        bfloat16: None (default): the decoder runs under a bfloat16 autocast where this CPU computes
            bfloat16 natively (:func:`~stylize3d_core.models.decoder.native_bfloat16`: AVX-512 BF16 or
            AMX), float32 elsewhere; True or False forces it. The rasterizer, the encoder, the stylizer and
            the palette map stay float32; ``bench speed`` measures bfloat16 frames against float32 ones.
        decoder_runtime: what runs the decoder's U-Net in float32: "auto" (default: ONNX Runtime for large
            frames, where it imports, torch for small ones, :func:`~stylize3d_core.models.decoder_onnx.prefers_onnx`),
            "onnxruntime" or "torch". ONNX Runtime gives the same frames within ~2e-6 and decodes a 768x512
            frame ~1.3x faster on this AVX2 CPU, a 256-px preview ~1.1x slower
            (:mod:`~stylize3d_core.models.decoder_onnx`). bfloat16 decoding always runs in torch.
        rasterizer: the rasterizer's backend, "auto" (default: its compiled inference path where it applies)
            or "tensor" (:attr:`~stylize3d_core.render.rasterize.RasterSettings.backend`).
        border_margin: pixels rendered beyond each side of a full frame and cut off (default 8; 0: none).
            The U-Net's zero padding makes its outermost ~8 pixels differ from what it decodes inside a
            frame (a visible coloured rim); with the margin, the frame's edge is decoded as its inside is,
            for the few percent more pixels the margin adds. Rounded up to a multiple of the
            decoder's stride, so the frame keeps the
            decoder's grid phase.
        preview_border_margin: the same for previews (default 8, as full frames: the rim is as wide at any
            size, so it covers more of a small preview; with the full frame's margin a preview decodes its
            edge as the full frame does).
        prior_size: models with the 2D style prior (``ModelConfig.style_prior``): long side in pixels at which
            the prior paints the LDI's layer images (default 512, see :mod:`~stylize3d_core.models.style_prior`).
            Larger keeps more of the photo's detail and makes the painting's marks finer.
    """

    strength: float = DEFAULT_STRENGTH
    supersample: int = 1
    preview_points_per_pixel: float = 5.0
    seed: int = 0
    final_points_per_pixel: Optional[float] = None
    match_palette: bool = True
    bfloat16: Optional[bool] = None
    decoder_runtime: str = "auto"
    rasterizer: str = "auto"
    border_margin: int = 8
    preview_border_margin: int = 8
    prior_size: int = 512

    def __post_init__(self) -> None:
        StylePriorSettings(size=self.prior_size)  # validates it
        for name, lo, hi, unit in (("border_margin", 0, 64, " (pixels)"), ("preview_border_margin", 0, 64, " (pixels)")):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
                raise InputError(name, f"must be an integer from {lo} to {hi}{unit}, got {value!r}")
        check_range(self.strength, "strength", 0.0, 1.0)
        if self.supersample not in (1, 2):
            raise InputError("supersample", f"must be 1 or 2, got {self.supersample!r}")
        check_range(self.preview_points_per_pixel, "preview_points_per_pixel", 0.5, 100.0)
        if self.final_points_per_pixel is not None:
            check_range(self.final_points_per_pixel, "final_points_per_pixel", 0.5, 100.0)
        if not isinstance(self.match_palette, bool):
            raise InputError("match_palette", f"must be True or False, got {self.match_palette!r}")
        if self.bfloat16 is not None and not isinstance(self.bfloat16, bool):
            raise InputError("bfloat16", f"must be None, True or False, got {self.bfloat16!r}")
        if self.rasterizer not in RASTER_BACKENDS:
            raise InputError("rasterizer", f"must be one of {', '.join(RASTER_BACKENDS)}, got {self.rasterizer!r}")
        if self.decoder_runtime not in DECODER_RUNTIMES:
            raise InputError("decoder_runtime", f"must be one of {', '.join(DECODER_RUNTIMES)}, "
                                                f"got {self.decoder_runtime!r}")

    @property
    def decode_bfloat16(self) -> bool:
        """Whether the decoder runs in bfloat16: ``bfloat16``, or where None, the CPU's native support."""
        return native_bfloat16() if self.bfloat16 is None else self.bfloat16

    def decode_onnx(self, pixels: Optional[int] = None) -> bool:
        """Whether ONNX Runtime runs the U-Net of a frame of ``pixels`` (None: a large one): float32 decoding
        where ONNX Runtime imports and has not failed (:func:`~stylize3d_core.models.decoder_onnx.available`),
        and ``decoder_runtime`` "onnxruntime", or "auto" and a frame large enough for this thread's thread
        count (:func:`~stylize3d_core.models.decoder_onnx.prefers_onnx`)."""
        if self.decode_bfloat16 or self.decoder_runtime == "torch" or not decoder_onnx.available():
            return False
        return self.decoder_runtime == "onnxruntime" or pixels is None or decoder_onnx.prefers_onnx(pixels)


def style_tensor(style_rgb: np.ndarray, name: str = "style image") -> torch.Tensor:
    """(h, w, 3) float style image in [0, 1] -> (1, 3, h, w) tensor (validated)."""
    check_shape(style_rgb, name, (None, None, 3))
    if not np.isfinite(style_rgb).all():
        raise InputError(name, "contains NaN or infinite values")
    return torch.from_numpy(np.ascontiguousarray(style_rgb, dtype=np.float32)).permute(2, 0, 1)[None].clamp(0, 1)


class StyleFeatureCache:
    """The style CNN's features of the last ``size`` style images, so a new photo with the same style skips the CNN.

    Keyed by the style tensor's shape and bytes (BLAKE2b) and the CPU autocast state (a bfloat16 autocast
    gives other features). The cached :class:`StyleFeatures` are inference tensors that nothing modifies.
    One cache per :class:`StyleEncoder` (:func:`style_feature_cache`), so every ``Stylized3DPhoto`` sharing
    an encoder (the viewer's photos) shares its cache.
    """

    def __init__(self, encoder: StyleEncoder, size: int = 4) -> None:
        if size < 1:
            raise InputError("style cache size", f"must be >= 1, got {size!r}")
        self.encoder = encoder
        self.size = int(size)
        self._entries: "OrderedDict[Tuple, StyleFeatures]" = OrderedDict()
        self.hits = 0
        self.misses = 0

    @staticmethod
    def key(style: torch.Tensor) -> Tuple:
        x = style.detach().contiguous()
        digest = hashlib.blake2b(x.numpy().tobytes(), digest_size=16).hexdigest()
        return (tuple(x.shape), str(x.dtype), digest, torch.is_autocast_enabled("cpu"),
                str(torch.get_autocast_dtype("cpu")))

    def features(self, style: torch.Tensor) -> StyleFeatures:
        """The encoder's features of ``style`` (1, 3, h, w), from the cache when this image was seen."""
        k = self.key(style)
        hit = self._entries.get(k)
        if hit is not None:
            self._entries.move_to_end(k)
            self.hits += 1
            return hit
        self.misses += 1
        with torch.inference_mode():
            maps = self.encoder(style)
        self._entries[k] = maps
        while len(self._entries) > self.size:
            self._entries.popitem(last=False)
        return maps

    def clear(self) -> None:
        self._entries.clear()

    def __len__(self) -> int:
        return len(self._entries)


_CACHES: "weakref.WeakKeyDictionary[StyleEncoder, StyleFeatureCache]" = weakref.WeakKeyDictionary()


def style_feature_cache(encoder: StyleEncoder) -> StyleFeatureCache:
    """The one :class:`StyleFeatureCache` of ``encoder`` (made at the first call, gone with the encoder)."""
    cache = _CACHES.get(encoder)
    if cache is None:
        cache = _CACHES[encoder] = StyleFeatureCache(encoder)
    return cache


_PRIORS: Dict[int, StylePrior] = {}


def style_prior(size: int) -> StylePrior:
    """The process's one :class:`StylePrior` painting at ``size`` (its ONNX sessions load once)."""
    prior = _PRIORS.get(size)
    if prior is None:
        prior = _PRIORS[size] = StylePrior(StylePriorSettings(size=size))
    return prior


def _with_margin(camera: Cameras, height: int, margin: int, align: int) -> Tuple[Cameras, int]:
    """``camera`` widened to render ``m`` more pixels on each side at the same focal length, and ``m``:
    ``margin`` rounded up to a multiple of ``align`` (0 stays 0; less where the wider field of view would
    pass :data:`~stylize3d_core.geometry.camera.MAX_FOV_DEG`)."""
    if margin <= 0:
        return camera, 0
    m = -(-margin // align) * align
    half = math.tan(math.radians(float(camera.fov_y_deg[0])) / 2.0)
    while m > 0:
        fov = math.degrees(2.0 * math.atan(half * (height + 2 * m) / height))
        if fov <= MAX_FOV_DEG:
            return Cameras.create(camera.cam_to_world, fov), m
        m -= align
    return camera, 0


class Stylized3DPhoto:
    """A 3D photo rendered through the stylization model (see the module docstring).

    Args:
        photo: the 3D photo (points, FOV, size).
        checkpoint: a loaded checkpoint or the path of one.
        settings: strength, supersampling, preview density.
        style_encoder: share one frozen style CNN between instances (built if None).
    """

    def __init__(
        self,
        photo: Photo3D,
        checkpoint,
        settings: StylizeSettings = StylizeSettings(),
        style_encoder: Optional[StyleEncoder] = None,
    ) -> None:
        ck = checkpoint if isinstance(checkpoint, Checkpoint) else load_checkpoint(checkpoint)
        self._checkpoint_name = "the model checkpoint" if isinstance(checkpoint, Checkpoint) else str(checkpoint)
        self.model: Stylize3DModel = ck.model.eval()
        self.stage = ck.stage
        self.settings = settings
        self.photo = photo
        self.timings: Dict[str, float] = {}
        self._style_encoder = style_encoder
        warm_up_async()  # the rasterizer's compiled kernels load while the geometry is built
        # Models whose covered pixels are their points' colours (the style prior's, passed through by the
        # decoder) need the learned features only where a view has uncovered pixels: the geometry, the
        # encoder and the stylizer then wait for the first such view (:meth:`prepare`).
        self._deferred = bool(self.model.config.style_prior and self.model.decoder.passes_covered_colours())
        if not self._deferred:
            start_fps_process()  # a no-op when it runs already (load_photo3d starts it)
        self._geom: Optional[SceneGeometry] = None  # the learned parts' geometry and content features (prepare)
        self._content: Optional[torch.Tensor] = None  # (M, C)
        self._in_order: Optional[SceneGeometry] = None
        self._early: dict = {}
        if self._deferred:
            self._in_point_order(transfer=False)
        else:
            self._build_features(transfer=True)
        early = self._early
        self._strata = early["strata"]
        self._order = self._strata.order  # (N,)
        # (N, 3) in self._order, stored as (3, N) (render.rasterizer.columns: the camera transform's fast layout)
        self._xyz = columns(early["xyz"])
        self._rgb = early["rgb"]  # (N, 3) the photo's colours in self._order
        self._maps: Optional[Tuple[torch.Tensor, ...]] = None  # the style's features, until the stylizer runs
        self._maps2: Optional[Tuple[torch.Tensor, ...]] = None  # ... of the second style
        self._stylized: Optional[torch.Tensor] = None  # (M, C) at strength 1
        self._stylized2: Optional[torch.Tensor] = None  # (M, C) of the second style, at strength 1
        self._style_stats: Optional[LabStats] = None  # colour statistics of the style (detail_transfer)
        self._style_stats2: Optional[LabStats] = None
        self._transfer: Optional[ColourTransfer] = early.get("transfer")  # the points' colours, ready to recolour
        self._mix = 0.0
        self._vector: Optional[np.ndarray] = None  # (100,) the style prior's vector of the style (style_prior)
        self._vector2: Optional[np.ndarray] = None  # ... of the second style
        self._own_vector: Optional[np.ndarray] = None  # ... of the photo itself (strength < 1)
        self._painted: "OrderedDict[bytes, torch.Tensor]" = OrderedDict()  # vector -> (N, 3) prior colours, ordered
        self._seam: Optional[tuple] = None  # (seam_anchors of the photo's LDI, possibly None), made at the first painting
        self._dense: Optional[torch.Tensor] = None  # (N, Cr) in self._order
        self._palette_target: Optional[LabStats] = None  # what the palette map aims at (set with the dense features)
        self._palette: Optional[Palette] = None  # the map the last render used (its size's, from self._palettes)
        self._palettes: Dict[tuple, Palette] = {}  # per render size, kind and fit settings (see _palette_for)
        self._strength = settings.strength

    def _in_point_order(self, transfer: bool = True) -> None:
        """What needs the points but not their geometry: the point order, the points in it, and their
        colours ready for the colour transfer (done while the geometry waits for the FPS worker)."""
        if self._early:
            return
        pts = self.photo.points.to_tensors()
        with torch.inference_mode(False):  # ordinary tensors, as if made outside an inference block
            strata = StratifiedOrder(pts.xyz.shape[0], self.settings.seed)
            rgb = pts.rgb.detach().float().index_select(0, strata.order)
            self._early.update(strata=strata, rgb=rgb, xyz=pts.xyz.detach().float().index_select(0, strata.order))
            if transfer and self.model.config.detail_transfer:
                self._early["transfer"] = ColourTransfer(rgb)

    def _build_features(self, transfer: bool) -> None:
        """The geometry of the points (NDC, FPS, neighbourhoods, upsampling) and the encoder's content
        features; the point order is made while the geometry waits for the FPS worker."""
        start_fps_process()
        t0 = time.perf_counter()
        pts = self.photo.points.to_tensors()
        with torch.inference_mode():
            geom = prepare_geometry(pts.xyz, pts.rgb, self.photo.fov_y_deg, self.photo.size,
                                    self.model.config.neighbourhood, seed=self.settings.seed,
                                    while_waiting=lambda: self._in_point_order(transfer))
            t1 = time.perf_counter()
            self._content = self.model.encode(geom).float()  # (M, C), float32 even under an autocast
        t2 = time.perf_counter()
        self._in_point_order(transfer=False)  # no wait came (a small cloud): the colour transfer when first asked
        order = self._early["strata"].order
        up = geom.upsample  # the upsampling and the colours in the point order: dense features come out ordered
        self._in_order = geom._replace(
            rgb=self._early["rgb"],
            upsample=up._replace(idx=up.idx.index_select(0, order), weight=up.weight.index_select(0, order)))
        self._geom = geom
        self.timings.update({"geometry": t1 - t0, "encode": t2 - t1})

    @property
    def prepared(self) -> bool:
        """Whether the learned parts' geometry and content features are made."""
        return self._geom is not None

    def prepare(self) -> None:
        """Make the learned parts' inputs now: the geometry, the content features, the stylizer's output
        for the styles set and the features upsampled to every point (seconds at 1 MP). A model whose
        covered pixels are its points' colours defers them to the first view with an uncovered pixel; a
        caller with idle time (the viewer, after its first frame) calls this so that such a view does not
        wait for them."""
        if self._dense is None:
            self._update_dense()

    def needs_learned_parts(self, camera: Cameras, height: int, width: int, *, preview: bool = False) -> bool:
        """Whether :meth:`render` of this view runs the learned parts (geometry, encoder, stylizer, U-Net):
        always for a model that is not deferred; for one that is, where a pixel of the view is uncovered or
        the view supersamples. Rasterizes the view's colours to find out (about a render's time)."""
        if not self._deferred:
            return True
        return self._render_colours(camera, height, width, preview=preview, should_stop=None) is None

    def _prepare_sparse(self) -> None:
        """The geometry, the content features and the stylizer's output for the styles set."""
        if self._geom is None:
            self._build_features(transfer=False)
        with torch.inference_mode():
            if self._maps is not None and self._stylized is None:
                self._stylized = self.model.stylizer.stylize(self._content, self._maps).float()
            if self._maps2 is not None and self._stylized2 is None:
                self._stylized2 = self.model.stylizer.stylize(self._content, self._maps2).float()

    @property
    def geometry(self) -> SceneGeometry:
        """The photo's prepared geometry (NDC, encoder subset, hierarchy, upsampling weights), in point order;
        a deferred model makes it (and the content and style features) at this first access."""
        self._prepare_sparse()
        return self._geom

    @property
    def num_points(self) -> int:
        return int(self._xyz.shape[0])

    @property
    def strength(self) -> float:
        return self._strength

    @property
    def has_style(self) -> bool:
        return self._style_stats is not None

    def _encoder(self) -> StyleEncoder:
        if self._style_encoder is None:
            self._style_encoder = StyleEncoder()
        return self._style_encoder

    def set_style(self, style_rgb: Optional[np.ndarray]) -> None:
        """Use a new style image (h, w, 3) float in [0, 1]; None removes the style."""
        if style_rgb is None:
            self._stylized = None
            self._maps = None
            self._style_stats = None
            self._vector = None
        else:
            t0 = time.perf_counter()
            with torch.inference_mode():
                self._maps = style_feature_cache(self._encoder()).features(style_tensor(style_rgb)).maps
                self._stylized = None
                if self.prepared:  # else when prepared
                    self._stylized = self.model.stylizer.stylize(self._content, self._maps).float()  # (M, C) float32
            self._style_stats = lab_stats(style_rgb)
            if self.model.config.style_prior:
                self._vector = self._prior().style_vector(style_rgb)
            self.timings["style"] = time.perf_counter() - t0
        self._dense = None

    def set_second_style(self, style_rgb: Optional[np.ndarray]) -> None:
        """A second style image to mix with the first (None removes it); see :meth:`set_mix`."""
        if style_rgb is None:
            self._stylized2 = None
            self._maps2 = None
            self._style_stats2 = None
            self._vector2 = None
        else:
            with torch.inference_mode():
                second = style_tensor(style_rgb, "second style image")
                self._maps2 = style_feature_cache(self._encoder()).features(second).maps
                self._stylized2 = None
                if self.prepared:  # else when prepared
                    self._stylized2 = self.model.stylizer.stylize(self._content, self._maps2).float()  # as set_style
            self._style_stats2 = lab_stats(style_rgb)
            if self.model.config.style_prior:
                self._vector2 = self._prior().style_vector(style_rgb, "second style image")
        self._dense = None

    def set_mix(self, mix: float) -> None:
        """Mix of the two styles in [0, 1]: 0 the first, 1 the second. Cheap: the stylizer's outputs for
        both are kept and blended (no re-encoding, no new style features)."""
        self._mix = check_range(mix, "style mix", 0.0, 1.0)
        self._dense = None

    @property
    def mix(self) -> float:
        return self._mix

    def set_strength(self, strength: float) -> None:
        """Change the style strength in [0, 1] (cheap: no re-encoding, no new style features)."""
        self._strength = check_range(strength, "strength", 0.0, 1.0)
        self._dense = None

    def _update_dense(self) -> None:
        self._prepare_sparse()
        t0, painting = time.perf_counter(), 0.0
        with torch.inference_mode():
            stylized, stats = self._stylized, self._style_stats
            if stylized is not None and self._stylized2 is not None and self._mix > 0.0:
                stylized = torch.lerp(stylized, self._stylized2, self._mix)
                stats = mix_stats(stats, self._style_stats2, self._mix)
            colours = None
            if stylized is None or self._strength == 0.0:
                sparse = self._content
            else:
                sparse = blend(self._content, stylized, self._strength)
                if self.model.config.detail_transfer and stats is not None:
                    colours = self._colour_transfer()(stats, self._strength)
                if self.model.config.style_prior and self._vector is not None:
                    p0 = time.perf_counter()
                    colours = self._prior_colours()
                    painting = time.perf_counter() - p0  # timed as "prior" where it paints (not cached)
            target = None
            if (stylized is not None and self._strength > 0.0 and stats is not None and self.settings.match_palette
                    and not self.model.config.style_prior):  # the prior paints the style's palette itself
                target = palette_target(self._colour_transfer().stats, stats, self._strength)
            dense = self.model.dense_features(sparse, self._in_order, colours)  # (N, Cr), in self._order
            if not torch.isfinite(dense.sum()) and not torch.isfinite(dense).all():
                raise InputError(self._checkpoint_name, "its weights make NaN or infinite features on this photo "
                                 "(the weights are finite but far too large: a diverged or corrupt checkpoint)")
            # float32 whatever the autocast dtype (bfloat16 under torch.autocast): the rasterizer takes float32
            self._dense = dense.float().contiguous()
        self._palette_target, self._palette = target, None
        self._palettes = {}
        self.timings["upsample"] = time.perf_counter() - t0 - painting

    def _prior(self) -> StylePrior:
        return style_prior(self.settings.prior_size)

    PAINTINGS_KEPT = 4
    """Prior paintings kept per photo (by style vector: going back to a recent strength or mix is free)."""

    def _prior_colours(self) -> torch.Tensor:
        """(N, 3) the style prior's colours of the points (in point order) for the current style, mix and
        strength: the style vector (the mix of the two styles' vectors, interpolated from the photo's own
        by the strength) paints the LDI's two layer images; each point reads its own layer's pixel."""
        vector = self._vector
        if self._vector2 is not None and self._mix > 0.0:
            vector = interpolate_vectors(vector, self._vector2, self._mix)
        if self._strength < 1.0:
            if self._own_vector is None:
                self._own_vector = self._prior().style_vector(self.photo.rgb, "photo")
            vector = interpolate_vectors(self._own_vector, vector, self._strength)
        key = np.asarray(vector, np.float32).tobytes()
        hit = self._painted.get(key)
        if hit is not None:
            self._painted.move_to_end(key)
            return hit
        t0 = time.perf_counter()
        ldi = self.photo.ldi
        layer0, layer1 = paint_layer_images(self._prior(), ldi, vector)
        if self._seam is None:
            self._seam = (seam_anchors(ldi),)  # once per photo: the seam does not depend on the painting
        layer1 = match_hidden_seam(ldi, layer0, layer1, self._seam[0])
        colours = layer_colours(self.photo.points, ldi, layer0, layer1)  # (N, 3) in the photo's point order
        ordered = torch.from_numpy(colours).index_select(0, self._order)
        self._painted[key] = ordered
        while len(self._painted) > self.PAINTINGS_KEPT:
            self._painted.popitem(last=False)
        self.timings["prior"] = time.perf_counter() - t0
        return ordered

    def _colour_transfer(self) -> ColourTransfer:
        if self._transfer is None:
            self._transfer = ColourTransfer(self._rgb)
        return self._transfer

    PALETTE_FIT_MAX = 1024
    """Longest side (px) of the own-view render a palette map is fitted on (larger frames: that size)."""
    PALETTE_SIZES = 64
    """Palette maps kept per style and strength, one per render size and kind (the least recently fitted
    goes): the viewer's adaptive previews go through many sizes."""

    def _palette_for(self, height: int, width: int, should_stop: Optional[Callable[[], bool]],
                     preview: bool = False) -> Palette:
        """The palette map for frames of (height, width): fitted once per size on the photo's own view
        rendered at that size. The model's colours depend on the size it renders at (where points are
        sparser than pixels its own fill shows more: version 6 of the lite model is up to ~12 levels bluer
        at 48 px than at 768 px), so one map fitted at one size left previews and full frames of other
        sizes off the target, and a visible colour jump when a full frame replaced a preview.

        Full frames fit on every point; previews on the preview's own point subset at their size, as
        they render (``preview`` True): the viewer's adaptive preview size changes from frame to frame,
        and an every-point fit (~0.1-0.15 s, mostly rasterizing every point) in the middle of a drag
        made the size adaptation shrink the previews; the subset's fit costs about a preview. The key holds
        the settings the fit's render depends on, so a change of them (the bench sweeps do it on one
        instance) fits again."""
        st = self.settings
        key = (height, width, bool(preview), st.decode_bfloat16) + (
            (st.preview_points_per_pixel, st.preview_border_margin) if preview
            else (st.border_margin,))
        pal = self._palettes.get(key)
        if pal is not None:
            return pal
        t0 = time.perf_counter()
        scale = min(1.0, self.PALETTE_FIT_MAX / max(height, width))
        fh, fw = max(8, round(height * scale)), max(8, round(width * scale))
        own = Cameras.identity(self.photo.fov_y_deg)
        # full frames: every point, no supersampling: the map depends on the photo, style, strength and size
        # only, not on the final point budget (a budget's subset changes the colours by up to ~0.3 levels);
        # previews: the preview render itself (its subset, its decode scale)
        rgb = self._render_model(own, fh, fw, preview=True, should_stop=should_stop, every_point=not preview)
        pal = fit_palette(rgb.permute(1, 2, 0).numpy(), self._palette_target)
        if len(self._palettes) >= self.PALETTE_SIZES:
            self._palettes.pop(next(iter(self._palettes)))
        self._palettes[key] = pal
        self.timings["palette"] = time.perf_counter() - t0
        return pal

    @property
    def palette(self) -> Optional[Palette]:
        """The palette map of the last render's size for the current style and strength (None: none applies,
        or not fitted yet)."""
        return self._palette

    def render(self, camera: Cameras, height: int, width: int, *, preview: bool = False,
               should_stop: Optional[Callable[[], bool]] = None) -> np.ndarray:
        """One view (H, W, 3) float32 in [0, 1]; ``preview`` renders a point subset without supersampling.

        ``should_stop`` (any thread may make it return True) is checked between
        the stages: before rasterizing, between chunks of points while
        rasterizing (:data:`~stylize3d_core.render.rasterize.CHUNK_POINTS`), and between the strips of rows of
        every decoder convolution (:func:`~stylize3d_core.models.decoder.conv_in_strips`); when it returns True the render stops with
        :class:`~stylize3d_core.errors.RenderInterrupted` (nothing is cached
        from a stopped render).
        """
        if self._deferred:  # covered views: the colours alone (a 3-channel raster), prepared or not
            rgb = self._render_colours(camera, height, width, preview=preview, should_stop=should_stop)
            if rgb is not None:
                return rgb.permute(1, 2, 0).contiguous().numpy()
        if self._dense is None:  # upsampled lazily: a style set right after construction is not done twice
            self._update_dense()
        pal = None if self._palette_target is None else self._palette_for(height, width, should_stop, preview)
        rgb = self._render_model(camera, height, width, preview=preview, should_stop=should_stop)
        self._palette = pal
        if pal is not None:
            rgb = apply_palette(rgb, pal.matrix)
        return rgb.permute(1, 2, 0).contiguous().numpy()

    def _point_colours(self) -> torch.Tensor:
        """(N, 3) the colours a covered pixel shows, in point order (the decoder's pass-through input):
        the style prior's painting, or the photo's colours without a style or at strength 0."""
        if self._vector is not None and self._strength > 0.0:
            return self._prior_colours()
        return self._rgb

    def _render_colours(self, camera: Cameras, height: int, width: int, *, preview: bool,
                        should_stop: Optional[Callable[[], bool]]) -> Optional[torch.Tensor]:
        """The view (3, H, W) from the points' colours alone, where every pixel of it is covered: what
        :meth:`_render_model` returns there (the decoder passes covered pixels through; the same points,
        margin and rasterizer, so the same pixels), without the learned features. None where a pixel is
        uncovered or the view supersamples (the decoder is needed)."""
        st = self.settings
        if not preview and st.supersample != 1:
            return None
        camera, m, _, keep = self._view_plan(camera, height, width, preview=preview)
        colours = self._point_colours()
        with torch.inference_mode():
            if should_stop is not None and should_stop():
                raise RenderInterrupted("render stopped before rasterizing")
            settings = RasterSettings(height=height + 2 * m, width=width + 2 * m, backend=st.rasterizer)
            frags = PointRasterizer(settings)(self._xyz[:keep], colours[:keep], camera, should_stop=should_stop,
                                              features_finite=True)
            if bool(frags.hole[m : m + height, m : m + width].any()):
                return None
            rgb = frags.image[:, m : m + height, m : m + width]
            return torch.nan_to_num(rgb.float(), nan=0.0).clamp_(0.0, 1.0)

    def _view_plan(self, camera: Cameras, height: int, width: int, *, preview: bool,
                   every_point: bool = False) -> Tuple[Cameras, int, int, int]:
        """How a view is rasterized: the camera widened by the border margin, the margin ``m`` in pixels, the
        supersampling factor, and how many points of the stored order it draws (a preview: a prefix)."""
        st = self.settings
        if every_point:
            ss, per_pixel, margin = 1, None, st.border_margin
        elif preview:
            ss, per_pixel, margin = 1, st.preview_points_per_pixel, st.preview_border_margin
        else:
            ss, per_pixel, margin = st.supersample, st.final_points_per_pixel, st.border_margin
        camera, m = _with_margin(camera, height, margin, 2 ** self.model.config.decoder.levels)
        n = self.num_points
        keep = n if per_pixel is None else self._strata.prefix(
            preview_point_count(n, (height + 2 * m) * ss, (width + 2 * m) * ss, per_pixel))
        return camera, m, ss, keep

    def _render_model(self, camera: Cameras, height: int, width: int, *, preview: bool,
                      should_stop: Optional[Callable[[], bool]], every_point: bool = False) -> torch.Tensor:
        """The model's view (3, H, W) float32 in [0, 1], before the palette map (``every_point``: a preview
        render, i.e. no supersampling, of all the points at full-size decoding)."""
        st = self.settings
        camera, m, ss, keep = self._view_plan(camera, height, width, preview=preview, every_point=every_point)
        decoded = (height + 2 * m) * (width + 2 * m)  # the U-Net's pixels
        runtime = decoder_onnx.onnx_unet(self.model.decoder) if st.decode_onnx(decoded) else None
        with torch.inference_mode():
            if should_stop is not None and should_stop():
                raise RenderInterrupted("render stopped before rasterizing")
            rgb, _ = self.model.render_view(self._dense[:keep], self._xyz[:keep], camera, height + 2 * m,
                                            width + 2 * m, supersample=ss, should_stop=should_stop,
                                            bfloat16=st.decode_bfloat16, features_finite=True, runtime=runtime,
                                            raster_backend=st.rasterizer)
            if m:
                rgb = rgb[..., m : m + height, m : m + width]
            return torch.nan_to_num(rgb.float(), nan=0.0).clamp_(0.0, 1.0)  # float32 after a bfloat16 autocast

    def frames(self, cameras: Cameras, height: int, width: int) -> Iterator[np.ndarray]:
        """Lazily render one full-quality frame per camera."""
        for i in range(len(cameras)):
            yield self.render(cameras[i], height, width)
