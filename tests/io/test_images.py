"""Tests for stylize3d_core.io.images: decoding, orientation, resizing, EXIF focal length, bad files, saving."""

from __future__ import annotations

import math
import struct
import zlib

import cv2
import numpy as np
import pytest
import skimage.data
from PIL import Image, ImageFile, ImageOps

from stylize3d_core.errors import ExportError, InputError
from stylize3d_core.io.images import (
    LoadedImage,
    apply_orientation,
    fov_y_deg_from_exif,
    load_image,
    load_image_array,
    resize_image,
    save_image,
)


def _noise(shape, dtype=np.uint8, seed=0):
    top = np.iinfo(dtype).max
    return np.random.default_rng(seed).integers(0, top + 1, size=shape, dtype=np.int64).astype(dtype)


# ---------------------------------------------------------------------------- formats


def test_astronaut_jpeg_is_shrunk_with_area_averaging(write_image):
    photo = skimage.data.astronaut()  # (512, 512, 3)
    path = write_image("astronaut.jpg", photo, quality=95)
    img = load_image(path, max_size=256)
    assert img.rgb.shape == (256, 256, 3) and img.rgb.dtype == np.float32
    assert img.original_size == (512, 512) and img.bit_depth == 8 and img.alpha is None
    assert img.path == str(path)
    assert 0.0 <= img.rgb.min() and img.rgb.max() <= 1.0
    reference = cv2.resize(photo, (256, 256), interpolation=cv2.INTER_AREA) / 255.0
    assert np.abs(img.rgb - reference).mean() < 0.02  # JPEG loss only


def test_chelsea_keeps_aspect_and_is_never_enlarged(write_image):
    photo = skimage.data.chelsea()  # (300, 451, 3)
    path = write_image("chelsea.png", photo)
    small = load_image(path, max_size=200)
    assert small.rgb.shape == (133, 200, 3) and small.original_size == (300, 451)
    assert abs(133 / 200 - 300 / 451) < 0.01
    full = load_image(path, max_size=1000)
    np.testing.assert_array_equal(full.rgb, photo.astype(np.float32) / 255.0)


def test_png_8bit_rgb_is_exact(write_image):
    a = _noise((40, 50, 3))
    img = load_image(write_image("a.png", a))
    np.testing.assert_array_equal(img.rgb, a.astype(np.float32) / 255.0)


def test_png_16bit_rgb_keeps_16_bits(tmp_path):
    a = _noise((40, 50, 3), np.uint16, seed=1)
    assert (a % 257 != 0).any()  # values an 8-bit decode cannot hold
    cv2.imwrite(str(tmp_path / "a16.png"), a[..., ::-1])  # OpenCV writes BGR
    img = load_image(tmp_path / "a16.png")
    assert img.bit_depth == 16 and img.alpha is None
    np.testing.assert_allclose(img.rgb, a / 65535.0, atol=1e-7)


def test_png_16bit_rgba(tmp_path):
    a = _noise((40, 50, 4), np.uint16, seed=2)
    cv2.imwrite(str(tmp_path / "a16.png"), a[..., [2, 1, 0, 3]])
    img = load_image(tmp_path / "a16.png")
    np.testing.assert_allclose(img.rgb, a[..., :3] / 65535.0, atol=1e-7)
    np.testing.assert_allclose(img.alpha, a[..., 3] / 65535.0, atol=1e-7)


@pytest.mark.parametrize("suffix", [".png", ".tif"])
def test_16bit_grey_becomes_three_equal_channels(tmp_path, suffix):
    g = _noise((40, 50), np.uint16, seed=3)
    cv2.imwrite(str(tmp_path / f"g{suffix}"), g)
    img = load_image(tmp_path / f"g{suffix}")
    assert img.bit_depth == 16
    for c in range(3):
        np.testing.assert_allclose(img.rgb[..., c], g / 65535.0, atol=1e-7)


def test_8bit_grey_png(write_image):
    g = _noise((40, 50), seed=4)
    img = load_image(write_image("g.png", g))
    np.testing.assert_array_equal(img.rgb, np.repeat(g[..., None], 3, 2) / np.float32(255))


def test_grey_alpha_png(write_image):
    la = _noise((40, 50, 2), seed=5)
    img = load_image(write_image("la.png", la, "LA"))
    np.testing.assert_array_equal(img.rgb[..., 1], la[..., 0] / np.float32(255))
    np.testing.assert_array_equal(img.alpha, la[..., 1] / np.float32(255))


def test_rgba_png_colour_is_not_premultiplied(write_image):
    rgba = _noise((40, 50, 4), seed=6)
    rgba[:5, :5, 3] = 0  # transparent, but keeps its colour
    img = load_image(write_image("rgba.png", rgba))
    np.testing.assert_array_equal(img.rgb, rgba[..., :3] / np.float32(255))
    np.testing.assert_array_equal(img.alpha, rgba[..., 3] / np.float32(255))


def test_palette_png_with_and_without_transparency(write_image):
    index = (np.arange(40 * 50).reshape(40, 50) % 3).astype(np.uint8)
    pal = Image.fromarray(index, "P")
    pal.putpalette([255, 0, 0, 0, 255, 0, 0, 0, 255] + [0] * 759)
    plain = load_image(write_image("p.png", pal))
    colours = np.eye(3, dtype=np.float32)
    np.testing.assert_array_equal(plain.rgb, colours[index])
    assert plain.alpha is None
    see_through = load_image(write_image("pt.png", pal, transparency=1))
    np.testing.assert_array_equal(see_through.alpha, (index != 1).astype(np.float32))


def test_webp_lossless_and_tiff_8bit(write_image):
    a = _noise((40, 50, 3), seed=7)
    np.testing.assert_array_equal(load_image(write_image("a.webp", a, lossless=True)).rgb, a / np.float32(255))
    np.testing.assert_array_equal(load_image(write_image("a.tif", a)).rgb, a / np.float32(255))


def test_tiff_16bit_rgb(tmp_path):
    a = _noise((40, 50, 3), np.uint16, seed=8)
    cv2.imwrite(str(tmp_path / "a.tif"), a[..., ::-1])
    img = load_image(tmp_path / "a.tif")
    assert img.bit_depth == 16
    np.testing.assert_allclose(img.rgb, a / 65535.0, atol=1e-7)


# ---------------------------------------------------------------------------- orientation


@pytest.mark.parametrize("orientation", range(1, 9))
def test_exif_orientation_jpeg_ends_upright(write_exif_jpeg, quadrants, orientation):
    path = write_exif_jpeg(f"o{orientation}.jpg", quadrants, orientation)
    img = load_image(path)
    assert img.rgb.shape == quadrants.shape and img.original_size == (48, 64)
    assert np.abs(img.rgb - quadrants / 255.0).mean() < 0.02
    with Image.open(path) as stored:  # reference: Pillow's own transpose
        reference = np.asarray(ImageOps.exif_transpose(stored).convert("RGB")) / 255.0
    assert np.abs(img.rgb - reference).max() < 1e-6


@pytest.mark.parametrize("orientation", range(1, 9))
def test_apply_orientation_matches_pillow(orientation, upright_op):
    a = _noise((5, 7, 3), seed=orientation)
    reference = a if orientation == 1 else np.asarray(Image.fromarray(a).transpose(upright_op[orientation]))
    np.testing.assert_array_equal(apply_orientation(a, orientation), reference)


def test_exif_orientation_in_png_and_alpha(write_image, quadrants):
    rgba = np.dstack([quadrants, np.full((48, 64), 200, np.uint8)])
    rgba[:24, :32, 3] = 10  # top-left quadrant nearly transparent
    stored = Image.fromarray(rgba).transpose(Image.Transpose.ROTATE_90)  # orientation 6 undoes this
    exif = Image.Exif()
    exif[0x0112] = 6
    img = load_image(write_image("o6.png", stored, exif=exif))
    np.testing.assert_array_equal(img.rgb, quadrants / np.float32(255))
    np.testing.assert_array_equal(img.alpha, rgba[..., 3] / np.float32(255))


def test_exif_orientation_in_16bit_colour_png(tmp_path):
    upright = _noise((40, 50, 3), np.uint16, seed=11)
    stored = np.rot90(upright, k=-1)  # orientation 8 (turn 90 degrees counter-clockwise) undoes this
    ok, buf = cv2.imencode(".png", np.ascontiguousarray(stored[..., ::-1]))
    exif = Image.Exif()
    exif[0x0112] = 8
    payload = exif.tobytes()
    chunk = struct.pack(">I", len(payload)) + b"eXIf" + payload + struct.pack(">I", zlib.crc32(b"eXIf" + payload))
    data = buf.tobytes()
    at = data.index(b"IDAT") - 4  # insert the eXIf chunk before the image data
    (tmp_path / "o8.png").write_bytes(data[:at] + chunk + data[at:])
    img = load_image(tmp_path / "o8.png")
    assert img.bit_depth == 16 and img.original_size == (40, 50)
    np.testing.assert_allclose(img.rgb, upright / 65535.0, atol=1e-7)
    assert img.orientation == 8 and img.format == "PNG"


@pytest.mark.parametrize("orientation", [1, 3, 6, 8])
def test_loaded_image_keeps_the_orientation_and_the_file_bytes(write_exif_jpeg, quadrants, orientation):
    path = write_exif_jpeg(f"o{orientation}.jpg", quadrants, orientation)
    img = load_image(path, max_size=48)  # shrunk: the bytes are still the whole file, as read
    assert img.orientation == orientation and img.format == "JPEG"
    assert img.data == path.read_bytes()
    assert "data=" not in repr(img)  # a photo's bytes are not printed
    stored = np.asarray(Image.open(path).convert("RGB"))  # data kept in the stored orientation turns upright
    assert apply_orientation(stored, img.orientation).shape[:2] == img.original_size


def test_in_memory_images_have_no_file_metadata(quadrants):
    img = load_image_array(quadrants)
    assert img.orientation == 1 and img.data is None and img.format is None and img.path is None
    with pytest.raises(InputError, match="orientation"):
        LoadedImage(img.rgb, None, None, img.size, 8, None, orientation=9)


# ---------------------------------------------------------------------------- EXIF focal length


def test_focal_35mm_gives_fov_for_landscape_and_portrait(write_exif_jpeg):
    landscape = np.full((64, 96, 3), 128, np.uint8)  # 3:2, like 35 mm film
    img = load_image(write_exif_jpeg("f.jpg", landscape, focal_35mm=50))
    assert img.focal_35mm == 50.0
    assert fov_y_deg_from_exif(img) == pytest.approx(math.degrees(2 * math.atan(12 / 50)), abs=1e-9)
    portrait = landscape.transpose(1, 0, 2)  # stored as a landscape, turned upright by orientation 6
    turned = load_image(write_exif_jpeg("p.jpg", portrait, orientation=6, focal_35mm=50))
    with Image.open(turned.path) as stored:
        assert stored.size == (96, 64)  # (W, H) as stored
    assert turned.original_size == (96, 64)
    assert turned.fov_y_deg() == pytest.approx(math.degrees(2 * math.atan(18 / 50)), abs=1e-9)


def test_focal_from_focal_length_and_focal_plane_resolution(write_exif_jpeg):
    # 4000 x 3000 sensor of 6.4 x 4.8 mm (8 mm diagonal), 4.5 mm lens -> 4.5 * 43.27 / 8
    tags = {0x920A: 4.5, 0xA20E: 6250.0, 0xA20F: 6250.0, 0xA210: 3, 0xA002: 4000, 0xA003: 3000}
    img = load_image(write_exif_jpeg("f.jpg", np.full((48, 64, 3), 90, np.uint8), exif_ifd=tags))
    assert img.focal_35mm == pytest.approx(4.5 * math.hypot(36, 24) / 8.0, rel=1e-6)


@pytest.mark.parametrize("focal", [None, 0.0, 1.0, 1e5, float("nan")])
def test_absent_or_absurd_focal_gives_no_fov(focal):
    img = LoadedImage(np.zeros((40, 60, 3), np.float32), None, None, (40, 60), 8, focal)
    assert fov_y_deg_from_exif(img) is None


def test_no_exif_means_no_focal(write_image, quadrants):
    assert load_image(write_image("plain.jpg", quadrants)).focal_35mm is None


# ---------------------------------------------------------------------------- resizing


def test_shrinking_weights_colour_by_alpha(write_image):
    rgba = np.zeros((40, 64, 4), np.uint8)
    rgba[..., 1] = 255  # transparent green on the left...
    rgba[:, 33:] = (255, 0, 0, 255)  # ...opaque red from column 33
    img = load_image(write_image("edge.png", rgba), max_size=32, min_size=16)
    assert img.rgb.shape == (20, 32, 3)
    np.testing.assert_allclose(img.alpha[:, 16], 0.5, atol=1e-6)  # covers source columns 32 and 33
    np.testing.assert_allclose(img.rgb[:, 16], [[1.0, 0.0, 0.0]] * 20, atol=1e-5)  # no green bleeding in


def test_resize_image_area_down_and_clipped_cubic_up():
    a = np.random.default_rng(0).random((40, 60, 3)).astype(np.float32)
    np.testing.assert_allclose(resize_image(a, (20, 30)), cv2.resize(a, (30, 20), interpolation=cv2.INTER_AREA))
    up = resize_image(a, (80, 120))
    assert up.shape == (80, 120, 3) and up.min() >= 0.0 and up.max() <= 1.0
    assert resize_image(a[..., :1], (20, 30)).shape == (20, 30, 1)
    assert resize_image(a[..., 0], (20, 30)).shape == (20, 30)
    with pytest.raises(InputError, match="size_hw"):
        resize_image(a, (0, 10))
    with pytest.raises(InputError):
        resize_image((a * 255).astype(np.uint8), (20, 30))


# ---------------------------------------------------------------------------- bad files


def _raises_naming(path, match, **kwargs):
    with pytest.raises(InputError, match=match) as info:
        load_image(path, **kwargs)
    assert path.name in str(info.value)


def test_missing_folder_and_empty_files(tmp_path, write_bytes):
    _raises_naming(tmp_path / "nope.jpg", "not found")
    (tmp_path / "folder.png").mkdir()
    _raises_naming(tmp_path / "folder.png", "folder")
    _raises_naming(write_bytes("empty.jpg", b""), "empty")


def test_not_an_image(write_bytes):
    _raises_naming(write_bytes("notes.jpg", b"these are not pixels\n" * 20), "not an image")
    _raises_naming(write_bytes("noise.png", bytes(_noise((500,)))), "not an image")


def test_corrupt_png_data(write_image, write_bytes):
    data = bytearray(write_image("whole.png", _noise((40, 50, 3))).read_bytes())
    start = data.index(b"IDAT") + 4
    data[start + 100 : start + 200] = bytes(100)  # structure intact, compressed pixels destroyed
    _raises_naming(write_bytes("broken.png", bytes(data)), "corrupt")


@pytest.mark.parametrize("load_truncated", [False, True])
def test_truncated_jpeg_and_png(write_image, write_bytes, monkeypatch, load_truncated):
    monkeypatch.setattr(ImageFile, "LOAD_TRUNCATED_IMAGES", load_truncated)  # must not matter
    photo = skimage.data.chelsea()
    for suffix in (".jpg", ".png"):
        data = write_image("whole" + suffix, photo).read_bytes()
        load_image(write_bytes("ok" + suffix, data))
        for name, cut in (("half", len(data) // 2), ("tail", len(data) - 2)):
            _raises_naming(write_bytes(name + suffix, data[:cut]), "truncated")


def test_too_small_and_too_elongated(write_image):
    _raises_naming(write_image("tiny.png", np.zeros((20, 40, 3), np.uint8)), "too small")
    _raises_naming(write_image("strip.png", np.zeros((32, 2000, 3), np.uint8)), "elongated", max_size=1024)
    assert load_image(write_image("tiny2.png", np.zeros((20, 40, 3), np.uint8)), min_size=16).size == (20, 40)


def test_decompression_bomb_checked_on_header(write_bytes, make_png_bytes):
    # 100000 x 100000 pixels claimed by a 60-byte file: refused before any decoding
    _raises_naming(write_bytes("bomb.png", make_png_bytes(100_000, 100_000)), "decompression bomb")
    _raises_naming(write_bytes("big.png", make_png_bytes(2000, 1000)), "max_pixels", max_pixels=1_000_000)


@pytest.mark.parametrize("pil_limit", [1500, 1000])  # warning zone (> limit), error zone (> 2 * limit)
def test_pillow_bomb_warning_and_error_become_input_errors(write_image, monkeypatch, pil_limit):
    path = write_image("pil.png", np.zeros((40, 50, 3), np.uint8))  # 2000 pixels
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", pil_limit)
    _raises_naming(path, "decompression bomb")


def test_unsupported_mode(tmp_path):
    cv2.imwrite(str(tmp_path / "float.tif"), np.random.default_rng(0).random((40, 50)).astype(np.float32))
    _raises_naming(tmp_path / "float.tif", "unsupported pixel mode")


def test_bad_settings():
    with pytest.raises(InputError, match="max_size"):
        load_image_array(np.zeros((40, 40, 3), np.uint8), max_size=10)


# ---------------------------------------------------------------------------- arrays


def test_load_image_array_dtypes_and_shapes():
    a = _noise((40, 50, 3), seed=9)
    before = a.copy()
    img8 = load_image_array(a)
    np.testing.assert_array_equal(a, before)  # input untouched
    np.testing.assert_array_equal(img8.rgb, a / np.float32(255))
    assert img8.bit_depth == 8 and img8.path is None
    a16 = _noise((40, 50), np.uint16, seed=10)
    img16 = load_image_array(a16)
    assert img16.bit_depth == 16 and img16.rgb.shape == (40, 50, 3)
    np.testing.assert_allclose(img16.rgb[..., 2], a16 / 65535.0, atol=1e-7)
    rgba = np.random.default_rng(1).random((40, 50, 4))
    imgf = load_image_array(rgba)
    np.testing.assert_allclose(imgf.alpha, rgba[..., 3], atol=1e-7)
    assert load_image_array(skimage.data.astronaut(), max_size=128).rgb.shape == (128, 128, 3)


@pytest.mark.parametrize(
    "array, match",
    [
        (np.full((40, 50, 3), np.nan), "NaN"),
        (np.full((40, 50, 3), 1.5), r"\[0, 1\]"),
        (np.zeros((40, 50, 3), bool), "dtype"),
        (np.zeros((40, 50, 2), np.uint8), "shape"),
        (np.zeros((10, 50, 3), np.uint8), "too small"),
    ],
)
def test_load_image_array_rejects(array, match):
    with pytest.raises(InputError, match=match) as info:
        load_image_array(array, name="my_photo")
    assert "my_photo" in str(info.value)


# ---------------------------------------------------------------------------- saving


def test_save_png_8_and_16_bit_round_trip(tmp_path):
    rgb = np.random.default_rng(2).random((40, 50, 3)).astype(np.float32)
    save_image(tmp_path / "a.png", rgb)
    np.testing.assert_allclose(load_image(tmp_path / "a.png").rgb, rgb, atol=0.5 / 255 + 1e-6)
    save_image(tmp_path / "b.png", rgb, bit_depth=16)
    back = load_image(tmp_path / "b.png")
    assert back.bit_depth == 16
    np.testing.assert_allclose(back.rgb, rgb, atol=0.5 / 65535 + 1e-6)


@pytest.mark.parametrize("suffix", [".jpg", ".jpeg", ".webp"])
def test_save_lossy_formats(tmp_path, suffix):
    photo = skimage.data.chelsea() / 255.0
    save_image(tmp_path / f"c{suffix}", photo)
    assert np.abs(load_image(tmp_path / f"c{suffix}", max_size=1000).rgb - photo).mean() < 0.03
    assert not list(tmp_path.glob(".*partial*"))  # no temporary file left


def test_save_clips_and_accepts_grey(tmp_path):
    rgb = np.full((40, 50, 3), 0.5, np.float32)
    rgb[0, 0] = (-1.0, 2.0, 0.5)
    save_image(tmp_path / "c.png", rgb)
    back = load_image(tmp_path / "c.png").rgb
    np.testing.assert_allclose(back[0, 0], [0.0, 1.0, 128 / 255], atol=1e-6)
    save_image(tmp_path / "g.png", np.full((40, 50), 0.25))
    np.testing.assert_allclose(load_image(tmp_path / "g.png").rgb, 64 / 255, atol=1e-6)


def test_save_refuses_bad_input_and_keeps_old_file(tmp_path):
    good = tmp_path / "keep.png"
    save_image(good, np.zeros((40, 50, 3)))
    before = good.read_bytes()
    bad = np.zeros((40, 50, 3))
    bad[3, 3, 0] = np.inf
    with pytest.raises(InputError, match="NaN or infinite"):
        save_image(good, bad)
    assert good.read_bytes() == before
    with pytest.raises(InputError, match="unsupported image format"):
        save_image(tmp_path / "a.bmp", np.zeros((40, 50, 3)))
    with pytest.raises(InputError, match="16-bit"):
        save_image(tmp_path / "a.jpg", np.zeros((40, 50, 3)), bit_depth=16)
    with pytest.raises(InputError, match="shape"):
        save_image(tmp_path / "a.png", np.zeros((40, 50, 2)))
    with pytest.raises(ExportError):
        save_image(tmp_path / "no_such_folder" / "a.png", np.zeros((40, 50, 3)))
