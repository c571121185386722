"""Foreground masks: files (size checks), GrabCut in a rectangle."""

import numpy as np
import pytest
from PIL import Image

from stylize3d_core.errors import InputError
from stylize3d_core.scene.masks import fit_mask, grabcut_mask, load_mask_file, parse_rect


def _save(path, array):
    Image.fromarray(array).save(path)
    return path


def test_mask_file_at_photo_and_file_size(tmp_path):
    m = np.zeros((40, 60), np.uint8)
    m[10:30, 20:40] = 255
    path = _save(tmp_path / "m.png", m)
    same = load_mask_file(path, (40, 60), (40, 60))
    assert same.dtype == bool and same.sum() == 400
    small = load_mask_file(path, (20, 30), (40, 60))  # the photo was shrunk by max_size
    assert small.shape == (20, 30) and small.sum() == 100
    rgba = np.zeros((40, 60, 4), np.uint8)
    rgba[5:15, 5:15, 3] = 255
    assert load_mask_file(_save(tmp_path / "a.png", rgba), (40, 60), (40, 60)).sum() == 100


def test_mask_size_mismatch_and_bad_files(tmp_path):
    path = _save(tmp_path / "m.png", np.full((41, 60), 255, np.uint8))
    with pytest.raises(InputError, match=r"m.png: the mask is 60x41 pixels but the photo is 60x40"):
        load_mask_file(path, (40, 60), (40, 60))
    with pytest.raises(InputError, match="120x80 \\(the photo file\\) or 60x40"):
        fit_mask(np.zeros((10, 10), bool), (40, 60), (80, 120), "m.png")
    empty = _save(tmp_path / "e.png", np.zeros((40, 60), np.uint8))
    with pytest.raises(InputError, match="no foreground"):
        load_mask_file(empty, (40, 60), (40, 60))
    with pytest.raises(InputError, match="no background"):
        load_mask_file(_save(tmp_path / "f.png", np.full((40, 60), 255, np.uint8)), (40, 60), (40, 60))
    with pytest.raises(InputError, match="not found"):
        load_mask_file(tmp_path / "missing.png", (40, 60), (40, 60))
    junk = tmp_path / "j.png"
    junk.write_bytes(b"not an image")
    with pytest.raises(InputError, match="cannot read"):
        load_mask_file(junk, (40, 60), (40, 60))


def test_grabcut_finds_an_object_in_its_rectangle():
    g = np.random.default_rng(0)
    rgb = np.empty((60, 80, 3), np.float32)
    rgb[:] = (0.1, 0.5, 0.2)
    rgb[20:45, 30:55] = (0.9, 0.2, 0.6)
    rgb = np.clip(rgb + 0.03 * g.standard_normal(rgb.shape), 0, 1).astype(np.float32)
    truth = np.zeros((60, 80), bool)
    truth[20:45, 30:55] = True
    mask = grabcut_mask(rgb, (25, 15, 36, 36))
    iou = (mask & truth).sum() / (mask | truth).sum()
    assert iou > 0.9
    half = grabcut_mask(rgb[::2, ::2], (25, 15, 36, 36), scale=0.5)  # rectangle in the file's pixels
    assert ((half & truth[::2, ::2]).sum() / (half | truth[::2, ::2]).sum()) > 0.85


def test_rectangle_errors():
    rgb = np.zeros((20, 20, 3), np.float32)
    with pytest.raises(InputError, match="outside"):
        grabcut_mask(rgb, (30, 30, 5, 5))
    with pytest.raises(InputError, match="whole photo"):
        grabcut_mask(rgb, (0, 0, 20, 20))
    with pytest.raises(InputError, match="X,Y,WIDTH,HEIGHT"):
        parse_rect("a,b,c,d")
    with pytest.raises(InputError, match="at least 2"):
        parse_rect("0,0,1,5")
    assert parse_rect(" 1, 2,30,40") == (1, 2, 30, 40)
