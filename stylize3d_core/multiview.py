"""Multi-view input on disk: a views JSON file -> the views -> one merged 3D photo (paper Sec. 4.4).

Views file (``format`` ``"stylize3d-views"``, ``version`` 1; paths relative to the file's folder)::

    {
      "format": "stylize3d-views",
      "version": 1,
      "trajectory": "cams.json",        # optional: the poses, one per view, from a stylize3d camera path
                                        # or an Open3D PinholeCameraTrajectory (then views need no pose)
      "views": [
        {"image": "view0.png",
         "depth": "view0_depth.npy",    # a depth file in the unit of the poses (any --depth FILE form
                                        # that gives metric depth)
         "cam_to_world": [[...], [...], [...], [0, 0, 0, 1]],   # 4 rows of 4 numbers (geometry/camera.py)
         "fov_y_deg": 55.0},            # or "intrinsics": {"width", "height", "fx", "fy", "cx", "cy"}
        ...                             #   (pixel centres at +0.5; square pixels, centred principal point)
      ]
    }

The photo given on the command line is the **centre view**: it must be one of
the images, and the merged cloud lives in its frame and NDC
(:func:`stylize3d_core.scene.multiview.merge_views`). Everything that does not
fit is an :class:`InputError` naming the views file: a pose count that is not
the image count, intrinsics for another image size, relative depth, a pose
that does not match its image (the merge's pose check).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, List, Tuple

import numpy as np

from .errors import InputError, PathLike
from .export.camera_paths import read_camera_path
from .geometry.camera import check_fov
from .io.images import load_image
from .io.json_files import read_json_file
from .scene.multiview import MergedViews, View, merge_views
from .scene.photo3d import Photo3DSettings

FORMAT_TAG = "stylize3d-views"
FORMAT_VERSION = 1


def _fov_from_intrinsics(k: Any, size: Tuple[int, int], where: str, src: Path) -> float:
    if not isinstance(k, dict) or not all(isinstance(k.get(n), (int, float)) for n in
                                          ("width", "height", "fx", "fy", "cx", "cy")):
        raise InputError(src, f"{where}: intrinsics must have numbers width, height, fx, fy, cx, cy")
    h, w = size
    if (int(k["height"]), int(k["width"])) != (h, w):
        raise InputError(src, f"{where}: intrinsics are for a {int(k['width'])}x{int(k['height'])} image but the "
                              f"image is {w}x{h}; the poses do not match the images")
    fx, fy, cx, cy = (float(k[n]) for n in ("fx", "fy", "cx", "cy"))
    if fy <= 0 or abs(fx - fy) > 1e-3 * fy:
        raise InputError(src, f"{where}: fx = {fx:g} and fy = {fy:g}: only square pixels (fx = fy > 0) are supported")
    if abs(cx - w / 2) > 0.5 + 1e-6 or abs(cy - h / 2) > 0.5 + 1e-6:
        raise InputError(src, f"{where}: principal point ({cx:g}, {cy:g}) is off centre for a {w}x{h} image")
    return math.degrees(2 * math.atan(0.5 * h / fy))


def _matrix(m: Any, where: str, src: Path) -> np.ndarray:
    ok = isinstance(m, list) and len(m) == 4 and all(isinstance(r, list) and len(r) == 4 for r in m)
    if not ok or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for r in m for v in r):
        raise InputError(src, f"{where}: cam_to_world must be 4 rows of 4 numbers")
    return np.asarray(m, np.float64)


def load_views(path: PathLike, *, max_size: int = 1024, log=lambda _m: None) -> List[View]:
    """The views a views file describes (schema in the module docstring), their depth read and checked."""
    from .depth.sources import parse_depth_spec  # the depth package loads onnxruntime

    src = Path(path)
    doc = read_json_file(src, "views file")
    if not isinstance(doc, dict) or doc.get("format") != FORMAT_TAG:
        raise InputError(src, f"not a stylize3d views file (expected \"format\": \"{FORMAT_TAG}\")")
    if doc.get("version") != FORMAT_VERSION:
        raise InputError(src, f"unsupported views-file version {doc.get('version')!r} (this reads {FORMAT_VERSION})")
    entries = doc.get("views")
    if not isinstance(entries, list) or len(entries) < 1:
        raise InputError(src, "'views' must be a non-empty list")
    base = src.parent
    traj = None
    if doc.get("trajectory") is not None:
        traj = read_camera_path(base / str(doc["trajectory"]))
        if len(traj.cameras) != len(entries):
            raise InputError(src, f"the trajectory {doc['trajectory']} has {len(traj.cameras)} poses but there are "
                                  f"{len(entries)} images; the poses do not match the images")
    views = []
    for i, e in enumerate(entries):
        where = f"view {i}"
        if not isinstance(e, dict) or not isinstance(e.get("image"), str):
            raise InputError(src, f"{where}: needs an \"image\"")
        if not isinstance(e.get("depth"), str):
            raise InputError(src, f"{where}: needs a \"depth\" file (multi-view merging needs each view's depth in "
                                  "the unit of the poses)")
        image = load_image(base / e["image"], max_size=max_size)
        found = parse_depth_spec(str(base / e["depth"])).estimate(image)
        if found.depth_map.kind != "metric":
            raise InputError(base / e["depth"], f"{where}: gives relative depth; merging views needs depth in one "
                                                "unit (a depth file, not disparity)")
        file_size = image.original_size
        if traj is not None:
            pose = traj.cameras.cam_to_world[i].double().numpy()
            fov = float(traj.cameras.fov_y_deg[i])
            if traj.image_size is not None and tuple(traj.image_size) != tuple(file_size):
                raise InputError(src, f"{where}: the trajectory is for {traj.image_size[1]}x{traj.image_size[0]} "
                                      f"images but {e['image']} is {file_size[1]}x{file_size[0]}; the poses do not "
                                      "match the images")
        else:
            if "cam_to_world" not in e:
                raise InputError(src, f"{where}: needs \"cam_to_world\" (or a \"trajectory\" for all views)")
            pose = _matrix(e["cam_to_world"], where, src)
            if "intrinsics" in e:
                fov = _fov_from_intrinsics(e["intrinsics"], file_size, where, src)
            elif isinstance(e.get("fov_y_deg"), (int, float)):
                fov = float(e["fov_y_deg"])
            else:
                raise InputError(src, f"{where}: needs \"fov_y_deg\" or \"intrinsics\"")
        views.append(View(found.rgb, found.depth_map, pose, check_fov(fov, f"{src}: {where}: fov"),
                          str(base / e["image"])))
    log(f"views {src}: {len(views)} images")
    return views


def centre_index(views: List[View], photo: PathLike, source: PathLike) -> int:
    """Index of the view whose image is ``photo``."""
    target = Path(photo).resolve()
    for i, v in enumerate(views):
        if Path(v.name).resolve() == target:
            return i
    raise InputError(photo, f"is not one of the images of {source}; the photo is the centre view")


def load_merged(path: PathLike, photo: PathLike, settings: Photo3DSettings = Photo3DSettings(), *,
                max_size: int = 1024, log=lambda _m: None) -> MergedViews:
    """Read a views file and merge its views in the frame of ``photo`` (one of them)."""
    views = load_views(path, max_size=max_size, log=log)
    merged = merge_views(views, centre_index(views, photo, path), settings)
    log(f"merged {len(views)} views into {len(merged.photo.points):,} points (kept per view: "
        f"{', '.join(map(str, merged.kept))}; pose agreement {', '.join(f'{a:.0%}' for a in merged.agreement)})")
    return merged





def save_views(folder: PathLike, views: List[View], *, trajectory: bool = False) -> Path:
    """Write ``views`` as a views file with its images (PNG) and depth files (NPY) in ``folder`` (created),
    each file atomically; with ``trajectory`` the poses go to an Open3D ``trajectory.json`` the views file
    names. Returns the views file's path."""
    import torch

    from .export.camera_paths import write_camera_path
    from .geometry.camera import Cameras
    from .io.atomic import atomic_path
    from .io.images import save_image

    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    entries = []
    for i, v in enumerate(views):
        image, depth = f"view{i}.png", f"view{i}_depth.npy"
        save_image(out / image, v.rgb)
        with atomic_path(out / depth) as tmp:
            with open(tmp, "wb") as fh:
                np.save(fh, v.depth.depth.astype(np.float32))
        entry = {"image": image, "depth": depth}
        if not trajectory:
            entry.update(cam_to_world=np.asarray(v.cam_to_world, np.float64).tolist(), fov_y_deg=float(v.fov_y_deg))
        entries.append(entry)
    doc = {"format": FORMAT_TAG, "version": FORMAT_VERSION, "views": entries}
    if trajectory:
        h, w = views[0].rgb.shape[:2]
        cams = Cameras(torch.from_numpy(np.stack([v.cam_to_world for v in views]).astype(np.float64)),
                       torch.tensor([v.fov_y_deg for v in views], dtype=torch.float64))
        write_camera_path(out / "trajectory.json", cams, fmt="open3d", fps=30, image_size=(h, w))
        doc["trajectory"] = "trajectory.json"
    dest = out / ("views_open3d.json" if trajectory else "views.json")
    with atomic_path(dest) as tmp:
        tmp.write_text(json.dumps(doc, indent=1), encoding="utf-8")
    return dest
