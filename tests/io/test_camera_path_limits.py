"""Hostile camera-path files: deep nesting, numbers that do not fit a float, huge frame counts, huge files."""

import json

import pytest

import stylize3d_core.io.camera_path as cp
from stylize3d_core.errors import InputError
from stylize3d_core.io.camera_path import MAX_FRAMES, load_camera_path, load_open3d_trajectory
from stylize3d_core.io.json_files import MAX_JSON_DEPTH, read_json_file

EYE = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]


def _doc(n=1, fps=30):
    return {"format": "stylize3d-camera-path", "version": 1, "fps": fps, "image_size": None,
            "frames": [{"cam_to_world": EYE, "fov_y_deg": 60}] * n}


@pytest.fixture
def write(tmp_path):
    def w(text, name="path.json"):
        p = tmp_path / name
        p.write_text(text) if isinstance(text, str) else p.write_bytes(text)
        return p
    return w


def test_the_plain_document_loads(write):
    assert len(load_camera_path(write(json.dumps(_doc(3)))).cameras) == 3


@pytest.mark.parametrize("depth", [33, 1000, 100_000])
def test_deep_nesting_is_refused_without_recursion(write, depth):
    p = write("[" * depth + "]" * depth)
    with pytest.raises(InputError, match=f"nested {depth} levels deep") as e:
        load_camera_path(p)
    assert e.value.source == str(p)


def test_brackets_inside_strings_do_not_count(write):
    doc = _doc()
    doc["conventions"] = "[{" * 100 + '\\"' + "]}" * 3
    assert len(load_camera_path(write(json.dumps(doc))).cameras) == 1


def test_nesting_up_to_the_limit_is_parsed(write):
    text = "[" * MAX_JSON_DEPTH + "]" * MAX_JSON_DEPTH
    assert read_json_file(write(text), "thing") == eval(text)


@pytest.mark.parametrize("where, make", [
    ("pose", lambda d, big: d["frames"][0].__setitem__("cam_to_world", [[1, 0, 0, big]] + EYE[1:])),
    ("fov", lambda d, big: d["frames"][0].__setitem__("fov_y_deg", big)),
    ("fps", lambda d, big: d.__setitem__("fps", big)),
])
@pytest.mark.parametrize("big", [10 ** 400, -(10 ** 400)])
def test_integers_too_large_for_a_float_are_refused(write, where, make, big):
    doc = _doc()
    make(doc, big)
    with pytest.raises(InputError, match="does not fit a floating-point number"):
        load_camera_path(write(json.dumps(doc)))


@pytest.mark.parametrize("number", ["1e400", "-1e400", "1" + "0" * 330 + ".5"])
def test_floats_that_overflow_are_refused(write, number):
    text = json.dumps(_doc()).replace('"fov_y_deg": 60', f'"fov_y_deg": {number}')
    with pytest.raises(InputError, match="does not fit a floating-point number"):
        load_camera_path(write(text))


def test_a_huge_integer_given_to_the_checks_directly_is_an_input_error():
    with pytest.raises(InputError, match="fov_y_deg must be in"):
        cp._check_fov_value(10 ** 400, "frame 0", "x.json")
    with pytest.raises(InputError, match="fps must be a finite number"):
        cp._check_fps(10 ** 400, "x.json")


@pytest.mark.slow
def test_two_hundred_thousand_frames_are_refused_with_the_limit_and_the_length(write):
    p = write(json.dumps(_doc(200_000)))
    with pytest.raises(InputError) as e:
        load_camera_path(p)
    assert e.value.source == str(p)
    assert "200,000 frames (111.1 min at 30 fps), more than the limit of 10,000" in e.value.problem
    assert "max_frames" in e.value.problem


def test_the_frame_limit_can_be_raised_and_lowered(write):
    p = write(json.dumps(_doc(MAX_FRAMES + 1)))
    assert len(load_camera_path(p, max_frames=MAX_FRAMES + 1).cameras) == MAX_FRAMES + 1
    with pytest.raises(InputError, match="more than the limit of 2"):
        load_camera_path(write(json.dumps(_doc(3)), "b.json"), max_frames=2)


def test_an_oversized_file_is_refused_before_it_is_read(write):
    with pytest.raises(InputError, match="more than the 1,000 a camera path may have"):
        read_json_file(write(" " * 1001), "camera path", max_bytes=1000)


@pytest.mark.parametrize("data, words", [
    (b"\xff\xfe{}", "not UTF-8"),
    (b'{"format": NaN}', "non-finite number NaN"),
    (b"", "not a valid JSON"),
    (b"{" * 10, "nested 10 levels deep" if MAX_JSON_DEPTH < 10 else "not a valid JSON"),
])
def test_other_broken_files(write, data, words):
    with pytest.raises(InputError, match=words):
        load_camera_path(write(data))


def test_a_folder_is_an_input_error(tmp_path):
    with pytest.raises(InputError, match="cannot read the file"):
        load_camera_path(tmp_path)


def test_open3d_trajectory_is_bounded_before_open3d_parses_it(write):
    with pytest.raises(InputError, match="nested 100000 levels deep"):
        load_open3d_trajectory(write("[" * 100_000 + "]" * 100_000))
    big = {"class_name": "PinholeCameraTrajectory", "parameters": [{}] * 3}
    with pytest.raises(InputError, match="3 frames, more than the limit of 2"):
        load_open3d_trajectory(write(json.dumps(big), "o3d.json"), max_frames=2)
    with pytest.raises(InputError, match="does not fit a floating-point number"):
        load_open3d_trajectory(write('{"parameters": [1e999]}', "o3d2.json"))
