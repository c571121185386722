"""The command line end to end, on small inputs (the full-size sample runs in the README command)."""

import imageio.v3 as iio
import numpy as np
import pytest
import torch

from app.cli import main
from stylize3d_core.io.camera_path import load_camera_path
from stylize3d_core.io.images import save_image
from stylize3d_core.io.ply import read_ply
from stylize3d_core.models.checkpoint import save_checkpoint
from stylize3d_core.models.stylize3d import ModelConfig, Stylize3DModel


@pytest.fixture(scope="module")
def photo(tmp_path_factory):
    import skimage.data

    path = tmp_path_factory.mktemp("in") / "photo.png"
    save_image(path, skimage.data.chelsea()[::4, ::4] / 255.0)  # 75 x 113
    return path


def test_render_writes_video_ply_and_camera_path(photo, tmp_path, capsys):
    out, ply, cams = tmp_path / "v.mp4", tmp_path / "c.ply", tmp_path / "cams.json"
    rc = main(["render", str(photo), "--frames", "6", "--size", "64", "-o", str(out), "--save-ply", str(ply),
               "--save-camera-path", str(cams), "--trajectory", "swing", "-q"])
    assert rc == 0
    video = iio.imread(out)
    assert video.shape == (6, 42, 64, 3)
    assert video[0].std() > 5  # a real picture, not a flat frame
    assert not np.array_equal(video[0], video[2])  # the camera moves
    cloud = read_ply(ply)
    assert cloud.xyz.shape[0] > 75 * 113 and cloud.labels is not None
    assert len(load_camera_path(cams).cameras) == 6


def test_render_follows_a_camera_path_and_writes_png_frames(photo, tmp_path):
    cams = tmp_path / "cams.json"
    assert main(["render", str(photo), "--frames", "3", "--size", "32", "-o", str(tmp_path / "a.gif"),
                 "--save-camera-path", str(cams), "-q"]) == 0
    frames = tmp_path / "frames"
    assert main(["render", str(photo), "--camera-path", str(cams), "--size", "32", "-o", str(frames) + "/", "-q"]) == 0
    assert sorted(p.name for p in frames.iterdir()) == ["frame_0000.png", "frame_0001.png", "frame_0002.png"]


def test_stylized_render(photo, tmp_path):
    torch.manual_seed(0)
    model = save_checkpoint(tmp_path / "m.safetensors", Stylize3DModel(ModelConfig.lite()), 2, {})
    style = tmp_path / "style.png"
    save_image(style, np.random.default_rng(0).random((64, 64, 3)))
    out = tmp_path / "s.mp4"
    assert main(["render", str(photo), "--style", str(style), "--model", str(model), "--frames", "2",
                 "--size", "48", "-o", str(out), "-q"]) == 0
    assert iio.imread(out).shape[0] == 2


def test_refine_depth_changes_the_geometry(photo, tmp_path, capsys):
    plain, refined = tmp_path / "plain.ply", tmp_path / "refined.ply"
    common = ["render", str(photo), "--frames", "2", "--size", "48", "-q"]
    assert main(common + ["-o", str(tmp_path / "a.mp4"), "--save-ply", str(plain)]) == 0
    assert main(common + ["-o", str(tmp_path / "b.mp4"), "--save-ply", str(refined),
                          "--refine-depth", "bilateral_median"]) == 0
    a, b = read_ply(plain), read_ply(refined)
    assert a.xyz.shape[1] == b.xyz.shape[1] == 3
    assert a.xyz.shape != b.xyz.shape or not np.allclose(a.xyz, b.xyz)
    with pytest.raises(SystemExit) as e:  # argparse's own usage error
        main(common + ["--refine-depth", "median"])
    assert e.value.code == 2 and "median" in capsys.readouterr().err


@pytest.mark.parametrize("args, needle", [
    (["render", "{missing}"], "not found"),
    (["render", "{photo}", "--depth", "{missing}"], "missing.png"),
    (["render", "{photo}", "--size", "3"], "size"),
    (["render", "{photo}", "--frames", "0"], "n_frames"),
    (["render", "{photo}", "-o", "{tmp}/x.avi"], ".avi"),
    (["render", "{photo}", "--style", "{missing}"], "missing.png"),
    (["render", "{photo}", "--camera-path", "{photo}"], "photo.png"),
])
def test_bad_input_exits_2_and_names_the_problem(photo, tmp_path, capsys, args, needle):
    fill = {"missing": str(tmp_path / "missing.png"), "photo": str(photo), "tmp": str(tmp_path)}
    rc = main([a.format(**fill) for a in args] + ["-q"])
    assert rc == 2
    assert needle in capsys.readouterr().err


def test_failed_export_keeps_the_old_file(photo, tmp_path):
    out = tmp_path / "keep.mp4"
    out.write_bytes(b"precious")
    rc = main(["render", str(photo), "--depth", str(tmp_path / "missing.npy"), "-o", str(out), "-q"])
    assert rc == 2 and out.read_bytes() == b"precious"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.mp4"]
