"""``bench floor``: how far the decoder and the rasterizer are from what this CPU can do.

The work of one stylized full frame (the targets' case: the sample photo at 1 MP, frames
512 pixels on the long side) is counted, not guessed:

* decoder: every ``nn.Conv2d`` the U-Net runs on the whole frame (what it costs where no pixel passes
  through: the shipped decoder skips it on covered pixels), from the shapes a forward hook sees:
  ``2 * out.numel() * in_channels / groups * kh * kw`` FLOPs, and the bytes of its input,
  output and weights once each (float32; element-wise layers, padding and concatenation
  are not counted, so this is a lower bound on the bytes);
* rasterizer: a lower bound too: the points that survive culling (in front of the camera
  and in the image) are each projected (20 FLOPs) and splatted to 4 taps (bilinear; grown
  splats have more), each tap a weight (4 FLOPs) and a weighted sum of the C feature
  channels (2 C FLOPs); bytes: each point's position and features read once, 16 bytes per
  tap (z-buffer and weight entries, written and read), the (H, W) image of C channels plus
  weight, depth and hole written once.

The machine's own limits, with the same torch threads: the throughput of a large conv
(3x3, 256 -> 256 channels on a 128 x 128 channels-last image: what oneDNN reaches on this
CPU) and the bandwidth of a large tensor copy (bytes read + written). Each stage's floor is
``max(FLOPs / conv throughput, bytes / bandwidth)``; the table gives the measured time,
the fraction of each limit reached and the measured time over the floor.

Where the CPU computes bfloat16 natively (``models.decoder.native_bfloat16``: AVX-512 BF16 or
AMX), three rows more: the same large conv in bfloat16 (its own compute limit), the decoder
in bfloat16 (``StylizeSettings.bfloat16``, the default there; its bytes counted at 2 per value)
and the full frame with it, both against the bfloat16 limit.
"""

from __future__ import annotations

import statistics
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, List, Optional, Sequence, Tuple

import torch

from ..eval.timing import time_runs
from ..models.decoder import native_bfloat16
from .report import Log, progress, quiet, write_table


@dataclass(frozen=True)
class FloorPreset:
    megapixels: float
    frame: int
    conv_channels: int
    conv_size: int
    copy_mib: int
    repeats: int


FULL = FloorPreset(megapixels=1.0, frame=512, conv_channels=256, conv_size=128, copy_mib=256, repeats=5)
QUICK = FloorPreset(megapixels=0.01, frame=64, conv_channels=64, conv_size=32, copy_mib=8, repeats=1)


@dataclass(frozen=True)
class ConvWork:
    name: str
    shape: str  # "Cin->Cout kxk, out WxH"
    flops: float
    bytes: float


def conv_flops(inp: torch.Tensor, out: torch.Tensor, conv: torch.nn.Conv2d) -> float:
    """Multiply-adds x 2 of one ``Conv2d`` call: ``2 * out.numel() * Cin / groups * kh * kw`` (bias not counted)."""
    kh, kw = conv.kernel_size
    return 2.0 * out.numel() * (conv.in_channels // conv.groups) * kh * kw


def decoder_work(decoder: torch.nn.Module, features: torch.Tensor, mask: torch.Tensor) -> List[ConvWork]:
    """The convolutions of one decoder forward on ``features`` (1, C, H, W), counted by forward hooks."""
    work: List[ConvWork] = []
    names = {m: n for n, m in decoder.named_modules()}

    def hook(module, inputs, output) -> None:
        x = inputs[0]
        kh, kw = module.kernel_size
        work.append(ConvWork(names[module], f"{module.in_channels}->{module.out_channels} {kh}x{kw}, out "
                             f"{output.shape[-1]}x{output.shape[-2]}", conv_flops(x, output, module),
                             4.0 * (x.numel() + output.numel() + module.weight.numel())))

    hooks = [m.register_forward_hook(hook) for m in decoder.modules() if isinstance(m, torch.nn.Conv2d)]
    try:
        with torch.inference_mode():
            decoder(features, mask)
    finally:
        for h in hooks:
            h.remove()
    return work


def kept_points(xyz: torch.Tensor, camera, height: int, width: int, near: float) -> int:
    """Points in front of ``camera`` (z > ``near``) that project into the (height, width) image."""
    w2c = camera.world_to_cam()[0].to(xyz.dtype)
    pc = xyz @ w2c[:3, :3].T + w2c[:3, 3]
    K = camera.intrinsics(height, width, dtype=xyz.dtype)[0]
    z = pc[:, 2]
    front = z > near
    uv = (pc[front] @ K.T)
    u, v = uv[:, 0] / uv[:, 2], uv[:, 1] / uv[:, 2]
    inside = (u > -1) & (u < width) & (v > -1) & (v < height)
    return int(inside.sum())


def raster_work(n_kept: int, channels: int, height: int, width: int, taps: int = 4) -> Tuple[float, float]:
    """(FLOPs, bytes) lower bound of rasterizing ``n_kept`` points of ``channels`` features (module docstring)."""
    flops = n_kept * (20.0 + taps * (4.0 + 2.0 * channels))
    moved = n_kept * (12.0 + 4.0 * channels) + n_kept * taps * 16.0 + height * width * (4.0 * channels + 9.0)
    return flops, moved


def interleaved_medians(fns: Sequence[Callable[[], object]], repeats: int) -> List[float]:
    """Median seconds of each callable, timed in ``repeats`` rounds that call each once (after one warm-up
    round), so a change of load on a shared machine hits every measurement alike."""
    for fn in fns:
        fn()
    times: List[List[float]] = [[] for _ in fns]
    for _ in range(repeats):
        for i, fn in enumerate(fns):
            times[i].extend(time_runs(fn, 1))
    return [statistics.median(t) for t in times]


def conv_limit(channels: int, size: int, dtype: torch.dtype = torch.float32) -> Tuple[Callable[[], object], float, float]:
    """A 3x3 ``channels`` -> ``channels`` conv on a (1, C, size, size) channels-last image in ``dtype``:
    (call, FLOPs, bytes)."""
    conv = torch.nn.Conv2d(channels, channels, 3, padding=1).eval().to(memory_format=torch.channels_last, dtype=dtype)
    x = torch.rand(1, channels, size, size).contiguous(memory_format=torch.channels_last).to(dtype)
    with torch.inference_mode():
        out = conv(x)

    def call() -> None:
        with torch.inference_mode():
            conv(x)
    item = x.element_size()
    return call, conv_flops(x, out, conv), float(item) * (x.numel() + out.numel() + conv.weight.numel())


def copy_limit(mib: int) -> Tuple[Callable[[], object], float]:
    """Copying a ``mib`` MiB float32 tensor: (call, bytes read + written)."""
    a = torch.rand(mib * 2**18)
    b = torch.empty_like(a)
    return (lambda: b.copy_(a)), 2.0 * a.numel() * 4


def run_floor(out: Path, quick: bool = False, show_progress: bool = False, log: Log = quiet,
              photo: Optional[str] = None) -> List[dict]:
    import tempfile

    from ..geometry.trajectories import circle
    from ..models.checkpoint import load_checkpoint
    from ..pipeline import PhotoSpec, load_photo3d
    from ..render.plain import frame_size
    from ..render.rasterize import RasterSettings
    from ..render.rasterizer import PointRasterizer
    from ..resources import resolve_model
    from .photos import photo_at_megapixels
    p = QUICK if quick else FULL
    steps = iter(progress(range(3), 3, "floor", show_progress))
    next(steps)
    with tempfile.TemporaryDirectory() as tmp:
        p3d = load_photo3d(PhotoSpec(photo=str(photo_at_megapixels(p.megapixels, Path(tmp), photo)), depth="prior",
                                     max_size=8192))
    model = load_checkpoint(resolve_model("lite")).model.eval()
    decoder = model.decoder
    C = decoder.config.in_channels
    H, W = frame_size(p3d.size, p.frame)
    cam = circle(90, fov_y_deg=p3d.fov_y_deg)[3]
    xyz = torch.from_numpy(p3d.points.xyz).float()
    g = torch.Generator().manual_seed(0)
    feats = torch.rand(xyz.shape[0], C, generator=g)  # the cost does not depend on the values
    settings = RasterSettings(height=H, width=W)
    raster = PointRasterizer(settings)
    with torch.inference_mode():
        frags = raster(xyz, feats, cam)
    image = frags.image.unsqueeze(0)
    # every pixel marked uncovered: the whole U-Net runs (the shipped decoder passes covered pixels through
    # and decodes only the uncovered ones, UNetDecoder.passes_covered_colours); its cost does not depend on
    # the mask's values
    mask = torch.zeros_like(frags.hole, dtype=image.dtype)[None, None]
    convs = decoder_work(decoder, image, mask)
    next(steps)

    def rasterize() -> None:
        with torch.inference_mode():
            raster(xyz, feats, cam)

    def decode(bfloat16: bool = False) -> Callable[[], None]:
        def call() -> None:
            with torch.inference_mode():
                decoder(image, mask, bfloat16=bfloat16)
        return call

    conv_call, conv_flops_, conv_bytes = conv_limit(p.conv_channels, p.conv_size)
    bf_call, bf_flops, bf_bytes = conv_limit(p.conv_channels, p.conv_size, torch.bfloat16)
    copy_call, copy_bytes = copy_limit(p.copy_mib)
    fns = [conv_call, copy_call, rasterize, decode()]
    bf16 = native_bfloat16()  # where it is emulated, bfloat16 is slower: those rows are left out
    t_conv, t_copy, t_raster, t_decoder, *t_bf = interleaved_medians(
        fns + ([bf_call, decode(True)] if bf16 else []), p.repeats)
    peak_gflops_f32, bandwidth = conv_flops_ / t_conv / 1e9, copy_bytes / t_copy / 1e9
    next(steps, None)
    n_kept = kept_points(xyz, cam, H, W, settings.near_clip)
    r_flops, r_bytes = raster_work(n_kept, C, H, W)
    d_flops, d_bytes = sum(c.flops for c in convs), sum(c.bytes for c in convs)

    def row(stage: str, flops: float, moved: float, seconds: float, peak: Optional[float] = None) -> dict:
        peak_gflops = peak or peak_gflops_f32
        floor_s = max(flops / (peak_gflops * 1e9), moved / (bandwidth * 1e9))
        return {"stage": stage, "gflop": flops / 1e9, "mb_moved": moved / 1e6, "ms": 1000 * seconds,
                "gflop_per_s": flops / seconds / 1e9, "pct_conv_peak": 100 * flops / seconds / 1e9 / peak_gflops,
                "gb_per_s": moved / seconds / 1e9, "pct_bandwidth": 100 * moved / seconds / 1e9 / bandwidth,
                "floor_ms": 1000 * floor_s, "x_floor": seconds / floor_s if floor_s > 0 else float("inf"),
                "bound": "compute" if flops / (peak_gflops * 1e9) >= moved / (bandwidth * 1e9) else "memory"}

    rows = [
        row(f"large conv 3x3 {p.conv_channels}->{p.conv_channels} at {p.conv_size}x{p.conv_size} (compute limit)",
            conv_flops_, conv_bytes, t_conv),
        row(f"tensor copy {p.copy_mib} MiB (bandwidth limit)", 0.0, copy_bytes, t_copy),
        row(f"decoder ({len(convs)} convs), {W}x{H} frame", d_flops, d_bytes, t_decoder),
        row(f"rasterizer, {n_kept:,} of {xyz.shape[0]:,} points x {C} channels -> {W}x{H}", r_flops, r_bytes,
            t_raster),
        row(f"full frame (rasterizer + decoder), {W}x{H}", d_flops + r_flops, d_bytes + r_bytes,
            t_decoder + t_raster),
    ]
    if bf16:  # the bfloat16 rows against the bfloat16 conv's throughput (half the bytes per value)
        peak_bf = bf_flops / t_bf[0] / 1e9
        rows += [row(f"large conv 3x3 {p.conv_channels}->{p.conv_channels} at {p.conv_size}x{p.conv_size}, "
                     "bfloat16 (compute limit)", bf_flops, bf_bytes, t_bf[0], peak_bf),
                 row(f"decoder in bfloat16 (StylizeSettings.bfloat16), {W}x{H} frame", d_flops, d_bytes / 2, t_bf[1],
                     peak_bf),
                 row(f"full frame, decoder in bfloat16, {W}x{H}", d_flops + r_flops, d_bytes / 2 + r_bytes,
                     t_bf[1] + t_raster, peak_bf)]
    out = Path(out)
    write_table(out, "floor", "The floor: work of a stylized frame against this CPU's limits", rows, notes=[
        f"photo {p3d.size[1]}x{p3d.size[0]} ({xyz.shape[0]:,} points), frame {W}x{H}, {C} rasterized channels; "
        f"torch threads {torch.get_num_threads()}; median of {p.repeats} round(s) after a warm-up round, each "
        "round timing the conv, the copy, the rasterizer and the decoder once (interleaved)"
        + (" (--quick preset)" if quick else ""),
        f"limits measured here: {peak_gflops_f32:.1f} GFLOP/s (large conv)"
        + (f", {bf_flops / t_bf[0] / 1e9:.0f} GFLOP/s in bfloat16 (this CPU computes it natively; the bfloat16 "
           "rows are against that)" if bf16 else ", bfloat16 not native here (no bfloat16 rows)")
        + f", {bandwidth:.1f} GB/s (copy, read + write)",
        "decoder: the convolutions' FLOPs and bytes counted by forward hooks (element-wise layers not counted); "
        "rasterizer: a lower bound (4 taps per kept point; see stylize3d_core/bench/floor.py)",
        "floor_ms = max(GFLOP / conv limit, MB / bandwidth); x_floor = ms / floor_ms; bound: which limit sets "
        "the floor"])
    total = sum(c.flops for c in convs)
    write_table(out, "floor_decoder", "Decoder convolutions of one frame", [
        {"conv": c.name, "shape": c.shape, "gflop": c.flops / 1e9, "mb_moved": c.bytes / 1e6,
         "share_of_flops": c.flops / total if total else 0.0} for c in convs], notes=[
        f"frame {W}x{H} (padded to a multiple of {2 ** decoder.config.levels}); decoder {decoder.config}"])
    log(f"floor: conv {peak_gflops_f32:.1f} GFLOP/s, copy {bandwidth:.1f} GB/s; decoder {rows[2]['x_floor']:.1f}x its "
        f"floor, rasterizer {rows[3]['x_floor']:.1f}x")
    return rows


__all__ = ["conv_flops", "decoder_work", "kept_points", "raster_work", "conv_limit", "copy_limit",
           "interleaved_medians", "run_floor"]
