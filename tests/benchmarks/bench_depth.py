"""Depth sources on this CPU (prints figures; asserts nothing).

    .venv/bin/python tests/benchmarks/bench_depth.py [--repeats 5]

Reports the median (and minimum, the least disturbed run on a shared machine)
over ``--repeats`` runs after one warm-up:

* the built-in prior on the bundled sample photos scaled to 0.25, 1 and 2 MP
  (target: well under 2 s at 1 MP);
* stereo (SGBM + left-right check + hole filling) on scikit-image's motorcycle
  pair at full resolution, and its bad-pixel rate (|d - d_gt| > 2 px) over the
  pixels with ground truth;
* the ONNX runner's overhead: ``OnnxDepth.estimate`` on a 1 MP photo minus the
  bare ``InferenceSession.run`` on the prepared input, for a tiny model
  exported here (so the model itself costs ~nothing), at the MiDaS (384^2) and
  Depth Anything (518^2) presets;
* edge alignment (refine) at 1 MP.
"""

from __future__ import annotations

import argparse
import tempfile
import warnings
from pathlib import Path
from typing import Callable, Tuple

import cv2
import numpy as np


from stylize3d_core.depth.onnx_model import PRESETS, OnnxDepthModel, OnnxSettings  # noqa: E402
from stylize3d_core.depth.prior import estimate_prior  # noqa: E402
from stylize3d_core.depth.refine import RefineSettings, refine_disparity  # noqa: E402
from stylize3d_core.depth.stereo import compute_disparity  # noqa: E402
from stylize3d_core.eval.timing import median_and_min  # noqa: E402

SAMPLES = ("astronaut", "chelsea", "coffee", "rocket")


def timed(fn: Callable[[], object], repeats: int) -> Tuple[float, float]:
    """(median s, min s) of ``fn`` after one warm-up call."""
    return median_and_min(fn, repeats, warmup=1)


def photo_at(name: str, megapixels: float) -> np.ndarray:
    """A scikit-image sample scaled (bicubic) to about ``megapixels``, (H, W, 3) float32 in [0, 1]."""
    from skimage import data

    img = getattr(data, name)()
    s = (megapixels * 1e6 / (img.shape[0] * img.shape[1])) ** 0.5
    big = cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_CUBIC)
    return big.astype(np.float32) / 255.0


def bench_prior(repeats: int) -> None:
    print("built-in prior (median / min of runs):")
    for mp in (0.25, 1.0, 2.0):
        for name in SAMPLES:
            rgb = photo_at(name, mp)
            med, best = timed(lambda: estimate_prior(rgb), repeats)
            h, w = rgb.shape[:2]
            print(f"  {name:10s} {w}x{h} ({w * h / 1e6:.2f} MP): {med:.2f} s / {best:.2f} s")


def bench_stereo(repeats: int) -> None:
    from skimage import data

    left, right, gt = data.stereo_motorcycle()
    lf, rf = left.astype(np.float32) / 255.0, right.astype(np.float32) / 255.0
    result = compute_disparity(lf, rf)
    has_gt = np.isfinite(gt)
    err = np.abs(result.disparity - gt)
    bad_all = float((err[has_gt] > 2).mean())
    bad_valid = float((err[has_gt & result.valid] > 2).mean())
    med, best = timed(lambda: compute_disparity(lf, rf), repeats)
    h, w = gt.shape
    print(f"stereo, motorcycle pair {w}x{h} (full resolution):")
    print(f"  bad-pixel rate (|d - d_gt| > 2 px): {100 * bad_all:.1f}% over all pixels with ground truth "
          f"(holes filled); {100 * bad_valid:.1f}% over the {100 * result.valid[has_gt].mean():.0f}% passing "
          "the left-right check")
    print(f"  time: {med:.2f} s / {best:.2f} s")


def bench_onnx(repeats: int) -> None:
    import torch

    class Tiny(torch.nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.conv = torch.nn.Conv2d(3, 1, 1)

        def forward(self, x: torch.Tensor) -> torch.Tensor:
            return torch.nn.functional.softplus(self.conv(x))

    rgb = photo_at("coffee", 1.0)
    h, w = rgb.shape[:2]
    print(f"ONNX runner overhead, {w}x{h} photo, tiny 1x1-conv model (estimate() minus session.run):")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "tiny.onnx"
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            torch.onnx.export(Tiny().eval(), (torch.rand(1, 3, 64, 64),), str(path), input_names=["image"],
                              output_names=["depth"], dynamic_axes={"image": {2: "h", 3: "w"}}, dynamo=False)
        for preset in ("midas", "depth_anything"):
            model = OnnxDepthModel(path, OnnxSettings(preset=PRESETS[preset]))
            x = model.preprocess(rgb)
            run_med, _ = timed(lambda: model.session.run(None, {model.input_name: x}), repeats)
            total_med, total_min = timed(lambda: model.estimate(rgb), repeats)
            ih, iw = x.shape[2:]
            print(f"  {preset:15s} input {iw}x{ih}: estimate {1000 * total_med:.0f} ms, session.run "
                  f"{1000 * run_med:.0f} ms -> overhead {1000 * (total_med - run_med):.0f} ms")


def bench_refine(repeats: int) -> None:
    rgb = photo_at("astronaut", 1.0)
    disp = estimate_prior(rgb).nearness
    print(f"edge alignment on {rgb.shape[1]}x{rgb.shape[0]}:")
    for s in (RefineSettings(), RefineSettings(radius=2), RefineSettings(method="joint_bilateral"),
              RefineSettings(method="guided")):
        med, best = timed(lambda: refine_disparity(disp, rgb, s), max(1, repeats // 2))
        print(f"  {s.method:16s} radius {s.radius}: {med:.2f} s / {best:.2f} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    bench_prior(args.repeats)
    bench_stereo(args.repeats)
    bench_onnx(args.repeats)
    bench_refine(args.repeats)


if __name__ == "__main__":
    main()
