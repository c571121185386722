"""The style bank (``train/styles.py``) and the procedural textures (``train/textures.py``)."""

import json

import numpy as np
import pytest
import torch

from stylize3d_core.errors import InputError
from stylize3d_core.io.images import load_image, save_image
from stylize3d_core.train.styles import (
    HELD_OUT_PAINTING_STYLES, NUM_PAINTING_STYLES, StyleBank, StyleBankConfig, build_style_bank, make_painting,
)
from stylize3d_core.train.textures import TEXTURE_KINDS, colour_map, hsv_to_rgb, make_texture, random_texture

CONFIG = StyleBankConfig(size=48, painting_fraction=0.5, photos=("coffee",), work_size=128)


@pytest.fixture(scope="module")
def bank_dir(tmp_path_factory):
    root = tmp_path_factory.mktemp("styles")
    entries = build_style_bank(root, 6, seed=1, config=CONFIG)
    return root, entries


# ----------------------------------------------------------------------------- textures


@pytest.mark.parametrize("kind", TEXTURE_KINDS)
def test_every_texture_kind(kind):
    a = make_texture(kind, np.random.default_rng(3), (33, 47))
    assert a.shape == (33, 47, 3) and a.dtype == np.float32
    assert np.isfinite(a).all() and a.min() >= 0.0 and a.max() <= 1.0
    np.testing.assert_array_equal(a, make_texture(kind, np.random.default_rng(3), (33, 47)))
    if kind == "constant":
        assert float(np.ptp(a, axis=(0, 1)).max()) == 0.0  # one colour exactly
    elif kind != "gradient":
        assert float(a.std()) > 0.01  # has structure


def test_texture_helpers_known_values():
    np.testing.assert_allclose(hsv_to_rgb(np.array([[0.0, 1.0, 1.0], [1 / 3, 1.0, 1.0], [0.0, 0.0, 0.5]])),
                               [[1, 0, 0], [0, 1, 0], [0.5, 0.5, 0.5]], atol=1e-6)
    pal = np.array([[0, 0, 0], [1, 1, 1]], np.float32)
    np.testing.assert_allclose(colour_map(np.array([[0.0, 0.25, 1.0]]), pal)[0, :, 0], [0.0, 0.25, 1.0], atol=1e-6)
    with pytest.raises(InputError, match="kind"):
        make_texture("marble", np.random.default_rng(0), (8, 8))
    with pytest.raises(InputError, match="size"):
        make_texture("noise", np.random.default_rng(0), (0, 8))
    kind, img = random_texture(np.random.default_rng(0), (8, 8), kinds=("checker",))
    assert kind == "checker" and img.shape == (8, 8, 3)


# ----------------------------------------------------------------------------- paintings


def test_make_painting():
    rng = np.random.default_rng(0)
    photo = np.clip(np.linspace(0, 1, 64)[None, :, None] + 0.1 * rng.random((48, 64, 3)), 0, 1).astype(np.float32)
    out = make_painting(photo, 3, (24, 32), work_size=128)
    assert out.shape == (24, 32, 3) and out.dtype == np.float32 and 0 <= out.min() and out.max() <= 1
    assert np.abs(out - photo[::2, ::2]).mean() > 0.05  # it is painted, not copied
    np.testing.assert_array_equal(out, make_painting(photo, 3, (24, 32), work_size=128))
    with pytest.raises(InputError, match="style_index"):
        make_painting(photo, 26, (24, 32))


# ----------------------------------------------------------------------------- bank


def test_build_style_bank_writes_pngs_in_range_with_a_constant_style(bank_dir):
    root, entries = bank_dir
    assert [e.kind for e in entries] == ["painting"] * 3 + ["texture"] * 3
    assert "style 0" in entries[0].how and "style 2" in entries[2].how
    manifest = json.loads((root / "styles.json").read_text())
    assert [s["file"] for s in manifest["styles"]] == [e.file for e in entries]
    constant = 0
    for e in entries:
        assert e.file.endswith(".png")
        rgb = load_image(root / e.file).rgb
        assert rgb.shape == (48, 48, 3) and 0.0 <= rgb.min() and rgb.max() <= 1.0
        constant += float(np.ptp(rgb, axis=(0, 1)).max()) == 0.0
    assert constant == 1 and "constant" in entries[3].file


def test_default_bank_never_uses_the_held_out_network_styles(tmp_path):
    styles = StyleBankConfig().painting_styles
    assert set(styles).isdisjoint(HELD_OUT_PAINTING_STYLES) and HELD_OUT_PAINTING_STYLES
    assert len(styles) + len(HELD_OUT_PAINTING_STYLES) == NUM_PAINTING_STYLES
    config = StyleBankConfig(size=32, painting_fraction=0.75, photos=("coffee",), work_size=64,
                             painting_styles=(4, 9))
    entries = build_style_bank(tmp_path, 4, seed=0, config=config)
    assert ["style 4" in entries[0].how, "style 9" in entries[1].how, "style 4" in entries[2].how] == [True] * 3
    for bad in ((), (26,), (True,)):
        with pytest.raises(InputError, match="painting_styles"):
            StyleBankConfig(painting_styles=bad)


def test_style_bank_is_reproducible(bank_dir, tmp_path):
    root, entries = bank_dir
    again = build_style_bank(tmp_path, 6, seed=1, config=CONFIG)
    assert again == entries
    for e in entries:
        np.testing.assert_array_equal(load_image(root / e.file).rgb, load_image(tmp_path / e.file).rgb)


def test_style_bank_loads_and_crops(bank_dir):
    root, entries = bank_dir
    bank = StyleBank(root)
    assert len(bank) == 6 and sorted(e.file for e in entries) == [bank.name(i) for i in range(6)]
    x = bank[0]
    assert x.shape == (3, 48, 48) and x.dtype == torch.float32 and 0 <= x.min() and x.max() <= 1
    c = bank.crop(1, np.random.default_rng(0), 32)
    assert c.shape == (3, 32, 32) and 0 <= c.min() and c.max() <= 1
    assert torch.equal(c, bank.crop(1, np.random.default_rng(0), 32))
    s, i = bank.sample(np.random.default_rng(5), 20)
    assert s.shape == (3, 20, 20) and 0 <= i < 6
    k = bank.files.index(root / entries[3].file)  # the constant style
    for img, tol in ((bank[k], 0.0), (bank.crop(k, np.random.default_rng(1), 16), 1e-6)):  # resizing rounds
        assert float((img.amax(dim=(1, 2)) - img.amin(dim=(1, 2))).max()) <= tol
    with pytest.raises(IndexError):
        bank[6]


def test_style_crops_cover_the_asked_share_of_the_style(tmp_path):
    """A horizontal ramp 0..255 over 200 pixels: a crop whose side is a quarter of the short side spans a
    quarter of the ramp (the strokes magnified 4x once resized), the whole-image crop all of it."""
    ramp = np.repeat(np.linspace(0, 255, 200)[None, :, None], 200, axis=0).repeat(3, axis=2).astype(np.uint8)
    save_image(tmp_path / "ramp.png", ramp)
    bank = StyleBank(tmp_path)
    rng = np.random.default_rng(0)
    for lo, hi in ((0.25, 0.25), (1.0, 1.0), (0.3, 0.6)):
        for _ in range(4):
            crop = bank.crop(0, rng, 40, min_scale=lo, max_scale=hi, flip=0.0)[0]
            span = float(crop[0, -1] - crop[0, 0])  # the ramp's share the crop covers (its ends resampled)
            assert lo - 0.03 <= span <= hi + 0.01, (lo, hi, span)
    assert bank.sample(rng, 16, 0.25, 0.25)[0].shape == (3, 16, 16)
    with pytest.raises(InputError, match="max_scale"):
        bank.crop(0, rng, 16, min_scale=0.5, max_scale=0.4)


def test_style_bank_errors(tmp_path):
    with pytest.raises(InputError, match="not found"):
        StyleBank(tmp_path / "missing")
    with pytest.raises(InputError, match="no style images"):
        StyleBank(tmp_path)
    (tmp_path / "broken.png").write_bytes(b"\x89PNG\r\n\x1a\n garbage")
    with pytest.raises(InputError, match="broken.png"):
        StyleBank(tmp_path)
    with pytest.raises(InputError, match="n"):
        build_style_bank(tmp_path, 0)
    with pytest.raises(InputError, match="texture_kinds"):
        StyleBankConfig(texture_kinds=("marble",))
