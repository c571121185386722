"""The viewer's start-up choices: the Filament back end (app/viewer/backend.py: parsing, the library hook, GLX,
image rows) and the torch threads of full frames."""

from __future__ import annotations

import ctypes
import os
import subprocess
import sys

import numpy as np
import pytest

from stylize3d_app.viewer import backend
from stylize3d_app.viewer import build_parser, main


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


def test_auto_leaves_open3d_to_choose_and_never_flips(monkeypatch):
    monkeypatch.setattr(backend, "_flip_rows", False)
    assert backend.select_backend("auto") == "auto"
    assert not backend._flip_rows


def test_widget_images_are_flipped_only_under_opengl(monkeypatch):
    rgb = np.arange(4 * 3 * 3, dtype=np.uint8).reshape(4, 3, 3)
    monkeypatch.setattr(backend, "_flip_rows", False)
    assert np.array_equal(np.asarray(backend.widget_image(rgb)), rgb)
    monkeypatch.setattr(backend, "_flip_rows", True)
    assert np.array_equal(np.asarray(backend.widget_image(rgb)), rgb[::-1])
    view = rgb[:, ::-1]  # a non-contiguous view is copied, not refused
    assert np.array_equal(np.asarray(backend.widget_image(view)), view[::-1])


def _open_window(display: str, choice: str) -> str:
    """stdout + stderr of a subprocess that selects ``choice`` and opens an Open3D window on ``display``
    (Filament logs the back end it resolved; "opened" once the window ran a tick)."""
    code = ("from stylize3d_app.viewer.backend import start_gui\n"
            f"print(start_gui({choice!r}), flush=True)\n"
            "import open3d.visualization.gui as gui\n"
            "app = gui.Application.instance\n"
            "w = app.create_window('t', 200, 100); app.run_one_tick(); w.close(); print('opened')\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         env={**os.environ, "DISPLAY": display})
    return out.stdout + out.stderr


def test_the_choice_reaches_filament_and_opengl_falls_back_without_glx(monkeypatch):
    """Each choice resolves to its Filament back end (its own log line: the RenderingType values are right).
    An X server without GLX (Xvfb -extension GLX) cannot run an OpenGL engine: the choice falls back to
    Open3D's own (Vulkan), and the window still opens there."""
    from stylize3d_app.viewer.xserver import XDisplay, start_xvfb

    assert XDisplay.open("") is None  # no display named
    servers = [start_xvfb((640, 480)), start_xvfb((640, 480), extra_args=("-extension", "GLX"))]
    try:
        if any(s is None for s in servers):
            pytest.skip("Xvfb is not installed or did not start")
        (_, with_glx), (_, without) = servers
        with XDisplay.open(with_glx) as conn:
            assert conn.has_extension("GLX") is True
        with XDisplay.open(without) as conn:
            assert conn.has_extension("GLX") is False
        for choice, resolved in (("opengl", "OpenGL"), ("vulkan", "Vulkan")):
            log = _open_window(with_glx, choice)
            assert f"resolved backend: {resolved}" in log and "opened" in log, log
            assert "headless" not in log, log  # a real window, not Open3D's windowless fallback
        monkeypatch.setattr(backend, "_flip_rows", False)
        with XDisplay.open(without) as conn:
            assert "no GLX" in backend.select_backend("opengl", conn) and not backend._flip_rows
        log = _open_window(without, "opengl")
        assert "no GLX" in log and "resolved backend: Vulkan" in log and "opened" in log, log
    finally:
        for server in servers:
            if server is not None:
                server[0].terminate()
                server[0].wait(timeout=10)


def test_the_display_connection_is_held_until_open3d_has_its_own(monkeypatch):
    """An X server resets when its last client leaves, and refuses connections meanwhile: the GLX check's
    connection stays open until Open3D has connected (start_gui), so Open3D never meets the reset. Checked
    where the race lives: a fresh, resetting Xvfb whose only client is the check, 5 starts in a row."""
    from stylize3d_app.viewer.xserver import XDisplay, start_xvfb

    server = start_xvfb((640, 480))
    if server is None:
        pytest.skip("Xvfb is not installed or did not start")
    proc, name = server
    try:
        with XDisplay.open(name) as conn:
            assert conn.has_extension("GLX") is True
        with pytest.raises(ValueError, match="closed"):
            conn.has_extension("GLX")
        for _ in range(5):
            log = _open_window(name, "opengl")
            assert "resolved backend: OpenGL" in log and "opened" in log and "headless" not in log, log
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def test_a_display_that_does_not_open_is_a_clear_error(monkeypatch, capsys):
    """No window can open: exit 2 naming the display, instead of Open3D's windowless fallback running
    with nothing on screen."""
    monkeypatch.setenv("DISPLAY", ":987")  # no X server there
    assert main(["--no-model"]) == 2
    assert "cannot open the X display ':987'" in capsys.readouterr().err
    monkeypatch.delenv("DISPLAY")
    assert main(["--no-model"]) == 2
    assert "DISPLAY is not set" in capsys.readouterr().err


def test_full_frames_use_all_but_one_core_from_three_cores_and_bad_counts_are_refused(capsys):
    from stylize3d_app.viewer import default_full_threads

    assert [default_full_threads(n) for n in (1, 2, 3, 4, 16)] == [1, 1, 2, 3, 15]
    assert main(["--full-threads", "0", "--no-model"]) == 2
    assert "--full-threads must be >= 1" in capsys.readouterr().err
