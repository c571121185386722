"""`stylize3d render --export ... / --loop / --mask ...` end to end, with the bad inputs of each."""

import imageio.v3 as iio
import numpy as np
import pytest
from PIL import Image

from stylize3d_app.cli import main
from stylize3d_core.export.camera_paths import camera_path_format
from stylize3d_core.export.splat import read_splat_ply
from stylize3d_core.io.images import save_image
from stylize3d_core.io.ply import read_ply


@pytest.fixture(scope="module")
def photo(tmp_path_factory):
    import skimage.data

    path = tmp_path_factory.mktemp("in") / "photo.png"
    save_image(path, skimage.data.chelsea()[::6, ::6] / 255.0)  # 50 x 76
    return path


@pytest.fixture(scope="module")
def style(tmp_path_factory):
    path = tmp_path_factory.mktemp("style") / "style.png"
    save_image(path, np.random.default_rng(0).random((48, 48, 3)))
    return path


def test_stereo_videos_and_loops(photo, tmp_path):
    base = ["render", str(photo), "--frames", "3", "--size", "48", "-q"]
    assert main(base + ["--export", "sbs", "-o", str(tmp_path / "full.mp4")]) == 0
    assert iio.imread(tmp_path / "full.mp4").shape == (3, 32, 96, 3)
    assert main(base + ["--export", "sbs", "--stereo-layout", "half", "-o", str(tmp_path / "half.mp4")]) == 0
    assert iio.imread(tmp_path / "half.mp4").shape == (3, 32, 48, 3)
    assert main(base + ["--export", "anaglyph", "--loop", "--fps", "10", "-o", str(tmp_path / "a.gif")]) == 0
    gif = iio.imread(tmp_path / "a.gif")
    assert gif.shape[0] == 4 and np.array_equal(gif[1], gif[3])  # forward 0 1 2, back 1
    assert main(base + ["--loop", "-o", str(tmp_path / "l.webp")]) == 0
    with Image.open(tmp_path / "l.webp") as im:
        assert im.n_frames == 4


def test_point_exports_with_baked_style(photo, style, untrained, tmp_path):
    styled = ["--style", str(style), "--model", str(untrained), "--max-size", "64", "-q"]
    assert main(["render", str(photo), "--export", "ply", "-o", str(tmp_path / "s.ply"), *styled]) == 0
    assert main(["render", str(photo), "--export", "ply", "-o", str(tmp_path / "p.ply"), "--max-size", "64",
                 "-q"]) == 0
    baked, plain = read_ply(tmp_path / "s.ply"), read_ply(tmp_path / "p.ply")
    assert np.array_equal(baked.xyz, plain.xyz)
    assert np.abs(baked.rgb.astype(int) - plain.rgb.astype(int)).mean() > 5  # the model's colours, not the photo's
    assert main(["render", str(photo), "--export", "splat", "--splat-scale", "0.8", "-o", str(tmp_path / "g.ply"),
                 *styled]) == 0
    splat = read_splat_ply(tmp_path / "g.ply")
    assert np.array_equal(splat.xyz, plain.xyz)
    assert np.abs(splat.rgb * 255 - baked.rgb).max() < 1.01  # the same baked colours


def test_open3d_trajectory_out_and_in(photo, tmp_path):
    traj = tmp_path / "traj.json"
    assert main(["render", str(photo), "--frames", "4", "--size", "32", "--trajectory", "swing",
                 "--save-trajectory", str(traj), "-o", str(tmp_path / "a.mp4"), "-q"]) == 0
    assert camera_path_format(traj) == "open3d"
    assert main(["render", str(photo), "--camera-path", str(traj), "--size", "32", "-o", str(tmp_path / "b.mp4"),
                 "-q"]) == 0
    a, b = iio.imread(tmp_path / "a.mp4"), iio.imread(tmp_path / "b.mp4")
    assert a.shape == b.shape and np.abs(a.astype(int) - b.astype(int)).mean() < 1.0


def test_layered_render_keeps_the_foreground(style, untrained, tmp_path):
    g = np.random.default_rng(0)
    yy, xx = np.mgrid[:64, :96]
    disc = (yy - 32) ** 2 + (xx - 48) ** 2 < 18 ** 2
    rgb = 0.3 + 0.2 * g.random((64, 96, 3))  # a grey, textured background
    rgb[disc] = (0.9, 0.2, 0.1)
    photo = tmp_path / "disc.png"
    save_image(photo, rgb)
    out = tmp_path / "frames"
    assert main(["render", str(photo), "--style", str(style), "--model", str(untrained), "--mask-rect", "26,10,44,44",
                 "--trajectory", "static", "--frames", "1", "--size", "96", "-o", str(out) + "/", "-q"]) == 0
    frame = iio.imread(out / "frame_0000.png").astype(float)
    src = iio.imread(photo).astype(float)
    assert frame.shape == src.shape
    inner = (yy - 32) ** 2 + (xx - 48) ** 2 < 14 ** 2
    assert np.abs(frame[inner] - src[inner]).mean() < 3  # the disc keeps its colours
    outside = (yy - 32) ** 2 + (xx - 48) ** 2 > 24 ** 2
    assert np.abs(frame[outside] - src[outside]).mean() > 10  # the background is stylized


def test_mask_file_at_the_photo_files_size(style, untrained, tmp_path):
    yy, xx = np.mgrid[:128, :192]
    disc = (yy - 64) ** 2 + (xx - 96) ** 2 < 36 ** 2
    rgb = 0.3 + 0.2 * np.random.default_rng(1).random((128, 192, 3))
    rgb[disc] = (0.1, 0.3, 0.9)
    photo, mask = tmp_path / "disc.png", tmp_path / "mask.png"
    save_image(photo, rgb)
    Image.fromarray((disc * 255).astype(np.uint8)).save(mask)
    out = tmp_path / "frames"
    assert main(["render", str(photo), "--style", str(style), "--model", str(untrained), "--mask", str(mask),
                 "--max-size", "96", "--trajectory", "static", "--frames", "1", "--size", "96", "-o", str(out) + "/",
                 "-q"]) == 0  # the photo is shrunk to 96 x 64: so is the mask
    frame = iio.imread(out / "frame_0000.png").astype(float)
    inner = ((yy - 64) ** 2 + (xx - 96) ** 2 < 28 ** 2)[::2, ::2]
    assert np.abs(frame[inner] - np.array([0.1, 0.3, 0.9]) * 255).mean() < 4


@pytest.mark.parametrize("extra, message", [
    (["--export", "anaglyph", "--eye-distance", "0.6"], "eye_distance: 0.6 would put an eye"),
    (["--export", "ply"], "must end in .ply"),
    (["--export", "ply", "--loop", "-o", "x.ply"], "loop: a loop is a video"),
    (["-o", "/no/such/folder/v.mp4"], "does not exist"),
    (["--mask-rect", "1,1,10,10"], "needs a style"),
    (["-o", "v.avi"], "unsupported video format"),
])
def test_bad_inputs_exit_2(photo, tmp_path, capsys, monkeypatch, extra, message):
    monkeypatch.chdir(tmp_path)
    rc = main(["render", str(photo), "--frames", "2", "--size", "32", *extra])
    assert rc == 2 and message in capsys.readouterr().err


def test_mask_of_the_wrong_size_exits_2(photo, style, untrained, tmp_path, capsys):
    mask = tmp_path / "mask.png"
    Image.fromarray(np.full((10, 10), 255, np.uint8)).save(mask)
    rc = main(["render", str(photo), "--style", str(style), "--model", str(untrained), "--mask", str(mask),
               "--frames", "1", "--size", "32", "-o", str(tmp_path / "o.mp4")])
    err = capsys.readouterr().err
    assert rc == 2 and "mask.png: the mask is 10x10 pixels but the photo is 76x50" in err
    assert not (tmp_path / "o.mp4").exists()
