"""The decoder's U-Net in torch against ONNX Runtime (float32), and what an int8 ONNX Runtime U-Net would cost.

Part 1 (always): the shipped model's U-Net alone (``UNetDecoder.forward`` on random features, the
padded sizes of the viewer's 768x512 full frame, a 512x342 frame and a 256x170 preview with their
border margins), torch and ONNX Runtime interleaved, ``--repeats`` rounds, at 1 and 2 threads: median
ms, the ratio of each round's times, and the largest difference of the outputs.

Part 2 (``--stylized``): whole stylized frames of the 1 MP sample (``Stylized3DPhoto.render``,
``decoder_runtime`` torch / onnxruntime, interleaved), 768x512 and 512x342 full frames and 256x170
previews.

Part 3 (``--int8``): the U-Net quantized statically to int8 (``onnxruntime.quantization``, QDQ,
per-channel weights, min-max calibration on the inputs of 12 frames of two sample photos), variants
leaving the first / last convolutions in float32; per variant, the PSNR of whole stylized frames of
the four sample photos (cameras not used in the calibration) against the float32 frames, and the time.
(Rejected as a default: see the figures it prints; ``docs/performance.md``.)

    .venv/bin/python tests/benchmarks/bench_decoder_runtime.py [--repeats 7] [--stylized] [--int8] [--no-unet]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[2]

from stylize3d_core.models.checkpoint import load_checkpoint  # noqa: E402
from stylize3d_core.models.decoder_onnx import OnnxUNet, onnx_unet  # noqa: E402

MODEL = ROOT / "assets" / "model" / "stylize3d_lite.safetensors"
SIZES = {"768x512 full (+8 px margins)": (528, 784), "512x342 full": (360, 528), "256x170 preview (+4)": (180, 264)}


def _time(f) -> float:
    t = time.perf_counter()
    f()
    return time.perf_counter() - t


def unet_alone(repeats: int) -> None:
    dec = load_checkpoint(str(MODEL)).model.decoder.eval()
    rt = onnx_unet(dec)
    c = dec.config.in_channels
    print(f"U-Net alone (shipped model, C_in {c}); median ms over {repeats} interleaved rounds")
    print(f"{'size':30s} {'threads':>7s} {'torch':>8s} {'onnxrt':>8s} {'ratio':>6s} {'max diff':>9s}")
    for name, (h, w) in SIZES.items():
        g = torch.Generator().manual_seed(0)
        mask = (torch.rand(1, 1, h, w, generator=g) > 0.05).float()
        feats = (torch.randn(1, h, w, c, generator=g).permute(0, 3, 1, 2) * mask)
        for threads in (1, 2):
            torch.set_num_threads(threads)
            with torch.inference_mode():
                ref, out = dec(feats, mask), dec(feats, mask, runtime=rt)  # also the warm-up
                diff = (ref - out).abs().max().item()
                tt, to = [], []
                for _ in range(repeats):
                    tt.append(_time(lambda: dec(feats, mask)))
                    to.append(_time(lambda: dec(feats, mask, runtime=rt)))
            ratio = statistics.median(a / b for a, b in zip(tt, to))
            print(f"{name:30s} {threads:7d} {1e3 * statistics.median(tt):8.1f} {1e3 * statistics.median(to):8.1f} "
                  f"{ratio:6.2f} {diff:9.1e}")


def _scene(photo: str, style: str, max_size: int = 1225):
    from stylize3d_core.geometry.trajectories import circle
    from stylize3d_core.io.images import load_image
    from stylize3d_core.pipeline import PhotoSpec, load_photo3d
    from stylize3d_core.resources import sample_photo, style_image
    from stylize3d_core.stylize import Stylized3DPhoto, StylizeSettings

    p3d = load_photo3d(PhotoSpec(str(sample_photo(photo)), "prior", max_size=max_size))
    st = Stylized3DPhoto(p3d, load_checkpoint(str(MODEL)), StylizeSettings())
    st.set_style(load_image(str(style_image(style)), max_size=512).rgb)
    return st, circle(8, fov_y_deg=p3d.fov_y_deg)


def stylized(repeats: int) -> None:
    st, cams = _scene("coffee.jpg", "painting_style03_coffee.jpg")
    base = st.settings
    print(f"\nstylized frames of the 1 MP sample ({st.num_points:,} points); median ms over {repeats} rounds")
    print(f"{'frame':22s} {'threads':>7s} {'torch':>8s} {'onnxrt':>8s} {'ratio':>6s} {'max diff':>9s}")
    for threads in (1, 2):
        torch.set_num_threads(threads)
        for name, size, preview in (("768x512 full", (512, 768), False), ("512x342 full", (342, 512), False),
                                    ("256x170 preview", (170, 256), True)):
            times = {"torch": [], "onnxruntime": []}
            diff = 0.0
            for k in range(repeats + 1):
                outs = {}
                for runtime in times:
                    st.settings = replace(base, decoder_runtime=runtime)
                    t = time.perf_counter()
                    outs[runtime] = st.render(cams[k % len(cams)], *size, preview=preview)
                    if k:
                        times[runtime].append(time.perf_counter() - t)
                diff = max(diff, float(np.abs(outs["torch"] - outs["onnxruntime"]).max()))
            ratio = statistics.median(a / b for a, b in zip(times["torch"], times["onnxruntime"]))
            print(f"{name:22s} {threads:7d} {1e3 * statistics.median(times['torch']):8.1f} "
                  f"{1e3 * statistics.median(times['onnxruntime']):8.1f} {ratio:6.2f} {diff:9.1e}")
    st.settings = base


class _Fixed(OnnxUNet):
    """An OnnxUNet of a given serialized model (the quantized one)."""

    def __init__(self, like: OnnxUNet, model_bytes: bytes) -> None:
        self.levels, self.has_coefficients, self.fingerprint = like.levels, like.has_coefficients, like.fingerprint
        self.model_bytes, self._sessions, self.abandoned = model_bytes, {}, None


def int8(threads: int = 2) -> None:
    import onnx
    from onnxruntime.quantization import CalibrationDataReader, QuantFormat, QuantType, quantize_static

    from stylize3d_core.bench.speed import psnr
    from stylize3d_core.models import decoder_onnx

    torch.set_num_threads(threads)
    pairs = [("coffee.jpg", "painting_style03_coffee.jpg"), ("rocket.jpg", "texture_voronoi_seed7.jpg"),
             ("chelsea.jpg", "painting_style13_rocket.jpg"), ("astronaut.jpg", "painting_style19_chelsea.jpg")]
    scenes = [(p, *_scene(p, s, 1024)) for p, s in pairs]
    for _, st, _ in scenes:  # every frame through ONNX Runtime (auto would decode the small ones in torch)
        st.settings = replace(st.settings, decoder_runtime="onnxruntime")
    fp32 = onnx_unet(scenes[0][1].model.decoder)
    captured = []
    real = decoder_onnx.onnx_unet

    class Capture(OnnxUNet):
        def __init__(self) -> None:
            self.levels, self.has_coefficients = fp32.levels, fp32.has_coefficients

        def run(self, x, should_stop=None, threads=None):
            captured.append(x.permute(0, 2, 3, 1).contiguous().numpy().copy())
            return fp32.run(x, should_stop, threads)

    decoder_onnx.onnx_unet = lambda d: Capture()
    try:  # calibration: cameras 0, 2, 4 of the first two photos, full frames and previews
        for _, st, cams in scenes[:2]:
            for k in (0, 2, 4):
                st.render(cams[k], 256, 384)
                st.render(cams[k], 170, 256, preview=True)
    finally:
        decoder_onnx.onnx_unet = real

    class Reader(CalibrationDataReader):
        def __init__(self) -> None:
            self.it = iter([{"x_nhwc": c} for c in captured])

        def get_next(self):
            return next(self.it, None)

    print(f"\nint8 U-Net (QDQ, per-channel, min-max calibration on {len(captured)} inputs of coffee and rocket); "
          f"PSNR of stylized frames vs float32, cameras 1, 3, 5; {threads} threads")
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "fp32.onnx"
        onnx.save(onnx.load_from_string(fp32.model_bytes), str(src))
        first, last = ["skip0", "down0.conv1"], ["up0.up", "up0.conv", "out_conv", "y", "coefficients"]
        for name, exclude in (("all int8", []), ("first layer float", first), ("last layers float", last),
                              ("first + last float", first + last)):
            dst = Path(tmp) / "q.onnx"
            quantize_static(str(src), str(dst), Reader(), quant_format=QuantFormat.QDQ,
                            activation_type=QuantType.QUInt8, weight_type=QuantType.QInt8, per_channel=True,
                            nodes_to_exclude=exclude)
            q = _Fixed(fp32, dst.read_bytes())
            rows = []
            for photo, st, cams in scenes:
                for k in (1, 3, 5):
                    for size, preview in (((342, 512), False), ((170, 256), True)):
                        ref = st.render(cams[k], *size, preview=preview)
                        decoder_onnx.onnx_unet = lambda d: q
                        try:
                            t = time.perf_counter()
                            out = st.render(cams[k], *size, preview=preview)
                            dt = time.perf_counter() - t
                        finally:
                            decoder_onnx.onnx_unet = real
                        rows.append((photo, preview, psnr(out, ref), dt))
            for photo, *_ in scenes:
                for preview in (False, True):
                    r = [x for x in rows if x[0] == photo and x[1] == preview]
                    print(f"{name:20s} {photo:14s} {'preview' if preview else '512 full':8s} "
                          f"PSNR min {min(x[2] for x in r):5.2f} median {statistics.median(x[2] for x in r):5.2f} dB; "
                          f"{1e3 * statistics.median(x[3] for x in r):6.1f} ms")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--stylized", action="store_true", help="also whole stylized frames")
    ap.add_argument("--int8", action="store_true", help="also the int8 experiment")
    ap.add_argument("--no-unet", action="store_true", help="without part 1 (the U-Net alone)")
    args = ap.parse_args()
    if not args.no_unet:
        unet_alone(args.repeats)
    if args.stylized:
        stylized(args.repeats)
    if args.int8:
        int8()


if __name__ == "__main__":
    main()
