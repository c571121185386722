"""The viewer's choice of Filament back end (app/viewer/backend.py): parsing, the library hook, image rows."""

from __future__ import annotations

import ctypes

import numpy as np
import pytest

from app.viewer import backend
from app.viewer import build_parser, main


def test_choice_from_the_command_line_the_environment_or_the_default(monkeypatch):
    monkeypatch.delenv(backend.ENV_VAR, raising=False)
    assert backend.backend_choice() == backend.DEFAULT_BACKEND == "opengl"
    monkeypatch.setenv(backend.ENV_VAR, " Vulkan ")
    assert backend.backend_choice() == "vulkan"
    assert backend.backend_choice("auto") == "auto"  # the command line wins over the environment
    monkeypatch.setenv(backend.ENV_VAR, "")
    assert backend.backend_choice() == "opengl"


@pytest.mark.parametrize("cli, env, named", [("metal", None, "--render-backend"), (None, "gl", backend.ENV_VAR)])
def test_unknown_choices_are_refused_naming_where_they_came_from(monkeypatch, cli, env, named):
    if env is None:
        monkeypatch.delenv(backend.ENV_VAR, raising=False)
    else:
        monkeypatch.setenv(backend.ENV_VAR, env)
    with pytest.raises(ValueError, match=named):
        backend.backend_choice(cli)


def test_the_viewer_refuses_a_bad_environment_value_before_opening_anything(monkeypatch, capsys):
    monkeypatch.setenv(backend.ENV_VAR, "directx")
    assert main(["--no-model"]) == 2
    assert backend.ENV_VAR in capsys.readouterr().err
    assert build_parser().parse_args(["--render-backend", "vulkan"]).render_backend == "vulkan"


def test_the_installed_open3d_exports_the_backend_hook():
    """The pinned Open3D (0.20) exports EngineInstance::SelectBackend under the name select_backend calls."""
    lib = backend.open3d_library()
    assert lib is not None and lib.name.startswith("libOpen3D.so")
    assert hasattr(ctypes.CDLL(str(lib)), backend._SELECT_BACKEND)
    assert backend.BACKENDS == {"auto": 0, "opengl": 1, "vulkan": 2}  # RenderingType's kDefault, kOpenGL, kVulkan


def test_auto_leaves_open3d_to_choose_and_never_flips(monkeypatch):
    monkeypatch.setattr(backend, "_flip_rows", False)
    assert backend.select_backend("auto") == "auto"
    assert not backend.rows_flipped()


def test_widget_images_are_flipped_only_under_opengl(monkeypatch):
    rgb = np.arange(4 * 3 * 3, dtype=np.uint8).reshape(4, 3, 3)
    monkeypatch.setattr(backend, "_flip_rows", False)
    assert np.array_equal(np.asarray(backend.widget_image(rgb)), rgb)
    monkeypatch.setattr(backend, "_flip_rows", True)
    assert np.array_equal(np.asarray(backend.widget_image(rgb)), rgb[::-1])
    view = rgb[:, ::-1]  # a non-contiguous view is copied, not refused
    assert np.array_equal(np.asarray(backend.widget_image(view)), view[::-1])
