"""Depth sources behind one interface, and the spec strings that name them."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from PIL import Image

from stylize3d_core.depth.refine import RefineSettings
from stylize3d_core.depth.sources import (
    AutoDepth,
    DepthSource,
    FileDepth,
    OnnxDepth,
    PhoneDepth,
    PriorDepth,
    RefinedDepth,
    StereoDepth,
    parse_depth_spec,
)
import stylize3d_core.depth.sources as sources_module
from stylize3d_core.depth.types import DepthMap, PhotoDepth
from stylize3d_core.errors import InputError
from stylize3d_core.io.images import load_image, load_image_array


class MeanPlusOne(torch.nn.Module):
    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return 1.0 + x.mean(dim=1, keepdim=True)


@pytest.fixture(scope="module")
def tiny_model(export_onnx):
    return export_onnx(MeanPlusOne(), torch.rand(1, 3, 32, 48), "tiny_depth.onnx")


def save_png(path, rgb: np.ndarray):
    Image.fromarray((np.clip(rgb, 0, 1) * 255 + 0.5).astype(np.uint8)).save(path)
    return path


def check_found(found: PhotoDepth, image) -> DepthMap:
    """A source's result for a photo that is not a stereo card: that photo, and its depth map."""
    assert isinstance(found, PhotoDepth) and found.rgb is image.rgb
    check_depth_map(found.depth_map, image.size)
    return found.depth_map


def check_depth_map(dm: DepthMap, shape):
    assert isinstance(dm, DepthMap)
    assert dm.shape == tuple(shape) and dm.depth.dtype == np.float32 and dm.valid.dtype == np.bool_
    assert np.isfinite(dm.depth).all() and (dm.depth > 0).all()
    assert dm.kind in ("metric", "relative") and dm.source


# --------------------------------------------------------------------------- parse_depth_spec


def test_simple_specs():
    assert isinstance(parse_depth_spec("auto"), AutoDepth)
    assert isinstance(parse_depth_spec(" prior "), PriorDepth)
    assert isinstance(parse_depth_spec("phone"), PhoneDepth)
    refined = parse_depth_spec("prior", refine=RefineSettings(method="guided"))
    assert isinstance(refined, RefinedDepth) and isinstance(refined.inner, PriorDepth)


def test_file_specs(tmp_path):
    path = tmp_path / "depth.npy"
    np.save(path, np.ones((6, 8), np.float32))
    src = parse_depth_spec(str(path))
    assert isinstance(src, FileDepth) and src.kind == "depth"
    src = parse_depth_spec(f"{path}:disparity")
    assert isinstance(src, FileDepth) and src.kind == "disparity" and src.path == str(path)
    assert parse_depth_spec(f"{path}:depth").kind == "depth"


def test_onnx_specs(tiny_model):
    src = parse_depth_spec(f"onnx:{tiny_model}")
    assert isinstance(src, OnnxDepth) and src.model.settings.preset.size == 384  # midas preset
    src = parse_depth_spec(f"onnx:{tiny_model}:depth_anything")
    assert src.model.settings.preset.multiple_of == 14


def test_stereo_specs(tmp_path):
    right = save_png(tmp_path / "right.png", np.zeros((40, 60, 3)))
    src = parse_depth_spec(f"stereo:{right}")
    assert isinstance(src, StereoDepth) and not src.side_by_side
    assert parse_depth_spec("stereo:sbs").side_by_side
    assert parse_depth_spec("stereo:sbs:cross").settings.cross_eyed


@pytest.mark.parametrize(
    "spec, message",
    [
        ("", "empty depth source"),
        ("lidar:scan.ply", "unknown depth source"),
        ("missing_depth.png", "depth file not found"),
        ("missing_depth.png:disparity", "depth file not found"),
        ("onnx:", "needs a model file"),
        ("onnx:missing.onnx", "no such ONNX model file"),
        ("stereo:", "needs the right image"),
        ("stereo:missing_right.png", "right stereo image not found"),
    ],
)
def test_bad_specs(spec, message):
    with pytest.raises(InputError, match=message):
        parse_depth_spec(spec)


def test_unknown_onnx_preset(tiny_model):
    with pytest.raises(InputError, match="onnx preset"):
        parse_depth_spec(f"onnx:{tiny_model}:leres")


def test_depth_source_is_abstract():
    with pytest.raises(TypeError):
        DepthSource()


# --------------------------------------------------------------------------- sources end to end


def test_file_source_wraps_load_depth_file(tmp_path, helpers):
    image = load_image_array(helpers.gradient_photo(48, 64))
    depth = (1.0 + np.arange(24 * 32, dtype=np.float32).reshape(24, 32) / 100.0)
    np.save(tmp_path / "d.npy", depth)
    dm = check_found(parse_depth_spec(str(tmp_path / "d.npy")).estimate(image), image)
    assert dm.shape == (48, 64)
    assert dm.kind == "metric" and "d.npy" in dm.source
    assert dm.depth.min() == pytest.approx(depth.min(), rel=0.02)
    assert dm.depth.max() == pytest.approx(depth.max(), rel=0.02)
    disp = parse_depth_spec(f"{tmp_path / 'd.npy'}:disparity").estimate(image).depth_map
    assert disp.kind == "relative"
    assert disp.depth.max() == pytest.approx(1.0 / depth.min(), rel=0.02)


def test_onnx_source(tiny_model, helpers):
    image = load_image_array(helpers.gradient_photo(48, 64))
    dm = check_found(OnnxDepth(tiny_model, "raw").estimate(image), image)
    assert dm.shape == (48, 64)


def test_prior_source(helpers):
    rgb = helpers.sample_photo("chelsea")
    image = load_image_array(rgb)
    dm = check_found(PriorDepth().estimate(image), image)
    assert dm.shape == rgb.shape[:2]
    assert dm.kind == "relative" and dm.valid.all() and dm.source == "prior"


def test_sources_take_a_loaded_image(helpers):
    with pytest.raises(TypeError, match="LoadedImage"):
        PriorDepth().estimate(helpers.gradient_photo(48, 64))


def test_stereo_pair_from_files(tmp_path, motorcycle):
    left, right, gt = motorcycle
    lp = save_png(tmp_path / "left.png", left)
    rp = save_png(tmp_path / "right.png", right)
    photo = load_image(lp, max_size=400)  # both views shrunk alike
    src = parse_depth_spec(f"stereo:{rp}")
    dm = check_found(src.estimate(photo), photo)
    assert dm.kind == "relative" and 0.5 < dm.valid.mean() < 1.0
    # The motorcycle's front wheel (lower right) is nearer than the back wall (top left).
    h, w = photo.size
    assert np.median(dm.depth[int(0.75 * h) :, int(0.7 * w) :]) < np.median(dm.depth[: int(0.2 * h), : int(0.2 * w)])


def test_stereo_pair_of_different_sizes(tmp_path, motorcycle):
    left, right, _ = motorcycle
    lp = save_png(tmp_path / "left.png", left)
    rp = save_png(tmp_path / "right_small.png", right[:, :600])
    photo = load_image(lp)
    with pytest.raises(InputError, match="same size") as err:
        StereoDepth(rp).estimate(photo)
    assert "right_small.png" in str(err.value)
    rp2 = save_png(tmp_path / "right_big.png", np.repeat(np.repeat(right, 2, 0), 2, 1))
    with pytest.raises(InputError, match="same size"):
        StereoDepth(rp2).estimate(photo)


def test_stereo_pair_sizes_compare_the_upright_files(tmp_path, motorcycle):
    # Shrunk to the same loaded size, views of different original sizes are still refused
    # (the left view's original size comes from the LoadedImage, not from reading the file again).
    left, right, _ = motorcycle
    lp = save_png(tmp_path / "left.png", left[:, :-2])  # 2 px narrower than the right view
    rp = save_png(tmp_path / "right.png", right)
    photo = load_image(lp, max_size=200)
    assert load_image(rp, max_size=200).size == photo.size  # the loaded sizes alone would not tell
    with pytest.raises(InputError, match="same size") as err:
        StereoDepth(rp).estimate(photo)
    assert "left.png" in str(err.value) and "right.png" in str(err.value)


def test_side_by_side_card(motorcycle, monkeypatch):
    left, right, _ = motorcycle
    card = load_image_array(np.concatenate([left, right], axis=1)[::2, ::2])  # (250, 741, 3)
    splits = []
    split = sources_module.split_side_by_side
    monkeypatch.setattr(sources_module, "split_side_by_side", lambda *a, **k: splits.append(1) or split(*a, **k))
    found = parse_depth_spec("stereo:sbs").estimate(card)
    assert found.rgb.shape == (250, 370, 3)
    np.testing.assert_array_equal(found.rgb, card.rgb[:, :370])  # the left view is the photo
    check_depth_map(found.depth_map, (250, 370))
    assert "side-by-side" in found.depth_map.source
    assert len(splits) == 1  # the card is split once, and its left view returned with the depth


def test_refined_side_by_side_card_aligns_with_the_left_view(motorcycle):
    left, right, _ = motorcycle
    card = load_image_array(np.concatenate([left, right], axis=1)[::2, ::2])
    found = parse_depth_spec("stereo:sbs", refine=RefineSettings(method="guided")).estimate(card)
    assert found.rgb.shape == (250, 370, 3) and found.depth_map.shape == (250, 370)
    assert found.depth_map.source.endswith("+ guided")


def test_side_by_side_card_that_is_not_one(tmp_path, helpers):
    path = save_png(tmp_path / "rocket.png", helpers.sample_photo("rocket"))
    with pytest.raises(InputError, match="side-by-side") as err:
        parse_depth_spec("stereo:sbs").estimate(load_image(path))
    assert "rocket.png" in str(err.value)


def test_phone_and_auto_sources(write_gdepth_jpeg, tmp_path, helpers):
    depth = np.tile(np.linspace(0.6, 3.0, 40), (30, 1))
    path = write_gdepth_jpeg(depth, near=0.5, far=5.0)
    photo = load_image(path)
    phone = check_found(PhoneDepth().estimate(photo), photo)
    assert phone.kind == "metric"
    auto = check_found(parse_depth_spec("auto").estimate(photo), photo)
    assert auto.source == phone.source and np.array_equal(auto.depth, phone.depth)
    plain = load_image(save_png(tmp_path / "plain.png", photo.rgb))
    assert parse_depth_spec("auto").estimate(plain).depth_map.source == "prior"
    in_memory = load_image_array(photo.rgb)
    assert parse_depth_spec("auto").estimate(in_memory).depth_map.source == "prior"
    with pytest.raises(InputError, match="no photo file"):
        PhoneDepth().estimate(in_memory)


def test_phone_depth_is_read_from_the_loaded_bytes(write_gdepth_jpeg):
    path = write_gdepth_jpeg(np.tile(np.linspace(0.6, 3.0, 40), (30, 1)), near=0.5, far=5.0)
    photo = load_image(path)
    expected = PhoneDepth().estimate(photo).depth_map.depth
    path.unlink()  # the sources do not go back to the file
    np.testing.assert_array_equal(PhoneDepth().estimate(photo).depth_map.depth, expected)
    np.testing.assert_array_equal(AutoDepth().estimate(photo).depth_map.depth, expected)


def test_auto_ignores_depth_namespace_without_depth(tmp_path, helpers):
    # A JPEG whose XMP declares GDepth parameters but holds no depth image (e.g. after editing).
    packet = (
        '<x:xmpmeta xmlns:x="adobe:ns:meta/"><rdf:RDF xmlns:rdf="http://www.w3.org/1999/02/22-rdf-syntax-ns#">'
        '<rdf:Description rdf:about="" xmlns:GDepth="http://ns.google.com/photos/1.0/depthmap/" '
        'GDepth:Format="RangeInverse" GDepth:Near="0.5" GDepth:Far="9"/></rdf:RDF></x:xmpmeta>'
    ).encode()
    rgb8 = (helpers.gradient_photo() * 255).astype(np.uint8)
    path = tmp_path / "edited.jpg"
    xmp = b"http://ns.adobe.com/xap/1.0/\x00" + packet
    path.write_bytes(helpers.insert_app1_segments(helpers.primary_jpeg(rgb8), [xmp]))
    photo = load_image(path)
    assert parse_depth_spec("auto").estimate(photo).depth_map.source == "prior"
    with pytest.raises(InputError, match="no embedded depth"):
        PhoneDepth().estimate(photo)


def test_auto_reports_corrupt_phone_depth(write_gdepth_jpeg):
    path = write_gdepth_jpeg(np.ones((30, 40)), data="***")
    photo = load_image(path)
    with pytest.raises(InputError, match="base64.*--depth prior") as err:
        AutoDepth().estimate(photo)
    assert str(path) in str(err.value)


def test_refined_source_aligns_edges(tmp_path, helpers):
    h, w = 40, 60
    rgb = np.zeros((h, w, 3), np.float32)
    rgb[:, 30:] = 1.0
    depth = np.where(np.arange(w) < 28, 1.0, 2.0).astype(np.float32)  # edge 2 px off the colour edge
    np.save(tmp_path / "d.npy", np.repeat(depth[None], h, axis=0))
    src = parse_depth_spec(str(tmp_path / "d.npy"), refine=RefineSettings(radius=5, iterations=2))
    image = load_image_array(rgb)
    dm = check_found(src.estimate(image), image)
    assert dm.shape == (h, w)
    assert dm.source.endswith("+ bilateral_median")
    assert (dm.depth[:, :30] == 1.0).all() and (dm.depth[:, 30:] == 2.0).all()


def test_sources_do_not_modify_the_photo(tiny_model, helpers):
    image = load_image_array(helpers.gradient_photo(48, 64))
    before = image.rgb.copy()
    for src in (PriorDepth(), OnnxDepth(tiny_model, "raw"), RefinedDepth(PriorDepth())):
        src.estimate(image)
    np.testing.assert_array_equal(image.rgb, before)
