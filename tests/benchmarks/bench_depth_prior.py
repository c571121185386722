"""The built-in depth prior: ordinal agreement with stereo ground truth and time at 1 MP, before and after.

    .venv/bin/python tests/benchmarks/bench_depth_prior.py [--repeats 5] [--before REV] [--threads 2]

* Ordinal agreement (``stylize3d_core.eval.ordinal``) on scikit-image's
  motorcycle pair: the share of 200 000 random pixel pairs with ground-truth
  disparity (fixed seed, pairs whose disparities differ by more than 1 px)
  that the prior puts in the right order, nearer = larger disparity.
* Time of ``estimate_prior`` on the bundled samples scaled to 1 MP (median
  and min of ``--repeats`` runs after one warm-up), with OpenCV limited to
  ``--threads`` threads.

"before" is the prior at git revision ``--before`` (default: the revision the
rework started from, see ``tests/benchmarks/prior_before.py``); "after" is this
checkout's. Prints figures; asserts nothing.
"""

from __future__ import annotations

import argparse

import cv2
import numpy as np

from prior_before import BEFORE_REV, load_prior_at  # noqa: E402
from stylize3d_core.depth import prior as prior_after  # noqa: E402
from stylize3d_core.eval.ordinal import ordinal_agreement  # noqa: E402
from stylize3d_core.eval.timing import median_and_min  # noqa: E402

SAMPLES = ("astronaut", "chelsea", "coffee", "rocket")


def motorcycle():
    from skimage import data

    left, _, disp = data.stereo_motorcycle()
    return left.astype(np.float32) / 255.0, disp


def photo_at(name: str, megapixels: float) -> np.ndarray:
    from skimage import data

    img = getattr(data, name)()
    s = (megapixels * 1e6 / (img.shape[0] * img.shape[1])) ** 0.5
    return cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_CUBIC).astype(np.float32) / 255.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--before", default=BEFORE_REV)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    cv2.setNumThreads(args.threads)
    versions = {"before": load_prior_at(args.before), "after": prior_after}
    left, gt = motorcycle()
    print(f"ordinal agreement, motorcycle {left.shape[1]}x{left.shape[0]} (200k pairs, margin 1 px, seed 0):")
    for tag, mod in versions.items():
        print(f"  {tag:6s}: {ordinal_agreement(mod.estimate_prior(left).depth, gt):.4f}")
    print(f"time at 1 MP, {args.threads} OpenCV threads (median / min of {args.repeats} runs):")
    for name in SAMPLES:
        rgb = photo_at(name, 1.0)
        h, w = rgb.shape[:2]
        cells = []
        for tag, mod in versions.items():
            med, best = median_and_min(lambda: mod.estimate_prior(rgb), args.repeats, warmup=1)
            cells.append(f"{tag} {med:.2f} / {best:.2f} s")
        print(f"  {name:10s} {w}x{h}: " + ", ".join(cells))


if __name__ == "__main__":
    main()
