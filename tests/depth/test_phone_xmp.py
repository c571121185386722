"""Depth embedded by phones: GDepth (extended XMP) and Dynamic Depth (appended image)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from stylize3d_core.depth.phone_xmp import decode_range, embedded_depth_map, has_embedded_depth, read_embedded_depth
from stylize3d_core.errors import InputError
from stylize3d_core.io.images import load_image, load_image_array


def read(path):
    """The embedded depth of a file, decoded from its bytes (as the sources do with LoadedImage.data)."""
    return read_embedded_depth(path.read_bytes(), path)


def has_depth(path) -> bool:
    return has_embedded_depth(path.read_bytes())


def depth_pattern(h: int = 30, w: int = 40, near: float = 0.5, far: float = 10.0) -> np.ndarray:
    """A depth map (h, w) spanning [near, far] with structure in both directions."""
    yy, xx = np.mgrid[0:h, 0:w]
    t = (xx / (w - 1) * 0.7 + yy / (h - 1) * 0.3)
    return (near + t * (far - near)).astype(np.float64)


# --------------------------------------------------------------------------- decoding formulas


@pytest.mark.parametrize("fmt", ["RangeLinear", "RangeInverse"])
def test_decode_range_known_values(fmt):
    near, far = 0.5, 8.0
    dn = np.array([[0.0, 1.0]])
    d = decode_range(dn, fmt, near, far, "f.jpg", "GDepth")
    np.testing.assert_allclose(d, [[near, far]], rtol=1e-6)
    mid = decode_range(np.array([[0.5]]), fmt, near, far, "f.jpg", "GDepth")[0, 0]
    expected = (near + far) / 2 if fmt == "RangeLinear" else far * near / (far - 0.5 * (far - near))
    assert mid == pytest.approx(expected, rel=1e-6)


def test_decode_range_rejects_bad_parameters():
    with pytest.raises(InputError, match="Near and Far"):
        decode_range(np.zeros((2, 2)), "RangeLinear", 2.0, 1.0, "f.jpg", "GDepth")
    with pytest.raises(InputError, match="Format"):
        decode_range(np.zeros((2, 2)), "Disparity", 0.5, 1.0, "f.jpg", "GDepth")


# --------------------------------------------------------------------------- GDepth


@pytest.mark.parametrize("fmt", ["RangeInverse", "RangeLinear"])
def test_gdepth_round_trip_png16(write_gdepth_jpeg, fmt):
    depth = depth_pattern()
    path = write_gdepth_jpeg(depth, fmt=fmt, near=0.5, far=10.0, bits=16, chunk=1500)
    emb = read(path)
    assert emb is not None and emb.layout == "GDepth" and emb.kind == "metric" and emb.units == "m"
    assert emb.depth.shape == depth.shape and emb.depth.dtype == np.float32
    np.testing.assert_allclose(emb.depth, depth, rtol=2e-3)
    assert has_depth(path)


def test_gdepth_8bit_jpeg_payload(write_gdepth_jpeg):
    depth = depth_pattern()
    path = write_gdepth_jpeg(depth, fmt="RangeLinear", near=1.0, far=5.0, bits=8, mime="image/jpeg")
    emb = read(path)
    # 8-bit quantisation (4/255 m) plus JPEG loss.
    assert np.abs(emb.depth - depth.clip(1, 5)).max() < 0.15


def test_gdepth_depth_map_aligned_and_resized(write_gdepth_jpeg):
    depth = depth_pattern(30, 40)
    path = write_gdepth_jpeg(depth, near=0.5, far=10.0)
    photo = load_image(path)  # the primary is 80 x 60
    dm = embedded_depth_map(photo)
    assert dm.shape == photo.size == (60, 80)
    assert dm.kind == "metric" and dm.valid.all() and "GDepth" in dm.source
    assert np.isfinite(dm.depth).all() and (dm.depth > 0).all()
    # Left is near, right is far, as in the pattern.
    assert dm.depth[:, :5].mean() < dm.depth[:, -5:].mean()
    np.testing.assert_allclose(dm.depth[::2, ::2].mean(), depth.mean(), rtol=0.02)


@pytest.mark.parametrize("orientation", [3, 6, 8])
def test_depth_follows_exif_orientation(write_gdepth_jpeg, orientation):
    h, w = 30, 40
    depth = np.full((h, w), 2.0)
    depth[:10, :10] = 0.6  # a near patch in the stored top-left corner
    stored = np.zeros((h * 2, w * 2, 3), np.uint8)
    stored[:20, :20] = 255  # the same corner of the stored photo is white
    path = write_gdepth_jpeg(depth, near=0.5, far=10.0, photo=stored, orientation=orientation)
    photo = load_image(path)
    assert photo.orientation == orientation  # parsed once, by load_image
    dm = embedded_depth_map(photo)
    white = photo.rgb.mean(axis=2) > 0.5  # where the patch is in the upright photo
    near = dm.depth < 1.3
    assert (white & near).sum() > 0.8 * white.sum()
    assert (near & ~white).sum() < 0.1 * near.sum()


def test_plain_jpeg_and_png_have_no_depth(tmp_path, helpers):
    from PIL import Image

    img = (helpers.gradient_photo() * 255).astype(np.uint8)
    Image.fromarray(img).save(tmp_path / "plain.jpg")
    Image.fromarray(img).save(tmp_path / "plain.png")
    for name in ("plain.jpg", "plain.png"):
        assert read(tmp_path / name) is None
        assert not has_depth(tmp_path / name)
    with pytest.raises(InputError, match="no embedded depth"):
        embedded_depth_map(load_image(tmp_path / "plain.jpg"))
    assert embedded_depth_map(load_image(tmp_path / "plain.jpg"), required=False) is None
    with pytest.raises(InputError, match="no photo file"):
        embedded_depth_map(load_image_array(img))
    assert embedded_depth_map(load_image_array(img), required=False) is None


# --------------------------------------------------------------------------- Dynamic Depth


@pytest.mark.parametrize("google", [False, True])
@pytest.mark.parametrize("padding", [0, 7])
def test_dynamic_depth_appended_image(write_dynamic_depth_jpeg, google, padding):
    depth = depth_pattern(24, 32, near=0.3, far=4.0)
    path = write_dynamic_depth_jpeg(depth, fmt="RangeLinear", near=0.3, far=4.0, google=google, padding=padding)
    emb = read(path)
    assert emb is not None and emb.layout == "DynamicDepth"
    np.testing.assert_allclose(emb.depth, depth, atol=1e-3)
    dm = embedded_depth_map(load_image(path))  # the primary is 64 x 48
    assert dm.shape == (48, 64) and dm.kind == "metric"
    assert has_depth(path)


# --------------------------------------------------------------------------- bad input


def test_corrupt_base64_payload(write_gdepth_jpeg):
    path = write_gdepth_jpeg(depth_pattern(), data="@@not*base64@@")
    with pytest.raises(InputError, match="base64") as err:
        read(path)
    assert str(path) in str(err.value)


def test_payload_that_is_not_an_image(write_gdepth_jpeg):
    import base64

    path = write_gdepth_jpeg(depth_pattern(), data=base64.b64encode(b"definitely not a png" * 10).decode())
    with pytest.raises(InputError, match="not a readable PNG or JPEG") as err:
        read(path)
    assert str(path) in str(err.value)


@pytest.mark.parametrize(
    "extra, message",
    [
        ({"GDepth:Near": None}, "no Near"),
        ({"GDepth:Far": "far away"}, "not a number"),
        ({"GDepth:Near": "5.0", "GDepth:Far": "1.0"}, "Near and Far"),
        ({"GDepth:Format": "Bananas"}, "Format"),
    ],
)
def test_bad_gdepth_parameters(write_gdepth_jpeg, extra, message):
    path = write_gdepth_jpeg(depth_pattern(), extra=extra)
    with pytest.raises(InputError, match=message) as err:
        read(path)
    assert str(path) in str(err.value)


def test_missing_extended_xmp_chunk(write_gdepth_jpeg):
    path = write_gdepth_jpeg(depth_pattern(), chunk=1000, drop_chunk=1)
    with pytest.raises(InputError, match="incomplete"):
        read(path)


def test_malformed_xmp(tmp_path, helpers):
    bad = b"http://ns.adobe.com/xap/1.0/\x00<x:xmpmeta><rdf:RDF>unclosed"
    path = tmp_path / "bad_xmp.jpg"
    photo = helpers.primary_jpeg((helpers.gradient_photo() * 255).astype(np.uint8))
    path.write_bytes(helpers.insert_app1_segments(photo, [bad]))
    with pytest.raises(InputError, match="corrupt XMP") as err:
        read(path)
    assert str(path) in str(err.value)


def test_container_length_that_does_not_match(write_dynamic_depth_jpeg):
    path = write_dynamic_depth_jpeg(depth_pattern(24, 32), length_delta=+13)
    with pytest.raises(InputError, match="not where the XMP directory says"):
        read(path)


def test_depth_with_another_aspect_ratio(write_gdepth_jpeg):
    path = write_gdepth_jpeg(depth_pattern(30, 40))
    photo = load_image(path)
    square = dataclasses.replace(photo, rgb=np.ascontiguousarray(photo.rgb[:, :60]))  # (60, 60): another aspect
    with pytest.raises(InputError, match="does not match the photo") as err:
        embedded_depth_map(square)
    assert str(path) in str(err.value)


def test_truncated_jpeg_segment(tmp_path):
    path = tmp_path / "trunc.jpg"
    path.write_bytes(b"\xff\xd8\xff\xe1\xff\xf0http://ns.adobe.com/xap/1.0/\x00<x/>")
    with pytest.raises(InputError, match="overruns"):
        read(path)
