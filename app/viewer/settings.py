"""The viewer's settings file: recent photos and styles, the last folder a file came from.

A small JSON file in the user's configuration folder, read at start and
written (atomically: temporary file, read back, rename; see
``stylize3d_core.io.atomic``) after each photo or style opens::

    {"version": 1, "recent_photos": ["/abs/photo.jpg", ...],
     "recent_styles": ["/abs/style.jpg", ...], "last_folder": "/abs/folder"}

The folder is ``$STYLIZE3D_CONFIG_DIR`` when set (the tests point it at a
temporary folder), else ``$XDG_CONFIG_HOME/stylize3d``, else
``~/.config/stylize3d``. A missing file means no history; a file that cannot be
read or parsed, or holds values of the wrong type, is ignored with a warning
(:attr:`LoadedSettings.warning`) and replaced at the next save: a bad settings
file never stops the viewer. Pure file handling: no widgets, no threads.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, NamedTuple, Optional, Tuple

from stylize3d_core.errors import ExportError
from stylize3d_core.io.atomic import write_atomically

from .state import push_recent

SETTINGS_VERSION = 1
SETTINGS_NAME = "viewer.json"
MAX_RECENT = 8
"""Recent photos (and, separately, styles) kept."""


def config_dir() -> Path:
    """The folder of the settings file (see the module docstring)."""
    explicit = os.environ.get("STYLIZE3D_CONFIG_DIR")
    if explicit:
        return Path(explicit).expanduser()
    xdg = os.environ.get("XDG_CONFIG_HOME")
    base = Path(xdg).expanduser() if xdg else Path.home() / ".config"
    return base / "stylize3d"


def settings_path() -> Path:
    """The settings file: ``config_dir() / "viewer.json"``."""
    return config_dir() / SETTINGS_NAME


@dataclass(frozen=True)
class ViewerSettings:
    """What the viewer remembers between runs.

    Attributes:
        recent_photos: absolute paths of the photos opened last, most recent first (at most 8).
        recent_styles: the same for style images.
        last_folder: the folder the last file was chosen in (the file dialogs start there), or None.
    """

    recent_photos: Tuple[str, ...] = field(default_factory=tuple)
    recent_styles: Tuple[str, ...] = field(default_factory=tuple)
    last_folder: Optional[str] = None

    def with_photo(self, path: str) -> "ViewerSettings":
        """The settings after opening photo ``path`` (made absolute)."""
        p = os.path.abspath(os.path.expanduser(str(path)))
        return replace(self, recent_photos=push_recent(self.recent_photos, p, MAX_RECENT),
                       last_folder=os.path.dirname(p))

    def with_style(self, path: str) -> "ViewerSettings":
        """The settings after opening style ``path`` (made absolute)."""
        p = os.path.abspath(os.path.expanduser(str(path)))
        return replace(self, recent_styles=push_recent(self.recent_styles, p, MAX_RECENT),
                       last_folder=os.path.dirname(p))

    def without(self, path: str) -> "ViewerSettings":
        """The settings with ``path`` taken off both recent lists (it could not be opened)."""
        p = os.path.abspath(os.path.expanduser(str(path)))
        return replace(self, recent_photos=tuple(r for r in self.recent_photos if r != p),
                       recent_styles=tuple(r for r in self.recent_styles if r != p))

    def to_json(self) -> dict:
        return {"version": SETTINGS_VERSION, "recent_photos": list(self.recent_photos),
                "recent_styles": list(self.recent_styles), "last_folder": self.last_folder}


class LoadedSettings(NamedTuple):
    """What :func:`load_settings` read: the settings, and why the file was ignored (None if it was not)."""

    settings: ViewerSettings
    warning: Optional[str]


def _paths(doc: dict, key: str) -> Tuple[str, ...]:
    value = doc.get(key, [])
    if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
        raise ValueError(f"{key!r} must be a list of paths, got {value!r}")
    return tuple(dict.fromkeys(value))[:MAX_RECENT]


def parse_settings(doc: Any) -> ViewerSettings:
    """Settings from a parsed JSON document; ValueError naming the bad entry."""
    if not isinstance(doc, dict):
        raise ValueError(f"expected a JSON object, got {type(doc).__name__}")
    version = doc.get("version", SETTINGS_VERSION)
    if version != SETTINGS_VERSION:
        raise ValueError(f"unknown version {version!r} (this viewer writes {SETTINGS_VERSION})")
    folder = doc.get("last_folder")
    if folder is not None and (not isinstance(folder, str) or not folder):
        raise ValueError(f"'last_folder' must be a path or null, got {folder!r}")
    return ViewerSettings(_paths(doc, "recent_photos"), _paths(doc, "recent_styles"), folder)


def load_settings(path: Optional[Path] = None) -> LoadedSettings:
    """Read the settings file (default :func:`settings_path`); never raises: a missing file gives the
    defaults, an unreadable or malformed one the defaults and a warning naming the file and the problem."""
    p = Path(path) if path is not None else settings_path()
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        return LoadedSettings(ViewerSettings(), None)
    except (OSError, UnicodeDecodeError) as e:
        return LoadedSettings(ViewerSettings(), f"{p}: could not read the settings ({e}); starting without history")
    try:
        return LoadedSettings(parse_settings(json.loads(text)), None)
    except (ValueError, RecursionError) as e:  # json.JSONDecodeError is a ValueError; too deep a nesting recurses
        why = "nested too deeply" if isinstance(e, RecursionError) else e
        return LoadedSettings(ViewerSettings(), f"{p}: settings ignored ({why}); they are rewritten at the next save")


def save_settings(settings: ViewerSettings, path: Optional[Path] = None) -> Path:
    """Write ``settings`` atomically (the folder is created); ExportError naming the file on failure."""
    p = Path(path) if path is not None else settings_path()
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ExportError(f"{p.parent}: could not create the settings folder ({e})") from e
    text = json.dumps(settings.to_json(), indent=1) + "\n"
    return write_atomically(p, "viewer settings", lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))
