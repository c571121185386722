"""The built wheel, installed outside the checkout, works: the CI check of a real install.

The module builds the wheel from a copy of the source tree (``pip wheel
--no-build-isolation --no-deps``: no downloads, nothing written into the
checkout), installs it with ``pip install --no-deps`` into a fresh virtual
environment under a temporary folder, and runs the installed commands from an
unrelated working directory with ``PYTHONPATH`` unset.

The fresh environment gets its *dependencies* (torch, Open3D, ...) from the
environment running the tests, through a ``.pth`` file naming that
environment's site-packages; a full ``pip install`` of the wheel with its
dependencies copies about 2 GB (torch, Open3D) and takes minutes, too slow to
repeat in CI. A ``.pth`` line only adds a folder to ``sys.path``: the ``.pth``
files inside it -- among them the editable install's finder that maps
``stylize3d_core`` onto the checkout -- are not run, and the tests assert that
every stylize3d package is imported from the fresh environment.
"""

from __future__ import annotations

import json
import os
import shutil
import site
import subprocess
import sys
import time
import zipfile
from pathlib import Path
from typing import Dict, List

import pytest

pytestmark = pytest.mark.slow  # builds and installs a wheel, renders and opens the viewer from it: 1-2 min

REPO = Path(__file__).resolve().parents[1]
BUILD_INPUTS = ("pyproject.toml", "README.md", "LICENSE", "stylize3d", "stylize3d_core", "app", "assets")
"""What the build reads (pyproject.toml's packages, package-dir, readme and license-files)."""
OUR_PACKAGES = ("stylize3d", "stylize3d_core", "stylize3d_app", "stylize3d_assets")
TIMEOUT_S = 300


def _run(cmd: List[str], cwd: Path, env: Dict[str, str], timeout: float = TIMEOUT_S) -> subprocess.CompletedProcess:
    out = subprocess.run([str(c) for c in cmd], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert out.returncode == 0, f"{cmd} exited {out.returncode}\nstdout:\n{out.stdout}\nstderr:\n{out.stderr}"
    return out


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> Dict[str, object]:
    """The wheel, and a fresh venv with it installed: {"wheel", "venv", "bin", "cwd", "env", "seconds"}."""
    base = tmp_path_factory.mktemp("wheel")
    src = base / "src"
    src.mkdir()
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info")
    for name in BUILD_INPUTS:
        (shutil.copytree(REPO / name, src / name, ignore=ignore) if (REPO / name).is_dir()
         else shutil.copy2(REPO / name, src / name))
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "PYTHONSTARTUP")}
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    env["STYLIZE3D_CONFIG_DIR"] = str(base / "config")  # the viewer's recent files stay out of the user's home
    seconds: Dict[str, float] = {}

    t0 = time.perf_counter()
    _run([sys.executable, "-m", "pip", "wheel", "--no-build-isolation", "--no-deps", "--no-index", "-q",
          "-w", base / "dist", "."], src, env)
    seconds["build"] = time.perf_counter() - t0
    (wheel,) = (base / "dist").glob("stylize3d-*.whl")

    t0 = time.perf_counter()
    venv = base / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", venv], base, env)
    python = venv / "bin" / "python"
    # Installed before the .pth exists, so pip sees an empty environment (and never the
    # checkout's editable install).
    _run([sys.executable, "-m", "pip", "--python", python, "install", "--no-deps", "--no-index", "-q", wheel],
         base, env)
    purelib = Path(_run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], base,
                        env).stdout.strip())
    deps = [p for p in site.getsitepackages() if Path(p).is_dir()]
    (purelib / "_stylize3d_test_deps.pth").write_text("".join(f"{p}\n" for p in deps))
    seconds["install"] = time.perf_counter() - t0

    cwd = base / "elsewhere"
    cwd.mkdir()
    return {"wheel": wheel, "venv": venv, "bin": venv / "bin", "cwd": cwd, "env": env, "seconds": seconds,
            "purelib": purelib}


@pytest.fixture(scope="module")
def report(built) -> Dict[str, object]:
    """``stylize3d info --json`` of the install."""
    return json.loads(_run([built["bin"] / "stylize3d", "info", "--json"], built["cwd"], built["env"]).stdout)


def test_the_wheel_carries_every_package_the_model_samples_and_styles(built):
    wheel: Path = built["wheel"]
    names = set(zipfile.ZipFile(wheel).namelist())
    # Every package folder of the source tree is in the wheel (pyproject.toml lists them by hand).
    for top, installed in (("stylize3d", "stylize3d"), ("stylize3d_core", "stylize3d_core"), ("app", "stylize3d_app")):
        for init in (REPO / top).rglob("__init__.py"):
            name = f"{installed}/{init.relative_to(REPO / top).as_posix()}"
            assert name in names, f"{init.parent} is missing from pyproject's packages"
    assert not any(n.startswith("app/") for n in names)  # no top-level package called "app"
    for name in ("model/stylize3d_lite.safetensors", "model/selfie_segmentation.onnx", "model/LICENSE-mediapipe.txt",
                 "model/README.md", "samples/coffee.jpg",
                 "styles/painting_style19_chelsea.jpg", "styles/vangogh_starry_night.jpg", "styles/README.md"):
        assert f"stylize3d_assets/{name}" in names
    assert any(n.endswith(".dist-info/licenses/LICENSE") for n in names)
    assert not any(n.startswith(("tests/", "assets/")) or n.endswith(".jsonl") for n in names)
    size = wheel.stat().st_size
    assert 2_400_000 < size < 5_000_000, f"wheel is {size} bytes"  # the model is 2.5 MB; samples stay small
    print(f"\n{wheel.name}: {size / 1e6:.2f} MB, {len(names)} files; "
          + ", ".join(f"{k} {v:.1f} s" for k, v in built["seconds"].items()))


def test_installed_packages_come_from_the_fresh_venv_not_the_checkout(built):
    code = (
        "import importlib, importlib.metadata as md, json, sys\n"
        f"mods = {{n: importlib.import_module(n).__file__ for n in {OUR_PACKAGES!r}}}\n"
        "from stylize3d_app.viewer.session import DEFAULT_MODEL, SAMPLE_PHOTO, SAMPLE_STYLE\n"
        "viewer = {k: str(v) for k, v in dict(model=DEFAULT_MODEL, photo=SAMPLE_PHOTO, style=SAMPLE_STYLE).items()}\n"
        "dist = str(md.distribution('stylize3d').locate_file('stylize3d_core'))\n"
        "print(json.dumps({'modules': mods, 'viewer': viewer, 'dist': dist,\n"
        "                  'editable_finder': [m for m in sys.modules if 'editable' in m]}))\n"
    )
    out = json.loads(_run([built["bin"] / "python", "-c", code], built["cwd"], built["env"]).stdout)
    venv = Path(built["venv"]).resolve()
    for name, path in list(out["modules"].items()) + list(out["viewer"].items()) + [("dist", out["dist"])]:
        assert venv in Path(path).resolve().parents, f"{name} from {path}, not the fresh venv"
    assert all(Path(p).is_file() for p in out["viewer"].values())  # the viewer's sample, style and model
    assert out["editable_finder"] == []


def test_version_and_info_from_the_install(built, report):
    for cmd in ([built["bin"] / "stylize3d", "--version"], [built["bin"] / "python", "-m", "stylize3d", "--version"]):
        assert _run(cmd, built["cwd"], built["env"]).stdout.strip().startswith("stylize3d 0.")
    venv = Path(built["venv"]).resolve()
    data = report["data"]
    assert data["found_as"] == "installed package"
    assert venv in Path(data["location"]).resolve().parents
    assert Path(data["models"]["lite"]["path"]).is_file() and "coffee.jpg" in data["samples"]["names"]
    assert venv in Path(report["stylize3d"]["library"]).resolve().parents
    assert report["stylize3d"]["installed_version"] == report["stylize3d"]["version"]


def test_render_the_bundled_sample_in_the_bundled_style_from_the_install(built, report):
    import imageio.v3 as iio

    data = report["data"]
    photo = Path(data["samples"]["folder"]) / "coffee.jpg"
    style = Path(data["styles"]["folder"]) / "painting_style19_chelsea.jpg"
    out = _run([built["bin"] / "stylize3d", "render", photo, "--style", style, "--frames", "3", "--size", "96",
                "--max-size", "192", "-o", "coffee_stylized.mp4"], built["cwd"], built["env"])
    assert f"with {data['models']['lite']['path']}" in out.stderr  # the default model is the installed one
    video = iio.imread(built["cwd"] / "coffee_stylized.mp4")
    assert video.shape[0] == 3 and max(video.shape[1:3]) == 96 and video.std() > 5


def _xvfb(screen: str = "800x600x24") -> "tuple[subprocess.Popen, str]":
    """A private Xvfb on a free display number (Xvfb picks it, -displayfd); skips without Xvfb."""
    xvfb = shutil.which("Xvfb")
    if xvfb is None:
        pytest.skip("Xvfb is not installed: the window test needs an X server (apt-get install xvfb)")
    r, w = os.pipe()
    proc = subprocess.Popen([xvfb, "-displayfd", str(w), "-screen", "0", screen, "-nolisten", "tcp"],
                            pass_fds=(w,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    os.close(w)
    with os.fdopen(r, "rb") as f:
        number = f.readline().strip()  # Xvfb writes the number once it listens (EOF if it died)
    if not number.isdigit():
        proc.kill()
        proc.wait()
        pytest.skip("Xvfb did not start: no X server for the window test")
    return proc, f":{int(number)}"


@pytest.mark.gui
def test_the_installed_viewer_opens_its_sample_stylized_with_its_model(built, tmp_path):
    steps = [{"op": "load_sample"}, {"op": "wait_idle", "timeout": 240}, {"op": "state"}, {"op": "quit"}]
    (tmp_path / "steps.json").write_text(json.dumps(steps))
    xvfb, display = _xvfb()
    try:
        subprocess.run([str(built["bin"] / "stylize3d-viewer"), "--max-size", "160", "--size", "800x600",
                        "--test-script", str(tmp_path / "steps.json"), "--test-report", str(tmp_path / "r.json")],
                       cwd=built["cwd"], env={**built["env"], "DISPLAY": display}, capture_output=True,
                       timeout=TIMEOUT_S)
    finally:
        xvfb.terminate()
        xvfb.wait(timeout=10)
    result = json.loads((tmp_path / "r.json").read_text())
    assert result["ok"] and not result["errors"], result
    shown = [s for s in result["steps"] if s["op"] == "wait_idle"][0]["result"]["shown"]
    assert shown["stylized"] is True, "the installed viewer did not find its model"
    state = [s for s in result["steps"] if s["op"] == "state"][0]["result"]
    venv = Path(built["venv"]).resolve()
    for key, path in (("photo", state["spec"]["photo"]), ("style", state["style"])):
        assert venv in Path(path).resolve().parents, f"{key} {path} is not the installed sample"
