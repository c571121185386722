"""The U-Net in ONNX Runtime against the torch decoder (the reference): same frames, stopping, weights that
change, bad inputs."""

from __future__ import annotations

import threading

import onnx
import pytest
import torch

from stylize3d_core.errors import InputError, RenderInterrupted
from stylize3d_core.models import decoder_onnx
from stylize3d_core.models.decoder import DecoderConfig, UNetDecoder, constant_transform
from stylize3d_core.models.decoder_onnx import OnnxUNet, onnx_unet, unet_graph

TOL = 2e-5


def _decoder(texture=3, transform=3, varying_head=True, width=16, levels=2, seed=0) -> UNetDecoder:
    """A decoder with random weights everywhere (a new one starts with a zero texture and a constant head)."""
    torch.manual_seed(seed)
    cfg = DecoderConfig(in_channels=8 + 3 if transform else 8, width=width, levels=levels,
                        transform_channels=transform, transform_gain=1.0 / width, texture_channels=texture)
    dec = UNetDecoder(cfg).eval()
    with torch.no_grad():
        for name, p in dec.named_parameters():
            if name.startswith("transform.") and not varying_head:
                continue
            p.copy_(torch.randn_like(p) * (0.5 / max(1, p[0].numel()) ** 0.5 if p.dim() > 1 else 0.1))
    return dec


def _inputs(h, w, c, seed=1):
    g = torch.Generator().manual_seed(seed)
    mask = (torch.rand(1, 1, h, w, generator=g) > 0.2).float()
    feats = torch.randn(1, c, h, w, generator=g)
    if c > 8:
        feats[:, -3:] = torch.rand(1, 3, h, w, generator=g)
    return feats * mask, mask


@pytest.mark.parametrize("kind", ["texture + varying head", "texture + constant head", "no texture", "no transform",
                                  "3 levels"])
@pytest.mark.parametrize("hw", [(1, 1), (13, 22), (40, 33)])
def test_onnx_unet_gives_the_torch_decoders_frames(kind, hw):
    dec = {"texture + varying head": lambda: _decoder(),
           "texture + constant head": lambda: _decoder(varying_head=False),
           "no texture": lambda: _decoder(texture=0),
           "no transform": lambda: _decoder(texture=0, transform=0),
           "3 levels": lambda: _decoder(levels=3, width=24)}[kind]()
    feats, mask = _inputs(*hw, dec.config.in_channels)
    rt = OnnxUNet(dec)
    assert rt.has_coefficients == (kind in ("texture + varying head", "no texture", "3 levels"))
    with torch.inference_mode():
        ref = dec(feats, mask)
        out = dec(feats, mask, runtime=rt)
        stopped_never = dec(feats, mask, runtime=rt, should_stop=lambda: False)
    assert out.shape == ref.shape == (1, 3, *hw)
    assert (out - ref).abs().max().item() <= TOL
    assert torch.equal(out, stopped_never)


def test_the_graph_and_its_channel_groups(monkeypatch):
    dec = _decoder(width=32)
    model = unet_graph(dec)
    ops = [n.op_type for n in model.graph.node]
    assert ops[0] == "Transpose" and "Concat" in ops  # the input channels-last; the skips concatenated
    assert [o.name for o in model.graph.output] == ["y", "coefficients"]
    assert [d.dim_param for d in model.graph.input[0].type.tensor_type.shape.dim] == ["B", "H", "W", ""]
    plain = ops.count("Conv") + ops.count("ConvTranspose")
    assert plain == 2 * 3 + 2 * 2 + 2 + 1  # per level: skip + 2 down, transpose + conv; out_conv, out_rgb; head
    # a low limit splits the widest convolutions into groups of multiples of 8 channels: the same values
    monkeypatch.setattr(decoder_onnx, "NODE_MACS_PER_PIXEL", 500)
    split = unet_graph(dec)
    convs = [n for n in split.graph.node if n.op_type in ("Conv", "ConvTranspose")]
    assert len(convs) > plain
    weights = {t.name: t for t in split.graph.initializer}
    for n in convs:
        w = onnx.numpy_helper.to_array(weights[n.input[1]])
        channels = w.shape[1] if n.op_type == "ConvTranspose" else w.shape[0]
        assert channels % 8 == 0 or n.name in ("y", "coefficients") or channels < 8, (n.name, w.shape)
    feats, mask = _inputs(20, 28, 11)
    with torch.inference_mode():
        ref = dec(feats, mask)
        out = dec(feats, mask, runtime=OnnxUNet(dec))
    assert (out - ref).abs().max().item() <= TOL


def test_groups_known_values(monkeypatch):
    monkeypatch.setattr(decoder_onnx, "NODE_MACS_PER_PIXEL", 12_000)
    assert decoder_onnx._groups(96, 20_736) == 2  # the lite decoder's widest layer
    assert decoder_onnx._groups(96, 7_776) == 1
    assert decoder_onnx._groups(96, 100_000) == 12  # at most one group per 8 channels
    assert decoder_onnx._groups(12, 1e9) == 1  # 12 channels: no group of whole blocks of 8
    assert decoder_onnx._groups(24, 30_000) == 3


def test_a_stop_returns_at_once_and_the_session_stays_usable():
    dec = _decoder(width=64)
    rt = OnnxUNet(dec)
    feats, mask = _inputs(256, 384, 11)
    calls = []
    with torch.inference_mode():
        with pytest.raises(RenderInterrupted):
            dec(feats, mask, runtime=rt, should_stop=lambda: True)  # before the run
        flag = threading.Event()

        def stop() -> bool:
            calls.append(1)
            if len(calls) == 3:  # during the run (the first call is before it)
                flag.set()
            return flag.is_set()

        with pytest.raises(RenderInterrupted):
            dec(feats, mask, runtime=rt, should_stop=stop)
        assert flag.is_set()
        ref = dec(feats, mask)
        out = dec(feats, mask, runtime=rt, should_stop=lambda: False)  # the same session, right after
    assert (out - ref).abs().max().item() <= TOL


def test_an_abandoned_run_is_terminated():
    """The run left behind by a stop ends early (RunOptions.terminate: an error from ONNX Runtime), not
    after its last node (its outputs)."""
    dec = _decoder(width=64)
    rt = OnnxUNet(dec)
    x = torch.rand(1, 384, 512, 12).permute(0, 3, 1, 2)
    n = [0]

    def stop():  # stop at the third poll, a few ms into a run of ~0.2 s
        n[0] += 1
        return n[0] > 2

    with pytest.raises(RenderInterrupted):
        rt.run(x, should_stop=stop, threads=1)
    run = rt.abandoned
    assert run is not None and run.options.terminate
    assert run.done.wait(60)
    assert isinstance(run.result, Exception) and "terminate" in str(run.result).lower()
    y, _ = rt.run(x, threads=1)  # the session after a terminated run
    assert torch.isfinite(y).all()


def test_changed_weights_make_a_new_runtime():
    dec = _decoder()
    feats, mask = _inputs(16, 20, 11)
    rt = onnx_unet(dec)
    assert onnx_unet(dec) is rt
    with torch.no_grad():
        dec.out_conv.weight.mul_(1.5)  # in place
    rt2 = onnx_unet(dec)
    assert rt2 is not rt
    with torch.inference_mode():
        assert (dec(feats, mask, runtime=rt2) - dec(feats, mask)).abs().max().item() <= TOL
    dec.out_conv.weight = torch.nn.Parameter(dec.out_conv.weight.detach() * 0.5)  # replaced
    assert onnx_unet(dec) is not rt2


def test_a_zero_head_is_left_to_the_torch_side():
    dec = _decoder(varying_head=False)
    assert constant_transform(dec.transform) is not None
    assert [o.name for o in unet_graph(dec).graph.output] == ["y"]


def test_bad_uses():
    dec = _decoder()
    rt = OnnxUNet(dec)
    feats, mask = _inputs(8, 8, 11)
    with pytest.raises(InputError, match="runtime"):
        dec(feats, mask, runtime=rt)  # gradients on: the ONNX U-Net is inference only
    with torch.inference_mode():
        with pytest.raises(InputError, match="runtime"):
            dec(feats, mask, runtime=rt, bfloat16=True)
        with pytest.raises(InputError, match="multiples of 4"):
            rt.run(torch.zeros(1, 12, 10, 8))
    with pytest.raises(InputError, match="supersampling"):
        unet_graph(UNetDecoder(DecoderConfig(in_channels=4, width=8, supersample=True)))


def test_a_failing_runtime_falls_back_to_torch(monkeypatch):
    """An ONNX Runtime error (not a stop) warns once, the frame is decoded in torch, and "auto" stays off."""
    dec = _decoder()
    rt = OnnxUNet(dec)
    feats, mask = _inputs(12, 16, 11)

    def broken(*a, **k):
        raise RuntimeError("no kernel for this CPU")

    monkeypatch.setattr(rt, "run", broken)  # run_or_none catches it
    monkeypatch.setattr(decoder_onnx, "ENABLED", True)
    with torch.inference_mode():
        ref = dec(feats, mask)
        with pytest.warns(RuntimeWarning, match="decoding in torch"):
            out = dec(feats, mask, runtime=rt)
    assert torch.equal(out, ref)
    assert not decoder_onnx.available()
