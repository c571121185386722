"""Depth sources: every way a user can give a photo its depth (stage 2 in docs/architecture.md, "Pipeline stages").

Modules: ``types`` (DepthMap and PhotoDepth, the results), ``sources`` (the
DepthSource interface, its implementations and ``parse_depth_spec``), ``files``
(depth and disparity files: filling, range clamp, resizing), ``fill`` (nearest
fill), ``prior`` and ``foreground`` (the built-in prior), ``refine`` (edge
alignment), ``onnx_model`` (user-supplied ONNX networks), ``stereo`` (SGBM),
``phone_xmp`` (depth embedded by phone cameras). Import them directly; this
package imports nothing, so that ``scene`` can use ``depth.types`` without
loading onnxruntime. Depth sits above ``io`` (which reads the files) and below
``scene``; ``tests/test_layers.py`` checks the order.
"""
