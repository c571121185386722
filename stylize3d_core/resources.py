"""The files stylize3d ships -- the trained model, sample photos, style images -- and model names.

They are package data of the companion package ``stylize3d_assets``, which is
the repository's ``assets/`` folder mapped to that name by ``pyproject.toml``
(``[tool.setuptools.package-dir]``): a wheel carries it as
``site-packages/stylize3d_assets/``, an editable install maps the name onto the
checkout's ``assets/``. Everything here finds it with :mod:`importlib.resources`;
nothing computes paths relative to this file -- except :func:`assets_location`'s
one documented fallback for a source checkout whose install predates the
package (or that is not installed at all): then the checkout's own ``assets/``
is used, and the location says so (``stylize3d info`` prints it).

Models are given by **name** (``"lite"``, the shipped one, see :data:`MODELS`)
or by **path** (a checkpoint you trained); :func:`resolve_model` turns either
into a path and says clearly when a named model is missing from an install.

Importing this module is cheap (no torch, no image libraries).
"""

from __future__ import annotations

import atexit
import contextlib
import functools
import importlib.resources
import importlib.util
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Tuple

from .errors import InputError, PathLike

ASSETS_PACKAGE = "stylize3d_assets"
"""The import name of the shipped data (the repository's ``assets/``)."""

MODELS: Dict[str, str] = {"lite": "model/stylize3d_lite.safetensors"}
"""Shipped models: name -> file inside :data:`ASSETS_PACKAGE`."""
DEFAULT_MODEL_NAME = "lite"
SAMPLE_PHOTO_NAME = "coffee.jpg"
"""The sample photo the README, the viewer's "Open bundled sample" and the wheel test use."""
SAMPLE_STYLE_NAME = "vangogh_starry_night.jpg"
"""The style image that goes with :data:`SAMPLE_PHOTO_NAME`."""

_PHOTO_SUFFIXES = (".jpg", ".jpeg", ".png", ".webp", ".tif", ".tiff")

INSTALLED = "installed package"
CHECKOUT = "source checkout (stylize3d_assets not installed)"
MISSING = "missing"


@dataclass(frozen=True)
class AssetsLocation:
    """Where the shipped data was found.

    Attributes:
        root: the folder holding ``model/``, ``samples/``, ``styles/``; None when not found.
        how: :data:`INSTALLED` (found by ``importlib.resources``), :data:`CHECKOUT`
            (the fallback: this source checkout's ``assets/``), or :data:`MISSING`.
    """

    root: Optional[Path]
    how: str


_extracted = contextlib.ExitStack()  # files copied out of a zip install; removed at exit
atexit.register(_extracted.close)


def _as_path(resource) -> Path:
    """A file-system path for an ``importlib.resources`` Traversable (extracted if it is inside a zip)."""
    if isinstance(resource, Path):
        return resource
    return _extracted.enter_context(importlib.resources.as_file(resource))


def _checkout_assets() -> Optional[Path]:
    """This source checkout's ``assets/`` -- only when this file sits in a checkout (``pyproject.toml`` beside)."""
    top = Path(__file__).resolve().parents[1]
    assets = top / "assets"
    if (top / "pyproject.toml").is_file() and (assets / "__init__.py").is_file() and (assets / "model").is_dir():
        return assets
    return None


@functools.lru_cache(maxsize=None)
def assets_location() -> AssetsLocation:
    """Where ``model/``, ``samples/`` and ``styles/`` are (cached: ``assets_location.cache_clear()`` looks again)."""
    if importlib.util.find_spec(ASSETS_PACKAGE) is not None:
        root = importlib.resources.files(ASSETS_PACKAGE)
        if isinstance(root, Path):
            return AssetsLocation(root, INSTALLED)
        # Not a plain folder (a zip import): files are extracted one by one by _file().
        return AssetsLocation(None, INSTALLED)
    checkout = _checkout_assets()
    if checkout is not None:
        return AssetsLocation(checkout, CHECKOUT)
    return AssetsLocation(None, MISSING)


def _missing_package() -> InputError:
    return InputError(ASSETS_PACKAGE, "the data shipped with stylize3d (model, samples, styles) is not installed; "
                                      "reinstall stylize3d (pip install stylize3d-*.whl)")


def _file(relative: str) -> Optional[Path]:
    """The shipped file ``relative`` (e.g. ``"samples/coffee.jpg"``), or None if it is not there."""
    loc = assets_location()
    if loc.how == MISSING:
        raise _missing_package()
    if loc.root is not None:
        path = loc.root / relative
        return path if path.is_file() else None
    return _extracted_file(relative)


@functools.lru_cache(maxsize=None)
def _extracted_file(relative: str) -> Optional[Path]:
    """``relative`` copied out of a package that is not a plain folder (once per process), or None."""
    resource = importlib.resources.files(ASSETS_PACKAGE).joinpath(*relative.split("/"))
    return _as_path(resource) if resource.is_file() else None


def _listing(folder: str, suffixes: Tuple[str, ...]) -> List[str]:
    loc = assets_location()
    if loc.how == MISSING:
        return []
    base = loc.root / folder if loc.root is not None else importlib.resources.files(ASSETS_PACKAGE) / folder
    if not base.is_dir():
        return []
    return sorted(p.name for p in base.iterdir() if p.is_file() and p.name.lower().endswith(suffixes))


# -- models --------------------------------------------------------------------------------------
def model_names() -> List[str]:
    """Names :func:`resolve_model` accepts (whether or not this install has their files)."""
    return sorted(MODELS)


def model_path(name: str = DEFAULT_MODEL_NAME) -> Path:
    """The checkpoint of the shipped model ``name``; InputError naming it when this install lacks it."""
    if name not in MODELS:
        raise InputError(name, f"no shipped model of this name; shipped models: {', '.join(model_names())}, "
                               "or give the path of a checkpoint (.safetensors)")
    try:
        path = _file(MODELS[name])
    except InputError:
        path = None
    if path is None:
        where = assets_location()
        if where.root is not None:
            looked = f"looked in {where.root / 'model'}"
        else:
            looked = (f"{ASSETS_PACKAGE} is not installed" if where.how == MISSING
                      else f"looked in {ASSETS_PACKAGE}/model")
        raise InputError(name, f"the shipped model {name!r} is missing from this install ({looked}); "
                               "reinstall stylize3d, or give the path of a checkpoint (.safetensors)")
    return path


def default_model() -> str:
    """The default checkpoint as a path string: the shipped lite model's location in this install.

    Never raises: when the data is not installed it returns the name ``"lite"``,
    which :func:`resolve_model` turns into a clear error.
    """
    if assets_location().how == MISSING:
        return DEFAULT_MODEL_NAME
    return str(shipped_location(MODELS[DEFAULT_MODEL_NAME]))


def resolve_model(spec: Optional[PathLike]) -> str:
    """A model given by name or path -> the checkpoint's path (as a string).

    * None or a name from :data:`MODELS` (``"lite"``): the shipped checkpoint;
      InputError when this install lacks it.
    * Anything else is a checkpoint path; it must be an existing file (a bare
      word that is neither a name nor a file gets an error listing the names).
      The default path (:func:`default_model`) of a missing shipped model gets
      the same error as its name.
    """
    if spec is None:
        return str(model_path(DEFAULT_MODEL_NAME))
    text = os.fspath(spec)
    if text in MODELS:
        return str(model_path(text))
    path = Path(text).expanduser()
    if path.is_file():
        return str(path)
    for name in MODELS:  # the shipped location of a name, missing: say so by name
        if assets_location().how != MISSING and path.resolve() == shipped_location(MODELS[name]).resolve():
            return str(model_path(name))
    if path.is_dir():
        raise InputError(text, "is a folder; give a checkpoint file (.safetensors) or a model name "
                               f"({', '.join(model_names())})")
    if os.sep not in text and "/" not in text and not path.suffix:
        raise InputError(text, f"no model of this name and no such file; shipped models: {', '.join(model_names())}, "
                               "or give the path of a checkpoint (.safetensors)")
    raise InputError(text, "model checkpoint not found (train one with `stylize3d train`, or use a shipped "
                           f"model: {', '.join(model_names())})")


# -- samples and styles ----------------------------------------------------------------------------
def sample_names() -> List[str]:
    """File names of the shipped sample photos (empty if the data is not installed)."""
    return _listing("samples", _PHOTO_SUFFIXES)


def style_names() -> List[str]:
    """File names of the shipped style images (empty if the data is not installed)."""
    return _listing("styles", _PHOTO_SUFFIXES)


def _named(folder: str, name: str, names: List[str], what: str) -> Path:
    path = _file(f"{folder}/{name}") if "/" not in name and os.sep not in name else None
    if path is None:
        have = ", ".join(names) or "none"
        raise InputError(name, f"no shipped {what} of this name in this install; shipped: {have}")
    return path


def sample_photo(name: str = SAMPLE_PHOTO_NAME) -> Path:
    """The shipped sample photo ``name`` (a file name from :func:`sample_names`)."""
    return _named("samples", name, sample_names(), "sample photo")


def style_image(name: str = SAMPLE_STYLE_NAME) -> Path:
    """The shipped style image ``name`` (a file name from :func:`style_names`)."""
    return _named("styles", name, style_names(), "style image")


def shipped_location(relative: str) -> Path:
    """Where the shipped file ``relative`` (``"samples/coffee.jpg"``) is, or would be; for constants set at import.

    Never raises and does not check that the file is there: use
    :func:`sample_photo`, :func:`style_image` or :func:`model_path` for a checked
    path. When the data is not installed at all, the path is
    ``stylize3d_assets/RELATIVE`` under the working directory, which normally
    does not exist, so the caller's own "not found" handling applies.
    """
    try:
        path = _file(relative)
    except InputError:
        path = None
    if path is not None:
        return path
    root = assets_location().root
    return (root if root is not None else Path(ASSETS_PACKAGE)).joinpath(*relative.split("/"))
