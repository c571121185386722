"""Depth sources: one interface over every way a user can give a photo its depth.

Every source turns a loaded photo (:class:`~stylize3d_core.io.images.LoadedImage`:
its pixels, and for a file its bytes and EXIF orientation) into a
:class:`~stylize3d_core.depth.types.PhotoDepth`: the photo ``rgb`` (H, W, 3)
float32 in [0, 1] and a :class:`~stylize3d_core.depth.types.DepthMap` of the
same (H, W): depth finite and > 0 everywhere, a validity mask, and its kind
("metric" or "relative"). No source opens the photo file again.

=================================  =================================================
spec (command line ``--depth``)     source
=================================  =================================================
``auto``                            :class:`AutoDepth`: phone depth if embedded, else Depth Anything
                                    where its weights are cached, else the prior
``prior``                           :class:`PriorDepth`: built-in prior, no weights
``phone``                           :class:`PhoneDepth`: depth embedded by a phone camera
``FILE`` / ``FILE:disparity``       :class:`FileDepth`: a depth (default) or disparity file
``depth-anything[:FOLDER]``          :class:`DepthAnythingDepth`: Depth Anything V2 Small through
                                    Transformers (:mod:`.depth_anything`; the ``depth`` extra and
                                    ``stylize3d models download depth-anything``)
``onnx:MODEL.onnx[:PRESET]``        :class:`OnnxDepth`: a depth network in ONNX (presets
                                    in ``onnx_model.PRESETS``; default "midas")
``stereo:RIGHT``                    :class:`StereoDepth`: the photo is the left view
``stereo:sbs`` / ``stereo:sbs:cross``  :class:`StereoDepth`: the photo is a side-by-side
                                    stereo card (parallel / cross-eyed); the photo used
                                    is its left view, returned as ``PhotoDepth.rgb``
``stereo:card`` / ``stereo:card:cross``  :class:`StereoCardDepth`: a scanned historical card
                                    (mount borders, exposure, rotation: :mod:`.stereo_card`;
                                    parallel / cross-eyed); the photo used is its cropped
                                    left-eye print
=================================  =================================================

Any source can be followed by edge alignment (:mod:`.refine`) by wrapping it in
:class:`RefinedDepth` (``parse_depth_spec(spec, refine=RefineSettings())``).
"""

from __future__ import annotations

import os
from abc import ABC, abstractmethod
from typing import Literal, Optional, Tuple, Union

import numpy as np

from ..errors import InputError, PathLike
from ..io.images import LoadedImage, load_image
from .files import load_depth_file
from .onnx_model import DEFAULT_PRESET, OnnxDepthModel, OnnxPreset, OnnxSettings, preset_by_name
from .phone_xmp import embedded_depth_map, has_embedded_depth
from .prior import PriorSettings, estimate_prior
from .refine import RefineSettings, refine_depth
from .stereo import StereoSettings, compute_disparity, disparity_to_depth, split_side_by_side
from .stereo_card import CardSettings, card_depth
from .types import DepthMap, PhotoDepth

SPEC_HELP = (
    "auto, prior, depth-anything, phone, FILE, FILE:disparity, onnx:MODEL.onnx[:PRESET], stereo:RIGHT_IMAGE, "
    "stereo:sbs[:cross], "
    "stereo:card[:cross]"
)


def _check_image(image: LoadedImage) -> LoadedImage:
    if not isinstance(image, LoadedImage):
        raise TypeError(f"a depth source takes a LoadedImage (io.images.load_image or load_image_array), "
                        f"got {type(image).__name__}")
    return image


class DepthSource(ABC):
    """Something that gives a photo its depth. Subclasses implement :meth:`estimate`."""

    @abstractmethod
    def estimate(self, image: LoadedImage) -> PhotoDepth:
        """The photo ``image`` holds and its depth.

        Args:
            image: the photo as loaded (not modified): its pixels, and, when it
                came from a file, the file's bytes and EXIF orientation (phone
                depth is read from those; the file is not opened again).
        Returns:
            :class:`~.types.PhotoDepth`: ``rgb`` is ``image.rgb``, except for a
            side-by-side stereo card, whose left view it is; ``depth_map`` is
            aligned with ``rgb``.
        """

    def describe(self) -> str:
        """A short description for logs."""
        return type(self).__name__


class PriorDepth(DepthSource):
    """The built-in prior (:mod:`.prior`): relative depth from image cues, no learned weights."""

    def __init__(self, settings: PriorSettings = PriorSettings()) -> None:
        self.settings = settings

    def estimate(self, image: LoadedImage) -> PhotoDepth:
        rgb = _check_image(image).rgb
        result = estimate_prior(rgb, self.settings)
        return PhotoDepth(rgb, DepthMap(result.depth, np.ones(result.depth.shape, bool), "relative", "prior"))

    def describe(self) -> str:
        return "built-in prior"


class FileDepth(DepthSource):
    """A depth or disparity file (16-bit PNG, .npy, .pfm, TIFF, EXR), resized to the photo (:mod:`.files`)."""

    def __init__(self, path: PathLike, kind: Literal["depth", "disparity"] = "depth", scale: float = 1.0) -> None:
        self.path = os.fspath(path)
        if kind not in ("depth", "disparity"):
            raise InputError("depth kind", f"must be 'depth' or 'disparity', got {kind!r}")
        if not os.path.isfile(self.path):
            raise InputError(self.path, "depth file not found")
        self.kind = kind
        self.scale = scale

    def estimate(self, image: LoadedImage) -> PhotoDepth:
        image = _check_image(image)
        return PhotoDepth(image.rgb, load_depth_file(self.path, kind=self.kind, size=image.size, scale=self.scale))

    def describe(self) -> str:
        return f"{self.kind} file {self.path}"


class OnnxDepth(DepthSource):
    """A monocular depth network supplied as an ONNX file, run on the CPU (:mod:`.onnx_model`)."""

    def __init__(self, model_path: PathLike, preset: Union[str, OnnxPreset] = DEFAULT_PRESET,
                 settings: Optional[OnnxSettings] = None) -> None:
        p = preset_by_name(preset) if isinstance(preset, str) else preset
        base = settings if settings is not None else OnnxSettings()
        self.model = OnnxDepthModel(model_path, OnnxSettings(preset=p, far_ratio=base.far_ratio, threads=base.threads))

    def estimate(self, image: LoadedImage) -> PhotoDepth:
        rgb = _check_image(image).rgb
        return PhotoDepth(rgb, self.model.estimate(rgb))

    def describe(self) -> str:
        return f"ONNX model {self.model.path}"


class DepthAnythingDepth(DepthSource):
    """Depth Anything V2 Small through Transformers (:mod:`.depth_anything`), loaded on first use."""

    def __init__(self, folder: Optional[PathLike] = None) -> None:
        from . import depth_anything

        depth_anything._transformers()  # a missing extra or missing weights are errors now, not at the first photo
        if folder is None:
            depth_anything.require_weights()
        self.folder = folder
        self._model = None

    def estimate(self, image: LoadedImage) -> PhotoDepth:
        from .depth_anything import DepthAnythingModel

        rgb = _check_image(image).rgb
        if self._model is None:
            self._model = DepthAnythingModel(self.folder)
        return PhotoDepth(rgb, self._model.estimate(rgb))

    def describe(self) -> str:
        from .depth_anything import MODEL_ID

        return f"Depth Anything V2 Small ({self.folder or MODEL_ID})"


class StereoDepth(DepthSource):
    """Depth from a rectified stereo pair (the photo is the left view) or a side-by-side card.

    Args:
        right_path: the right view; None for a side-by-side card (``side_by_side=True``).
        settings: matcher settings (:class:`~.stereo.StereoSettings`).
        side_by_side: the photo is a stereo card; its left half is the photo,
            returned as ``PhotoDepth.rgb`` (the card is split once, here).

    The right view is loaded with ``max_size`` = the photo's longer side: a
    photo shrunk by ``load_image(max_size=M)`` has a longer side of M, so a right
    view of the same original size is shrunk identically. Views of different
    original sizes are refused (compared on the upright sizes of the files
    when the photo came from a file, ``LoadedImage.original_size``, else on the
    loaded sizes).
    """

    def __init__(self, right_path: Optional[PathLike] = None, settings: StereoSettings = StereoSettings(),
                 *, side_by_side: bool = False) -> None:
        if side_by_side == (right_path is not None):
            raise InputError("stereo", "give either a right image or side_by_side=True, not both or neither")
        self.right_path = None if right_path is None else os.fspath(right_path)
        if self.right_path is not None and not os.path.isfile(self.right_path):
            raise InputError(self.right_path, "right stereo image not found")
        self.settings = settings
        self.side_by_side = side_by_side

    def _pair(self, image: LoadedImage) -> Tuple[np.ndarray, np.ndarray]:
        name = image.path if image.path is not None else "stereo card"
        if self.side_by_side:
            return split_side_by_side(image.rgb, self.settings, name)
        left = image.rgb
        right_img = load_image(self.right_path, max_size=max(image.size))
        left_name = name if image.path is not None else "the photo"
        if image.path is not None and right_img.original_size != image.original_size:
            (rh, rw), (lh, lw) = right_img.original_size, image.original_size
            raise InputError(self.right_path, f"right image is {rw}x{rh} pixels but the left image {left_name} is "
                                              f"{lw}x{lh}; a stereo pair must have the same size")
        if right_img.size != image.size:
            raise InputError(self.right_path, f"right image is {right_img.size[1]}x{right_img.size[0]} pixels (as "
                                              f"loaded) but the left image {left_name} is {left.shape[1]}x"
                                              f"{left.shape[0]}; a stereo pair must have the same size")
        return left, right_img.rgb

    def estimate(self, image: LoadedImage) -> PhotoDepth:
        left, right = self._pair(_check_image(image))
        result = compute_disparity(left, right, self.settings)
        depth, kind = disparity_to_depth(result.disparity, result.valid, self.settings)
        what = "side-by-side card" if self.side_by_side else f"right={os.path.basename(self.right_path)}"
        return PhotoDepth(left, DepthMap(depth, result.valid, kind, f"stereo ({what})"))

    def describe(self) -> str:
        return "stereo card" if self.side_by_side else f"stereo pair with {self.right_path}"


class StereoCardDepth(DepthSource):
    """Depth from a scanned stereo card: prints on a mount, split, exposure-matched, aligned by features and
    rectified (:mod:`.stereo_card`). The photo used is the cropped left print, returned as ``PhotoDepth.rgb``."""

    def __init__(self, settings: CardSettings = CardSettings()) -> None:
        self.settings = settings

    def estimate(self, image: LoadedImage) -> PhotoDepth:
        image = _check_image(image)
        return card_depth(image.rgb, self.settings, image.path if image.path is not None else "stereo card")

    def describe(self) -> str:
        return "scanned stereo card" + (" (cross-eyed)" if self.settings.stereo.cross_eyed else "")


class PhoneDepth(DepthSource):
    """Depth embedded by a phone camera in the photo's JPEG (GDepth or Dynamic Depth, :mod:`.phone_xmp`).

    It is read from the file's bytes that :func:`~stylize3d_core.io.images.load_image` kept
    (``LoadedImage.data``); a photo given as an array has none, which is an InputError.
    """

    def estimate(self, image: LoadedImage) -> PhotoDepth:
        image = _check_image(image)
        return PhotoDepth(image.rgb, embedded_depth_map(image))

    def describe(self) -> str:
        return "depth embedded in the photo"


class AutoDepth(DepthSource):
    """The best source a photo has on its own: embedded phone depth if present, else the prior.

    Corrupt embedded depth is an error (use the "prior" source to ignore it).
    """

    def __init__(self, prior: PriorSettings = PriorSettings()) -> None:
        from . import depth_anything

        self.prior = PriorDepth(prior)
        learned = depth_anything.cached_folder() is not None and depth_anything.available()  # no import without
        self.fallback: DepthSource = DepthAnythingDepth() if learned else self.prior

    def estimate(self, image: LoadedImage) -> PhotoDepth:
        image = _check_image(image)
        if image.data is not None and has_embedded_depth(image.data):
            try:
                found = embedded_depth_map(image, required=False)
            except InputError as exc:
                raise InputError(exc.source, f"{exc.problem} (use --depth prior to ignore the embedded depth)") from exc
            if found is not None:
                return PhotoDepth(image.rgb, found)
        return self.fallback.estimate(image)

    def describe(self) -> str:
        if isinstance(self.fallback, DepthAnythingDepth):
            return "auto (phone depth, else Depth Anything V2 Small: its weights are cached)"
        return "auto (phone depth, else the built-in prior: Depth Anything's weights are not cached)"


class RefinedDepth(DepthSource):
    """Another source followed by edge alignment (:func:`~.refine.refine_depth`) with the photo it returns."""

    def __init__(self, inner: DepthSource, settings: RefineSettings = RefineSettings()) -> None:
        self.inner = inner
        self.settings = settings

    def estimate(self, image: LoadedImage) -> PhotoDepth:
        found = self.inner.estimate(image)
        return PhotoDepth(found.rgb, refine_depth(found.depth_map, found.rgb, self.settings))

    def describe(self) -> str:
        return f"{self.inner.describe()} + {self.settings.method}"


def _split_suffix(spec: str, choices: Tuple[str, ...]) -> Tuple[str, Optional[str]]:
    """'a:b' -> ('a', 'b') if b is one of ``choices``, else (spec, None)."""
    head, sep, tail = spec.rpartition(":")
    if sep and head and tail in choices:
        return head, tail
    return spec, None


def parse_depth_spec(spec: str, *, refine: Optional[RefineSettings] = None) -> DepthSource:
    """The depth source a spec string names (see the module docstring for the forms).

    Args:
        spec: e.g. "auto", "prior", "depth.png", "disp.pfm:disparity", "onnx:midas.onnx:dpt",
            "stereo:right.jpg", "stereo:sbs".
        refine: when given, the source is wrapped in :class:`RefinedDepth`.
    Raises:
        InputError: for an unknown form, a missing file or a bad model, naming it.
    """
    if not isinstance(spec, str) or not spec.strip():
        raise InputError("depth", f"empty depth source; expected one of: {SPEC_HELP}")
    s = spec.strip()
    source: DepthSource
    if s == "auto":
        source = AutoDepth()
    elif s == "prior":
        source = PriorDepth()
    elif s == "phone":
        source = PhoneDepth()
    elif s == "depth-anything" or s.startswith("depth-anything:"):
        folder = s[len("depth-anything:"):] if ":" in s else None
        if folder is not None and not os.path.isdir(folder):
            raise InputError(folder, "depth-anything: needs a folder saved with save_pretrained (not found)")
        source = DepthAnythingDepth(folder)
    elif s.startswith("onnx:"):
        rest = s[len("onnx:"):]
        if not rest:
            raise InputError("depth", "onnx: needs a model file, e.g. onnx:midas.onnx")
        model, preset = rest, DEFAULT_PRESET
        if not rest.lower().endswith(".onnx") and ":" in rest:
            model, preset = rest.rsplit(":", 1)
            preset_by_name(preset)  # unknown preset -> InputError listing the presets
        source = OnnxDepth(model, preset)
    elif s.startswith("stereo:"):
        rest = s[len("stereo:"):]
        if rest in ("card", "card:cross"):
            source = StereoCardDepth(CardSettings(stereo=StereoSettings(cross_eyed=rest == "card:cross")))
        elif rest in ("sbs", "sbs:cross"):
            source = StereoDepth(None, StereoSettings(cross_eyed=rest == "sbs:cross"), side_by_side=True)
        elif not rest:
            raise InputError("depth", "stereo: needs the right image, e.g. stereo:right.jpg, or stereo:sbs")
        else:
            source = StereoDepth(rest)
    else:
        path, kind = _split_suffix(s, ("depth", "disparity"))
        if not os.path.isfile(path):
            scheme = s.split(":", 1)[0] if ":" in s else ""
            if kind is None and scheme.isalnum() and len(scheme) > 1:  # "lidar:x" -- not "C:\\x"
                raise InputError("depth", f"unknown depth source {spec!r}; expected one of: {SPEC_HELP}")
            raise InputError(path, f"depth file not found (depth sources: {SPEC_HELP})")
        source = FileDepth(path, kind or "depth")
    return source if refine is None else RefinedDepth(source, refine)
