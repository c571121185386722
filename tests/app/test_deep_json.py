"""JSON nested far deeper than Python's parser can recurse, in every file a user hands over: a clear
error naming the file (exit 2 from the command line), never an internal error."""

import json

import pytest

from stylize3d_app.cli import main
from stylize3d_app.viewer.settings import load_settings
from stylize3d_core.errors import InputError
from stylize3d_core.io.images import save_image
from stylize3d_core.io.json_files import read_json_file
from stylize3d_core.io.keyframes import load_keyframes
from stylize3d_core.models.checkpoint import config_from_json
from stylize3d_core.multiview import load_views

LEVELS = 100_000


def _arrays(n=LEVELS):
    return "[" * n + "]" * n


def _objects(n=LEVELS):
    return '{"a":' * n + "1" + "}" * n


def _open3d_class(n=LEVELS):  # an Open3D trajectory whose parameters are nested deep
    return '{"class_name": "PinholeCameraTrajectory", "parameters": ' + _arrays(n) + "}"


@pytest.fixture(scope="module")
def photo(tmp_path_factory):
    import numpy as np

    path = tmp_path_factory.mktemp("in") / "photo.png"
    y, x = np.mgrid[0:48, 0:64]
    save_image(path, np.stack([x / 64, y / 48, 0.5 + 0 * x], -1))
    return path


@pytest.mark.parametrize("make", [_arrays, _objects, _open3d_class])
@pytest.mark.parametrize("flag", ["--camera-path", "--views"])
def test_the_command_line_exits_2_naming_the_file(photo, tmp_path, capsys, make, flag):
    bad = tmp_path / "deep.json"
    bad.write_text(make())
    out = tmp_path / "out.mp4"
    out.write_bytes(b"precious")
    rc = main(["render", str(photo), flag, str(bad), "--frames", "2", "--size", "32", "-o", str(out), "-q"])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert str(bad) in err and "nested" in err and "internal error" not in err
    assert out.read_bytes() == b"precious"


@pytest.mark.parametrize("make", [_arrays, _objects])
def test_library_readers_refuse_it(tmp_path, make):
    bad = tmp_path / "deep.json"
    bad.write_text(make())
    for read in (lambda p: read_json_file(p, "thing"), load_keyframes, load_views):
        with pytest.raises(InputError, match="nested 100000 levels deep") as e:
            read(bad)
        assert str(bad) in str(e.value)


def test_just_below_python_s_own_limit_is_still_a_clear_error(tmp_path):
    bad = tmp_path / "deep.json"
    bad.write_text(_arrays(900))  # the C parser would take it; the schema never needs it
    with pytest.raises(InputError, match="nested 900 levels deep"):
        read_json_file(bad, "camera path")


def test_a_shallow_file_reads(tmp_path):
    ok = tmp_path / "ok.json"
    ok.write_text(json.dumps({"a": [[1, 2], [3, {"b": 4}]]}))
    assert read_json_file(ok, "thing") == {"a": [[1, 2], [3, {"b": 4}]]}


def test_viewer_settings_nested_deep_start_from_the_defaults(tmp_path):
    bad = tmp_path / "viewer.json"
    bad.write_text(_objects())
    loaded = load_settings(bad)
    assert loaded.warning and str(bad) in loaded.warning and "nested too deeply" in loaded.warning
    assert loaded.settings == load_settings(tmp_path / "missing.json").settings


def test_a_checkpoint_configuration_nested_deep_is_unreadable(tmp_path):
    with pytest.raises(InputError, match="unreadable"):
        config_from_json(_objects(), tmp_path / "model.safetensors")
