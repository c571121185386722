"""The declared dependencies: Open3D's Linux-only CPU build on Linux and the full package elsewhere, at one
version, and torch pinned (a loose torch pulls a multi-GB CUDA build)."""

import tomllib
from pathlib import Path

from packaging.requirements import Requirement

PYPROJECT = tomllib.loads((Path(__file__).resolve().parents[1] / "pyproject.toml").read_text(encoding="utf-8"))
REQUIREMENTS = [Requirement(r) for r in PYPROJECT["project"]["dependencies"]]


def _chosen(platform: str):
    env = {"sys_platform": platform}
    return {r.name: str(r.specifier) for r in REQUIREMENTS if r.marker is None or r.marker.evaluate(env)}


def test_open3d_per_platform():
    linux, mac, windows = _chosen("linux"), _chosen("darwin"), _chosen("win32")
    assert "open3d-cpu" in linux and "open3d" not in linux
    for other in (mac, windows):
        assert "open3d" in other and "open3d-cpu" not in other
    assert linux["open3d-cpu"] == mac["open3d"] == windows["open3d"]


def test_torch_is_pinned_everywhere():
    for platform in ("linux", "darwin", "win32"):
        assert _chosen(platform)["torch"].startswith("==")
