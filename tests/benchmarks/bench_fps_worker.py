"""Farthest point sampling in this process against its worker process (``stylize3d_core/points/sampling.py``).

fpsample holds the GIL for the whole call. Per cloud size N (uniform random points, N -> N/4), prints:

* the sampling's time in this process and in the worker (median of ``--repeats``), and whether the indices
  are the same;
* the longest gap of a main-thread loop (``time.sleep(0.005)`` in a loop) while the sampling runs in another
  thread: what a GUI's event loop would wait;
* with ``--photo-mp M``: ``prepare_geometry`` of the sample photo resized to M megapixels, in-process and with
  the worker, interleaved, where the sampling of each level runs beside the level's k-NN search.

No timing is asserted; pause other work (or say the load) when you quote the figures.

    .venv/bin/python -m benchmarks.bench_fps_worker [--sizes 75000 300000] [--repeats 3] [--photo-mp 1.0]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import torch

from stylize3d_core.eval.timing import median_time
from stylize3d_core.points import farthest_point_sample
from stylize3d_core.points import sampling


def longest_gap(run) -> float:
    """Longest wait of a main-thread loop of 5 ms sleeps while ``run()`` works in another thread."""
    done = threading.Event()
    worker = threading.Thread(target=lambda: (run(), done.set()))
    gaps, last = [], time.perf_counter()
    worker.start()
    while not done.is_set():
        time.sleep(0.005)
        now = time.perf_counter()
        gaps.append(now - last)
        last = now
    worker.join()
    return max(gaps) if gaps else 0.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[75_000, 300_000])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--photo-mp", type=float, default=None)
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f}, torch threads {torch.get_num_threads()}")
    sampling.start_fps_process()
    farthest_point_sample(torch.rand(sampling.PROCESS_MIN_POINTS, 3), 10)  # the worker's imports done
    for n in args.sizes:
        xyz = torch.rand(n, 3, generator=torch.Generator().manual_seed(n))
        m = n // 4
        out = {}
        for mode in (False, True):
            sampling.set_fps_process(mode)
            if mode:
                sampling.start_fps_process()
                farthest_point_sample(xyz[: sampling.PROCESS_MIN_POINTS], 10)
            out[mode] = (median_time(lambda: farthest_point_sample(xyz, m), args.repeats),
                         longest_gap(lambda: farthest_point_sample(xyz, m)), farthest_point_sample(xyz, m))
        same = torch.equal(out[False][2], out[True][2])
        print(f"N = {n:,} -> {m:,}: in-process {out[False][0]:.3f} s (main thread waits up to {out[False][1]:.3f} s); "
              f"worker {out[True][0]:.3f} s (waits up to {out[True][1]:.3f} s); same indices: {same}")
    if args.photo_mp:
        from stylize3d_core.bench.photos import photo_at_megapixels
        from stylize3d_core.models.checkpoint import load_checkpoint
        from stylize3d_core.models.scene_geometry import prepare_geometry
        from stylize3d_core.pipeline import PhotoSpec, load_photo3d
        from stylize3d_core.resources import resolve_model

        with tempfile.TemporaryDirectory() as tmp:
            p3d = load_photo3d(PhotoSpec(photo=str(photo_at_megapixels(args.photo_mp, Path(tmp))), depth="prior"))
        hood = load_checkpoint(resolve_model(None)).model.config.neighbourhood
        pts = p3d.points.to_tensors()
        times = {False: [], True: []}
        for _ in range(args.repeats):
            for mode in (False, True):
                sampling.set_fps_process(mode)
                sampling.start_fps_process()
                time.sleep(0.5)
                t0 = time.perf_counter()
                with torch.inference_mode():
                    prepare_geometry(pts.xyz, pts.rgb, p3d.fov_y_deg, p3d.size, hood)
                times[mode].append(time.perf_counter() - t0)
        print(f"prepare_geometry, {args.photo_mp:g} MP photo ({pts.xyz.shape[0]:,} points), median of "
              f"{args.repeats}: in-process {np.median(times[False]):.2f} s, worker {np.median(times[True]):.2f} s")
    sampling.set_fps_process(True)


if __name__ == "__main__":
    main()
