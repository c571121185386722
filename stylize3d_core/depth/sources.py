"""Depth sources: one interface over every way a user can give a photo its depth.

Every source turns a photo ``rgb`` (H, W, 3) float32 in [0, 1] into a
:class:`~stylize3d_core.depth.types.DepthMap` of the same (H, W): depth finite
and > 0 everywhere, a validity mask, and its kind ("metric" or "relative").

=================================  =================================================
spec (command line ``--depth``)     source
=================================  =================================================
``auto``                            :class:`AutoDepth`: phone depth if embedded, else the prior
``prior``                           :class:`PriorDepth`: built-in prior, no weights
``phone``                           :class:`PhoneDepth`: depth embedded by a phone camera
``FILE`` / ``FILE:disparity``       :class:`FileDepth`: a depth (default) or disparity file
``onnx:MODEL.onnx[:PRESET]``        :class:`OnnxDepth`: a depth network in ONNX (presets
                                    in ``onnx_model.PRESETS``; default "midas")
``stereo:RIGHT``                    :class:`StereoDepth`: the photo is the left view
``stereo:sbs`` / ``stereo:sbs:cross``  :class:`StereoDepth`: the photo is a side-by-side
                                    stereo card (parallel / cross-eyed); the photo used
                                    is its left view, see :meth:`DepthSource.photo_view`
=================================  =================================================

Any source can be followed by edge alignment (:mod:`.refine`) by wrapping it in
:class:`RefinedDepth` (``parse_depth_spec(spec, refine=RefineSettings())``).
"""

from __future__ import annotations

import os
from abc import ABC, abstractmethod
from typing import Literal, Optional, Tuple, Union

import numpy as np
from PIL import Image, UnidentifiedImageError

from ..errors import InputError, PathLike
from ..io.images import load_image
from ._util import check_rgb
from .files import load_depth_file
from .onnx_model import DEFAULT_PRESET, OnnxDepthModel, OnnxPreset, OnnxSettings, preset_by_name
from .phone_xmp import embedded_depth_map, has_embedded_depth
from .prior import PriorSettings, estimate_prior
from .refine import RefineSettings, refine_depth
from .stereo import StereoSettings, compute_disparity, disparity_to_depth, split_side_by_side
from .types import DepthMap

SPEC_HELP = (
    "auto, prior, phone, FILE, FILE:disparity, onnx:MODEL.onnx[:PRESET], stereo:RIGHT_IMAGE, stereo:sbs[:cross]"
)


class DepthSource(ABC):
    """Something that gives a photo its depth. Subclasses implement :meth:`estimate`."""

    @abstractmethod
    def estimate(self, rgb: np.ndarray, *, photo_path: Optional[PathLike] = None) -> DepthMap:
        """Depth for the photo ``rgb`` (H, W, 3) float in [0, 1].

        Args:
            rgb: the photo as loaded (not modified). For a side-by-side stereo
                card this is the whole card; the depth is that of
                ``photo_view(rgb)``.
            photo_path: the file the photo came from, when there is one (needed
                by sources that read the file itself, e.g. phone depth).
        Returns:
            DepthMap aligned with ``photo_view(rgb)``.
        """

    def photo_view(self, rgb: np.ndarray) -> np.ndarray:
        """The part of the loaded image that is the photo: ``rgb`` itself, except for stereo cards."""
        return rgb

    def describe(self) -> str:
        """A short description for logs."""
        return type(self).__name__


class PriorDepth(DepthSource):
    """The built-in prior (:mod:`.prior`): relative depth from image cues, no learned weights."""

    def __init__(self, settings: PriorSettings = PriorSettings()) -> None:
        self.settings = settings

    def estimate(self, rgb: np.ndarray, *, photo_path: Optional[PathLike] = None) -> DepthMap:
        result = estimate_prior(rgb, self.settings)
        return DepthMap(result.depth, np.ones(result.depth.shape, bool), "relative", "prior")

    def describe(self) -> str:
        return "built-in prior"


class FileDepth(DepthSource):
    """A depth or disparity file (16-bit PNG, .npy, .pfm, TIFF, EXR), resized to the photo."""

    def __init__(self, path: PathLike, kind: Literal["depth", "disparity"] = "depth", scale: float = 1.0) -> None:
        self.path = os.fspath(path)
        if kind not in ("depth", "disparity"):
            raise InputError("depth kind", f"must be 'depth' or 'disparity', got {kind!r}")
        if not os.path.isfile(self.path):
            raise InputError(self.path, "depth file not found")
        self.kind = kind
        self.scale = scale

    def estimate(self, rgb: np.ndarray, *, photo_path: Optional[PathLike] = None) -> DepthMap:
        shape = check_rgb(rgb).shape[:2]
        return load_depth_file(self.path, kind=self.kind, size=shape, scale=self.scale)

    def describe(self) -> str:
        return f"{self.kind} file {self.path}"


class OnnxDepth(DepthSource):
    """A monocular depth network supplied as an ONNX file, run on the CPU (:mod:`.onnx_model`)."""

    def __init__(self, model_path: PathLike, preset: Union[str, OnnxPreset] = DEFAULT_PRESET,
                 settings: Optional[OnnxSettings] = None) -> None:
        p = preset_by_name(preset) if isinstance(preset, str) else preset
        base = settings if settings is not None else OnnxSettings()
        self.model = OnnxDepthModel(model_path, OnnxSettings(preset=p, far_ratio=base.far_ratio, threads=base.threads))

    def estimate(self, rgb: np.ndarray, *, photo_path: Optional[PathLike] = None) -> DepthMap:
        return self.model.estimate(rgb)

    def describe(self) -> str:
        return f"ONNX model {self.model.path}"


def _upright_size(path: str) -> Optional[Tuple[int, int]]:
    """(H, W) of an image file as displayed (EXIF orientation applied), from its header; None if unreadable."""
    try:
        with Image.open(path) as im:
            w, h = im.size
            orientation = im.getexif().get(0x0112, 1)
    except (OSError, UnidentifiedImageError):
        return None
    return (w, h) if orientation in (5, 6, 7, 8) else (h, w)


class StereoDepth(DepthSource):
    """Depth from a rectified stereo pair (the photo is the left view) or a side-by-side card.

    Args:
        right_path: the right view; None for a side-by-side card (``side_by_side=True``).
        settings: matcher settings (:class:`~.stereo.StereoSettings`).
        side_by_side: the photo is a stereo card; its left half is the photo.

    The right view is loaded with ``max_size`` = the photo's longer side: a
    photo shrunk by ``load_image(max_size=M)`` has a longer side of M, so a right
    view of the same original size is shrunk identically. Views of different
    original sizes are refused (compared on the files' headers when the photo's
    path is known, else on the loaded sizes).
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

    def photo_view(self, rgb: np.ndarray) -> np.ndarray:
        if not self.side_by_side:
            return rgb
        return split_side_by_side(rgb, self.settings)[0]

    def _pair(self, rgb: np.ndarray, photo_path: Optional[PathLike]) -> Tuple[np.ndarray, np.ndarray]:
        name = os.fspath(photo_path) if photo_path is not None else "stereo card"
        if self.side_by_side:
            return split_side_by_side(rgb, self.settings, name)
        left = check_rgb(rgb, name)
        right_img = load_image(self.right_path, max_size=max(left.shape[:2]))
        left_name = name if photo_path is not None else "the photo"
        if photo_path is not None:
            sizes = (_upright_size(os.fspath(photo_path)), _upright_size(self.right_path))
            if None not in sizes and sizes[0] != sizes[1]:
                raise InputError(self.right_path, f"right image is {sizes[1][1]}x{sizes[1][0]} pixels but the left "
                                                  f"image {left_name} is {sizes[0][1]}x{sizes[0][0]}; a stereo pair "
                                                  "must have the same size")
        if right_img.size != left.shape[:2]:
            raise InputError(self.right_path, f"right image is {right_img.size[1]}x{right_img.size[0]} pixels (as "
                                              f"loaded) but the left image {left_name} is {left.shape[1]}x"
                                              f"{left.shape[0]}; a stereo pair must have the same size")
        return left, right_img.rgb

    def estimate(self, rgb: np.ndarray, *, photo_path: Optional[PathLike] = None) -> DepthMap:
        left, right = self._pair(rgb, photo_path)
        result = compute_disparity(left, right, self.settings)
        depth, kind = disparity_to_depth(result.disparity, result.valid, self.settings)
        what = "side-by-side card" if self.side_by_side else f"right={os.path.basename(self.right_path)}"
        return DepthMap(depth, result.valid, kind, f"stereo ({what})")

    def describe(self) -> str:
        return "stereo card" if self.side_by_side else f"stereo pair with {self.right_path}"


class PhoneDepth(DepthSource):
    """Depth embedded by a phone camera in the photo's JPEG (GDepth or Dynamic Depth, :mod:`.phone_xmp`)."""

    def estimate(self, rgb: np.ndarray, *, photo_path: Optional[PathLike] = None) -> DepthMap:
        if photo_path is None:
            raise InputError("depth", "phone depth is read from the photo file; no photo file was given")
        return embedded_depth_map(photo_path, check_rgb(rgb).shape[:2])

    def describe(self) -> str:
        return "depth embedded in the photo"


class AutoDepth(DepthSource):
    """The best source a photo has on its own: embedded phone depth if present, else the prior.

    Corrupt embedded depth is an error (use the "prior" source to ignore it).
    """

    def __init__(self, prior: PriorSettings = PriorSettings()) -> None:
        self.prior = PriorDepth(prior)

    def estimate(self, rgb: np.ndarray, *, photo_path: Optional[PathLike] = None) -> DepthMap:
        if photo_path is not None and has_embedded_depth(photo_path):
            try:
                found = embedded_depth_map(photo_path, check_rgb(rgb).shape[:2], required=False)
            except InputError as exc:
                raise InputError(exc.source, f"{exc.problem} (use --depth prior to ignore the embedded depth)") from exc
            if found is not None:
                return found
        return self.prior.estimate(rgb)

    def describe(self) -> str:
        return "auto (phone depth, else the built-in prior)"


class RefinedDepth(DepthSource):
    """Another source followed by edge alignment (:func:`~.refine.refine_depth`)."""

    def __init__(self, inner: DepthSource, settings: RefineSettings = RefineSettings()) -> None:
        self.inner = inner
        self.settings = settings

    def photo_view(self, rgb: np.ndarray) -> np.ndarray:
        return self.inner.photo_view(rgb)

    def estimate(self, rgb: np.ndarray, *, photo_path: Optional[PathLike] = None) -> DepthMap:
        depth = self.inner.estimate(rgb, photo_path=photo_path)
        return refine_depth(depth, self.inner.photo_view(rgb), self.settings)

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
        if rest in ("sbs", "sbs:cross"):
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
