"""The fixed split of a folder of real photos and paintings."""

from __future__ import annotations

import numpy as np
import pytest

from stylize3d_core.errors import InputError
from stylize3d_core.io.images import save_image
from stylize3d_core.train.real_images import (
    HELD_OUT_SHARE, name_fraction, source_of, split_real_images,
)


def _folder(root, photos, paintings):
    img = np.full((4, 4, 3), 0.5, np.float32)
    for sub, names in (("photos", photos), ("paintings", paintings)):
        (root / sub).mkdir(parents=True)
        for n in names:
            save_image(root / sub / n, img)
    (root / "photos" / "notes.txt").write_text("not an image")
    return root


def test_split_is_disjoint_complete_and_stable(tmp_path):
    photos = [f"kodak_{i:02d}.png" for i in range(5)] + [f"cc0_{i:03d}.png" for i in range(60)]
    paintings = [f"wga_{i:03d}.png" for i in range(80)] + [f"wikiart_{i:02d}.png" for i in range(20)]
    s = split_real_images(_folder(tmp_path, photos, paintings))
    assert sorted(p.name for p in s.train_photos + s.eval_photos) == sorted(photos)
    assert not set(s.train_photos) & set(s.eval_photos)
    assert not set(s.train_paintings) & set(s.eval_paintings)
    assert all(p.name.startswith("kodak_") is False for p in s.train_photos)  # a whole source held out
    assert not any(p.name.startswith("wikiart_") for p in s.eval_paintings)  # training only
    held = [p for p in s.eval_paintings]
    assert 0.05 < len(held) / 80 < 0.4  # about HELD_OUT_SHARE of the others, by name hash
    assert s == split_real_images(tmp_path)
    assert all(name_fraction(p.name) < HELD_OUT_SHARE for p in held)


def test_name_helpers():
    assert source_of("wga2_0300.jpg") == "wga2" and source_of("plain.jpg") == "plain"
    assert 0.0 <= name_fraction("a.jpg") < 1.0 and name_fraction("a.jpg") == name_fraction("a.jpg")


def test_bad_folders(tmp_path):
    with pytest.raises(InputError, match="expected a folder"):
        split_real_images(tmp_path / "missing")
    _folder(tmp_path, [], ["wga_1.png"])
    with pytest.raises(InputError, match="no images"):
        split_real_images(tmp_path)


def test_sample_styles_are_on_neither_side(tmp_path):
    from stylize3d_core.resources import SAMPLE_STYLE_NAME, style_image

    root = _folder(tmp_path, ["cc0_1.png"], [f"wga_{i:03d}.png" for i in range(30)])
    shipped = style_image(SAMPLE_STYLE_NAME)
    (root / "paintings" / "wga_copy.jpg").write_bytes(shipped.read_bytes())  # a sample style under another name
    s = split_real_images(root)
    names = {p.name for p in s.train_paintings + s.eval_paintings}
    assert "wga_copy.jpg" not in names and len(names) == 30
    kept = split_real_images(root, exclude=[])
    assert "wga_copy.jpg" in {p.name for p in kept.train_paintings + kept.eval_paintings}
