"""The viewer's settings file (app/viewer/settings.py): recent files, last folder; bad files tolerated."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from stylize3d_app.viewer.settings import (
    MAX_RECENT, ViewerSettings, config_dir, load_settings, parse_settings, save_settings, settings_path,
)
from stylize3d_core.errors import ExportError


def test_the_folder_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.setenv("STYLIZE3D_CONFIG_DIR", str(tmp_path / "cfg"))
    assert config_dir() == tmp_path / "cfg" and settings_path() == tmp_path / "cfg" / "viewer.json"
    monkeypatch.delenv("STYLIZE3D_CONFIG_DIR")
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))
    assert config_dir() == tmp_path / "xdg" / "stylize3d"
    monkeypatch.delenv("XDG_CONFIG_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert config_dir() == tmp_path / "home" / ".config" / "stylize3d"


def test_recent_files_round_trip_most_recent_first(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    s = ViewerSettings()
    for name in ("a.jpg", "b.jpg", "a.jpg"):
        s = s.with_photo(name)  # relative: made absolute
    s = s.with_style(str(tmp_path / "styles" / "ink.png"))
    assert s.recent_photos == (str(tmp_path / "a.jpg"), str(tmp_path / "b.jpg"))
    assert s.recent_styles == (str(tmp_path / "styles" / "ink.png"),) and s.last_folder == str(tmp_path / "styles")
    path = tmp_path / "cfg" / "viewer.json"  # the folder does not exist yet
    assert save_settings(s, path) == path
    assert json.loads(path.read_text())["version"] == 1
    assert load_settings(path) == (s, None)
    assert [p.name for p in path.parent.iterdir()] == ["viewer.json"]  # no temporary file left
    many = ViewerSettings()
    for i in range(MAX_RECENT + 3):
        many = many.with_photo(f"/p/{i}.jpg")
    assert len(many.recent_photos) == MAX_RECENT and many.recent_photos[0] == f"/p/{MAX_RECENT + 2}.jpg"
    assert str(tmp_path / "a.jpg") not in s.without(str(tmp_path / "a.jpg")).recent_photos


def test_missing_and_corrupt_files_give_defaults(tmp_path):
    assert load_settings(tmp_path / "none.json") == (ViewerSettings(), None)
    bad = tmp_path / "viewer.json"
    for text, problem in (("{not json", "settings ignored"), ('["a"]', "expected a JSON object"),
                          ('{"recent_photos": "a.jpg"}', "'recent_photos' must be a list of paths"),
                          ('{"recent_styles": [1]}', "'recent_styles' must be a list"),
                          ('{"version": 7}', "unknown version 7"), ('{"last_folder": 3}', "'last_folder'")):
        bad.write_text(text)
        loaded = load_settings(bad)
        assert loaded.settings == ViewerSettings()
        assert str(bad) in loaded.warning and problem in loaded.warning
    bad.write_bytes(b"\xff\xfe\x00garbage")
    assert load_settings(bad).settings == ViewerSettings() and str(bad) in load_settings(bad).warning
    # A later save replaces the bad file with a good one.
    save_settings(ViewerSettings(recent_photos=("/x.jpg",)), bad)
    assert load_settings(bad) == (ViewerSettings(recent_photos=("/x.jpg",)), None)
    assert parse_settings({"recent_photos": ["/a", "/a", "/b"]}).recent_photos == ("/a", "/b")  # duplicates once


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write into a read-only folder")
def test_an_unwritable_folder_is_a_clear_error_and_keeps_the_old_file(tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    path = folder / "viewer.json"
    save_settings(ViewerSettings(recent_photos=("/old.jpg",)), path)
    folder.chmod(0o500)
    try:
        with pytest.raises(ExportError, match="viewer.json"):
            save_settings(ViewerSettings(recent_photos=("/new.jpg",)), path)
    finally:
        folder.chmod(0o700)
    assert load_settings(path).settings.recent_photos == ("/old.jpg",)
