"""The decoder's U-Net run by ONNX Runtime (CPU inference; the torch decoder stays the reference and trains).

On CPUs without native bfloat16 the U-Net is most of a stylized frame's time, and on large frames ONNX
Runtime's convolutions (MLAS, blocked NCHWc layout, activation fused into the convolution) run it faster
than torch's oneDNN in float32, with the same outputs within ~1e-6; on small frames torch is faster (its
per-call overhead is lower), so ``decoder_runtime="auto"`` picks by the frame's size (:func:`prefers_onnx`;
``bench speed`` measures both).

**The graph** is written here, node by node, from the :class:`~.decoder.UNetDecoder`'s weights with
``onnx.helper`` (no tracing: the layout is the decoder's own, see its module docstring):
``x_nhwc``, ``[features | mask]`` channels-last (B, Hp, Wp, C_in + 1) as the rasterizer lays them out,
padded to a multiple of ``2**levels`` (a ``Transpose`` node makes it NCHW) -> ``y`` (B, 3 + texture,
Hp, Wp), the last convolution's output before the sigmoid / tanh, and, where the colour-transform head is
not constant (:func:`~.decoder.constant_transform`), ``coefficients`` (B, 12, Hp / 2**levels, Wp /
2**levels), the head's output (its input gain folded into its weights). The torch decoder does the rest
(crop, sigmoid, texture, the colour transform), so both runtimes share it. Height and width are free
(symbolic) dimensions: one session serves every frame size.

**Stopping** (:meth:`OnnxUNet.run` with ``should_stop``): the run goes on a thread of its own, the
caller polls ``should_stop`` and returns at once when it says stop, and sets ``RunOptions.terminate``,
which ONNX Runtime checks before each node: the abandoned run ends within one node. So that no node runs
long, a convolution of more than :data:`NODE_MACS_PER_PIXEL` multiply-adds per pixel of the padded
frame is written as convolutions over groups of output channels, concatenated (the same values), in
groups of multiples of 8 channels (the AVX2 block of MLAS's NCHWc kernels); the limit is as high as it
can be while a stop stays prompt, since finer groups re-read the input once per group.
"""

from __future__ import annotations

import atexit
import contextlib
import functools
import threading
import warnings
import weakref
from typing import Callable, Dict, Iterator, List, Optional, Tuple

import torch
from torch import nn

from ..errors import InputError, RenderInterrupted
from .decoder import UNetDecoder, constant_transform

StopCheck = Optional[Callable[[], bool]]

OPSET = 17
NODE_MACS_PER_PIXEL = 12_000
"""Most multiply-adds per pixel of the (padded) output frame in one node of the graph (see the module
docstring): the lite decoder's widest convolution (20,736 per pixel) becomes 2 nodes (~0.14 s each at
784x528 on one AVX2 thread)."""

CHANNEL_BLOCK = 8
"""Output-channel groups are multiples of this (MLAS's NCHWc block on AVX2)."""

POLL_S = 0.002
"""How often :meth:`OnnxUNet.run` calls ``should_stop`` while a stoppable run goes on (seconds)."""


def _groups(out_channels: int, macs_per_pixel: float) -> int:
    """How many groups of output channels a convolution is split into: the fewest that bring each group to
    at most :data:`NODE_MACS_PER_PIXEL`, among the counts whose groups are whole multiples of
    :data:`CHANNEL_BLOCK` channels (1 where none is)."""
    best = 1
    for g in range(1, out_channels // CHANNEL_BLOCK + 1):
        if out_channels % g or (out_channels // g) % CHANNEL_BLOCK:
            continue
        best = g
        if macs_per_pixel / g <= NODE_MACS_PER_PIXEL:
            break
    return best


class _GraphWriter:
    """Nodes and initializers of the U-Net's graph (float32 weights copied from the module)."""

    def __init__(self) -> None:
        self.nodes: list = []
        self.initializers: list = []

    def tensor(self, name: str, value: torch.Tensor) -> str:
        from onnx import numpy_helper
        self.initializers.append(numpy_helper.from_array(
            value.detach().to(torch.float32).contiguous().numpy(), name))
        return name

    def node(self, op: str, inputs: List[str], output: str, **attrs) -> str:
        from onnx import helper
        self.nodes.append(helper.make_node(op, inputs, [output], name=output, **attrs))
        return output

    def conv(self, name: str, conv: nn.Module, x: str, area: float, weight_scale: float = 1.0) -> str:
        """``conv(x)`` (an nn.Conv2d or nn.ConvTranspose2d: zero padding, no groups, no dilation) in groups
        of output channels; ``area``: its output pixels per pixel of the padded frame (1/4 at half size)."""
        transposed = isinstance(conv, nn.ConvTranspose2d)
        (kh, kw), (sh, sw), (ph, pw) = conv.kernel_size, conv.stride, conv.padding
        attrs = dict(kernel_shape=[kh, kw], strides=[sh, sw], pads=[ph, pw, ph, pw])
        if transposed:
            attrs["output_padding"] = list(conv.output_padding)
        weight = conv.weight * weight_scale if weight_scale != 1.0 else conv.weight
        cout = conv.out_channels
        macs = area * conv.in_channels * cout * kh * kw
        g = _groups(cout, macs)
        step = cout // g
        outs = []
        for i in range(g):
            part = slice(i * step, (i + 1) * step)
            w = weight[:, part] if transposed else weight[part]
            suffix = f".{i}" if g > 1 else ""
            outs.append(self.node("ConvTranspose" if transposed else "Conv",
                                  [x, self.tensor(f"{name}{suffix}.weight", w),
                                   self.tensor(f"{name}{suffix}.bias", conv.bias[part])],
                                  f"{name}{suffix}", **attrs))
        return outs[0] if g == 1 else self.node("Concat", outs, name, axis=1)


def unet_graph(decoder: UNetDecoder):
    """The ONNX model (``onnx.ModelProto``) of ``decoder``'s U-Net (see the module docstring): input ``x``,
    outputs ``y`` and, where its colour-transform head is not constant, ``coefficients``."""
    from onnx import TensorProto, checker, helper

    cfg = decoder.config
    if cfg.supersample:
        raise InputError("decoder", "the ONNX runtime takes a decoder without supersampling (the rasterizer "
                                    "supersamples)")
    g = _GraphWriter()
    # the input comes channels-last, as the rasterizer lays out its features; ONNX Runtime fuses this
    # transpose into its conversion to the blocked layout (one pass over the input, not two)
    transpose = helper.make_node("Transpose", ["x_nhwc"], ["x"], name="x", perm=[0, 3, 1, 2])
    x, skips, area = "x", [], 1.0
    slope = float(cfg.negative_slope)
    cin = cfg.in_channels + 1
    for i, (skip, down) in enumerate(zip(decoder.skips, decoder.downs)):
        skips.append(g.conv(f"skip{i}", skip, x, area))
        x = g.node("LeakyRelu", [g.conv(f"down{i}.conv1", down.conv1, x, area / 4)], f"down{i}.act1", alpha=slope)
        area /= 4
        x = g.node("LeakyRelu", [g.conv(f"down{i}.conv2", down.conv2, x, area)], f"down{i}.act2", alpha=slope)
    coarse = x
    for i in reversed(range(cfg.levels)):
        up = decoder.ups[i]
        area *= 4
        x = g.node("Relu", [g.conv(f"up{i}.up", up.up, x, area)], f"up{i}.act1")
        x = g.node("Concat", [x, skips[i]], f"up{i}.cat", axis=1)
        x = g.node("Relu", [g.conv(f"up{i}.conv", up.conv, x, area)], f"up{i}.act2")
    x = g.node("Relu", [g.conv("out_conv", decoder.out_conv, x, 1.0)], "out_conv.act")
    g.conv("y", decoder.out_rgb, x, 1.0)
    b, h, w = "B", "H", "W"
    outputs = [helper.make_tensor_value_info("y", TensorProto.FLOAT, [b, decoder.out_rgb.out_channels, h, w])]
    if decoder.transform is not None and constant_transform(decoder.transform) is None:
        g.conv("coefficients", decoder.transform, coarse, area / 4 ** cfg.levels, weight_scale=cfg.transform_gain)
        outputs.append(helper.make_tensor_value_info("coefficients", TensorProto.FLOAT, [b, 12, "h", "w"]))
    graph = helper.make_graph([transpose] + g.nodes, "stylize3d_unet",
                              [helper.make_tensor_value_info("x_nhwc", TensorProto.FLOAT, [b, h, w, cin])],
                              outputs, g.initializers)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)], producer_name="stylize3d")
    model.ir_version = min(model.ir_version, 8)  # readable by every onnxruntime the project allows (>= 1.17)
    checker.check_model(model)
    return model


def _fingerprint(module: nn.Module) -> Tuple:
    """Changes whenever a parameter of ``module`` is replaced or modified in place."""
    return tuple((p.data_ptr(), p._version) for p in module.parameters())


class OnnxUNet:
    """The U-Net of one decoder in ONNX Runtime: :meth:`run`. One session per thread count (made at first use).

    Call it from one thread at a time (like the torch decoder: one render at a time); a run abandoned by a
    stop may still be ending beside the next one, which ONNX Runtime's sessions allow."""

    def __init__(self, decoder: UNetDecoder) -> None:
        self.levels = decoder.config.levels
        self.fingerprint = _fingerprint(decoder)
        self.model_bytes = unet_graph(decoder).SerializeToString()
        self.has_coefficients = decoder.transform is not None and constant_transform(decoder.transform) is None
        self._sessions: Dict[int, object] = {}
        self.abandoned: Optional[_Run] = None
        """The last run a stop left behind (it ends at its next node)."""

    def session(self, threads: int):
        s = self._sessions.get(threads)
        if s is None:
            import onnxruntime as ort
            so = ort.SessionOptions()
            so.intra_op_num_threads = int(threads)
            so.inter_op_num_threads = 1
            so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
            so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
            # the threads sleep between runs instead of spinning: the viewer's GUI thread and the
            # rasterizer's pool share the cores
            so.add_session_config_entry("session.intra_op.allow_spinning", "0")
            so.log_severity_level = 3
            s = self._sessions[threads] = ort.InferenceSession(self.model_bytes, so,
                                                               providers=["CPUExecutionProvider"])
        return s

    def run(self, x: torch.Tensor, should_stop: StopCheck = None,
            threads: Optional[int] = None) -> Tuple[torch.Tensor, Optional[torch.Tensor]]:
        """``x`` (B, C_in + 1, Hp, Wp) float32 (channels-last memory saves a copy) -> (``y``,
        ``coefficients`` or None) as float32 tensors. ``threads``: ONNX Runtime's intra-op threads (default:
        the calling thread's :func:`onnx_threads`, else torch's count).

        ``should_stop``: the run goes on a thread of its own while this one polls ``should_stop`` every
        :data:`POLL_S`; when it returns True this method raises :class:`RenderInterrupted` at once and the
        run is told to end (``RunOptions.terminate``, seen before its next node), its result dropped. So a
        stop takes ~2 ms, whatever node runs, and the run's core is free again within one node."""
        m = 2 ** self.levels
        if x.dim() != 4 or x.shape[-2] % m or x.shape[-1] % m:
            raise InputError("x", f"expected (B, C, H, W) with H and W multiples of {m}, got {tuple(x.shape)}")
        feed = {"x_nhwc": x.detach().to(torch.float32).permute(0, 2, 3, 1).contiguous().numpy()}
        sess = self.session(threads or decode_threads())
        if should_stop is None:
            return self._outputs(sess.run(None, feed))
        if should_stop():
            raise RenderInterrupted("render stopped before the decoder")
        run = _Run(sess, feed)
        run.start()
        while not run.done.wait(POLL_S):
            if should_stop():
                run.options.terminate = True
                self.abandoned = run
                raise RenderInterrupted("render stopped inside the decoder")
        if isinstance(run.result, BaseException):
            raise run.result
        return self._outputs(run.result)

    def run_or_none(self, x: torch.Tensor, should_stop: StopCheck = None):
        """:meth:`run`, or None where ONNX Runtime fails (an error that is not a stop): :func:`disable` warns
        once and the caller decodes this frame in torch (``UNetDecoder.forward``)."""
        try:
            return self.run(x, should_stop)
        except (RenderInterrupted, InputError):
            raise
        except Exception as exc:  # noqa: BLE001 (onnxruntime's own errors)
            disable(exc)
            return None

    def _outputs(self, outs) -> Tuple[torch.Tensor, Optional[torch.Tensor]]:
        y = torch.from_numpy(outs[0])
        return y, (torch.from_numpy(outs[1]) if self.has_coefficients else None)


class _Run(threading.Thread):
    """One session run on a thread of its own (:meth:`OnnxUNet.run` with ``should_stop``): ``result`` is the
    outputs, or the exception the run raised (a terminated run's among them); ``done`` is set after it."""

    def __init__(self, session, feed) -> None:
        import onnxruntime as ort
        super().__init__(name="stylize3d-decoder", daemon=True)
        self.session, self.feed = session, feed
        self.options = ort.RunOptions()
        self.options.log_severity_level = 3
        self.result = None
        self.done = threading.Event()
        _LIVE.add(self)

    def run(self) -> None:
        try:
            self.result = self.session.run(None, self.feed, self.options)
        except BaseException as exc:  # noqa: BLE001 (handed to the caller)
            self.result = exc
        finally:
            self.feed = None
            self.done.set()
            _LIVE.discard(self)


_LIVE: "weakref.WeakSet[_Run]" = weakref.WeakSet()


@atexit.register
def _terminate_live_runs() -> None:
    """At exit, runs still going (abandoned by a stop) are told to end and given a moment to: a daemon
    thread inside ONNX Runtime while the interpreter shuts down is not left to chance."""
    runs = list(_LIVE)
    for r in runs:
        r.options.terminate = True
    for r in runs:
        r.done.wait(1.0)


_LOCAL = threading.local()


@contextlib.contextmanager
def onnx_threads(n: Optional[int]) -> Iterator[None]:
    """Within the block, this thread's U-Net runs use ``n`` ONNX Runtime threads (None: torch's count), whatever
    torch's own count: ONNX Runtime's threads sleep when idle, so the viewer's full frames give the U-Net
    every core while torch's OpenMP work stays on one thread (two OpenMP threads spin, and lost several
    seconds a frame when another process held a core)."""
    if n is not None and (isinstance(n, bool) or not isinstance(n, int) or n < 1):
        raise InputError("onnx threads", f"must be None or an integer >= 1, got {n!r}")
    before = getattr(_LOCAL, "threads", None)
    _LOCAL.threads = n
    try:
        yield
    finally:
        _LOCAL.threads = before


AUTO_PIXELS_PER_THREAD = 120_000
"""``decoder_runtime="auto"`` runs ONNX Runtime for frames of at least this many (padded) pixels per thread
(:func:`prefers_onnx`), torch below: ONNX Runtime's lead grows with the frame, torch (oneDNN) is faster on
small ones. ``tests/benchmarks/bench_decoder_runtime.py``, version 7's U-Net (width 96) on this AVX2 machine (torch /
ONNX Runtime ms): one thread 264x180 88 / 95, 528x360 442 / 366, 784x528 1116 / 840; two threads 528x360 192 /
206, 784x528 605 / 452. Version 8's (width 64): one thread 264x180 47 / 48, 784x528 530 / 449; two threads
264x180 25 / 32, 784x528 320 / 283."""


def decode_threads() -> int:
    """The ONNX Runtime threads a run on this thread gets: :func:`onnx_threads`' count, else torch's."""
    return getattr(_LOCAL, "threads", None) or torch.get_num_threads()


def prefers_onnx(pixels: int) -> bool:
    """Whether ONNX Runtime decodes a frame of ``pixels`` (padded) faster than torch on this thread: where
    :func:`onnx_threads` gives it more threads than torch has, always (two ONNX Runtime threads beat one
    torch thread at every frame size); else from
    :data:`AUTO_PIXELS_PER_THREAD` pixels per thread."""
    threads = decode_threads()
    return threads > torch.get_num_threads() or pixels >= AUTO_PIXELS_PER_THREAD * threads


_RUNTIMES: "weakref.WeakKeyDictionary[UNetDecoder, OnnxUNet]" = weakref.WeakKeyDictionary()
_RUNTIMES_LOCK = threading.Lock()


def onnx_unet(decoder: UNetDecoder) -> OnnxUNet:
    """The :class:`OnnxUNet` of ``decoder`` (made at the first call, again whenever its weights changed;
    gone with the decoder)."""
    with _RUNTIMES_LOCK:
        rt = _RUNTIMES.get(decoder)
        if rt is None or rt.fingerprint != _fingerprint(decoder):
            rt = _RUNTIMES[decoder] = OnnxUNet(decoder)
        return rt


ENABLED = True
"""False after :func:`disable`: ``decoder_runtime="auto"`` decodes in torch."""


@functools.lru_cache(maxsize=None)
def _importable() -> bool:
    try:
        import onnx  # noqa: F401
        import onnxruntime  # noqa: F401
    except Exception:  # noqa: BLE001
        return False
    return True


def available() -> bool:
    """True where onnx and onnxruntime import (both are dependencies of the package; tried once per process)
    and no run failed (:func:`disable`). Asked at every render."""
    return ENABLED and _importable()


def disable(exc: BaseException) -> None:
    """ONNX Runtime failed to run the U-Net (an error that is not a stop): warn once, and let "auto" decode
    in torch from now on (the decoder reruns the failed frame in torch)."""
    global ENABLED
    if ENABLED:
        ENABLED = False
        warnings.warn(f"stylize3d: ONNX Runtime failed to run the decoder ({type(exc).__name__}: {exc}); "
                      "decoding in torch from now on", RuntimeWarning, stacklevel=3)
