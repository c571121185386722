"""Fixtures for the depth tests: sample photos, phone JPEGs with depth, tiny ONNX models.

Everything is built in ``tmp_path`` by the tests themselves (no binaries in the repo).
"""

from __future__ import annotations

import base64
import io
import types
import uuid
import warnings
from pathlib import Path
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import cv2
import numpy as np
import pytest
from PIL import Image

GDEPTH_NS = "http://ns.google.com/photos/1.0/depthmap/"


# --------------------------------------------------------------------------- photos


def sample_photo(name: str) -> np.ndarray:
    """A bundled scikit-image photo as (H, W, 3) float32 in [0, 1] ("motorcycle" = left view)."""
    from skimage import data

    img = data.stereo_motorcycle()[0] if name == "motorcycle" else getattr(data, name)()
    return img.astype(np.float32) / 255.0


@pytest.fixture(scope="session")
def motorcycle() -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """scikit-image's stereo pair: left, right (H, W, 3) float32 in [0, 1], ground-truth disparity (inf = none)."""
    from skimage import data

    left, right, disp = data.stereo_motorcycle()
    return left.astype(np.float32) / 255.0, right.astype(np.float32) / 255.0, disp


def gradient_photo(h: int = 48, w: int = 64) -> np.ndarray:
    """(h, w, 3) float32 photo with distinct content everywhere (for alignment tests)."""
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    return np.stack([xx / w, yy / h, 0.5 + 0.4 * np.sin(xx / 5.0) * np.cos(yy / 7.0)], axis=-1).astype(np.float32)


# --------------------------------------------------------------------------- phone JPEGs


def _app1(payload: bytes) -> bytes:
    assert len(payload) + 2 < 65536
    return b"\xff\xe1" + (len(payload) + 2).to_bytes(2, "big") + payload


def xmp_packet(description_attrs: Dict[str, str], namespaces: Dict[str, str], body: str = "") -> bytes:
    """A complete XMP document with one rdf:Description holding ``description_attrs`` and ``body``."""
    ns = " ".join(f'xmlns:{p}="{u}"' for p, u in namespaces.items())
    attrs = " ".join(f'{k}="{v}"' for k, v in description_attrs.items())
    return (
        '<x:xmpmeta xmlns:x="adobe:ns:meta/">'
        '<rdf:RDF xmlns:rdf="http://www.w3.org/1999/02/22-rdf-syntax-ns#">'
        f'<rdf:Description rdf:about="" {ns} {attrs}>{body}</rdf:Description>'
        "</rdf:RDF></x:xmpmeta>"
    ).encode()


def insert_app1_segments(jpeg: bytes, segments: Sequence[bytes]) -> bytes:
    """Insert APP1 payloads right after the SOI marker of ``jpeg``."""
    assert jpeg[:2] == b"\xff\xd8"
    return b"\xff\xd8" + b"".join(_app1(s) for s in segments) + jpeg[2:]


def extended_xmp_segments(extended: bytes, guid: str, chunk: int) -> List[bytes]:
    """Split an extended XMP document into APP1 payloads of at most ``chunk`` bytes of data."""
    out = []
    for offset in range(0, len(extended), chunk):
        out.append(
            b"http://ns.adobe.com/xmp/extension/\x00" + guid.encode() + len(extended).to_bytes(4, "big")
            + offset.to_bytes(4, "big") + extended[offset : offset + chunk]
        )
    return out


def encode_range(depth: np.ndarray, fmt: str, near: float, far: float, bits: int) -> np.ndarray:
    """Depth (h, w) -> stored grey image per the GDepth encoding (uint8 or uint16)."""
    if fmt == "RangeLinear":
        dn = (depth - near) / (far - near)
    else:
        dn = far * (depth - near) / (depth * (far - near))
    top = 255 if bits == 8 else 65535
    return np.round(np.clip(dn, 0, 1) * top).astype(np.uint8 if bits == 8 else np.uint16)


def primary_jpeg(rgb_u8: np.ndarray, orientation: int = 1) -> bytes:
    """A JPEG of ``rgb_u8`` (h, w, 3) stored as is, with an EXIF orientation tag when != 1."""
    buf = io.BytesIO()
    im = Image.fromarray(rgb_u8)
    if orientation != 1:
        exif = Image.Exif()
        exif[0x0112] = orientation
        im.save(buf, format="JPEG", quality=95, exif=exif.tobytes())
    else:
        im.save(buf, format="JPEG", quality=95)
    return buf.getvalue()


@pytest.fixture
def write_gdepth_jpeg(tmp_path: Path) -> Callable[..., Path]:
    """Write a JPEG with a GDepth depth map in its extended XMP; returns the path.

    Keyword args: depth (h, w) float, fmt, near, far, bits (8/16), mime ("image/png" or
    "image/jpeg"), photo (H, W, 3) uint8, orientation, data (override the base64 text),
    extra (dict of extra GDepth attributes, None values remove one), chunk (extended
    XMP chunk size), drop_chunk (index of an extended chunk to leave out), name.
    """

    def write(depth: np.ndarray, *, fmt: str = "RangeInverse", near: float = 0.5, far: float = 10.0,
              bits: int = 16, mime: str = "image/png", photo: Optional[np.ndarray] = None,
              orientation: int = 1, data: Optional[str] = None, extra: Optional[Dict[str, Optional[str]]] = None,
              chunk: int = 4000, drop_chunk: Optional[int] = None, name: str = "gdepth.jpg") -> Path:
        stored = encode_range(depth, fmt, near, far, bits)
        ok, blob = cv2.imencode(".png" if mime == "image/png" else ".jpg", stored)
        assert ok
        b64 = data if data is not None else base64.b64encode(blob.tobytes()).decode()
        guid = uuid.uuid4().hex.upper()
        attrs = {"GDepth:Format": fmt, "GDepth:Near": repr(near), "GDepth:Far": repr(far),
                 "GDepth:Mime": mime, "GDepth:Units": "m", "xmpNote:HasExtendedXMP": guid}
        for k, v in (extra or {}).items():
            if v is None:
                attrs.pop(k, None)
            else:
                attrs[k] = v
        namespaces = {"GDepth": GDEPTH_NS, "xmpNote": "http://ns.adobe.com/xmp/note/"}
        standard = xmp_packet(attrs, namespaces)
        extended = xmp_packet({"GDepth:Data": b64}, {"GDepth": GDEPTH_NS})
        ext = extended_xmp_segments(extended, guid, chunk)
        if drop_chunk is not None:
            ext.pop(drop_chunk)
        h, w = depth.shape
        img = photo if photo is not None else (gradient_photo(h * 2, w * 2) * 255).astype(np.uint8)
        out = insert_app1_segments(primary_jpeg(img, orientation),
                                   [b"http://ns.adobe.com/xap/1.0/\x00" + standard] + ext)
        path = tmp_path / name
        path.write_bytes(out)
        return path

    return write


@pytest.fixture
def write_dynamic_depth_jpeg(tmp_path: Path) -> Callable[..., Path]:
    """Write a Dynamic Depth JPEG: depth PNG (and a confidence PNG) appended after the primary image.

    Keyword args: depth (h, w), fmt, near, far, photo (uint8), google (use Google's container
    namespaces with Item:Semantic and GDepth parameters instead of DDF), length_delta (added
    to the depth item's declared length), padding (bytes after the primary), name.
    """

    def write(depth: np.ndarray, *, fmt: str = "RangeLinear", near: float = 0.3, far: float = 4.0,
              photo: Optional[np.ndarray] = None, google: bool = False, length_delta: int = 0,
              padding: int = 0, name: str = "dynamic.jpg") -> Path:
        ok, depth_png = cv2.imencode(".png", encode_range(depth, fmt, near, far, 16))
        ok2, conf_png = cv2.imencode(".png", np.full(depth.shape, 255, np.uint8))
        assert ok and ok2
        depth_b, conf_b = depth_png.tobytes(), conf_png.tobytes()
        if google:
            ns = {"Container": "http://ns.google.com/photos/1.0/container/",
                  "Item": "http://ns.google.com/photos/1.0/container/item/", "GDepth": GDEPTH_NS}
            items = (
                f'<Container:Directory><rdf:Seq>'
                f'<rdf:li rdf:parseType="Resource"><Container:Item Item:Mime="image/jpeg" Item:Semantic="Primary" '
                f'Item:Length="0" Item:Padding="{padding}"/></rdf:li>'
                f'<rdf:li rdf:parseType="Resource"><Container:Item Item:Mime="image/png" Item:Semantic="Depth" '
                f'Item:Length="{len(depth_b) + length_delta}"/></rdf:li>'
                f'<rdf:li rdf:parseType="Resource"><Container:Item Item:Mime="image/png" '
                f'Item:Semantic="Confidence" Item:Length="{len(conf_b)}"/></rdf:li>'
                f"</rdf:Seq></Container:Directory>"
            )
            attrs = {"GDepth:Format": fmt, "GDepth:Near": repr(near), "GDepth:Far": repr(far),
                     "GDepth:Mime": "image/png"}
            packet = xmp_packet(attrs, ns, items)
            appended = depth_b + conf_b  # file order as in the directory
        else:
            ns = {"Device": "http://ns.google.com/photos/dd/1.0/device/",
                  "Container": "http://ns.google.com/photos/dd/1.0/container/",
                  "Item": "http://ns.google.com/photos/dd/1.0/item/",
                  "Camera": "http://ns.google.com/photos/dd/1.0/camera/",
                  "DepthMap": "http://ns.google.com/photos/dd/1.0/depthmap/"}
            body = (
                "<Device:Container><Container:Directory><rdf:Seq>"
                f'<rdf:li rdf:parseType="Resource"><Container:Item Item:Mime="image/jpeg" Item:Length="0" '
                f'Item:Padding="{padding}" Item:DataURI="primary_image"/></rdf:li>'
                f'<rdf:li rdf:parseType="Resource"><Container:Item Item:Mime="image/png" '
                f'Item:Length="{len(conf_b)}" Item:DataURI="android/confidencemap"/></rdf:li>'
                f'<rdf:li rdf:parseType="Resource"><Container:Item Item:Mime="image/png" '
                f'Item:Length="{len(depth_b) + length_delta}" Item:DataURI="android/depthmap"/></rdf:li>'
                "</rdf:Seq></Container:Directory></Device:Container>"
                "<Device:Cameras><rdf:Seq><rdf:li rdf:parseType=\"Resource\"><Camera:DepthMap "
                f'rdf:parseType="Resource" DepthMap:Format="{fmt}" DepthMap:Near="{near!r}" DepthMap:Far="{far!r}" '
                'DepthMap:Units="Meters" DepthMap:DepthURI="android/depthmap" '
                'DepthMap:ConfidenceURI="android/confidencemap"/></rdf:li></rdf:Seq></Device:Cameras>'
            )
            packet = xmp_packet({}, ns, body)
            appended = conf_b + depth_b  # file order as in the directory: confidence, then depth
        h, w = depth.shape
        img = photo if photo is not None else (gradient_photo(h * 2, w * 2) * 255).astype(np.uint8)
        primary = insert_app1_segments(primary_jpeg(img), [b"http://ns.adobe.com/xap/1.0/\x00" + packet])
        path = tmp_path / name
        path.write_bytes(primary + b"\x00" * padding + appended)
        return path

    return write


# --------------------------------------------------------------------------- tiny ONNX models


@pytest.fixture(scope="session")
def export_onnx(tmp_path_factory: pytest.TempPathFactory) -> Callable[..., Path]:
    """Export a torch module to ONNX (TorchScript exporter) and return the file's path.

    Args of the returned function: module, example input, name, dynamic (H, W dynamic),
    input_names (defaults to ["image"]).
    """
    import torch

    folder = tmp_path_factory.mktemp("onnx")

    def export(module: "torch.nn.Module", example, name: str, *, dynamic: bool = True,
               nhwc: bool = False) -> Path:
        path = folder / name
        examples = example if isinstance(example, tuple) else (example,)
        names = [f"input{i}" for i in range(len(examples))] if len(examples) > 1 else ["image"]
        axes = None
        if dynamic:
            hw = {1: "h", 2: "w"} if nhwc else {2: "h", 3: "w"}
            axes = {n: ({0: "batch", **hw} if examples[i].dim() == 4 else {0: "batch"}) for i, n in enumerate(names)}
        module.eval()
        with warnings.catch_warnings():  # the TorchScript exporter announces its deprecation
            warnings.simplefilter("ignore", DeprecationWarning)
            torch.onnx.export(module, examples, str(path), input_names=names, output_names=["depth"],
                              dynamic_axes=axes, dynamo=False, opset_version=17)
        return path

    return export


@pytest.fixture(scope="session")
def helpers() -> types.SimpleNamespace:
    """The plain helper functions of this conftest, for tests that need them directly."""
    return types.SimpleNamespace(
        sample_photo=sample_photo,
        gradient_photo=gradient_photo,
        insert_app1_segments=insert_app1_segments,
        primary_jpeg=primary_jpeg,
        encode_range=encode_range,
    )
