import os

import imageio.v2 as iio
import numpy as np
import pytest
from PIL import Image

from stylize3d_core.errors import ExportError, InputError
from stylize3d_core.io.video import (
    ExportCancelled,
    console_progress,
    to_uint8_frame,
    video_kind,
    write_video,
)

OLD = b"an earlier, good export"


def colour_frames(n: int, h: int = 48, w: int = 64):
    """Distinct solid-colour frames (uint8) with a bright square that moves."""
    out = []
    for i in range(n):
        f = np.empty((h, w, 3), np.uint8)
        f[:] = (20 + 10 * i, 200 - 10 * i, 90)
        f[4:12, 4 + 2 * i: 12 + 2 * i] = 255
        out.append(f)
    return out


def read_mp4(path):
    reader = iio.get_reader(str(path), format="FFMPEG")
    try:
        frames = [f for f in reader]
        meta = reader.get_meta_data()
    finally:
        reader.close()
    return frames, meta


def test_mp4_written_and_read_back(tmp_path):
    dest = tmp_path / "out.mp4"
    frames = colour_frames(12)
    calls = []
    assert write_video(dest, frames, fps=30, progress=lambda d, n: calls.append((d, n))) == dest
    assert calls == [(i, 12) for i in range(1, 13)]
    back, meta = read_mp4(dest)
    assert len(back) == 12 and back[0].shape == (48, 64, 3)
    assert meta["fps"] == pytest.approx(30.0)
    for a, b in zip(frames, back):
        np.testing.assert_allclose(b[20:].reshape(-1, 3).mean(0), a[20:].reshape(-1, 3).mean(0), atol=3.0)
    assert os.listdir(tmp_path) == ["out.mp4"]


def test_mp4_odd_size_pads_one_pixel_and_float_frames(tmp_path):
    dest = tmp_path / "odd.mp4"
    frames = (np.full((33, 47, 3), v, np.float32) for v in (0.2, 0.5, 0.8))
    write_video(dest, frames, n_frames=3)
    back, _ = read_mp4(dest)
    assert len(back) == 3 and back[0].shape == (34, 48, 3)
    for v, b in zip((0.2, 0.5, 0.8), back):
        np.testing.assert_allclose(b.mean(), v * 255, atol=3.0)


def test_gif_loops_forever_at_the_requested_fps(tmp_path):
    dest = tmp_path / "out.gif"
    write_video(dest, colour_frames(4), fps=20)
    with Image.open(dest) as im:
        assert im.n_frames == 4 and im.info["loop"] == 0
        durations = []
        for i in range(im.n_frames):
            im.seek(i)
            durations.append(im.info["duration"])
            np.testing.assert_allclose(
                np.asarray(im.convert("RGB"))[20:].reshape(-1, 3).mean(0),
                colour_frames(4)[i][20:].reshape(-1, 3).mean(0), atol=4.0)
    assert durations == [50] * 4
    with pytest.raises(InputError, match="fps"):
        write_video(tmp_path / "fast.gif", colour_frames(2), fps=60)


@pytest.mark.parametrize("name", ["frames", "frames/"])
def test_png_frames_are_lossless(tmp_path, name):
    dest = os.path.join(tmp_path, name)
    frames = colour_frames(3, 31, 17)
    write_video(dest, frames)
    folder = tmp_path / "frames"
    assert sorted(os.listdir(folder)) == ["frame_0000.png", "frame_0001.png", "frame_0002.png"]
    for i, f in enumerate(frames):
        np.testing.assert_array_equal(np.asarray(Image.open(folder / f"frame_{i:04d}.png")), f)
    assert os.listdir(tmp_path) == ["frames"]


def test_png_folder_replaces_an_earlier_export_only(tmp_path):
    folder = tmp_path / "frames"
    write_video(folder, colour_frames(5))
    write_video(folder, colour_frames(2))
    assert sorted(os.listdir(folder)) == ["frame_0000.png", "frame_0001.png"]
    (folder / "notes.txt").write_text("mine")
    with pytest.raises(InputError, match="other files"):
        write_video(folder, colour_frames(2))
    assert sorted(os.listdir(folder)) == ["frame_0000.png", "frame_0001.png", "notes.txt"]
    (tmp_path / "afile").write_text("x")
    with pytest.raises(InputError, match="not a folder"):
        write_video(tmp_path / "afile", colour_frames(2))


def _listing_after_failure(tmp_path, dest_name, run):
    dest = tmp_path / dest_name
    if dest_name.endswith("/") or "." not in dest_name:
        write_video(dest, colour_frames(2))
        before = {p: (dest / p).read_bytes() for p in os.listdir(dest)}
        run(dest)
        assert {p: (dest / p).read_bytes() for p in os.listdir(dest)} == before
    else:
        dest.write_bytes(OLD)
        run(dest)
        assert dest.read_bytes() == OLD
    assert os.listdir(tmp_path) == [dest.name]


@pytest.mark.parametrize("dest_name", ["v.mp4", "v.gif", "frames"])
def test_cancel_mid_export_leaves_destination_untouched(tmp_path, dest_name):
    def cancel_at_3(done, total):
        if done == 3:
            raise ExportCancelled("cancelled by the user")

    def run(dest):
        with pytest.raises(ExportCancelled):
            write_video(dest, colour_frames(8), progress=cancel_at_3)

    _listing_after_failure(tmp_path, dest_name, run)


@pytest.mark.parametrize("dest_name", ["v.mp4", "v.gif", "frames"])
def test_failing_frame_generator_leaves_destination_untouched(tmp_path, dest_name):
    def frames():
        yield from colour_frames(3)
        raise OSError("renderer ran out of memory")

    def run(dest):
        with pytest.raises(OSError, match="renderer ran out of memory") as e:
            write_video(dest, frames())
        assert not isinstance(e.value, ExportError)

    _listing_after_failure(tmp_path, dest_name, run)


@pytest.mark.parametrize("dest_name", ["v.mp4", "v.gif", "frames"])
def test_bad_frames_name_the_frame_and_leave_nothing(tmp_path, dest_name):
    def nan_frame(dest):
        frames = [np.zeros((8, 8, 3))] * 2 + [np.full((8, 8, 3), np.nan)]
        with pytest.raises(InputError, match="frame 2.*NaN"):
            write_video(dest, frames)

    def size_change(dest):
        frames = colour_frames(2) + colour_frames(1, 20, 20)
        with pytest.raises(InputError, match="frame 2.*differs"):
            write_video(dest, frames)

    _listing_after_failure(tmp_path, dest_name, nan_frame)
    _listing_after_failure(tmp_path, dest_name, size_change)


def test_frame_conversion():
    f = np.array([[[-0.5, 0.5, 1.5], [0.0, 1.0, 0.25]]])
    np.testing.assert_array_equal(to_uint8_frame(f, 0), [[[0, 128, 255], [0, 255, 64]]])
    assert f[0, 0, 0] == -0.5  # input untouched
    u = np.zeros((2, 2, 3), np.uint8)
    assert to_uint8_frame(u, 0).dtype == np.uint8
    with pytest.raises(InputError, match=r"frame 4.*\(H, W, 3\)"):
        to_uint8_frame(np.zeros((4, 4)), 4)
    with pytest.raises(InputError, match="dtype"):
        to_uint8_frame(np.zeros((4, 4, 3), np.int32), 0)
    with pytest.raises(InputError, match="NaN"):
        to_uint8_frame(np.full((4, 4, 3), np.inf), 0)


def test_bad_arguments(tmp_path):
    with pytest.raises(InputError) as e:
        write_video(tmp_path / "v.avi", colour_frames(2))
    assert ".mp4" in str(e.value) and ".gif" in str(e.value) and "folder" in str(e.value)
    assert video_kind("a/b.MP4") == "mp4" and video_kind("a/b") == "png" and video_kind("a/b.c/") == "png"
    with pytest.raises(InputError, match="no frames"):
        write_video(tmp_path / "v.mp4", [])
    with pytest.raises(InputError, match="no frames"):
        write_video(tmp_path / "v.mp4", iter([]))
    with pytest.raises(InputError, match="fps"):
        write_video(tmp_path / "v.mp4", colour_frames(2), fps=0)
    with pytest.raises(InputError, match="quality"):
        write_video(tmp_path / "v.mp4", colour_frames(2), quality=11)
    with pytest.raises(InputError, match="n_frames"):
        write_video(tmp_path / "v.gif", iter(colour_frames(2)), n_frames=3)
    with pytest.raises(InputError, match="n_frames"):
        write_video(tmp_path / "v.gif", iter(colour_frames(4)), n_frames=3)
    assert os.listdir(tmp_path) == []


def test_disk_errors_become_export_errors(tmp_path):
    with pytest.raises(ExportError, match="does not exist"):
        write_video(tmp_path / "no" / "v.mp4", colour_frames(2))
    (tmp_path / "v.gif").mkdir()  # a folder where the file should go: the final rename fails
    with pytest.raises(ExportError, match="v.gif"):
        write_video(tmp_path / "v.gif", colour_frames(2))
    assert os.listdir(tmp_path) == ["v.gif"] and os.listdir(tmp_path / "v.gif") == []


def test_console_progress_runs(tmp_path, capsys):
    report = console_progress("test")
    write_video(tmp_path / "f", colour_frames(3), progress=report)
    assert "test" in capsys.readouterr().err
