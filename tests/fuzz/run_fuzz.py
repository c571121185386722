"""Coverage-guided fuzzing of one target of ``targets.py`` with atheris (libFuzzer).

    python tests/fuzz/run_fuzz.py TARGET [libFuzzer options] NEW_CORPUS_DIR tests/fuzz/corpus/TARGET

CI runs each target for a short budget (``test_fuzz.py``, STYLIZE3D_FUZZ_SECONDS,
default 8 s). For a longer local run, e.g. ten minutes a target::

    mkdir -p /tmp/fz && python tests/fuzz/run_fuzz.py camera_path -max_total_time=600 \\
        -max_len=16384 /tmp/fz tests/fuzz/corpus/camera_path

A crash leaves ``crash-*`` with the input; copy it to ``tests/fuzz/crashes/TARGET/``
(replayed by test_fuzz.py) once it is fixed, and add the small interesting inputs
from /tmp/fz to the corpus.
"""

from __future__ import annotations

import sys

import atheris


import numpy  # noqa: E402,F401  (heavy dependencies are not instrumented)
import torch  # noqa: E402,F401

with atheris.instrument_imports(include=["stylize3d_core"]):
    import stylize3d_core.depth.phone_xmp  # noqa: F401
    import stylize3d_core.io.camera_path  # noqa: F401
    import stylize3d_core.io.depth_files  # noqa: F401
    import stylize3d_core.models.checkpoint  # noqa: F401

import targets  # noqa: E402


def main() -> None:
    name = sys.argv[1]
    if name not in targets.TARGETS:
        sys.exit(f"unknown target {name!r}; one of {', '.join(targets.TARGETS)}")
    atheris.Setup([sys.argv[0]] + sys.argv[2:], lambda data: targets.run_one(name, data))
    atheris.Fuzz()


if __name__ == "__main__":
    main()
