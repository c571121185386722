"""Bench output: a table as Markdown and JSON, a scatter plot as PNG (OpenCV, no plotting library).

A table is a list of rows (dicts with the same keys, numbers or text); its JSON
file is ``{"title", "columns", "rows", "notes", "machine"}`` so that a test or a
later run can read it back, and its Markdown file holds the same rows, numbers
rounded to ``digits`` significant figures. Every file is written atomically.
"""

from __future__ import annotations

import json
import math
import os
import platform
import time
from pathlib import Path
from typing import Callable, Dict, Iterable, List, Optional, Sequence, Tuple, TypeVar

import numpy as np

from ..errors import InputError
from ..io.atomic import write_atomically

Row = Dict[str, object]


T = TypeVar("T")
Log = Callable[[str], None]
"""Where a suite reports progress in words (the command line prints it; tests pass a list's append)."""


def quiet(_: str) -> None:
    """A :data:`Log` that says nothing."""
    return None


def progress(items: Iterable[T], total: int, desc: str, enabled: bool) -> Iterable[T]:
    """``items`` with a tqdm progress bar on stderr (or plain, when not ``enabled``)."""
    if not enabled:
        return items
    from tqdm import tqdm

    return tqdm(items, total=total, desc=desc, unit="case", leave=False)


def machine() -> Dict[str, object]:
    """Where a bench ran: CPU count, torch threads, platform, the load average (a busy machine is pessimistic)."""
    import torch

    try:
        load = [round(x, 2) for x in os.getloadavg()]
    except OSError:
        load = []
    return {"platform": platform.platform(), "python": platform.python_version(), "torch": torch.__version__,
            "cpus": os.cpu_count(), "torch_threads": torch.get_num_threads(), "load_average": load,
            "time_utc": time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime())}


def _cell(v: object, digits: int) -> str:
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        if not math.isfinite(v):
            return str(v)
        return f"{v:.{digits}g}"
    return str(v).replace("|", "\\|")


def _json_value(v: object) -> object:
    if isinstance(v, (np.floating, float)):
        v = float(v)
        return v if math.isfinite(v) else str(v)  # JSON has no NaN / inf
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, (np.bool_,)):
        return bool(v)
    return v


def markdown_table(rows: Sequence[Row], columns: Sequence[str], digits: int = 4) -> str:
    lines = ["| " + " | ".join(columns) + " |", "| " + " | ".join("---" for _ in columns) + " |"]
    for r in rows:
        lines.append("| " + " | ".join(_cell(r.get(c, ""), digits) for c in columns) + " |")
    return "\n".join(lines) + "\n"


def write_table(folder: Path, name: str, title: str, rows: Sequence[Row], columns: Optional[Sequence[str]] = None,
                notes: Sequence[str] = (), digits: int = 4) -> Tuple[Path, Path]:
    """Write ``folder/name.md`` and ``folder/name.json``; returns both paths."""
    if not rows:
        raise InputError(name, "no rows to write")
    cols = list(columns) if columns is not None else list(rows[0].keys())
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    info = machine()
    load = ", ".join(str(x) for x in info["load_average"]) or "unknown"
    md = [f"# {title}", "", markdown_table(rows, cols, digits)]
    md += [f"* {n}" for n in notes]
    md += [f"* machine: {info['platform']}, {info['cpus']} CPUs, torch {info['torch']} with {info['torch_threads']} "
           f"threads; load average {load} (figures on a loaded machine are pessimistic); {info['time_utc']} UTC", ""]
    data = {"title": title, "columns": cols, "rows": [{c: _json_value(r.get(c)) for c in cols} for r in rows],
            "notes": list(notes), "machine": info}
    md_path = write_atomically(folder / f"{name}.md", "bench table", lambda p: p.write_text("\n".join(md)))
    js_path = write_atomically(folder / f"{name}.json", "bench table",
                               lambda p: p.write_text(json.dumps(data, indent=2)))
    return md_path, js_path


def pareto_front(points: Sequence[Tuple[float, float]]) -> List[int]:
    """Indices of the points no other point beats on both axes (lower x and higher y are better)."""
    front = []
    for i, (x, y) in enumerate(points):
        dominated = any((x2 <= x and y2 >= y) and (x2 < x or y2 > y) for j, (x2, y2) in enumerate(points) if j != i)
        if not dominated:
            front.append(i)
    return sorted(front, key=lambda i: points[i][0])


def scatter_plot(path: Path, points: Sequence[Tuple[float, float]], labels: Sequence[str], xlabel: str, ylabel: str,
                 title: str, front: Sequence[int] = (), size: Tuple[int, int] = (640, 900),
                 log_x: bool = False) -> Path:
    """A scatter plot PNG: every point labelled (labels moved down where they would overlap, to the left
    near the right edge), the points of ``front`` joined by a red line; ``log_x``: a logarithmic x axis
    (positive x only)."""
    import cv2

    h, w = size
    img = np.full((h, w, 3), 255, np.uint8)
    left, right, top, bottom = 70, 30, 40, 60
    xs = np.array([p[0] for p in points], float)
    ys = np.array([p[1] for p in points], float)
    if log_x:
        with np.errstate(divide="ignore", invalid="ignore"):
            xs = np.where(xs > 0, np.log10(np.where(xs > 0, xs, 1.0)), np.nan)
    ok = np.isfinite(xs) & np.isfinite(ys)
    if not ok.any():
        xs, ys, ok = np.zeros(1), np.zeros(1), np.ones(1, bool)
    x0, x1 = xs[ok].min(), xs[ok].max()
    y0, y1 = ys[ok].min(), ys[ok].max()
    x1, y1 = (x1 if x1 > x0 else x0 + 1.0), (y1 if y1 > y0 else y0 + 1.0)
    pad_x, pad_y = 0.05 * (x1 - x0), 0.08 * (y1 - y0)
    x0, x1, y0, y1 = x0 - pad_x, x1 + pad_x, y0 - pad_y, y1 + pad_y

    def px(x: float, y: float) -> Tuple[int, int]:
        return (int(left + (x - x0) / (x1 - x0) * (w - left - right)),
                int(h - bottom - (y - y0) / (y1 - y0) * (h - top - bottom)))

    black, grey, red, blue = (0, 0, 0), (200, 200, 200), (0, 0, 220), (200, 90, 0)
    cv2.rectangle(img, (left, top), (w - right, h - bottom), black, 1)
    for k in range(5):
        fx, fy = x0 + (x1 - x0) * k / 4, y0 + (y1 - y0) * k / 4
        gx, _ = px(fx, y0)
        _, gy = px(x0, fy)
        cv2.line(img, (gx, top), (gx, h - bottom), grey, 1)
        cv2.line(img, (left, gy), (w - right, gy), grey, 1)
        cv2.putText(img, f"{10 ** fx if log_x else fx:.3g}", (gx - 15, h - bottom + 18), cv2.FONT_HERSHEY_SIMPLEX,
                    0.4, black, 1)
        cv2.putText(img, f"{fy:.3g}", (5, gy + 4), cv2.FONT_HERSHEY_SIMPLEX, 0.4, black, 1)
    cv2.putText(img, xlabel, (w // 2 - 80, h - 15), cv2.FONT_HERSHEY_SIMPLEX, 0.5, black, 1)
    cv2.putText(img, ylabel, (5, 25), cv2.FONT_HERSHEY_SIMPLEX, 0.5, black, 1)
    cv2.putText(img, title, (w // 2 - 120, 25), cv2.FONT_HERSHEY_SIMPLEX, 0.55, black, 1)
    fr = [i for i in front if ok[i]]
    for a, b in zip(fr, fr[1:]):
        cv2.line(img, px(xs[a], ys[a]), px(xs[b], ys[b]), red, 2)
    placed: List[Tuple[int, int, int]] = []  # (x0, x1, y) of the labels so far
    for i in sorted(np.flatnonzero(ok), key=lambda j: (-ys[j], xs[j])):
        c = px(xs[i], ys[i])
        cv2.circle(img, c, 5, red if i in fr else blue, -1)
        text = str(labels[i])[:32]
        tw = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, 0.35, 1)[0][0]
        lx = c[0] + 6 if c[0] + 6 + tw < w - 2 else c[0] - 6 - tw
        ly = c[1] - 6
        while any(abs(ly - py) < 11 and lx < px1 and lx + tw > px0 for px0, px1, py in placed):
            ly += 11
        placed.append((lx, lx + tw, ly))
        cv2.putText(img, text, (lx, ly), cv2.FONT_HERSHEY_SIMPLEX, 0.35, black, 1)
    path = Path(path)

    def write(tmp: Path) -> None:
        ok_, buf = cv2.imencode(".png", img)
        tmp.write_bytes(buf.tobytes())

    return write_atomically(path, "bench plot", write)
