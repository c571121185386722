"""A 3D photo as one self-contained HTML page that orbits in any WebGL2 browser, offline.

The page (``web_page.html``, filled in by :func:`page_html`) holds everything it
needs: its script (plain WebGL2, no library, no network), the points and the
camera settings. It draws every point as a square splat and lets the viewer
orbit, pan and dolly within the photo's camera range (``Photo3D.camera_range``),
with the desktop viewer's controls (left drag orbits, right or shift drag pans,
the wheel moves in and out, a double click resets; on touch one finger orbits,
two pan and pinch), a reset button and the job's trajectory played by a Play
button.

**Points.** Each point is stored by where the photo's camera sees it: photo
pixel coordinates ``(u, v)`` and disparity ``1 / z``, so the page rebuilds
``((u - W/2) z / f, (v - H/2) z / f, z)``. Quantisation:

* ``u, v``: 16-bit, ``s`` steps per photo pixel (``s = floor(65535 / span)``,
  at least 1), so the points of an LDI's pixel grid take whole steps and their
  differences repeat; the error is at most ``1 / (2 s)`` pixel;
* disparity: 16-bit over ``[1 / z_max, 1 / z_min]`` (finest where depth matters most, near);
* colour: 8 bits per channel.

Each channel is delta-coded along the point order (wrapping, ``uint16`` or ``uint8``),
split into byte planes (u low, u high, v low, v high, d low, d high, r, g, b:
nine planes of N bytes), deflated (zlib) and embedded as base64; the page
inflates it with the browser's ``DecompressionStream``. The points of a 3D photo
come in the LDI's raster order, so most differences are small and repeat.

**Point budget.** Above ``max_points`` the photo is thinned on a lattice: only
points whose photo pixel ``(floor(u), floor(v))`` has both coordinates divisible by
the smallest stride ``k`` that fits are kept, and each splat is ``k`` times as
wide, so a thinned photo still shows closed surfaces (a coarser image).

**Splats.** A point stands for its photo pixel, a patch of side ``z / f`` at its
depth (as the desktop renderer's grown splats, ``render/rasterize.py``); a view
with focal length ``F`` (pixels) and the point at depth ``z'`` draws it as a square
of ``SPLAT_SIZE * F (z / f) / z'`` pixels, at least one pixel and at most
:data:`MAX_POINT_PX`; the z-buffer keeps the front surface. The desktop's tent
splats of half-width ``k`` tile a surface seen head-on; the square is 1.5 times
as wide so that surfaces seen at a slant (the desktop stretches its splats to the
neighbours there) stay closed too.

**Size cap.** The page is built in memory; one larger than ``max_bytes`` is an
:class:`~stylize3d_core.errors.ExportError` naming the file, the size and the way
out (``--max-points``), and nothing is written. Otherwise it is written
atomically (``io/atomic.py``) and read back: its payload must decode to the
points it was built from.
"""

from __future__ import annotations

import base64
import html
import json
import zlib
from importlib import resources
from pathlib import Path
from typing import Dict, NamedTuple, Optional

import numpy as np

from ..errors import ExportError, InputError, PathLike
from ..geometry.camera import Cameras, check_fov, focal_from_fov
from ..geometry.camera_range import CameraRange
from ..io.atomic import write_atomically

SPLAT_SIZE = 1.5
"""Side of a point's square splat, in its footprints (see the module docstring)."""
MAX_POINT_PX = 24.0
"""Largest splat side in canvas pixels (a point magnified more leaves gaps rather than blocks)."""
MAX_TRAJECTORY_POSES = 600
"""Most poses of the trajectory the page plays (a longer one is resampled evenly)."""
FORMAT_VERSION = 1
"""Version of the embedded point format (``meta.format``), for readers of the page."""
_DEFAULT_RANGE = CameraRange()


class WebPoints(NamedTuple):
    """The points of a page, quantised (see the module docstring).

    Attributes:
        q: (N, 3) uint16 quantised ``u, v, disparity``.
        rgb: (N, 3) uint8 colours.
        lo: (3,) float64 value of quantum 0 for ``u, v, disparity``.
        step: (3,) float64 size of one quantum.
        stride: the lattice stride of the point budget (1: every point).
    """

    q: np.ndarray
    rgb: np.ndarray
    lo: np.ndarray
    step: np.ndarray
    stride: int

    def decoded(self) -> np.ndarray:
        """(N, 3) float64 ``u, v, disparity`` as the page reads them."""
        return self.lo + self.q.astype(np.float64) * self.step


def budget_stride(uv: np.ndarray, max_points: int) -> int:
    """The smallest lattice stride ``k >= 1`` that keeps at most ``max_points`` of the points at photo pixel
    coordinates ``uv`` (N, 2) (those whose ``floor(u)`` and ``floor(v)`` are multiples of ``k``)."""
    if isinstance(max_points, bool) or int(max_points) != max_points or max_points < 1:
        raise InputError("max_points", f"must be a positive integer, got {max_points!r}")
    cells = np.floor(uv).astype(np.int64)  # (N, 2)
    k = 1
    while np.count_nonzero((cells % k == 0).all(axis=1)) > max_points:
        k += 1
    return k


def quantise_points(xyz: np.ndarray, rgb: np.ndarray, photo_size, fov_y_deg: float,
                    max_points: int) -> WebPoints:
    """Project ``xyz`` (N, 3, in the photo's camera frame, z > 0) into the photo of ``photo_size`` (H, W) and
    ``fov_y_deg``, thin to ``max_points`` and quantise, with colours ``rgb`` (N, 3) in [0, 1]."""
    if not isinstance(xyz, np.ndarray) or xyz.ndim != 2 or xyz.shape[1] != 3 or len(xyz) == 0:
        raise InputError("xyz", f"expected a non-empty (N, 3) array, got {getattr(xyz, 'shape', None)}")
    if not isinstance(rgb, np.ndarray) or rgb.shape != xyz.shape:
        raise InputError("rgb", f"expected {xyz.shape} colours, got {getattr(rgb, 'shape', None)}")
    if not (np.isfinite(xyz).all() and np.isfinite(rgb).all()):
        raise InputError("xyz", "points and colours must be finite")
    h, w = (int(v) for v in photo_size)
    f = focal_from_fov(check_fov(fov_y_deg, "fov_y_deg"), h)
    p = xyz.astype(np.float64)
    z = p[:, 2]
    if (z <= 0).any():
        raise InputError("xyz", "points must lie in front of the photo's camera (z > 0)")
    uv = p[:, :2] / z[:, None] * f + (w / 2.0, h / 2.0)  # (N, 2) photo pixels
    stride = budget_stride(uv, max_points)
    if stride > 1:
        keep = (np.floor(uv).astype(np.int64) % stride == 0).all(axis=1)
        uv, z, rgb = uv[keep], z[keep], rgb[keep]
    lo_uv = np.floor(uv.min(axis=0))  # (2,)
    span = float(np.ceil((uv.max(axis=0) - lo_uv).max()))
    if span > 65535:
        raise InputError("xyz", f"the points spread over {span:,.0f} photo pixels; 16-bit positions hold 65,535")
    per_px = max(1, int(65535 // max(1.0, span)))
    q_uv = np.rint((uv - lo_uv) * per_px)
    disparity = 1.0 / z
    d_lo, d_hi = float(disparity.min()), float(disparity.max())
    d_step = (d_hi - d_lo) / 65535.0 if d_hi > d_lo else 1.0
    q_d = np.rint((disparity - d_lo) / d_step)
    q = np.concatenate([q_uv, q_d[:, None]], axis=1).clip(0, 65535).astype(np.uint16)
    colours = np.rint(np.clip(rgb, 0.0, 1.0) * 255.0).astype(np.uint8)
    return WebPoints(q, colours, np.array([lo_uv[0], lo_uv[1], d_lo]),
                     np.array([1.0 / per_px, 1.0 / per_px, d_step]), stride)


def encode_points(points: WebPoints) -> bytes:
    """The deflated byte planes of ``points`` (the layout of the module docstring)."""
    planes = []
    for c in range(3):
        d = np.diff(points.q[:, c], prepend=np.uint16(0))  # wraps in uint16
        planes += [(d & 0xFF).astype(np.uint8), (d >> 8).astype(np.uint8)]
    for c in range(3):
        planes.append(np.diff(points.rgb[:, c], prepend=np.uint8(0)))
    return zlib.compress(np.concatenate(planes).tobytes(), 9)


def decode_points(data: bytes, n: int) -> tuple:
    """``(q (N, 3) uint16, rgb (N, 3) uint8)`` from :func:`encode_points`' bytes (as the page decodes them)."""
    raw = np.frombuffer(zlib.decompress(data), np.uint8)
    if raw.size != 9 * n:
        raise InputError("points", f"expected {9 * n} bytes for {n} points, got {raw.size}")
    planes = raw.reshape(9, n)
    q = np.stack([np.cumsum(planes[2 * c].astype(np.uint16) | (planes[2 * c + 1].astype(np.uint16) << 8),
                            dtype=np.uint16) for c in range(3)], axis=1)
    rgb = np.stack([np.cumsum(planes[6 + c], dtype=np.uint8) for c in range(3)], axis=1)
    return q, rgb


def orbit_centre(depth: np.ndarray) -> Dict[str, float]:
    """The orbit centre and near depth of the desktop viewer (``OrbitScene.from_depths``): the median and the
    1st percentile of the photo's visible depths ``depth`` (any shape)."""
    z = np.asarray(depth, np.float64).reshape(-1)
    z = z[np.isfinite(z) & (z > 0)]
    if z.size == 0:
        raise InputError("depth", "no finite positive depth to place the orbit centre")
    near, centre = np.percentile(z, [1.0, 50.0])
    return {"centre_depth": float(max(centre, near)), "near_depth": float(near)}


def _ratio(value: float, default: float) -> float:
    return float(value) / float(default) if default > 0 else 0.0


def page_meta(points: WebPoints, photo_size, fov_y_deg: float, camera_range: CameraRange,
              scene: Dict[str, float], trajectory: Optional[Cameras], fps: float, title: str) -> dict:
    """Everything but the points that the page reads (``meta`` in ``web_page.html``)."""
    h, w = (int(v) for v in photo_size)
    r = camera_range
    # The desktop viewer's speeds relative to the range (OrbitLimits.from_range): 200 px of drag reach the
    # yaw limit and 15 wheel steps the forward limit on any photo.
    speeds = {"deg_per_pixel": 0.04 * _ratio(r.max_yaw_deg, _DEFAULT_RANGE.max_yaw_deg),
              "dolly_per_tick": 0.04 * _ratio(r.max_dolly, _DEFAULT_RANGE.max_dolly),
              "pan_gain": _ratio(r.max_pan, _DEFAULT_RANGE.max_pan)}
    poses, fovs = [], []
    if trajectory is not None and len(trajectory):
        c2w = trajectory.cam_to_world.detach().cpu().numpy().astype(np.float64)  # (B, 4, 4)
        fov = trajectory.fov_y_deg.detach().cpu().numpy().astype(np.float64).reshape(-1)
        fov = np.broadcast_to(fov, (len(c2w),)) if fov.size in (1, len(c2w)) else np.full(len(c2w), fov_y_deg)
        pick = np.unique(np.linspace(0, len(c2w) - 1, min(len(c2w), MAX_TRAJECTORY_POSES)).round().astype(int))
        if not (np.isfinite(c2w[pick]).all() and np.isfinite(fov[pick]).all()):
            raise InputError("trajectory", "camera poses must be finite")
        poses = [[round(float(v), 7) for v in c2w[i, :3, :].reshape(-1)] for i in pick]
        fovs = [round(float(fov[i]), 5) for i in pick]
        fps = float(fps) * len(pick) / len(c2w)
    return {
        "format": FORMAT_VERSION, "title": title, "count": int(len(points.q)),
        "photo": {"width": w, "height": h, "focal": focal_from_fov(fov_y_deg, h), "fov_y_deg": float(fov_y_deg)},
        "lo": [float(v) for v in points.lo], "step": [float(v) for v in points.step],
        "splat": SPLAT_SIZE * points.stride, "max_point_px": MAX_POINT_PX,
        "range": {"max_yaw_deg": r.max_yaw_deg, "max_pitch_deg": r.max_pitch_deg, "max_pan": r.max_pan,
                  "min_dolly": r.min_dolly, "max_dolly": r.max_dolly, "near_margin": r.near_margin},
        "scene": scene, "speeds": speeds,
        "trajectory": {"fps": float(fps), "cam_to_world": poses, "fov_y_deg": fovs},
    }


def page_html(meta: dict, payload: bytes) -> str:
    """The page: the template with ``meta`` (JSON) and the deflated points ``payload`` (base64) filled in."""
    template = resources.files(__package__).joinpath("web_page.html").read_text(encoding="utf-8")
    meta_json = json.dumps(meta, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")
    return (template.replace("{{TITLE}}", html.escape(str(meta.get("title", "3D photo"))))
            .replace("{{META}}", meta_json)
            .replace("{{POINTS}}", base64.b64encode(payload).decode("ascii")))


def read_page(path: PathLike) -> tuple:
    """``(meta, q (N, 3) uint16, rgb (N, 3) uint8)`` of a page this module wrote (a check of what it holds)."""
    src = Path(path)
    try:
        text = src.read_text(encoding="utf-8")
    except OSError as e:
        raise InputError(src, f"cannot read the page: {e}") from None
    try:
        meta = json.loads(_between(text, '<script type="application/json" id="meta">', "</script>"))
        payload = base64.b64decode(_between(text, '<script type="application/octet-stream" id="points">',
                                            "</script>").strip(), validate=True)
        q, rgb = decode_points(payload, int(meta["count"]))
    except (ValueError, KeyError, zlib.error, InputError) as e:
        raise InputError(src, f"not a readable stylize3d page ({e})") from None
    return meta, q, rgb


def _between(text: str, start: str, end: str) -> str:
    i = text.index(start) + len(start)
    return text[i:text.index(end, i)]


def write_page(path: PathLike, xyz: np.ndarray, rgb: np.ndarray, photo_size, fov_y_deg: float,
               camera_range: CameraRange, scene: Dict[str, float], *, trajectory: Optional[Cameras] = None,
               fps: float = 30.0, max_points: int = 2_000_000, max_bytes: int = 8 * 2 ** 20,
               title: str = "3D photo") -> Path:
    """Write the page of the points ``xyz`` (N, 3) with colours ``rgb`` (N, 3) of a photo of ``photo_size``
    (H, W) and ``fov_y_deg``, orbiting within ``camera_range`` about ``scene`` (:func:`orbit_centre`), with
    the ``trajectory`` played at ``fps``; at most ``max_points`` points, at most ``max_bytes`` bytes."""
    dest = Path(path)
    if dest.suffix.lower() not in (".html", ".htm"):
        raise InputError(dest, "a web page must end in .html or .htm")
    if isinstance(max_bytes, bool) or int(max_bytes) != max_bytes or max_bytes < 1:
        raise InputError("max_bytes", f"must be a positive integer, got {max_bytes!r}")
    points = quantise_points(xyz, rgb, photo_size, fov_y_deg, max_points)
    payload = encode_points(points)
    body = page_html(page_meta(points, photo_size, fov_y_deg, camera_range, scene, trajectory, fps, title),
                     payload).encode("utf-8")
    if len(body) > max_bytes:
        raise ExportError(f"{dest}: the page would be {len(body) / 2 ** 20:.1f} MB, over the cap of "
                          f"{max_bytes / 2 ** 20:.1f} MB ({len(points.q):,} points); lower --max-points or raise "
                          "--html-max-mb; nothing was written")

    def verify(tmp: Path) -> None:  # the payload reads back to the very points
        try:
            _, q, colours = read_page(tmp)
        except InputError as e:
            raise ExportError(f"{dest}: the written page does not read back ({e.problem})") from e
        if not (np.array_equal(q, points.q) and np.array_equal(colours, points.rgb)):
            raise ExportError(f"{dest}: the written page holds other points than were built")

    write_atomically(dest, "web page", lambda tmp: tmp.write_bytes(body), verify=verify, size=len(body))
    return dest

