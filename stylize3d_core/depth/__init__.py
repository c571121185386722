"""Depth sources: every way a user can give a photo its depth (stage 2 in docs/architecture.md, "Pipeline stages").

Modules: ``types`` (DepthMap, the one result), ``sources`` (the DepthSource
interface, its implementations and ``parse_depth_spec``), ``prior`` and
``foreground`` (the built-in prior), ``refine`` (edge alignment), ``onnx_model``
(user-supplied ONNX networks), ``stereo`` (SGBM), ``phone_xmp`` (depth embedded
by phone cameras). Import them directly; this package imports nothing, so that
``io`` can use ``depth.types`` without loading onnxruntime.
"""
