"""The command line end to end, on small inputs (the full-size sample runs in the README command)."""

import imageio.v3 as iio
import numpy as np
import pytest
import torch

from stylize3d_app.cli import main
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


def test_relief_exaggerates_the_depth_and_keeps_the_photo_view(photo, tmp_path):
    """--relief k raises every depth to the power k before the scene is normalised: the nearest surface stays
    at NEAR_DEPTH, so log(z / NEAR_DEPTH) scales by k, and every photo pixel stays on its own ray."""
    from stylize3d_core.geometry.camera import NEAR_DEPTH
    from stylize3d_core.scene.pointcloud import ORIGINAL

    common = ["render", str(photo), "--frames", "2", "--size", "48", "--depth", "prior", "-q"]
    clouds = {}
    for k in ("1", "2", "0.5"):
        ply = tmp_path / f"relief{k}.ply"
        assert main(common + ["--relief", k, "-o", str(tmp_path / f"v{k}.mp4"), "--save-ply", str(ply)]) == 0
        cloud = read_ply(ply)
        clouds[k] = cloud.xyz[cloud.labels == ORIGINAL]  # one point per photo pixel, in pixel order
    base = clouds["1"]
    for k, cloud in (("2", clouds["2"]), ("0.5", clouds["0.5"])):
        assert cloud.shape == base.shape
        spread = np.log(np.median(base[:, 2]) / NEAR_DEPTH)
        assert spread > 0.1
        np.testing.assert_allclose(np.log(np.median(cloud[:, 2]) / NEAR_DEPTH), float(k) * spread, rtol=0.1)
        # Points move along their rays: the photo's own camera sees the same picture (but for the foreground's
        # anti-aliased silhouette points, which sit up to half a pixel inwards of their pixel's centre,
        # LDI.offset; the relief changes which edges are silhouettes)
        rays, base_rays = cloud[:, :2] / cloud[:, 2:], base[:, :2] / base[:, 2:]
        pixel = np.median(np.abs(np.diff(base_rays[:, 0]))[np.abs(np.diff(base_rays[:, 0])) > 1e-6])  # 1 / f
        off = np.abs(rays - base_rays).max(axis=1)
        assert (off > 1e-4).mean() < 0.01 and off.max() <= 1.0 * pixel + 1e-4
    assert main(common + ["--relief", "5", "-o", str(tmp_path / "bad.mp4")]) == 2
    assert not (tmp_path / "bad.mp4").exists()


@pytest.mark.parametrize("args, needle", [
    (["render", "{missing}"], "not found"),
    (["render", "{photo}", "--depth", "{missing}"], "missing.png"),
    (["render", "{photo}", "--size", "3"], "size"),
    (["render", "{photo}", "--frames", "0"], "frames: must be an integer from 1"),
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


@pytest.mark.parametrize("args, needle", [
    (["--fps", "1e-9"], "fps: must be a number from 1 to 240"),
    (["--fps", "1e9"], "fps: must be a number from 1 to 240"),
    (["--fps", "nan"], "fps: must be a finite number"),
    (["--fps", "inf"], "fps: must be a finite number"),
    (["--fps", "60", "-o", "{out}/v.gif"], "a GIF plays at most 50 fps"),
    (["--frames", "10001"], "10,001 frames are more than max_frames=10,000"),
    (["--frames", "30", "--max-frames", "20"], "raise max_frames (--max-frames)"),
    (["--max-frames", "0"], "max_frames: must be an integer from 1"),
    (["--size", "8"], "size: must be an integer from 16 to 4096"),
    (["--size", "100000"], "size: must be an integer from 16 to 4096"),
    (["--max-size", "4"], "max_size: must be an integer from 32 to 8192"),
    (["--strength", "1.5"], "strength: must be a number from 0 to 1"),
    (["--strength=-inf"], "strength: must be a finite number"),
    (["--fov", "0"], "fov: must be a number from 1 to 170"),
    (["--fov", "nan"], "fov: must be a finite number"),
    (["-o", "{out}/v.avi"], "unsupported video format '.avi'"),
    (["-o", "{out}/no/such/folder/v.mp4"], "does not exist"),
    (["--save-ply", "{out}/c.txt"], "must end in .ply"),
    (["--save-ply", "{out}/missing/c.ply"], "does not exist"),
    (["--save-camera-path", "{out}/c.txt"], "must end in .json"),
    (["--save-ply", "{folder}"], "is a folder"),
    (["--save-camera-path", "{out}/same.json", "--camera-path", "{out}/same.json"], "both an input and an output"),
    (["-o", "{photo}"], "unsupported video format '.png'"),
])
def test_every_option_is_checked_before_anything_is_written(photo, tmp_path, capsys, args, needle):
    """Bad numbers (out of range or not finite) and bad output paths: exit 2 naming the option or the file,
    and no output at all, not even the --save-ply / --save-camera-path written before the video."""
    out = tmp_path / "out"
    out.mkdir()
    folder = tmp_path / "folder.ply"
    folder.mkdir()
    fill = {"out": str(out), "photo": str(photo), "folder": str(folder)}
    argv = [a.format(**fill) for a in args]
    defaults = {"-o": str(out / "v.mp4"), "--save-ply": str(out / "c.ply"),
                "--save-camera-path": str(out / "c.json")}
    for flag, value in defaults.items():
        if flag not in argv:
            argv += [flag, value]
    before = sorted(p.name for p in photo.parent.iterdir())
    rc = main(["render", str(photo), "--frames", "2", "--size", "32", "-q"] + argv)
    assert rc == 2
    err = capsys.readouterr().err
    assert needle in err, err
    assert list(out.rglob("*")) == [] and list(folder.iterdir()) == []
    assert sorted(p.name for p in photo.parent.iterdir()) == before


def test_a_camera_path_too_fast_for_a_gif_is_refused_before_writing(photo, tmp_path, capsys):
    from stylize3d_core.geometry.trajectories import static
    from stylize3d_core.io.camera_path import save_camera_path

    cams = save_camera_path(tmp_path / "fast.json", static(3), fps=120)
    ply = tmp_path / "c.ply"
    rc = main(["render", str(photo), "--camera-path", str(cams), "-o", str(tmp_path / "v.gif"),
               "--save-ply", str(ply), "-q"])
    assert rc == 2 and "too fast for a GIF" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fast.json"]


def test_a_camera_path_longer_than_max_frames_is_refused_before_writing(photo, tmp_path, capsys):
    from stylize3d_core.geometry.trajectories import static
    from stylize3d_core.io.camera_path import save_camera_path

    cams = save_camera_path(tmp_path / "long.json", static(30), fps=30)
    rc = main(["render", str(photo), "--camera-path", str(cams), "--max-frames", "20", "-o", str(tmp_path / "v.mp4"),
               "--save-ply", str(tmp_path / "c.ply"), "-q"])
    err = capsys.readouterr().err
    assert rc == 2 and "30 frames" in err and "--max-frames" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["long.json"]
    rc = main(["render", str(photo), "--camera-path", str(cams), "--max-frames", "30", "--size", "32",
               "-o", str(tmp_path / "v.mp4"), "-q"])
    assert rc == 0 and (tmp_path / "v.mp4").is_file()


def test_render_options_are_the_job_fields():
    """The render command's options are derived from RenderJob and PhotoSpec: one per field, same defaults."""
    import dataclasses

    from stylize3d_app.cli import build_parser
    from stylize3d_core.pipeline import PhotoSpec, RenderJob

    args = build_parser().parse_args(["render", "p.jpg"])
    job = RenderJob()
    for f in dataclasses.fields(RenderJob):
        value = getattr(job, f.name)
        if f.name == "spec":
            continue
        if dataclasses.is_dataclass(value):  # a nested settings group (exports, layers): its fields, no prefix
            for g in dataclasses.fields(value):
                assert getattr(args, g.name) == getattr(value, g.name), f"{f.name}.{g.name}"
        else:
            assert getattr(args, f.name) == value, f.name
    for f in dataclasses.fields(PhotoSpec):
        if f.name not in ("photo", "ldi"):
            assert getattr(args, f.name) == getattr(job.spec, f.name), f.name
    assert args.photo == "p.jpg" and not hasattr(args, "ldi")


def test_train_loss_weight_overrides_are_checked(capsys):
    from stylize3d_app.cli import _loss_weights

    w = _loss_weights(["colour=0", "teacher=2.5"])
    assert w.colour == 0.0 and w.teacher == 2.5 and w.style == 0.1  # the others keep their defaults
    for bad, words in (("bogus=1", "NAME one of"), ("colour", "NAME=VALUE"), ("colour=x", "not a number"),
                       ("colour=-1", ">= 0"), ("colour=nan", ">= 0")):
        assert main(["train", "--stage", "2", "--weight", bad]) == 2
        assert words in capsys.readouterr().err


def test_train_style_stages_are_checked(capsys):
    from stylize3d_app.cli import _stages

    assert _stages("1,2,3") == (1, 2, 3)
    for bad, words in (("1,x", "comma-separated integers"), ("1,9", "style_stages"), ("2,2", "style_stages")):
        assert main(["train", "--stage", "2", "--style-stages", bad]) == 2
        assert words in capsys.readouterr().err
    assert main(["train", "--stage", "2", "--style-crop", "0.6", "0.5"]) == 2
    assert "style_crop" in capsys.readouterr().err


def test_the_train_command_line_is_derived_from_trainconfig():
    """Every TrainConfig field is an option with the config's own default (written once, in the field)."""
    import argparse
    import dataclasses

    from stylize3d_app.cli import build_parser
    from stylize3d_core.train.trainer import TrainConfig

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices["train"]
    args = sub.parse_args(["--stage", "1"])
    d = TrainConfig()
    for f in dataclasses.fields(TrainConfig):
        if f.name in ("stage", "weights", "style_stages", "style_crop"):
            continue
        assert getattr(args, f.name) == getattr(d, f.name), f.name
    args = sub.parse_args(["--stage", "2", "--data", "d", "--hours", "0.5", "--lr-schedule", "cosine", "--teacher", "t",
                           "--style-prior"])
    assert (args.data_dir, args.max_hours, args.lr_schedule, args.teacher_dir, args.style_prior) == \
        ("d", 0.5, "cosine", "t", True)
