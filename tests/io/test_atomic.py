import os

import pytest

from stylize3d_core.errors import ExportError
from stylize3d_core.io.atomic import add_commit_check, atomic_path, remove_commit_check


def test_success_replaces_destination(tmp_path):
    dest = tmp_path / "out.txt"
    dest.write_text("old")
    with atomic_path(dest) as tmp:
        assert tmp.parent == tmp_path and tmp.suffix == ".txt" and tmp != dest
        tmp.write_text("new")
        assert dest.read_text() == "old"
    assert dest.read_text() == "new"
    assert os.listdir(tmp_path) == ["out.txt"]


def test_failure_keeps_old_file_and_cleans_up(tmp_path):
    dest = tmp_path / "out.txt"
    dest.write_text("old")
    with pytest.raises(RuntimeError):
        with atomic_path(dest) as tmp:
            tmp.write_text("half")
            raise RuntimeError("encoder died")
    assert dest.read_text() == "old"
    assert os.listdir(tmp_path) == ["out.txt"]


def test_keyboard_interrupt_cleans_up(tmp_path):
    dest = tmp_path / "x.bin"
    with pytest.raises(KeyboardInterrupt):
        with atomic_path(dest) as tmp:
            tmp.write_bytes(b"123")
            raise KeyboardInterrupt
    assert os.listdir(tmp_path) == []


def test_empty_output_is_an_error(tmp_path):
    dest = tmp_path / "x.bin"
    dest.write_bytes(b"good")
    with pytest.raises(ExportError, match="empty"):
        with atomic_path(dest):
            pass
    assert dest.read_bytes() == b"good"
    assert os.listdir(tmp_path) == ["x.bin"]


def test_missing_folder(tmp_path):
    with pytest.raises(ExportError, match="does not exist"):
        with atomic_path(tmp_path / "nope" / "x.png"):
            pass


def test_directory_mode(tmp_path):
    dest = tmp_path / "frames"
    dest.mkdir()
    (dest / "old.png").write_text("o")
    with atomic_path(dest, directory=True) as tmp:
        (tmp / "frame_0000.png").write_text("n")
    assert sorted(os.listdir(dest)) == ["frame_0000.png"]
    assert os.listdir(tmp_path) == ["frames"]
    with pytest.raises(ValueError):
        with atomic_path(dest, directory=True) as tmp:
            (tmp / "frame_0000.png").write_text("x")
            raise ValueError("cancel")
    assert (dest / "frame_0000.png").read_text() == "n"
    assert os.listdir(tmp_path) == ["frames"]


def test_written_file_gets_a_normal_mode(tmp_path):
    dest = tmp_path / "x.txt"
    mask = os.umask(0o022)
    try:
        with atomic_path(dest) as tmp:
            tmp.write_text("x")
    finally:
        os.umask(mask)
    assert dest.stat().st_mode & 0o777 == 0o644


def test_mode_is_normal_even_if_the_writer_recreates_the_file(tmp_path):
    dest = tmp_path / "y.bin"
    mask = os.umask(0o022)
    try:
        with atomic_path(dest) as tmp:
            tmp.unlink()
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT, 0o600)
            os.write(fd, b"data")
            os.close(fd)
    finally:
        os.umask(mask)
    assert dest.stat().st_mode & 0o777 == 0o644


@pytest.mark.parametrize("directory", [False, True])
def test_a_failing_commit_check_keeps_the_old_output(tmp_path, directory):
    dest = tmp_path / ("out" if directory else "a.txt")
    if directory:
        dest.mkdir()
        (dest / "old.txt").write_text("old")
    else:
        dest.write_text("old")

    class Stop(Exception):
        pass

    calls = []

    def check():
        calls.append(1)
        raise Stop

    add_commit_check(check)
    add_commit_check(check)  # once per function
    try:
        with pytest.raises(Stop):
            with atomic_path(dest, directory=directory) as tmp:
                if directory:
                    (tmp / "new.txt").write_text("new")
                else:
                    tmp.write_text("new")
    finally:
        remove_commit_check(check)
    assert calls == [1]
    assert (dest / "old.txt").read_text() == "old" if directory else dest.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == [dest.name]
    with atomic_path(dest) if not directory else atomic_path(dest, directory=True) as tmp:  # removed: commits
        if directory:
            (tmp / "new.txt").write_text("new")
        else:
            tmp.write_text("new")
    assert (dest / "new.txt").exists() if directory else dest.read_text() == "new"



@pytest.mark.parametrize("directory", [False, True])
def test_a_signal_the_instant_the_temporary_exists_leaves_nothing_behind(tmp_path, monkeypatch, directory):
    # Ctrl-C raised right after the temporary was created, before the writer ever runs (Python runs
    # signal handlers between any two bytecodes): the clean-up must already cover it.
    import signal

    from stylize3d_core.io import atomic

    dest = tmp_path / ("out" if directory else "out.png")
    if directory:
        dest.mkdir()
        (dest / "a").write_bytes(b"old")
    else:
        dest.write_bytes(b"old")
    real = atomic._create

    def create_then_signal(*args, **kwargs):
        real(*args, **kwargs)
        os.kill(os.getpid(), signal.SIGINT)  # default_int_handler raises KeyboardInterrupt

    monkeypatch.setattr(atomic, "_create", create_then_signal)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    wrote = []
    try:
        with pytest.raises(KeyboardInterrupt):
            with atomic_path(dest, directory=directory) as tmp:
                wrote.append(tmp)
    finally:
        signal.signal(signal.SIGINT, previous)
    assert wrote == []  # interrupted before the writer started
    assert sorted(p.name for p in tmp_path.iterdir()) == [dest.name]
    assert (dest / "a" if directory else dest).read_bytes() == b"old"


def test_a_name_taken_meanwhile_is_an_error_and_is_not_removed(tmp_path, monkeypatch):
    from stylize3d_core.io import atomic

    taken = tmp_path / ".out.taken.partial.png"
    taken.write_bytes(b"another process's")
    monkeypatch.setattr(atomic, "_unused_name", lambda parent, prefix, suffix: taken)
    with pytest.raises(ExportError, match="cannot create a file"):
        with atomic_path(tmp_path / "out.png"):
            pass
    assert taken.read_bytes() == b"another process's"


def test_temporaries_get_a_normal_mode_from_the_umask(tmp_path):
    old = os.umask(0o027)
    try:
        with atomic_path(tmp_path / "d", directory=True) as tmp:
            assert tmp.stat().st_mode & 0o777 == 0o750
        with atomic_path(tmp_path / "f.json") as tmp:
            assert tmp.stat().st_mode & 0o777 == 0o640
            tmp.write_text("{}")
    finally:
        os.umask(old)
    assert (tmp_path / "d").is_dir() and (tmp_path / "f.json").read_text() == "{}"


def test_an_interruption_between_the_folder_renames_puts_the_old_folder_back(tmp_path, monkeypatch):
    from stylize3d_core.io import atomic

    dest = tmp_path / "frames"
    dest.mkdir()
    (dest / "frame_0000.png").write_bytes(b"old frame")
    real_replace = os.replace
    calls = []

    def interrupted_second_rename(src, dst):
        calls.append((src, dst))
        if len(calls) == 2:  # the old folder moved aside; the new one not yet in place
            raise KeyboardInterrupt
        return real_replace(src, dst)

    with pytest.raises(KeyboardInterrupt):
        with atomic_path(dest, directory=True) as tmp:
            (tmp / "frame_0000.png").write_bytes(b"new frame")
            monkeypatch.setattr(atomic.os, "replace", interrupted_second_rename)
    monkeypatch.undo()
    assert len(calls) == 3  # aside, (interrupted), back
    assert sorted(p.name for p in tmp_path.iterdir()) == ["frames"]
    assert (dest / "frame_0000.png").read_bytes() == b"old frame"
