"""Fuzzing the parsers of user files (targets.py): a bounded atheris run per target, and replays.

The atheris runs are short in CI (STYLIZE3D_FUZZ_SECONDS, default 8 s per target);
run_fuzz.py documents a longer local run. The committed corpus and every crash
found so far (tests/fuzz/crashes/TARGET/) are replayed without atheris.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
_spec = importlib.util.spec_from_file_location("fuzz_targets", HERE / "targets.py")  # tests are no package
targets = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(targets)

BUDGET_S = int(os.environ.get("STYLIZE3D_FUZZ_SECONDS", "8"))


def _inputs(kind: str):
    for target in targets.TARGETS:
        folder = HERE / kind / target
        for path in sorted(folder.iterdir()) if folder.is_dir() else ():
            yield pytest.param(target, path, id=f"{target}/{path.name}")


def test_every_target_has_a_corpus():
    for target in targets.TARGETS:
        files = list((HERE / "corpus" / target).iterdir())
        assert files and sum(f.stat().st_size for f in files) < 64 * 1024, target


@pytest.mark.parametrize("target, path", list(_inputs("corpus")))
def test_corpus_replays(target, path):
    targets.run_one(target, path.read_bytes())


@pytest.mark.parametrize("target, path", list(_inputs("crashes")))
def test_crashes_found_are_refused_cleanly(target, path):
    """Every input that once crashed a parser now gets an InputError (or, if listed in KNOWN_OPEN, is open)."""
    targets.run_one(target, path.read_bytes())


def test_npy_header_tokenerror_is_an_input_error():
    """Found by the fuzzer: a corrupt .npy header made np.load raise tokenize.TokenError."""
    data = (HERE / "crashes" / "depth_file" / "npy-header-tokenerror").read_bytes()
    targets.run_one("depth_file", data, known_open=False)


def test_extended_xmp_length_is_checked_before_allocating():
    """Found by the fuzzer (out of memory in CI): a 4-byte extended-XMP length of 4 GB was allocated first."""
    import tracemalloc

    from stylize3d_core.depth.phone_xmp import read_embedded_depth
    from stylize3d_core.errors import InputError

    data = (HERE / "crashes" / "phone_jpeg" / "extended-xmp-huge-length").read_bytes()
    tracemalloc.start()
    try:
        with pytest.raises(InputError, match="incomplete"):
            read_embedded_depth(data, "p.jpg")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 16 * 2**20


def test_seed_inputs_reach_the_parsers_deep_paths(tmp_path):
    """The seeds are valid files, so mutations start from inputs that get past the first checks."""
    from stylize3d_core.depth.phone_xmp import read_embedded_depth
    from stylize3d_core.io.camera_path import load_camera_path
    from stylize3d_core.io.depth_files import read_depth_values

    seed = (HERE / "corpus" / "camera_path" / "stylize3d").read_bytes()[1:]
    (tmp_path / "c.json").write_bytes(seed)
    assert len(load_camera_path(tmp_path / "c.json").cameras) == 2
    for name, suffix in zip(("png16", "npy", "pfm", "tiff"), targets.DEPTH_SUFFIXES):
        (tmp_path / f"d{suffix}").write_bytes((HERE / "corpus" / "depth_file" / name).read_bytes()[1:])
        assert read_depth_values(tmp_path / f"d{suffix}")[0].shape == (6, 8)
    assert read_embedded_depth((HERE / "corpus" / "phone_jpeg" / "gdepth").read_bytes(), "p.jpg") is not None


@pytest.mark.slow
@pytest.mark.skipif(importlib.util.find_spec("atheris") is None, reason="atheris is not installed (test extra)")
@pytest.mark.parametrize("target", list(targets.TARGETS))
def test_fuzz_target(target, tmp_path):
    new = tmp_path / "new"
    new.mkdir()
    cmd = [sys.executable, str(HERE / "run_fuzz.py"), target, f"-max_total_time={BUDGET_S}",
           f"-max_len={targets.MAX_LEN}", "-timeout=20", "-rss_limit_mb=3072", f"-artifact_prefix={tmp_path}/",
           str(new), str(HERE / "corpus" / target)]
    env = {**os.environ, "TMPDIR": str(tmp_path)}  # libFuzzer exits without atexit: its files stay in tmp_path
    run = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=BUDGET_S + 240)
    crashes = sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(("crash-", "timeout-", "oom-")))
    # atheris prints an uncaught exception's traceback on stdout, libFuzzer its own report on stderr
    assert run.returncode == 0 and not crashes, f"{crashes}\n{run.stdout[-4000:]}\n{run.stderr[-2000:]}"
    assert "Done" in run.stderr  # libFuzzer finished its budget
