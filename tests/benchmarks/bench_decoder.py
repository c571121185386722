"""Timings of the style side and the decoder on this CPU (prints figures; asserts nothing).

    .venv/bin/python tests/benchmarks/bench_decoder.py [--repeats 9] [--widths 64 96 128 192] [--paper-512]

Reports the median (and the minimum, the least disturbed run on a shared
machine) over ``--repeats`` runs, after one warm-up, under
``torch.inference_mode()``:

* U-Net decoder, ``lite`` (C_in = 64) and ``paper`` (C_in = 256) presets, at 256^2
  and 512^2 (paper at 512^2 only with ``--paper-512``: seconds per frame);
* a width sweep of the decoder with C_in = 64 (targets: 512^2 <= 500 ms,
  256^2 <= 100 ms; ``DecoderConfig.lite`` is the widest width within both with headroom);
* StyleEncoder (EfficientNet-Lite0, all 5 stages) on a 512 x 512 style image;
* AdaAttN stylizer (paper and lite widths) for M = 20k and 60k points against
  that style (L = 32 x 32 = 1024), in full and with the content half cached.
"""

from __future__ import annotations

import argparse
from typing import Callable, Tuple

import torch


from stylize3d_core.eval.timing import median_and_min  # noqa: E402
from stylize3d_core.models.adaattn import AdaAttNConfig, AdaAttNStylizer  # noqa: E402
from stylize3d_core.models.decoder import DecoderConfig, UNetDecoder  # noqa: E402
from stylize3d_core.models.style_features import StyleEncoder  # noqa: E402


def timed(fn: Callable[[], object], repeats: int) -> Tuple[float, float]:
    """(median ms, min ms) of ``fn`` after one warm-up call."""
    med, best = median_and_min(fn, repeats, warmup=1)
    return 1000.0 * med, 1000.0 * best


def decoder_ms(config: DecoderConfig, size: int, repeats: int) -> Tuple[float, float]:
    torch.manual_seed(0)
    dec = UNetDecoder(config).eval()
    n = 2 * size if config.supersample else size
    feats = torch.randn(1, config.in_channels, n, n)
    mask = (torch.rand(1, 1, n, n) > 0.1).float()
    with torch.inference_mode():
        return timed(lambda: dec(feats, mask), repeats)


def row(label: str, ms: Tuple[float, float], target: float = 0.0) -> None:
    extra = f"   target {target:.0f} ms: {'ok' if ms[0] <= target else 'MISSED'} (median)" if target else ""
    print(f"  {label:<34} median {ms[0]:8.1f} ms   min {ms[1]:8.1f} ms{extra}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=9)
    parser.add_argument("--widths", type=int, nargs="*", default=[64, 96, 128, 192])
    parser.add_argument("--paper-512", action="store_true", help="also time the paper decoder at 512^2")
    parser.add_argument("--skip-style", action="store_true", help="decoder figures only")
    args = parser.parse_args()
    r = args.repeats
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads, repeats {r}")

    print("decoder presets")
    lite = DecoderConfig.lite()
    row(f"lite (width {lite.width}) 256^2", decoder_ms(lite, 256, r), 100)
    row(f"lite (width {lite.width}) 512^2", decoder_ms(lite, 512, r), 500)
    row(f"lite supersampled 2x -> 256^2", decoder_ms(DecoderConfig.lite(supersample=True), 256, r))
    paper = DecoderConfig.paper()
    row("paper (width 256) 256^2", decoder_ms(paper, 256, max(3, r // 3)))
    if args.paper_512:
        row("paper (width 256) 512^2", decoder_ms(paper, 512, 3))

    if args.widths:
        print("decoder width sweep (C_in = 64; full-resolution channels = width / 4)")
        for w in args.widths:
            cfg = DecoderConfig(in_channels=64, width=w)
            row(f"width {w:>3} 256^2", decoder_ms(cfg, 256, r), 100)
            row(f"width {w:>3} 512^2", decoder_ms(cfg, 512, r), 500)

    if args.skip_style:
        return
    print("style side")
    encoder = StyleEncoder()
    style = torch.rand(1, 3, 512, 512)
    with torch.inference_mode():
        row("StyleEncoder 512x512", timed(lambda: encoder(style), r))
        maps = encoder(style).maps
    for name, cfg in (("paper", AdaAttNConfig.paper()), ("lite", AdaAttNConfig.lite())):
        torch.manual_seed(0)
        stylizer = AdaAttNStylizer(cfg).eval()
        for m in (20_000, 60_000):
            content = torch.randn(m, cfg.content_channels)
            with torch.inference_mode():
                prepared = stylizer.prepare(content)
                row(f"AdaAttN {name} M={m // 1000}k L=1024", timed(lambda: stylizer(content, maps), max(3, r // 3)))
                row(f"  new style only (prepared)", timed(lambda: stylizer.stylize_prepared(prepared, maps), max(3, r // 3)))


if __name__ == "__main__":
    main()
