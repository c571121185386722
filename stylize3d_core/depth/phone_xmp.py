"""Depth maps that phone cameras embed in their JPEGs (XMP metadata).

Two layouts are read:

* **GDepth** (Google "depthmap metadata", Lens Blur / early portrait modes):
  XMP properties in the namespace ``http://ns.google.com/photos/1.0/depthmap/``:
  ``GDepth:Format`` (RangeInverse or RangeLinear), ``GDepth:Near``,
  ``GDepth:Far``, ``GDepth:Units`` (default "m"), ``GDepth:Mime`` and
  ``GDepth:Data``, a base64 PNG or JPEG -- too large for one APP1 segment, so
  it normally sits in the *extended* XMP (APP1 segments headed
  ``http://ns.adobe.com/xmp/extension/``, reassembled by the GUID given in
  ``xmpNote:HasExtendedXMP``).
* **Dynamic Depth** (Android DDF 1.0) and Google's container format: the depth
  image is a separate JPEG or PNG *appended after the primary image*; the
  primary image's XMP lists the appended items in a ``Container:Directory``
  (``Item:Mime``, ``Item:Length``, ``Item:Padding``, ``Item:DataURI``,
  ``Item:Semantic``) in file order, and the depth parameters are in a
  ``DepthMap`` element (DDF: ``DepthMap:Format/Near/Far/Units/DepthURI``) or
  in GDepth properties without ``Data``. The depth item is the one whose
  ``DataURI`` is ``DepthURI``, or else the one with ``Semantic`` "Depth".

Decoding a stored grey value ``v`` (8 or 16 bit) with ``dn = v / max``:
RangeLinear ``d = dn (far - near) + near``; RangeInverse
``d = far near / (far - dn (far - near))``. With near and far the depth is
"metric" (in ``Units``); the depth is aligned with the photo by the file's EXIF
orientation and stretched to the photo's size, as the format prescribes.
Namespaces are matched by local names, so minor variants of the prefixes work.

Nothing here opens the photo file: the depth is decoded from the bytes that
:func:`~stylize3d_core.io.images.load_image` read (``LoadedImage.data``), and
the EXIF orientation is the one it parsed (``LoadedImage.orientation``).
"""

from __future__ import annotations

import base64
import binascii
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple

import cv2
import numpy as np

from ..errors import InputError, PathLike
from ..io.images import LoadedImage, apply_orientation, check_jpeg_structure, check_png_structure, declared_pixels
from ._util import resize_to
from .types import DepthMap, DepthKind

XMP_STANDARD = b"http://ns.adobe.com/xap/1.0/\x00"
XMP_EXTENDED = b"http://ns.adobe.com/xmp/extension/\x00"
GDEPTH_NS = "http://ns.google.com/photos/1.0/depthmap/"
XMPNOTE_NS = "http://ns.adobe.com/xmp/note/"
_STANDALONE = {0x01, 0xD0, 0xD1, 0xD2, 0xD3, 0xD4, 0xD5, 0xD6, 0xD7}


@dataclass(frozen=True)
class EmbeddedDepth:
    """Depth decoded from a phone JPEG, at the depth image's own size and orientation."""

    depth: np.ndarray
    """(h, w) float32 depth, > 0."""
    kind: DepthKind
    """"metric" (near/far in ``units``) -- the only kind phones write."""
    layout: str
    """"GDepth" or "DynamicDepth"."""
    units: str
    """Unit of depth, e.g. "m"."""


# --------------------------------------------------------------------------- JPEG structure


def _jpeg_segments(data: bytes, name: str) -> Tuple[List[Tuple[int, bytes]], int]:
    """APP/marker segments of the primary JPEG before its first scan, and the offset just past its EOI."""
    if data[:2] != b"\xff\xd8":
        raise InputError(name, "not a JPEG file (no SOI marker)")
    segments: List[Tuple[int, bytes]] = []
    pos, n, in_scan = 2, len(data), False
    while pos < n:
        if in_scan:
            nxt = data.find(b"\xff", pos)
            if nxt < 0 or nxt + 1 >= n:
                return segments, n
            follow = data[nxt + 1]
            if follow == 0x00 or follow in _STANDALONE or follow == 0xFF:
                pos = nxt + (2 if follow != 0xFF else 1)
                continue
            pos, in_scan = nxt, False
        if data[pos] != 0xFF:
            raise InputError(name, f"corrupt JPEG: expected a marker at byte {pos}")
        while pos < n and data[pos] == 0xFF:
            pos += 1
        if pos >= n:
            break
        marker = data[pos]
        pos += 1
        if marker in _STANDALONE or marker == 0xD8:
            continue
        if marker == 0xD9:
            return segments, pos
        if pos + 2 > n:
            break
        length = int.from_bytes(data[pos : pos + 2], "big")
        if length < 2 or pos + length > n:
            raise InputError(name, f"corrupt JPEG: segment 0x{marker:02X} at byte {pos} overruns the file")
        segments.append((marker, data[pos + 2 : pos + length]))
        pos += length
        in_scan = marker == 0xDA
    return segments, n


def _xmp_packets(segments: List[Tuple[int, bytes]], name: str) -> Tuple[Optional[bytes], Dict[str, bytes]]:
    """The standard XMP packet and the extended XMP documents by GUID (reassembled)."""
    standard: Optional[bytes] = None
    parts: Dict[str, Tuple[int, Dict[int, bytes]]] = {}
    for marker, payload in segments:
        if marker != 0xE1:
            continue
        if payload.startswith(XMP_STANDARD) and standard is None:
            standard = payload[len(XMP_STANDARD) :]
        elif payload.startswith(XMP_EXTENDED):
            body = payload[len(XMP_EXTENDED) :]
            if len(body) < 40:
                raise InputError(name, "corrupt extended XMP segment (header too short)")
            guid = body[:32].decode("ascii", errors="replace")
            total = int.from_bytes(body[32:36], "big")
            offset = int.from_bytes(body[36:40], "big")
            parts.setdefault(guid, (total, {}))[1][offset] = body[40:]
    extended: Dict[str, bytes] = {}
    for guid, (total, chunks) in parts.items():
        # The chunks must tile [0, total) in order. Checked before anything of size
        # ``total`` exists: the length is 4 bytes of the file, up to 4 GB.
        covered = 0
        for offset, chunk in sorted(chunks.items()):
            if offset > covered:
                raise InputError(name, f"extended XMP {guid} is incomplete (bytes {covered}-{offset} of {total} are missing)")
            if offset < covered:
                raise InputError(name, f"corrupt extended XMP {guid}: a chunk at {offset} overlaps the one before it")
            if offset + len(chunk) > total:
                raise InputError(name, f"corrupt extended XMP {guid}: chunk at {offset} exceeds its length {total}")
            covered += len(chunk)
        if covered != total:
            raise InputError(name, f"extended XMP {guid} is incomplete ({covered} of {total} bytes)")
        extended[guid] = b"".join(chunk for _, chunk in sorted(chunks.items()))
    return standard, extended


def _parse_xml(packet: bytes, name: str, what: str) -> ET.Element:
    text = packet.rstrip(b"\x00 \r\n\t")
    try:
        return ET.fromstring(text)
    except ET.ParseError as exc:
        raise InputError(name, f"corrupt {what}: {exc}") from exc


def _local(tag: str) -> Tuple[str, str]:
    """'{ns}name' -> (ns, name)."""
    if tag.startswith("{"):
        ns, _, local = tag[1:].partition("}")
        return ns, local
    return "", tag


def _properties(elem: ET.Element, ns_filter) -> Dict[str, str]:
    """Attributes and simple child elements of ``elem`` whose namespace passes ``ns_filter``, by local name."""
    props: Dict[str, str] = {}
    for key, value in elem.attrib.items():
        ns, local = _local(key)
        if ns_filter(ns):
            props[local] = value
    for child in elem:
        ns, local = _local(child.tag)
        if ns_filter(ns) and len(child) == 0 and child.text is not None:
            props.setdefault(local, child.text.strip())
    return props


# --------------------------------------------------------------------------- decoding


def _number(props: Dict[str, str], key: str, name: str, where: str) -> float:
    if key not in props:
        raise InputError(name, f"{where} has no {key} value")
    try:
        value = float(props[key])
    except ValueError as exc:
        raise InputError(name, f"{where}:{key} is not a number: {props[key]!r}") from exc
    if not np.isfinite(value):
        raise InputError(name, f"{where}:{key} is not finite: {props[key]!r}")
    return value


MAX_PIXELS = 50_000_000
"""Largest embedded depth image accepted (phones store depth at or below the photo's 12-50 MP)."""


def _decode_image(blob: bytes, name: str, what: str) -> np.ndarray:
    """PNG/JPEG bytes -> (h, w) grey values in [0, 1] as float64.

    The image must be complete (a truncated JPEG would decode to grey filler) and
    at most :data:`MAX_PIXELS`, both checked on its structure before decoding.
    """
    if blob.startswith(_SIGNATURES["image/png"]):
        header = check_png_structure(blob, name)
        pixels = header.width * header.height
    elif blob.startswith(_SIGNATURES["image/jpeg"]):
        check_jpeg_structure(blob, name)
        pixels = declared_pixels(blob) or 0
    else:
        raise InputError(name, f"{what} is not a readable PNG or JPEG image")
    if pixels > MAX_PIXELS:
        raise InputError(name, f"{what} declares {pixels:,} pixels, more than {MAX_PIXELS:,} (not a phone depth map)")
    img = cv2.imdecode(np.frombuffer(blob, np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise InputError(name, f"{what} is not a readable PNG or JPEG image")
    if img.ndim == 3:
        img = img[..., 0]  # grey stored as colour: channels are equal
    if img.dtype == np.uint8:
        return img.astype(np.float64) / 255.0
    if img.dtype == np.uint16:
        return img.astype(np.float64) / 65535.0
    raise InputError(name, f"{what} has unsupported sample type {img.dtype}")


def decode_range(dn: np.ndarray, fmt: str, near: float, far: float, name: str, where: str) -> np.ndarray:
    """Normalised values ``dn`` (h, w) in [0, 1] -> depth (h, w) float32 (see the module docstring)."""
    if not (0 < near < far):
        raise InputError(name, f"{where}: Near and Far must satisfy 0 < Near < Far, got {near:g}, {far:g}")
    dn = np.clip(dn, 0.0, 1.0)
    if fmt == "RangeLinear":
        depth = dn * (far - near) + near
    elif fmt == "RangeInverse":
        depth = far * near / (far - dn * (far - near))
    else:
        raise InputError(name, f"{where}:Format must be RangeInverse or RangeLinear, got {fmt!r}")
    return depth.astype(np.float32)


def _gdepth(root_docs: List[ET.Element]) -> Dict[str, str]:
    props: Dict[str, str] = {}
    for root in root_docs:
        for elem in root.iter():
            for k, v in _properties(elem, lambda ns: ns == GDEPTH_NS).items():
                props.setdefault(k, v)
    return props


def _ddf_depthmap(root: ET.Element) -> Dict[str, str]:
    for elem in root.iter():
        ns, local = _local(elem.tag)
        if local == "DepthMap" and "/dd/" in ns:
            return _properties(elem, lambda n: "depthmap" in n.lower())
    return {}


def _container_items(root: ET.Element) -> List[Dict[str, str]]:
    items = []
    for elem in root.iter():
        ns, local = _local(elem.tag)
        if local == "Item" and "container" in ns.lower():
            items.append(_properties(elem, lambda n: True))
    return items


_SIGNATURES = {"image/jpeg": b"\xff\xd8", "image/png": b"\x89PNG\r\n\x1a\n"}


def _item_bytes(data: bytes, primary_end: int, items: List[Dict[str, str]], index: int, name: str) -> bytes:
    """Bytes of ``items[index]`` (a secondary item) following the container layout."""

    def ints(item: Dict[str, str], key: str) -> int:
        try:
            return int(item.get(key, "0") or 0)
        except ValueError as exc:
            raise InputError(name, f"container item has a non-integer {key}: {item.get(key)!r}") from exc

    sizes = [(ints(it, "Length"), ints(it, "Padding")) for it in items]
    target = items[index]
    sig = _SIGNATURES.get(target.get("Mime", ""), b"")
    # Forward from the end of the primary image (its Length is 0 = "the JPEG itself").
    starts = []
    pos = primary_end + sizes[0][1]
    for length, padding in sizes[1:]:
        starts.append(pos)
        pos += length + padding
    forward = starts[index - 1]
    # Backward from the end of the file (writers that pad the primary differently).
    tail = sum(length + padding for length, padding in sizes[1:])
    backward = len(data) - tail + sum(length + padding for length, padding in sizes[1:index])
    length = sizes[index][0]
    for start in (forward, backward):
        blob = data[start : start + length]
        if length > 0 and start >= primary_end and len(blob) == length and blob.startswith(sig):
            return blob
    raise InputError(
        name,
        f"corrupt depth container: item {index} ({target.get('Mime', '?')}, {length} bytes) "
        f"is not where the XMP directory says",
    )


def read_embedded_depth(data: bytes, name: PathLike = "photo") -> Optional[EmbeddedDepth]:
    """Decode the depth map embedded in a phone JPEG's bytes ``data``; None if it carries none.

    Args:
        data: the whole file, as read (``LoadedImage.data``).
        name: the file's name, for error messages.
    Raises:
        InputError: naming ``name`` when depth metadata is present but corrupt
            (bad XML, bad base64, an undecodable image, missing or absurd
            Near/Far, a container directory that does not match the bytes).
    """
    name = os.fspath(name)
    if data[:2] != b"\xff\xd8":
        return None  # not a JPEG: phones embed depth only in JPEGs
    segments, primary_end = _jpeg_segments(data, name)
    standard, extended = _xmp_packets(segments, name)
    if standard is None:
        return None
    root = _parse_xml(standard, name, "XMP metadata")
    docs = [root]
    guid = None
    for elem in root.iter():
        guid = guid or _properties(elem, lambda ns: ns == XMPNOTE_NS).get("HasExtendedXMP")
    ext_packets = [extended[guid]] if guid in extended else list(extended.values())
    docs += [_parse_xml(p, name, "extended XMP metadata") for p in ext_packets]

    gdepth = _gdepth(docs)
    ddf = _ddf_depthmap(root)
    items = _container_items(root)
    if "Data" in gdepth:
        try:
            blob = base64.b64decode("".join(gdepth["Data"].split()), validate=True)
        except (binascii.Error, ValueError) as exc:
            raise InputError(name, f"GDepth:Data is not valid base64 ({exc})") from exc
        dn = _decode_image(blob, name, "GDepth:Data")
        params, where, layout = gdepth, "GDepth", "GDepth"
    elif items and (ddf or gdepth):
        params = ddf or gdepth
        where = "DepthMap" if ddf else "GDepth"
        uri = params.get("DepthURI")
        index = next((i for i, it in enumerate(items) if uri and it.get("DataURI") == uri), None)
        if index is None:
            index = next((i for i, it in enumerate(items) if it.get("Semantic") == "Depth"), None)
        if index is None or index == 0:
            raise InputError(name, "depth metadata present but the container lists no depth image")
        dn = _decode_image(_item_bytes(data, primary_end, items, index, name), name, "the depth image")
        layout = "DynamicDepth"
    else:
        return None
    near = _number(params, "Near", name, where)
    far = _number(params, "Far", name, where)
    depth = decode_range(dn, params.get("Format", "RangeInverse"), near, far, name, where)
    return EmbeddedDepth(depth, "metric", layout, params.get("Units", "m"))


def has_embedded_depth(data: bytes) -> bool:
    """True if the file bytes ``data`` are a JPEG whose XMP mentions a depth map (cheap; does not decode it)."""
    return data[:2] == b"\xff\xd8" and ((GDEPTH_NS.encode() in data) or (b"/dd/1.0/depthmap/" in data))


def embedded_depth_map(image: LoadedImage, *, required: bool = True) -> Optional[DepthMap]:
    """The depth embedded in the file ``image`` was loaded from, as a DepthMap aligned with ``image.rgb``.

    The depth is read from ``image.data`` (the file is not opened again), turned
    upright like the photo (``image.orientation``) and stretched to
    ``image.size``. Raises :class:`InputError` naming the file if the depth's
    aspect ratio differs from the photo's by more than 5 %, if the metadata is
    corrupt, or -- with ``required`` -- if the file carries no depth or the
    image was not loaded from a file (else None is returned then).
    """
    name = image.path or "photo"
    if image.data is None:
        if not required:
            return None
        raise InputError("depth", "phone depth is read from the photo file; no photo file was given "
                                  "(the photo is an in-memory array)")
    emb = read_embedded_depth(image.data, name)
    if emb is None:
        if not required:
            return None
        raise InputError(name, "carries no embedded depth map (GDepth or Dynamic Depth XMP)")
    depth = apply_orientation(emb.depth, image.orientation)
    h, w = depth.shape
    H, W = image.size
    if abs((w / h) / (W / H) - 1.0) > 0.05:
        raise InputError(name, f"embedded depth map is {w}x{h}, which does not match the photo's shape {W}x{H}")
    out = resize_to(depth, (H, W)).astype(np.float32)
    out = np.clip(out, float(emb.depth.min()), float(emb.depth.max()))
    return DepthMap(out, np.ones((H, W), bool), emb.kind, f"phone:{os.path.basename(name)} ({emb.layout})")
