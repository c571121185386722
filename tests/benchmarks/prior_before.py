"""The built-in depth prior as it was at an earlier git revision, for before/after comparisons.

``load_prior_at(rev)`` reads ``stylize3d_core/depth/prior.py`` and
``foreground.py`` at ``rev`` with ``git show`` and imports them as stand-alone
modules (their relative imports pointed at the current library for everything
else), so the benchmarks and tools can run the old prior beside the new one
without a second checkout.
"""

from __future__ import annotations

import re
import subprocess
import sys
import types
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

BEFORE_REV = "facfcea"
"""The revision of the prior before issue 36's rework (the branch point of ``depth-prior``)."""


def _source(rev: str, path: str) -> str:
    return subprocess.run(["git", "show", f"{rev}:{path}"], cwd=ROOT, check=True, capture_output=True,
                          text=True).stdout


def _load(name: str, text: str) -> types.ModuleType:
    text = text.replace("from .foreground import", "from _prior_before_foreground import")
    text = re.sub(r"^from \.\.", "from stylize3d_core.", text, flags=re.M)
    text = re.sub(r"^from \.", "from stylize3d_core.depth.", text, flags=re.M)
    module = types.ModuleType(name)
    module.__file__ = f"<{name}>"
    sys.modules[name] = module
    exec(compile(text, module.__file__, "exec"), module.__dict__)
    return module


def load_prior_at(rev: str = BEFORE_REV) -> types.ModuleType:
    """The ``prior`` module at ``rev`` (its ``estimate_prior`` and ``PriorSettings``)."""
    _load("_prior_before_foreground", _source(rev, "stylize3d_core/depth/foreground.py"))
    return _load("_prior_before", _source(rev, "stylize3d_core/depth/prior.py"))
