"""Numerical stress cases: extreme depths, FOVs, cameras, sizes, styles and dtypes.

Each case builds its input through the library API (``Photo3D.build``,
``pipeline.load_photo3d``, ``PlainRenderer``, ``Stylized3DPhoto`` with the
shipped model) and returns the images it rendered. A case passes when every
image is finite and in [0, 1], or when the input is unusable and the library
said so with an :class:`~stylize3d_core.errors.InputError` (``expect="error"``).
Anything else (NaN, inf, another exception, an error where an image was due)
fails.

``tests/stress/`` runs every case; ``stylize3d bench stress`` tabulates them.
"""

from __future__ import annotations

import functools
import math
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Dict, List, Optional, Sequence

import numpy as np
import torch

from ..depth.types import DepthMap
from ..errors import InputError
from ..geometry.camera import NEAR_DEPTH, Cameras
from ..scene.photo3d import Photo3D, Photo3DSettings

Images = List[np.ndarray]


@dataclass(frozen=True)
class StressCase:
    """One stress case: ``run(quick)`` returns the rendered images (or raises)."""

    name: str
    category: str
    run: Callable[[bool], Images]
    expect: str = "image"  # "image": finite images in [0, 1]; "error": an InputError
    stylized: bool = False  # needs the shipped model (slower)
    heavy: bool = False  # large inputs: left out of the --quick subset


@dataclass(frozen=True)
class StressOutcome:
    name: str
    category: str
    expect: str
    passed: bool
    outcome: str  # "images", "input error", "NaN/inf", "out of range", "exception"
    detail: str
    seconds: float


# ---------------------------------------------------------------------------- inputs


def make_photo(h: int = 48, w: int = 64, seed: int = 0) -> np.ndarray:
    """A smooth, textured (H, W, 3) float32 photo in [0, 1]."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    rgb = np.stack([0.5 + 0.4 * np.sin(x / max(w, 1) * 6.0 + c) * np.cos(y / max(h, 1) * 4.0 + c)
                    for c in (0.0, 1.0, 2.0)], -1)
    return np.clip(rgb + 0.05 * rng.standard_normal(rgb.shape), 0, 1).astype(np.float32)


def step_depth(h: int, w: int, near: float, far: float) -> np.ndarray:
    """(H, W) float32 depth: a far plane with a near square in the middle (one depth edge)."""
    d = np.full((h, w), far, np.float32)
    d[h // 4: h - h // 4, w // 4: w - w // 4] = near
    return d


def depth_map(depth: np.ndarray, kind: str = "metric") -> DepthMap:
    return DepthMap(depth.astype(np.float32), np.ones(depth.shape, bool), kind, "stress")


def camera(tz: float = 0.0, tx: float = 0.0, fov: float = 60.0, yaw_deg: float = 0.0) -> Cameras:
    c2w = np.eye(4)
    a = math.radians(yaw_deg)
    c2w[:3, :3] = [[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]]
    c2w[:3, 3] = [tx, 0.0, tz]
    return Cameras.create(c2w, fov)


@functools.lru_cache(maxsize=1)
def _checkpoint():
    from ..models.checkpoint import load_checkpoint
    from ..resources import resolve_model

    return load_checkpoint(resolve_model("lite"))


@functools.lru_cache(maxsize=1)
def _style_encoder():
    from ..models.style_features import StyleEncoder

    return StyleEncoder()


def stylized(p3d: Photo3D, style: Optional[np.ndarray] = None):
    from ..stylize import Stylized3DPhoto

    s = Stylized3DPhoto(p3d, _checkpoint(), style_encoder=_style_encoder())
    s.set_style(make_photo(32, 32, seed=3) if style is None else style)
    return s


def _photo3d(near: float = 1.0, far: float = 3.0, settings: Photo3DSettings = Photo3DSettings()) -> Photo3D:
    """The 64 x 48 test photo with one depth edge (``near`` square on a ``far`` plane)."""
    return Photo3D.build(make_photo(), depth_map(step_depth(48, 64, near, far)), settings)


def plain_views(p3d: Photo3D, cams: Sequence[Cameras], h: int = 32, w: int = 40) -> Images:
    from ..render.plain import PlainRenderer

    r = PlainRenderer(p3d.points)
    out = []
    for c in cams:
        out.append(r.render(c, h, w))
        out.append(r.render(c, h, w, preview=True))
    return out


def both_views(p3d: Photo3D, cams: Sequence[Cameras], h: int = 32, w: int = 40) -> Images:
    out = plain_views(p3d, cams, h, w)
    s = stylized(p3d)
    for c in cams:
        out.append(s.render(c, h, w))
        out.append(s.render(c, h, w, preview=True))
    return out


def _default_cams() -> List[Cameras]:
    return [camera(), camera(tx=0.05, tz=0.05)]


# ---------------------------------------------------------------------------- cases


def _depth_scale(near: float, far: float) -> Callable[[bool], Images]:
    def run(quick: bool) -> Images:
        p3d = _photo3d(near, far)
        return both_views(p3d, _default_cams())
    return run


def _depth_file(values: str) -> Callable[[bool], Images]:
    """A depth file (NPY) with NaN / inf / zero pixels, read through ``load_photo3d``."""
    def run(quick: bool) -> Images:
        from ..io.images import save_image
        from ..pipeline import PhotoSpec, load_photo3d

        d = step_depth(48, 64, 1.0, 3.0).astype(np.float32)
        if values == "nan":
            d[::3, ::4] = np.nan
        elif values == "inf":
            d[5:20, 5:30] = np.inf
        elif values == "zero":
            d[:, :10] = 0.0
        elif values == "negative":
            d[10:20, :] = -1.0
        elif values == "all_nan":
            d[:] = np.nan
        elif values == "all_zero":
            d[:] = 0.0
        with tempfile.TemporaryDirectory() as tmp:
            photo = Path(tmp) / "photo.png"
            save_image(photo, make_photo())
            np.save(Path(tmp) / "depth.npy", d)
            p3d = load_photo3d(PhotoSpec(photo=str(photo), depth=str(Path(tmp) / "depth.npy")))
        return both_views(p3d, _default_cams()) if not quick else plain_views(p3d, _default_cams())
    return run


def _fov(fov: float) -> Callable[[bool], Images]:
    def run(quick: bool) -> Images:
        p3d = _photo3d(1.0, 4.0, Photo3DSettings(fov_y_deg=fov))
        return both_views(p3d, [camera(fov=fov), camera(tx=0.05, fov=fov), camera(fov=5.0), camera(fov=150.0)])
    return run


def _camera(tz: float, yaw: float = 0.0) -> Callable[[bool], Images]:
    def run(quick: bool) -> Images:
        p3d = _photo3d(1.0, 4.0)
        return both_views(p3d, [camera(tz=tz, yaw_deg=yaw)])
    return run


def _coincident(quick: bool) -> Images:
    """Every pixel at the same depth and colour, then every point moved onto one position."""
    from dataclasses import replace

    rgb = np.full((24, 32, 3), 0.4, np.float32)
    p3d = Photo3D.build(rgb, depth_map(np.full((24, 32), 2.0, np.float32)))
    pts = p3d.points
    xyz = np.broadcast_to(pts.xyz[:1], pts.xyz.shape).copy()
    one = replace(p3d, points=replace(pts, xyz=xyz))
    return both_views(p3d, _default_cams()) + both_views(one, _default_cams())


def _constant_style(value: float) -> Callable[[bool], Images]:
    def run(quick: bool) -> Images:
        p3d = _photo3d()
        s = stylized(p3d, style=np.full((64, 64, 3), value, np.float32))
        return [s.render(c, 32, 40) for c in _default_cams()]
    return run


def _sizes(h: int, w: int, fh: int, fw: int, stylized: bool = True) -> Callable[[bool], Images]:
    def run(quick: bool) -> Images:
        p3d = Photo3D.build(make_photo(h, w), depth_map(step_depth(h, w, 1.0, 3.0)))
        return (both_views if stylized else plain_views)(p3d, _default_cams(), fh, fw)
    return run


def _bfloat16(style_only: bool) -> Callable[[bool], Images]:
    """Everything under a bfloat16 autocast; or (``style_only``) the model and style set under it, the frames
    rendered in float32 and then under it again at a new strength."""
    def run(quick: bool) -> Images:
        p3d = _photo3d()
        with torch.autocast("cpu", dtype=torch.bfloat16):
            s = stylized(p3d)
            out = [] if style_only else [s.render(c, 32, 40, preview=True) for c in _default_cams()]
        if style_only:
            out += [s.render(c, 32, 40) for c in _default_cams()]
            s.set_strength(0.5)
        with torch.autocast("cpu", dtype=torch.bfloat16):
            out += [s.render(c, 32, 40) for c in _default_cams()]
        return out
    return run


def _large_photo_file(quick: bool) -> Images:
    """A 4000 x 3000 photo file, shrunk by ``PhotoSpec.max_size`` (default 1024) on loading."""
    from ..io.images import save_image
    from ..pipeline import PhotoSpec, load_photo3d

    with tempfile.TemporaryDirectory() as tmp:
        photo = Path(tmp) / "big.jpg"
        ramp = np.linspace(0, 255, 4000, dtype=np.float32).astype(np.uint8)
        big = np.empty((3000, 4000, 3), np.uint8)
        big[..., 0], big[..., 1], big[..., 2] = ramp, ramp[::-1], 128
        big[1000:2000, 1500:2500] = 40  # a dark square: the prior gives it an edge
        save_image(photo, big)
        p3d = load_photo3d(PhotoSpec(photo=str(photo), depth="prior", max_size=256))
    if p3d.size != (192, 256):
        raise RuntimeError(f"expected a 256 x 192 photo after shrinking, got {p3d.size}")
    return plain_views(p3d, _default_cams(), 48, 64)


def _job(args: Dict[str, object], depth: Optional[np.ndarray] = None) -> Callable[[bool], Images]:
    """A render job (``pipeline.run_render``, what ``stylize3d render`` runs) of 3 PNG frames; ``args`` are
    ``RenderJob`` fields, ``fov`` the photo's, ``style="__style__"`` a generated style image. The library cannot
    import ``app/``: ``tests/stress`` runs the command line itself on the same inputs."""
    def run(quick: bool) -> Images:
        from ..io.images import load_image, save_image
        from ..pipeline import PhotoSpec, RenderJob, run_render

        with tempfile.TemporaryDirectory() as tmp:
            photo = Path(tmp) / "photo.png"
            save_image(photo, make_photo())
            spec_depth = "prior"
            if depth is not None:
                np.save(Path(tmp) / "depth.npy", depth)
                spec_depth = str(Path(tmp) / "depth.npy")
            kw = dict(args)
            fov = kw.pop("fov", None)
            if kw.get("style") == "__style__":
                save_image(Path(tmp) / "style.png", make_photo(32, 32, seed=3))
                kw["style"] = str(Path(tmp) / "style.png")
            job = RenderJob(spec=PhotoSpec(photo=str(photo), depth=spec_depth, fov=fov),
                            output=str(Path(tmp) / "frames") + "/", frames=3, size=64, **kw)
            run_render(job)
            frames = [load_image(str(p)).rgb for p in sorted((Path(tmp) / "frames").glob("*.png"))]
            if len(frames) != 3:
                raise RuntimeError(f"expected 3 frames, found {len(frames)}")
            return frames
    return run


def cases() -> List[StressCase]:
    nan = step_depth(48, 64, 1.0, 3.0)
    nan[::2, ::3] = np.nan
    return [
        StressCase("depth 1e-3..2e-3", "depth range", _depth_scale(1e-3, 2e-3), stylized=True),
        StressCase("depth 1e4..2e4", "depth range", _depth_scale(1e4, 2e4), stylized=True),
        StressCase("depth 1e-3..1e4", "depth range", _depth_scale(1e-3, 1e4), stylized=True),
        StressCase("depth file: NaN pixels", "bad depth", _depth_file("nan"), stylized=True),
        StressCase("depth file: inf pixels", "bad depth", _depth_file("inf"), stylized=True),
        StressCase("depth file: zero pixels", "bad depth", _depth_file("zero"), stylized=True),
        StressCase("depth file: negative pixels", "bad depth", _depth_file("negative"), stylized=True),
        StressCase("depth file: all NaN", "bad depth", _depth_file("all_nan"), expect="error"),
        StressCase("depth file: all zero", "bad depth", _depth_file("all_zero"), expect="error"),
        StressCase("DepthMap with NaN", "bad depth",
                   lambda q: [depth_map(np.full((4, 4), np.nan, np.float32))], expect="error"),
        StressCase("fov 5", "fov", _fov(5.0), stylized=True),
        StressCase("fov 150", "fov", _fov(150.0), stylized=True),
        StressCase("camera at the near plane", "camera", _camera(NEAR_DEPTH * 0.99), stylized=True),
        StressCase("camera inside the cloud", "camera", _camera(1.0 / 3.0 * 2.0), stylized=True),
        StressCase("camera behind every point", "camera", _camera(10.0), stylized=True),
        StressCase("camera looking away", "camera", _camera(0.0, yaw=180.0), stylized=True),
        StressCase("coincident points", "points", _coincident, stylized=True),
        StressCase("constant-colour style (grey)", "style", _constant_style(0.5), stylized=True),
        StressCase("constant-colour style (black)", "style", _constant_style(0.0), stylized=True),
        StressCase("constant-colour style (white)", "style", _constant_style(1.0), stylized=True),
        StressCase("photo 1 pixel wide", "size", _sizes(64, 1, 32, 1), expect="error"),
        StressCase("frame 1 pixel wide", "size", _sizes(48, 64, 32, 1), stylized=True),
        StressCase("frame 1 pixel high", "size", _sizes(48, 64, 1, 32), stylized=True),
        StressCase("frame 1 x 1", "size", _sizes(48, 64, 1, 1), stylized=True),
        StressCase("frame 4000 pixels wide", "size", _sizes(24, 32, 8, 4000), stylized=True),
        StressCase("photo 4000 pixels wide", "size", _sizes(16, 4000, 8, 64, stylized=False), heavy=True),
        StressCase("photo file 4000 x 3000, shrunk", "size", _large_photo_file, heavy=True),
        StressCase("bfloat16 autocast", "dtype", _bfloat16(False), stylized=True),
        StressCase("bfloat16 style, float32 frames", "dtype", _bfloat16(True), stylized=True),
        StressCase("job: NaN depth file, fov 150", "pipeline", _job({"fov": 150.0}, depth=nan)),
        StressCase("job: fov 5, stylized", "pipeline", _job({"fov": 5.0, "style": "__style__"}), stylized=True),
    ]


def _check(images: Images) -> Optional[str]:
    for i, im in enumerate(images):
        a = np.asarray(im)
        if not np.isfinite(a).all():
            return f"image {i}: {int((~np.isfinite(a)).sum())} NaN/inf values"
        if a.size and (a.min() < 0 or a.max() > 1):
            return f"image {i}: values outside [0, 1] ({a.min():g}..{a.max():g})"
    return None


def run_case(case: StressCase, quick: bool = False) -> StressOutcome:
    t0 = time.perf_counter()
    try:
        images = case.run(quick)
    except InputError as e:
        ok = case.expect == "error"
        return StressOutcome(case.name, case.category, case.expect, ok, "input error", str(e)[:200],
                             time.perf_counter() - t0)
    except Exception as e:  # noqa: BLE001 - a stress case reports every failure
        return StressOutcome(case.name, case.category, case.expect, False, "exception",
                             f"{type(e).__name__}: {e}"[:200], time.perf_counter() - t0)
    bad = _check(images)
    if bad is not None:
        return StressOutcome(case.name, case.category, case.expect, False,
                             "NaN/inf" if "NaN" in bad else "out of range", bad, time.perf_counter() - t0)
    ok = case.expect == "image"
    shapes = sorted({tuple(np.asarray(i).shape) for i in images})
    return StressOutcome(case.name, case.category, case.expect, ok, "images",
                         f"{len(images)} images {shapes}"[:200], time.perf_counter() - t0)
