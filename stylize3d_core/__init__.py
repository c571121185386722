"""stylize3d core library: stylized 3D photos from one photo and one style image.

Layers, one package each, in pipeline order:

* ``geometry`` -- cameras and conventions, NDC, trajectories (pure math);
* ``io`` -- images, depth files, videos, PLY, camera paths (atomic writes);
* ``depth`` -- depth sources (built-in prior, files, ONNX, stereo, phone XMP);
* ``scene`` -- layered depth image, point cloud, :class:`~stylize3d_core.scene.photo3d.Photo3D`;
* ``render`` -- differentiable point rasterizer, hole filling, plain renderer, reprojection;
* ``points`` -- FPS, ball query, 3-NN interpolation;
* ``models`` -- encoder, style features, AdaAttN, U-Net decoder, checkpoints;
* ``train`` / ``eval`` -- training data and trainer; consistency and view-synthesis metrics;
* :mod:`~stylize3d_core.stylize` and :mod:`~stylize3d_core.pipeline` -- the high-level API.

The library never imports a GUI toolkit; the viewer in ``app/`` imports it.
"""

__version__ = "0.1.0"
