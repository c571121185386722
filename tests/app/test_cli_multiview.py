"""`stylize3d render PHOTO --views views.json`: several photos, depth files and poses, one 3D photo."""

import json

import imageio.v3 as iio
import numpy as np
import pytest

from stylize3d_app.cli import main
from stylize3d_core.eval.multiview import procedural_views
from stylize3d_core.multiview import load_views, save_views


@pytest.fixture(scope="module")
def sample(tmp_path_factory):
    folder = tmp_path_factory.mktemp("views")
    data = procedural_views(3)
    return save_views(folder, data.views), save_views(folder, data.views, trajectory=True), data


def test_views_file_round_trip(sample):
    path, _, data = sample
    views = load_views(path)
    assert len(views) == 3
    for a, b in zip(views, data.views):
        assert np.allclose(a.cam_to_world, b.cam_to_world) and a.fov_y_deg == pytest.approx(b.fov_y_deg)
        assert np.allclose(a.depth.depth, b.depth.depth) and np.abs(a.rgb - b.rgb).max() < 1 / 255 + 1e-6


def test_render_from_views(sample, tmp_path):
    views = sample[0]
    out = tmp_path / "mv.mp4"
    assert main(["render", str(views.parent / "view0.png"), "--views", str(views), "--frames", "3", "--size", "64",
                 "-o", str(out), "-q"]) == 0
    assert iio.imread(out).shape == (3, 48, 64, 3)


def test_render_from_views_with_an_open3d_trajectory(sample, tmp_path):
    from stylize3d_core.io.ply import read_ply

    out = tmp_path / "m.ply"
    assert main(["render", str(sample[1].parent / "view1.png"), "--views", str(sample[1]), "--export", "ply",
                 "-o", str(out), "-q"]) == 0
    assert len(read_ply(out).xyz) > 96 * 128  # more than one view's points


def _edit(views, tmp_path, change):
    doc = json.loads(views.read_text())
    change(doc)
    bad = views.parent / f"bad_{tmp_path.name}.json"
    bad.write_text(json.dumps(doc))
    return bad


@pytest.mark.parametrize("change, message", [
    (lambda d: d["views"].pop(), "has 3 poses but there are 2 images"),
    (lambda d: d["views"][1].update(depth="view1.png"), "expected a single-channel (grey) depth"),
    (lambda d: d.update(format="x"), "not a stylize3d views file"),
])
def test_trajectory_views_bad_input(sample, tmp_path, capsys, change, message):
    bad = _edit(sample[1], tmp_path, change)
    rc = main(["render", str(sample[1].parent / "view0.png"), "--views", str(bad), "-o", str(tmp_path / "o.mp4")])
    assert rc == 2 and message in capsys.readouterr().err


@pytest.mark.parametrize("change, message", [
    (lambda d: d["views"][1].update(intrinsics={"width": 64, "height": 48, "fx": 50, "fy": 50, "cx": 32, "cy": 24}),
     "intrinsics are for a 64x48 image but the image is 128x96; the poses do not match the images"),
    (lambda d: d["views"][1].update(cam_to_world=d["views"][2]["cam_to_world"]), "its pose does not match"),
    (lambda d: d["views"][1].update(depth="view1_depth.npy:disparity"), "gives relative depth"),
    (lambda d: d["views"][1].pop("cam_to_world"), "needs \"cam_to_world\""),
])
def test_views_bad_input(sample, tmp_path, capsys, change, message):
    bad = _edit(sample[0], tmp_path, change)
    rc = main(["render", str(sample[0].parent / "view0.png"), "--views", str(bad), "-o", str(tmp_path / "o.mp4")])
    assert rc == 2 and message in capsys.readouterr().err
    assert not (tmp_path / "o.mp4").exists()


def test_photo_must_be_a_view(sample, tmp_path, capsys):
    from stylize3d_core.io.images import save_image

    other = tmp_path / "other.png"
    save_image(other, np.zeros((40, 40, 3)))
    assert main(["render", str(other), "--views", str(sample[0]), "-o", str(tmp_path / "o.mp4")]) == 2
    assert "is not one of the images" in capsys.readouterr().err
