"""``bench_viewer.py --window``: the real viewer window under Xvfb driven by real mouse events, its frame log
and the CPU time of each thread by role (imported by that script from its own folder)."""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Dict, List, Optional, Tuple

from stylize3d_app.viewer.backend import backend_choice
from stylize3d_app.viewer.session import SAMPLE_PHOTO, SAMPLE_STYLE


def big_sample(megapixels: float, tmp: str) -> Tuple[str, Tuple[int, int]]:
    """The sample photo upscaled (bicubic) to ``megapixels``, written to ``tmp``: (path, (H, W))."""
    import cv2
    import numpy as np

    from stylize3d_core.io.images import load_image, save_image

    rgb = load_image(str(SAMPLE_PHOTO)).rgb
    h, w = rgb.shape[:2]
    scale = (megapixels * 1e6 / (h * w)) ** 0.5
    big = cv2.resize(rgb, (int(round(w * scale)), int(round(h * scale))), interpolation=cv2.INTER_CUBIC)
    path = str(Path(tmp) / "sample_big.png")
    save_image(path, np.clip(big, 0, 1))
    return path, big.shape[:2]


def window_figures(stats: Dict[str, list], drags: List[Tuple[float, float, bool]]) -> Dict[str, List[float]]:
    """The figures of the window run from the viewer's frame log ``stats`` (``ViewerWindow.stats``, times
    in ``time.monotonic()``) and the drags sent ``(mouse-down, mouse-up, second drag of a pair)``."""
    shown = sorted(stats["preview_shown"])
    levels, fulls = sorted(stats["level_shown"]), sorted(stats["full_shown"])
    out: Dict[str, List[float]] = {k: [] for k in ("fps", "first_ms", "second_first_ms", "sharp_s", "full_s")}
    for i, (down, up, second) in enumerate(drags):
        moving = [t for t in shown if down <= t <= up]
        out["fps"].append(len(moving) / (up - down))
        first = [t for t in shown + levels + fulls if t > down]
        out["second_first_ms" if second else "first_ms"].append(1000 * (min(first) - down) if first else float("nan"))
        if second:  # a long rest follows it
            nxt = drags[i + 1][0] if i + 1 < len(drags) else float("inf")
            sharp = [t - up for t in levels + fulls if up < t < nxt]
            full = [t - up for t in fulls if up < t < nxt]
            out["sharp_s"].append(min(sharp) if sharp else float("nan"))
            out["full_s"].append(min(full) if full else float("nan"))
    return out


def thread_cpu(pid: int) -> Dict[int, Tuple[str, float]]:
    """CPU seconds (user + system) of each thread of process ``pid``: {thread id: (name, seconds)}, from
    /proc (empty where there is none)."""
    out: Dict[int, Tuple[str, float]] = {}
    tick = os.sysconf("SC_CLK_TCK")
    try:
        tids = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return out
    for tid in tids:
        try:
            raw = Path(f"/proc/{pid}/task/{tid}/stat").read_text()
        except OSError:
            continue
        name = raw[raw.index("(") + 1:raw.rindex(")")]
        fields = raw[raw.rindex(")") + 2:].split()
        out[int(tid)] = (name, (int(fields[11]) + int(fields[12])) / tick)
    return out


def cpu_by_role(before: Dict[int, Tuple[str, float]], after: Dict[int, Tuple[str, float]],
                roles: Dict[str, int]) -> Dict[str, float]:
    """CPU seconds spent between two :func:`thread_cpu` snapshots, summed by role: the threads named in
    ``roles`` (role -> thread id: "main", "worker"), the software renderer's ("llvmpipe"), the rest ("other")."""
    by_id = {tid: role for role, tid in roles.items()}
    out: Dict[str, float] = {}
    for tid, (name, sec) in after.items():
        role = by_id.get(tid) or ("llvmpipe" if name.startswith("llvmpipe") else "other")
        out[role] = out.get(role, 0.0) + sec - before.get(tid, (name, 0.0))[1]
    return out


FRAME_LOG = ("kind", "side", "requested", "wait", "render", "split", "convert", "resize", "image", "post",
             "update", "coalesced")
"""The columns of ``ViewerWindow.stats["frame_log"]``: one row per frame shown (kind 0 preview, 1 a first level,
2 full size; long side; perf_counter of the request; seconds waiting for the worker, rendering (the library),
composing a split view, converting to 8 bits, resizing, making the Open3D image, from the worker's end to
the GUI thread's turn, handing it to the widget; frames replaced in the hand-over slot so far)."""


def window(model: str, megapixels: float, tmp: str, max_size: int, repeats: int, threads: int,
           plain: bool = False, render_backend: Optional[str] = None, save_report: Optional[str] = None,
           full_threads: Optional[int] = None, decoder_threads: Optional[int] = None) -> None:
    """The viewer in its own process on Xvfb, driven with real XTest drags (see the module docstring)."""
    import json
    import multiprocessing

    import numpy as np

    from stylize3d_app.viewer import run_viewer_process
    from stylize3d_app.viewer.xserver import start_xvfb, xtest_libs

    screen = (1280, 800)
    libs, server = xtest_libs(), start_xvfb(screen)
    if libs is None or server is None:
        print("window: needs Xvfb and libXtst (apt-get install xvfb libxtst6); skipped")
        if server is not None:
            server[0].terminate()
        return
    lx, lt = libs
    xproc, display = server
    path, big_hw = big_sample(megapixels, tmp)
    script, report = Path(tmp) / "steps.json", Path(tmp) / "report.json"
    drag_s, gap_s, rest_s = 1.5, 0.3, 3.0
    script.write_text(json.dumps([
        {"op": "wait_idle", "timeout": 600},
        {"op": "grab_window", "path": str(Path(tmp) / "window.png")},
        {"op": "sleep", "seconds": repeats * (2 * drag_s + gap_s + rest_s) + 2.0},  # the drags happen now
        {"op": "wait_idle", "timeout": 120},
        {"op": "quit"},
    ]))
    argv = [path, "--style", str(SAMPLE_STYLE), *(["--no-model"] if plain else ["--model", model]),
            "--max-size", str(max_size or max(big_hw)),
            "--threads", str(threads), "--size", f"{screen[0]}x{screen[1]}",
            *(["--render-backend", render_backend] if render_backend else []),
            *(["--full-threads", str(full_threads)] if full_threads else []),
            *(["--decoder-threads", str(decoder_threads)] if decoder_threads else []),
            "--test-script", str(script), "--test-report", str(report)]
    proc = multiprocessing.get_context("spawn").Process(target=run_viewer_process, args=(argv, display))
    proc.start()
    drags: List[Tuple[float, float, bool]] = []
    try:
        box = None
        t_end = time.monotonic() + 600
        while box is None and time.monotonic() < t_end and proc.is_alive():
            try:
                rep = json.loads(report.read_text())
                box = next((s["result"]["box"] for s in rep["steps"] if s["op"] == "grab_window"), None)
            except (OSError, ValueError, KeyError, TypeError):
                pass
            time.sleep(0.1)
        if box is None:
            print("window: the viewer did not open the photo")
            return
        x0, y0, x1, y1 = box
        x, y = x0 + (x1 - x0) // 4, (y0 + y1) // 2
        dpy = lx.XOpenDisplay(display.encode())
        try:
            def drag(dx: int) -> Tuple[float, float]:
                lt.XTestFakeMotionEvent(dpy, -1, x, y, 0)
                lx.XFlush(dpy)
                time.sleep(0.05)
                down = time.monotonic()
                lt.XTestFakeButtonEvent(dpy, 1, 1, 0)
                lx.XFlush(dpy)
                n = int(drag_s * 60)
                for i in range(1, n + 1):
                    time.sleep(max(0.0, down + i / 60 - time.monotonic()))
                    lt.XTestFakeMotionEvent(dpy, -1, x + dx * i, y, 0)
                    lx.XFlush(dpy)
                lt.XTestFakeButtonEvent(dpy, 1, 0, 0)
                lx.XFlush(dpy)
                return down, time.monotonic()

            cpu = []
            for _ in range(repeats):
                before = thread_cpu(proc.pid)
                first = drag(2)
                drags.append((*first, False))
                cpu.append((first[1] - first[0], before, thread_cpu(proc.pid)))  # the first drag's CPU
                time.sleep(gap_s)  # the first rest's full frame is rendering when the second drag starts
                drags.append((*drag(-2), True))
                time.sleep(rest_s)
        finally:
            lx.XCloseDisplay(dpy)
        proc.join(300)
        rep = json.loads(report.read_text())
        if save_report:  # the window's own report (its frame log) and the drags sent, for a closer look
            Path(save_report).write_text(json.dumps({"report": rep, "drags": drags}))
    finally:
        if proc.is_alive():
            proc.kill()
            proc.join(10)
        xproc.terminate()
        xproc.wait(10)
    stats = rep.get("stats") or {}
    if not stats:
        print(f"window: no frame log in the report (ok {rep.get('ok')}, errors {rep.get('errors')})")
        return
    fig = window_figures(stats, drags)
    med = lambda v: float(np.nanmedian(v)) if len(v) and not np.all(np.isnan(v)) else float("nan")  # noqa: E731
    rng = lambda v: f"{np.nanmin(v):.2f}-{np.nanmax(v):.2f}" if v else "-"  # noqa: E731
    h, w = big_hw
    loaded = max_size or max(big_hw)
    side = stats.get("preview_sides", [])
    print(f"window (Xvfb, real XTest drags, {'no model: the plain 3D photo' if plain else 'model ' + Path(model).name}"
          f", torch threads {threads}, render back end {backend_choice(render_backend)}): photo {w}x{h} "
          f"({w * h / 1e6:.2f} MP) opened at long side {loaded}; {len(drags)} drags; load average "
          f"{os.getloadavg()[0]:.1f}")
    print(f"  frames shown while dragging: {med(fig['fps']):5.1f} fps median (range {rng(fig['fps'])})"
          + (f", previews {min(side)}-{max(side)} px" if side else ""))
    print(f"  mouse-down to first new frame: {med(fig['first_ms']):5.0f} ms (first drag), "
          f"{med(fig['second_first_ms']):5.0f} ms (second drag 0.3 s after the first, while its full frame renders)")
    sizes = stats.get("level_sizes", [])
    full_sizes = stats.get("full_sizes", [])
    print(f"  mouse-up to first full-quality frame: {med(fig['sharp_s']):5.2f} s median (range {rng(fig['sharp_s'])})"
          + (f" at {sizes[-1][1]}x{sizes[-1][0]}" if sizes else ""))
    print(f"  mouse-up to the full-size frame:      {med(fig['full_s']):5.2f} s median (range {rng(fig['full_s'])})"
          + (f" at {full_sizes[-1][1]}x{full_sizes[-1][0]}" if full_sizes else ""))
    jumps = stats.get("colour_jump", [])
    for label, keep in (("first full-quality frame", lambda j: True),):
        js = [j for j in jumps if keep(j)]
        if js:
            print(f"  colour jump last preview -> {label}: {med([j[1] for j in js]):.2f} levels mean colour, "
                  f"{med([j[2] for j in js]):.1f} mean pixel difference ({len(js)} releases)")
    print(f"  full renders interrupted by a new drag: {stats.get('interrupted', ['?'])[-1]}")
    print(f"  where the time goes (medians): preview render {1000 * med(stats['preview_seconds']):.0f} ms on the worker, "
          f"worker -> GUI thread hand-over {1000 * med(stats['post_delay']):.0f} ms, request -> shown "
          f"{1000 * med(stats['preview_latency']):.0f} ms; {len(stats['drag_moves'])} mouse moves received "
          f"of {sum(int(drag_s * 60) for _ in drags)} sent, {len(stats.get('drag_clamped', []))} of them at the "
          f"camera range's limit (no new view: frames shown while dragging count only moving time when this is 0)")
    log = [dict(zip(FRAME_LOG, row)) for row in stats.get("frame_log", [])]
    if os.environ.get("STYLIZE3D_BENCH_FRAME_LOG"):  # every frame shown, for a closer look
        Path(os.environ["STYLIZE3D_BENCH_FRAME_LOG"]).write_text(json.dumps(log))
    prev = [r for r in log if r["kind"] == 0]
    if prev:
        ms = lambda key: 1000 * float(np.median([r[key] for r in prev]))  # noqa: E731
        n_prev = len(prev)
        print(f"  per preview shown ({n_prev} previews, medians, ms): waiting for the worker {ms('wait'):.1f}, "
              f"render (library) {ms('render'):.1f}, split {ms('split'):.1f}, to 8 bits {ms('convert'):.2f}, "
              f"resize {ms('resize'):.2f}, Open3D image {ms('image'):.2f}, worker -> GUI thread {ms('post'):.1f}, "
              f"widget update {ms('update'):.2f}; frames replaced before the GUI thread took them: "
              f"{log[-1]['coalesced']}")
    moves = sorted(stats.get("drag_moves", []))
    firsts = []  # per drag: the first move received, the first frame's request, its wait, render, hand-over, shown
    for down, up, _ in drags:
        row = next((r for r in log if r["requested"] > down), None)
        move = next((t for t in moves if t > down), None)
        if row is not None and move is not None:
            done = row["requested"] + row["wait"] + row["render"] + row["split"] + row["convert"] + row["image"]
            firsts.append([move - down, row["requested"] - down, row["wait"], row["render"], row["post"],
                           done + row["post"] + row["update"] - down, row["side"]])
    if firsts:
        f = np.median(np.array(firsts, np.float64), axis=0)
        print(f"  mouse-down to first frame, by stage (medians of {len(firsts)} drags, ms): first move received "
              f"{1000 * f[0]:.0f}, preview requested {1000 * f[1]:.0f}, waiting for the worker {1000 * f[2]:.0f}, "
              f"render {1000 * f[3]:.0f} ({int(f[6])} px), worker -> GUI thread {1000 * f[4]:.0f}, on screen "
              f"(widget updated) {1000 * f[5]:.0f}")
    gap_f, gap = stats.get("tick_gap_frame", []), stats.get("tick_gap", [])
    if gap_f and gap:
        print(f"  GUI loop turn after a new frame (its redraw) {1000 * med(gap_f):.0f} ms median "
              f"(p90 {1000 * np.percentile(gap_f, 90):.0f}), without one {1000 * med(gap):.0f} ms; mouse callback "
              f"{1000 * med(stats.get('mouse_cb', [])):.2f} ms median")
    roles = {k: int(v) for k, v in (stats.get("threads") or {}).items()}
    if cpu and roles:
        total: Dict[str, float] = {}
        wall = sum(c[0] for c in cpu)
        for _, a, b in cpu:
            for role, sec in cpu_by_role(a, b, roles).items():
                total[role] = total.get(role, 0.0) + sec
        print("  CPU while dragging (cores busy, of 2): " + ", ".join(
            f"{role} {sec / wall:.2f}" for role, sec in sorted(total.items(), key=lambda kv: -kv[1])))
    ticks = np.diff(sorted(stats.get("drag_ticks", [])))
    ticks = ticks[ticks < 1.0]  # within a drag
    if len(ticks):
        print(f"  GUI loop while dragging: an iteration every {1000 * np.median(ticks):.0f} ms median "
              f"(p90 {1000 * np.percentile(ticks, 90):.0f} ms): Open3D's event handling and redraw (llvmpipe)")
