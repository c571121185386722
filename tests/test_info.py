"""``stylize3d info`` and ``--version``: the bug-report facts."""

import json
import sys
from pathlib import Path

import pytest

from stylize3d_app.cli import main
from stylize3d_core import __version__, info, resources


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="X11 / Wayland rules are the Linux ones")
def test_display_status(tmp_path):
    sockets = tmp_path / "X11"
    sockets.mkdir()
    (sockets / "X7").touch()
    assert info.display_status({}, str(sockets))["available"] is False
    assert info.display_status({"DISPLAY": ":7"}, str(sockets))["available"] is True
    assert info.display_status({"DISPLAY": ":7.0"}, str(sockets))["available"] is True
    gone = info.display_status({"DISPLAY": ":8"}, str(sockets))
    assert gone["available"] is False and "X8" in gone["detail"]
    assert info.display_status({"DISPLAY": "remote:10.0"}, str(sockets))["available"] is True  # not checkable
    assert info.display_status({"WAYLAND_DISPLAY": "wayland-0"}, str(sockets))["available"] is True


def test_a_failing_probe_is_reported_not_raised():
    def broken():
        raise OSError("libGL.so.1: cannot open shared object file")

    assert info._guard(broken) == {"error": "OSError: libGL.so.1: cannot open shared object file"}


def test_info_json_reports_versions_data_display_and_gpu(capsys):
    import cv2
    import torch

    assert main(["info", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["stylize3d"]["version"] == __version__
    assert report["torch"]["version"] == torch.__version__ and report["torch"]["threads"] == torch.get_num_threads()
    assert report["opencv"]["version"] == cv2.__version__
    assert report["open3d"]["version"].startswith("0.") and isinstance(report["open3d"]["gui_built"], bool)
    data = report["data"]
    assert data["found_as"] == resources.assets_location().how
    assert Path(data["models"]["lite"]["path"]) == resources.model_path("lite")
    assert data["models"]["lite"]["bytes"] == resources.model_path("lite").stat().st_size
    assert "coffee.jpg" in data["samples"]["names"] and Path(data["samples"]["folder"], "coffee.jpg").is_file()
    assert isinstance(report["display"]["available"], bool) and report["display"]["detail"]
    assert report["gpu"]["available"] == torch.cuda.is_available()


def test_info_text_is_one_aligned_fact_a_line(capsys, monkeypatch):
    monkeypatch.setattr(resources, "assets_location", lambda: resources.AssetsLocation(None, resources.MISSING))
    assert main(["info"]) == 0
    lines = capsys.readouterr().out.splitlines()
    facts = dict(line.split(None, 1) for line in lines)
    assert facts["data.found_as"] == resources.MISSING
    assert "is not installed" in facts["data.models.lite.error"]
    assert facts["data.samples.names"] == "-"
    value_column = {len(line) - len(line[len(line.split(None, 1)[0]):].lstrip()) for line in lines}
    assert len(value_column) == 1


def test_version(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0 and capsys.readouterr().out.strip() == f"stylize3d {__version__}"
