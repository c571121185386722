"""stylize3d core library: stylized 3D photos from one photo and one style image.

Layers (see the package folders): ``geometry`` (cameras, NDC, trajectories --
pure math), ``io`` (images, depth files, videos, point clouds), ``scene``
(depth, layered depth image, point cloud), ``render`` (point rasterizer).
The library never imports a GUI toolkit; the viewer in ``app/`` imports it.
"""

__version__ = "0.1.0"
