"""Shipped data (stylize3d_core.resources): finding the model, samples and styles; model names and paths."""

import hashlib
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from stylize3d_core import resources
from stylize3d_core.errors import InputError

REPO = Path(__file__).resolve().parents[1]


def _sha(path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


@pytest.fixture()
def fake_install(tmp_path, monkeypatch):
    """Shipped data at tmp_path/data with samples and styles but no model (an install that lost it)."""
    root = tmp_path / "data"
    for folder in ("samples", "styles"):
        (root / folder).mkdir(parents=True)
    (root / "model").mkdir()
    (root / "samples" / "coffee.jpg").write_bytes((REPO / "assets/samples/coffee.jpg").read_bytes())
    (root / "styles" / "s.jpg").write_bytes(b"not read here")
    (root / "styles" / "notes.txt").write_text("not an image")
    monkeypatch.setattr(resources, "assets_location", lambda: resources.AssetsLocation(root, resources.INSTALLED))
    return root


def test_the_shipped_files_are_found_and_are_the_repository_assets():
    loc = resources.assets_location()
    assert loc.how in (resources.INSTALLED, resources.CHECKOUT)
    assert _sha(resources.model_path("lite")) == _sha(REPO / "assets/model/stylize3d_lite.safetensors")
    assert _sha(resources.sample_photo()) == _sha(REPO / "assets/samples/coffee.jpg")
    assert _sha(resources.style_image()) == _sha(REPO / "assets/styles/vangogh_starry_night.jpg")
    assert {"astronaut.jpg", "chelsea.jpg", "coffee.jpg", "rocket.jpg"} <= set(resources.sample_names())
    assert "texture_voronoi_seed7.jpg" in resources.style_names()
    assert "README.md" not in resources.style_names()


def test_models_by_name_or_path(tmp_path):
    shipped = resources.resolve_model("lite")
    assert Path(shipped) == resources.model_path("lite") and Path(shipped).is_file()
    assert resources.resolve_model(None) == shipped
    assert Path(resources.resolve_model(resources.default_model())) == Path(shipped)
    mine = tmp_path / "mine.safetensors"
    mine.write_bytes(b"x")
    assert resources.resolve_model(mine) == str(mine)  # a path is taken as it is (loading checks its contents)


@pytest.mark.parametrize("spec, needle", [
    ("heavy", "no model of this name"),
    ("runs/nothing_here.safetensors", "model checkpoint not found"),
])
def test_unknown_models_name_the_choices(spec, needle):
    with pytest.raises(InputError) as e:
        resources.resolve_model(spec)
    assert e.value.source == spec and needle in e.value.problem and "lite" in e.value.problem


def test_a_folder_is_not_a_model(tmp_path):
    with pytest.raises(InputError, match="is a folder"):
        resources.resolve_model(tmp_path)


def test_a_named_model_missing_from_the_install_says_so(fake_install):
    for spec in ("lite", None, str(fake_install / "model" / "stylize3d_lite.safetensors")):
        with pytest.raises(InputError) as e:
            resources.resolve_model(spec)
        assert e.value.source == "lite"
        assert "missing from this install" in e.value.problem and str(fake_install / "model") in e.value.problem
    # The rest of the data is still there.
    assert resources.sample_names() == ["coffee.jpg"] and resources.style_names() == ["s.jpg"]
    assert resources.default_model() == str(fake_install / "model" / "stylize3d_lite.safetensors")


def test_render_with_a_missing_shipped_model_exits_2(fake_install, tmp_path, capsys):
    from stylize3d_app.cli import main

    rc = main(["render", str(fake_install / "samples/coffee.jpg"), "--style", str(REPO / "assets/styles/"
               "texture_voronoi_seed7.jpg"), "--model", "lite", "-o", str(tmp_path / "o.mp4"), "-q"])
    assert rc == 2
    assert "lite: the shipped model 'lite' is missing from this install" in capsys.readouterr().err
    assert not (tmp_path / "o.mp4").exists()


def test_unknown_sample_and_style_names_list_what_is_shipped(fake_install):
    with pytest.raises(InputError, match="shipped: coffee.jpg"):
        resources.sample_photo("nope.jpg")
    with pytest.raises(InputError, match="no shipped style image"):
        resources.style_image("../samples/coffee.jpg")  # names only, no paths out of the folder


def test_nothing_installed(monkeypatch):
    monkeypatch.setattr(resources, "assets_location", lambda: resources.AssetsLocation(None, resources.MISSING))
    assert resources.sample_names() == [] and resources.style_names() == []
    assert resources.default_model() == "lite"  # turned into the clear error below
    with pytest.raises(InputError, match="stylize3d_assets is not installed"):
        resources.resolve_model(resources.default_model())
    with pytest.raises(InputError, match="not installed"):
        resources.sample_photo()
    assert not resources.shipped_location("samples/coffee.jpg").is_file()


def test_shipped_files_inside_a_zip_are_extracted(tmp_path):
    """An install imported from a zip (zipimport): the files are copied out to real paths."""
    archive = tmp_path / "data.zip"
    with zipfile.ZipFile(archive, "w") as z:
        z.write(REPO / "assets/__init__.py", "stylize3d_assets/__init__.py")
        z.write(REPO / "assets/samples/coffee.jpg", "stylize3d_assets/samples/coffee.jpg")
        z.write(REPO / "assets/styles/painting_style19_chelsea.jpg",
                "stylize3d_assets/styles/painting_style19_chelsea.jpg")
    code = (
        "from stylize3d_core import resources as r\n"
        "loc = r.assets_location(); assert loc.how == r.INSTALLED and loc.root is None, loc\n"
        "p = r.sample_photo(); assert p.is_file() and 'data.zip' not in str(p), p\n"
        "print(p); print(r.sample_names(), r.style_names())\n"
        "try:\n    r.model_path('lite')\nexcept r.InputError as e:\n    print(e)\n"
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(archive), str(REPO)])}  # the zip first
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=tmp_path,
                         env=env)
    assert out.returncode == 0, out.stderr
    extracted, names, error = out.stdout.splitlines()
    assert not Path(extracted).exists()  # removed again at exit
    assert names == "['coffee.jpg'] ['painting_style19_chelsea.jpg']"
    assert "lite: the shipped model 'lite' is missing from this install" in error
