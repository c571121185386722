"""The ``stylize3d bench`` suites: each runs its measurements and writes its tables and plots to a folder.

``--quick`` presets are small enough for a CI test (seconds); the full presets
are for a quiet machine. Every figure is timed with ``eval/timing.py``
(median of repeated runs after a warm-up).
"""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

from .report import Log, progress, quiet, write_table
from .stress import cases as stress_cases, run_case


def run_stress(out: Path, quick: bool = False, show_progress: bool = False, log: Log = quiet) -> List[dict]:
    """Run the stress cases (``--quick``: the small ones without the model, and two with it); write ``stress.md/json``."""
    chosen = stress_cases()
    if quick:
        model_cases = [c for c in chosen if c.stylized][:2]
        chosen = [c for c in chosen if not (c.stylized or c.heavy)] + model_cases
    rows = []
    for case in progress(chosen, len(chosen), "stress", show_progress):
        o = run_case(case, quick)
        rows.append({"case": o.name, "category": o.category, "expected": o.expect, "outcome": o.outcome,
                     "pass": o.passed, "seconds": o.seconds, "detail": o.detail})
    failed = sum(not r["pass"] for r in rows)
    write_table(Path(out), "stress", "Numerical stress cases", rows,
                notes=[f"{len(rows) - failed} of {len(rows)} passed; pass = every image finite and in [0, 1], "
                       "or an InputError where the input is unusable (expected 'error')",
                       "cases: stylize3d_core/bench/stress.py" + (" (--quick subset)" if quick else "")])
    log(f"stress: {len(rows) - failed} of {len(rows)} passed")
    return rows


def run_suite(name: str, out, quick: bool = False, show_progress: bool = False, log: Log = quiet,
              photo: Optional[str] = None, style: Optional[str] = None, model: Optional[str] = None,
              eval_data: Optional[str] = None) -> List[dict]:
    """Run the suite ``name`` (speed, consistency, scaling, stress, skips, targets, floor, quality) and write its tables to ``out``.

    ``model`` and ``eval_data`` are used by ``quality`` only (the checkpoint measured, default the shipped
    one; a held-out dataset folder for the stage-1 PSNR / SSIM)."""
    from ..errors import InputError

    if name == "stress":
        return run_stress(Path(out), quick, show_progress, log)
    if name in ("speed", "skips"):
        from .speed import run_skips, run_speed

        fn = run_speed if name == "speed" else run_skips
        return fn(Path(out), quick, show_progress, log, photo=photo, style=style)
    if name == "consistency":
        from .consistency import run_consistency

        return run_consistency(Path(out), quick, show_progress, log, photo=photo, style=style)
    if name == "scaling":
        from .scaling import run_scaling

        return run_scaling(Path(out), quick, show_progress, log, photo=photo)
    if name == "targets":
        from .targets import run_targets

        return run_targets(Path(out), quick, show_progress, log, photo=photo)
    if name == "floor":
        from .floor import run_floor

        return run_floor(Path(out), quick, show_progress, log, photo=photo)
    if name == "quality":
        from .quality import run_quality

        return run_quality(Path(out), quick, show_progress, log, model=model, eval_data=eval_data)
    raise InputError("suite", f"must be one of speed, consistency, scaling, stress, skips, targets, floor, quality; got {name!r}")
