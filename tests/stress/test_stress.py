"""Numerical stress cases (stylize3d_core/bench/stress.py): no NaN or inf reaches an image; unusable input is an
InputError naming it. Also the command line's exit status for the same inputs."""

import numpy as np
import pytest
import torch

from stylize3d_app.cli import main
from stylize3d_core.bench import stress
from stylize3d_core.io.images import save_image

CASES = stress.cases()


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_stress_case(case):
    outcome = stress.run_case(case)
    assert outcome.passed, f"{case.name}: {outcome.outcome}: {outcome.detail}"


def test_checker_catches_nan_and_range():
    bad = stress.StressCase("nan", "test", lambda q: [np.full((2, 2, 3), np.nan, np.float32)])
    assert stress.run_case(bad).outcome == "NaN/inf" and not stress.run_case(bad).passed
    big = stress.StressCase("big", "test", lambda q: [np.full((2, 2, 3), 1.5, np.float32)])
    assert stress.run_case(big).outcome == "out of range"
    wrong = stress.StressCase("err", "test", lambda q: [np.zeros((2, 2, 3), np.float32)], expect="error")
    assert not stress.run_case(wrong).passed


def test_bfloat16_close_to_float32():
    p3d = stress.Photo3D.build(stress.make_photo(), stress.depth_map(stress.step_depth(48, 64, 1.0, 3.0)))
    s = stress.stylized(p3d)
    cam = stress.camera(tx=0.03)
    ref = s.render(cam, 32, 40)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        s.set_strength(s.strength)  # the dense features again, under autocast
        low = s.render(cam, 32, 40)
    assert low.dtype == np.float32 and np.isfinite(low).all()
    assert np.abs(low - ref).mean() < 0.05


@pytest.fixture()
def photo(tmp_path):
    path = tmp_path / "photo.png"
    save_image(path, stress.make_photo())
    return path


@pytest.mark.parametrize("fill, status", [("nan_some", 0), ("nan_all", 2)])
def test_cli_bad_depth_files(tmp_path, photo, fill, status, capsys):
    d = stress.step_depth(48, 64, 1.0, 3.0)
    if fill == "nan_some":
        d[::2, ::3] = np.nan
    elif fill == "nan_all":
        d[:] = np.nan
    else:
        d[:] = 0
    np.save(tmp_path / "d.npy", d)
    out = tmp_path / "frames"
    rc = main(["render", str(photo), "--depth", str(tmp_path / "d.npy"), "--frames", "2", "--size", "64",
               "-q", "-o", f"{out}/"])
    err = capsys.readouterr().err
    assert rc == status, err
    if status == 0:
        assert len(list(out.glob("*.png"))) == 2
    else:
        assert "d.npy" in err and not out.exists()


@pytest.mark.parametrize("fov, status", [(5, 0), (200, 2)])
def test_cli_extreme_fov(tmp_path, photo, fov, status, capsys):
    out = tmp_path / "frames"
    rc = main(["render", str(photo), "--depth", "prior", "--fov", str(fov), "--frames", "2", "--size", "64",
               "-q", "-o", f"{out}/"])
    err = capsys.readouterr().err
    assert rc == status, err
    if status:
        assert "fov" in err
    else:
        frames = sorted(out.glob("*.png"))
        assert len(frames) == 2
