"""Every writer reads its output back before the rename; any write error is an ExportError naming the file."""

import errno
import os
from collections import namedtuple

import numpy as np
import pytest
import torch

import stylize3d_core.io.atomic as atomic
import stylize3d_core.io.video as video
from stylize3d_core.errors import ExportError
from stylize3d_core.geometry.camera import Cameras
from stylize3d_core.io.atomic import describe_os_error, write_atomically
from stylize3d_core.io.camera_path import save_camera_path
from stylize3d_core.io.images import save_image
from stylize3d_core.io.ply import write_ply
from stylize3d_core.io.video import write_video

FRAMES = [np.random.default_rng(i).integers(0, 255, (24, 32, 3), dtype=np.uint8) for i in range(4)]


def _cams(n=3):
    return Cameras(torch.eye(4, dtype=torch.float64).repeat(n, 1, 1), torch.full((n,), 60.0, dtype=torch.float64))


WRITERS = {
    "mp4": ("v.mp4", lambda p: write_video(p, FRAMES, fps=10)),
    "gif": ("v.gif", lambda p: write_video(p, FRAMES, fps=10)),
    "ply": ("c.ply", lambda p: write_ply(p, np.random.default_rng(0).random((500, 3)), np.zeros((500, 3)))),
    "json": ("c.json", lambda p: save_camera_path(p, _cams())),
    "png image": ("i.png", lambda p: save_image(p, np.random.default_rng(0).random((32, 32, 3)))),
}


@pytest.mark.parametrize("kind", list(WRITERS))
def test_a_short_write_is_caught_before_the_rename(kind, tmp_path, monkeypatch):
    """The file loses its second half between the write and the rename (a lost write, a bad disk)."""
    name, write = WRITERS[kind]
    dest = tmp_path / name
    dest.write_bytes(b"good old file")
    real = atomic._fsync

    def truncate_then_fsync(path):
        os.truncate(path, max(1, path.stat().st_size // 2))
        real(path)

    monkeypatch.setattr(atomic, "_fsync", truncate_then_fsync)
    with pytest.raises(ExportError) as e:
        write(dest)
    assert str(dest) in str(e.value)
    assert dest.read_bytes() == b"good old file"
    assert os.listdir(tmp_path) == [name]


@pytest.mark.parametrize("kind", list(WRITERS))
def test_the_writers_still_write(kind, tmp_path):
    name, write = WRITERS[kind]
    write(tmp_path / name)
    assert os.listdir(tmp_path) == [name]


def test_an_mp4_that_reads_back_short_is_an_error(tmp_path, monkeypatch):
    dest = tmp_path / "v.mp4"
    dest.write_bytes(b"old")
    monkeypatch.setattr(video, "_probe_mp4", lambda path: (3, (32, 24)))
    with pytest.raises(ExportError, match="reads back as 3 frames .* 4 frames .* were written"):
        write_video(dest, FRAMES, fps=10)
    assert dest.read_bytes() == b"old" and os.listdir(tmp_path) == ["v.mp4"]


def test_the_mp4_probe_counts_frames_and_size(tmp_path):
    dest = write_video(tmp_path / "v.mp4", [np.zeros((25, 33, 3), np.uint8)] * 5, fps=10)
    assert video._probe_mp4(dest) == (5, (34, 26))  # padded to even
    (tmp_path / "bad.mp4").write_bytes(b"\0" * 1000)
    with pytest.raises(ExportError, match="ffmpeg cannot read it back"):
        video._probe_mp4(tmp_path / "bad.mp4")


def test_a_png_folder_missing_a_frame_is_an_error(tmp_path, monkeypatch):
    dest = tmp_path / "frames"
    dest.mkdir()
    (dest / "frame_0000.png").write_bytes(b"old")
    real = video._write_png

    def lose_last(tmp, source):
        real(tmp, source)
        os.unlink(tmp / "frame_0003.png")

    monkeypatch.setattr(video, "_write_png", lose_last)
    with pytest.raises(ExportError, match="incomplete \\(3 of 4 files\\)"):
        write_video(str(dest) + "/", FRAMES)
    assert os.listdir(dest) == ["frame_0000.png"] and (dest / "frame_0000.png").read_bytes() == b"old"
    assert os.listdir(tmp_path) == ["frames"]


@pytest.mark.parametrize("code, words", [(errno.ENOSPC, "the disk is full"), (errno.EFBIG, "file-size limit"),
                                         (errno.EIO, "input/output error"), (errno.EPIPE, "broken pipe"),
                                         (errno.EDQUOT, "quota"), (errno.EROFS, "read-only")])
@pytest.mark.parametrize("kind", ["mp4", "gif", "png", "ply", "json"])
def test_every_write_error_is_an_export_error(kind, code, words, tmp_path, monkeypatch):
    def fail(*_a, **_k):
        raise OSError(code, os.strerror(code))

    names = {"mp4": "v.mp4", "gif": "v.gif", "png": "frames", "ply": "c.ply", "json": "c.json"}
    dest = tmp_path / names[kind]
    if kind == "png":
        dest.mkdir()
        (dest / "frame_0000.png").write_bytes(b"old")
        monkeypatch.setattr(video, "_write_png", fail)
        call = lambda: write_video(str(dest) + "/", FRAMES)  # noqa: E731
    else:
        dest.write_bytes(b"old")
        if kind in ("mp4", "gif"):
            monkeypatch.setattr(video, f"_write_{kind}", fail)
        else:
            monkeypatch.setattr(atomic, "_fsync", fail)
        call = lambda: WRITERS[kind][1](dest)  # noqa: E731
    with pytest.raises(ExportError) as e:
        call()
    assert str(dest) in str(e.value) and words in str(e.value)
    assert sorted(os.listdir(tmp_path)) == [dest.name]
    assert (dest / "frame_0000.png" if kind == "png" else dest).read_bytes() == b"old"


def test_free_space_is_checked_when_the_size_is_known(tmp_path, monkeypatch):
    Usage = namedtuple("Usage", "total used free")
    monkeypatch.setattr(atomic.shutil, "disk_usage", lambda _p: Usage(10**6, 10**6 - 1000, 1000))
    dest = tmp_path / "c.json"
    dest.write_text("old")
    with pytest.raises(ExportError, match="not enough free space: the output needs about .* 1,000 bytes free"):
        save_camera_path(dest, _cams())
    with pytest.raises(ExportError, match="not enough free space"):
        write_ply(tmp_path / "c.ply", np.zeros((10, 3)), np.zeros((10, 3)))
    assert os.listdir(tmp_path) == ["c.json"] and dest.read_text() == "old"


def test_write_atomically_names_the_file_and_the_reason(tmp_path):
    def write(tmp):
        tmp.write_bytes(b"partial")
        raise OSError(errno.ENOSPC, "No space left on device")

    with pytest.raises(ExportError, match=r"x\.bin: could not write the thing: the disk is full \(No space"):
        write_atomically(tmp_path / "x.bin", "thing", write)
    assert os.listdir(tmp_path) == []


def test_an_uncreatable_temporary_file_is_an_export_error(tmp_path, monkeypatch):
    real_open = os.open

    def refuse_new_files(path, flags, *args, **kwargs):
        if flags & os.O_CREAT:  # root writes into read-only folders: refuse the creation itself
            raise PermissionError(errno.EACCES, "Permission denied")
        return real_open(path, flags, *args, **kwargs)

    monkeypatch.setattr(atomic.os, "open", refuse_new_files)
    with pytest.raises(ExportError, match="cannot create a file in .*permission denied"):
        write_ply(tmp_path / "c.ply", np.zeros((10, 3)), np.zeros((10, 3)))


def test_describe_os_error():
    assert describe_os_error(OSError(errno.ENOSPC, "No space left on device")) == \
        "the disk is full (No space left on device)"
    assert describe_os_error(OSError("odd")) == "odd"
    assert describe_os_error(ExportError("x: y")) == "x: y"


def test_verify_by_suffix_refuses_a_broken_image_and_json(tmp_path):
    bad_png = tmp_path / "a.png"
    save_image(bad_png, np.zeros((8, 8, 3)))
    bad_png.write_bytes(bad_png.read_bytes()[:-20])
    with pytest.raises(ExportError, match="does not read back"):
        atomic.verify_by_suffix(bad_png, tmp_path / "dest.png")
    (tmp_path / "b.json").write_text("{")
    with pytest.raises(ExportError, match="JSON does not read back"):
        atomic.verify_by_suffix(tmp_path / "b.json", tmp_path / "dest.json")
    (tmp_path / "c.bin").write_text("anything")
    atomic.verify_by_suffix(tmp_path / "c.bin", tmp_path / "dest.bin")  # no check for unknown suffixes
